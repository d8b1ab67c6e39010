"""The poses an asset's drivers actually produce: what the render pass draws and fidelity measures.

:func:`driver_poses` returns, in order:

- ``neutral`` (every weight 0);
- for an asset without drivers, or with an ``expressions`` driver: each expression of its table
  at full amount (name order), named by the expression;
- for every weight curve of another driver (``blendshapes``, ``curves``, and any other driver
  written as a region-weight curve): the frames where each region's weight peaks (its first
  maximum), so every region the curve drives is shown at least once; frames shared by several
  regions are drawn once. They are named by what drives them (:func:`pose_name`): the blend
  shapes weighted at that frame, ``Surprised @ 1.0 s``, else the regions peaking there,
  ``brow_L peak @ 1.0 s`` (with the curve's name added when two frames would share a name); a
  curve's morph-target weights at that frame (a blendshapes driver's inputs) come along, so the
  face can be shown in the shape that produced the wrinkles.

Per-vertex drivers (``bones``, ``dynamic``) give no region curve; they add no pose here.
Weights are ``[R, K]`` (``[R]`` under the ``signed`` policy), as the validator and
:func:`wrinklepipe.model.blend` take them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wrinklepipe.asset import WrinkleAsset

#: Driver kinds that give per-vertex weights (never written as a region curve).
PER_VERTEX_KINDS = ("bones", "dynamic")


@dataclass(frozen=True)
class DriverPose:
    """One pose: its name, the region weights and, for a curve frame, where it comes from."""

    name: str
    weights: np.ndarray  # [R, K] ([R] under "signed")
    curve: str | None = None
    time: float | None = None
    regions: tuple[str, ...] = ()  # the regions whose weight peaks here
    morphs: dict[str, float] = field(default_factory=dict)  # morph weights at this frame


def _shape(asset: WrinkleAsset, per_region: np.ndarray) -> np.ndarray:
    w = np.asarray(per_region, np.float32)
    if asset.policy == "signed":
        return w
    return w[:, None] * asset.region_state_matrix()


def seconds(t: float) -> str:
    """``1.0``, ``1.25``, ``0.042``: a time in seconds, to the millisecond, one decimal at
    least."""
    text = f"{t:.3f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


def pose_name(morphs: dict[str, float], regions: Sequence[str], t: float) -> str:
    """A curve frame named by what drives it: the blend shapes weighted there, strongest
    first (``Surprised @ 1.0 s``, ``Angry + Sad @ 2.5 s``), else the regions whose weight
    peaks there (``brow_L, brow_R peak @ 1.0 s``)."""
    if morphs:
        top = [n for n, _ in sorted(morphs.items(), key=lambda kv: (-abs(kv[1]), kv[0]))]
        what = " + ".join(top[:2]) + (f" + {len(top) - 2} more" if len(top) > 2 else "")
    else:
        shown = list(regions[:3])
        what = ", ".join(shown) + (f" + {len(regions) - 3} more" if len(regions) > 3 else "")
        what += " peak"
    return f"{what} @ {seconds(t)} s"


def curve_kinds(drivers: Sequence[dict[str, Any]]) -> dict[str, str]:
    """Curve name -> driver kind, named as :func:`wrinklepipe.pipeline.drivers.evaluate_drivers`
    names the curves it writes (``name`` or the kind, ``_i`` added to repeats)."""
    used: dict[str, str] = {}
    for i, spec in enumerate(drivers):
        kind = str(spec.get("kind", ""))
        if kind in PER_VERTEX_KINDS:
            continue
        name = str(spec.get("name") or kind)
        while name in used:
            name = f"{name}_{i}"
        used[name] = kind
    return used


def driver_poses(
    asset: WrinkleAsset, curves: Sequence[Any] = (), morph_names: Sequence[str] = ()
) -> list[DriverPose]:
    """Neutral, the expression table (when an expressions driver, or none, plays it) and each
    curve's per-region peak frames (see the module doc).

    ``curves``: objects with ``name``, ``times`` ``[T]``, ``values`` ``[T, R]`` and optionally
    ``morph_weights`` ``[T, M]`` (:class:`wrinklepipe.package.WeightCurves`);
    ``morph_names``: the names of those morph columns (default: the asset mesh's)."""
    regions = asset.region_names
    poses = [DriverPose("neutral", _shape(asset, np.zeros(len(regions), np.float32)))]
    kinds = curve_kinds(asset.drivers)
    table = not asset.drivers or "expressions" in kinds.values()
    if table:
        for e in sorted(asset.expressions):
            row = np.zeros(len(regions), np.float32)
            for r, w in asset.expressions[e].items():
                if r in regions:
                    row[regions.index(r)] += np.float32(w)
            poses.append(DriverPose(e, _shape(asset, row)))
    if not morph_names and asset.mesh is not None:
        morph_names = asset.mesh.morph_names
    taken = {p.name for p in poses}
    for c in curves:
        if kinds.get(str(c.name)) == "expressions" or (table and str(c.name) == "expressions"):
            continue  # the table itself (or the cycle convert writes through it)
        values = np.asarray(c.values, np.float32)
        times = np.asarray(c.times, np.float64)
        if values.ndim != 2 or values.shape[1] != len(regions) or not len(values):
            continue
        peaks: dict[int, list[str]] = {}
        for r, name in enumerate(regions):
            col = np.abs(values[:, r])
            if float(col.max()) > 0:
                peaks.setdefault(int(np.argmax(col)), []).append(name)
        morph = getattr(c, "morph_weights", None)
        for f in sorted(peaks):
            shape: dict[str, float] = {}
            if morph is not None and len(morph_names) == np.shape(morph)[1]:
                shape = {n: float(v) for n, v in zip(morph_names, np.asarray(morph)[f]) if v}
            name = pose_name(shape, peaks[f], float(times[f]))
            if name in taken:
                name = f"{name} ({c.name})"
            taken.add(name)
            poses.append(
                DriverPose(
                    name,
                    _shape(asset, values[f]),
                    str(c.name),
                    float(times[f]),
                    tuple(peaks[f]),
                    shape,
                )
            )
    return poses
