"""The drivers stage: the manifest's weight drivers -> per-region weight curves ``[T, R]``.

Each driver of the asset runs through :func:`wrinklepipe.drivers.evaluate`; an asset without
drivers gets a curve that visits each expression of its table in turn.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import drivers as wd
from wrinklepipe.asset import WrinkleAsset
from wrinklepipe.drivers.base import resolve
from wrinklepipe.drivers.clips import describe_clip
from wrinklepipe.drivers.curves import load_keys, morph_animation, sample_keys
from wrinklepipe.errors import InputError, Problem
from wrinklepipe.gltf.animation import read_morph_clips, read_morph_tracks
from wrinklepipe.package import WeightCurves
from wrinklepipe.readers.rig import GltfRig
from wrinklepipe.suffixes import is_gltf


def expression_cycle(asset: WrinkleAsset, seconds_per_expression: float = 1.0) -> WeightCurves:
    """Region weights ``[T, R]`` that visit each expression of the asset's table in turn.

    Keys: neutral at t = 0, expression i fully on at ``t = (i + 1) * seconds_per_expression``
    (linear in between, like the demo manifest's expression keys); rows are the table's region
    weights (Jimenez Table 1.1 for the demo).
    """
    names = asset.region_names
    exprs = list(asset.expressions)
    rows = [np.zeros(len(names), np.float32)]
    for e in exprs:
        rows.append(np.array([asset.expressions[e].get(r, 0.0) for r in names], np.float32))
    times = np.arange(len(rows), dtype=np.float32) * np.float32(seconds_per_expression)
    return WeightCurves("expressions", times, np.stack(rows))


def curves_from_weights(
    name: str, times: np.ndarray, weights: np.ndarray, region_states: np.ndarray
) -> tuple[WeightCurves, float]:
    """Driver weights ``[F, R, K]`` -> per-region curves ``[F, R]`` (+ the largest value lost).

    The extension animates one weight per region (spread over the states the region drives, as
    :meth:`DriverContext.spread` does); the value is read from the first state the region drives.
    The second value returned is ``max |w[f, r, k] - w_r[f] * region_states[r, k]|``, 0 when the
    driver's weights are of that form.
    """
    w = np.asarray(weights, np.float32)
    rs = np.asarray(region_states, np.float32)
    if w.shape[2] == 1:
        per_region = w[:, :, 0]
        lost = 0.0
    else:
        first = np.argmax(rs > 0, axis=1)
        per_region = np.take_along_axis(w, first[None, :, None], axis=2)[:, :, 0]
        lost = float(np.max(np.abs(w - per_region[:, :, None] * rs[None]), initial=0.0))
    return WeightCurves(name, np.asarray(times, np.float32), per_region.astype(np.float32)), lost


def morph_inputs(
    ctx: Any, spec: dict[str, Any], times: np.ndarray, names: tuple[str, ...]
) -> np.ndarray | None:
    """The morph-target weights ``[T, M]`` a blendshapes driver reads, sampled at ``times``
    (its glTF animation, keys or constant morphs, through :mod:`wrinklepipe.drivers.curves`),
    so the output plays the face and its wrinkles together. None when it has none."""
    t = np.asarray(times, np.float64)
    file = spec.get("file")
    if file is not None and is_gltf(file):
        _, got, x = morph_animation(ctx, resolve(ctx, str(file)), t, clip=spec.get("clip"))
        out = np.zeros((t.size, len(names)), np.float32)
        for j, n in enumerate(got):
            if n in names:
                out[:, names.index(n)] = x[:, j]
        return out
    if "morphs" in spec and "keys" not in spec and file is None:
        row = [float(spec["morphs"].get(n, 0.0)) for n in names]
        return np.tile(np.array(row, np.float32), (t.size, 1))
    keys, interp, _ = load_keys(ctx, spec)
    if not keys:
        return None
    return sample_keys(keys, names, t, interp or "linear").astype(np.float32)


def evaluate_drivers(
    asset: WrinkleAsset, root: Path, source: str | Path = ""
) -> tuple[list[WeightCurves], list[str]]:
    """Weight curves for each driver of the asset (wrinklepipe.drivers); notes on what happened.
    A bad driver spec is reported against ``source`` (the manifest) and its ``drivers[i]`` key."""
    notes: list[str] = []
    if not asset.drivers:
        return [expression_cycle(asset)] if asset.expressions else [], [
            "no drivers: a curve visiting each expression of the table was written"
        ]
    manifest = asset.provenance.get("manifest")
    ctx = wd.DriverContext.from_asset(
        asset,
        root,
        read_rig=GltfRig,
        read_morph_tracks=read_morph_tracks,
        source=str(Path(root) / manifest) if manifest else "<driver>",
        read_morph_clips=read_morph_clips,
    )
    curves: list[WeightCurves] = []
    used: set[str] = set()
    for i, spec in enumerate(asset.drivers):
        kind = str(spec["kind"])
        try:
            res = wd.evaluate(kind, ctx, spec)
        except InputError as exc:
            raise _in_manifest(exc, ctx.source, source, i) from None
        if res.per_vertex:
            notes.append(f"drivers[{i}] ({kind}) gives per-vertex weights; not written as a curve")
            continue
        name = str(spec.get("name") or kind)
        while name in used:
            name = f"{name}_{i}"
        used.add(name)
        curve, lost = curves_from_weights(name, res.times, res.weights, asset.region_state_matrix())
        curve.driver = {"index": i, "name": name, "kind": kind, **res.source}
        # the morph weights played with the curve are those of the clip the driver read
        played = {**spec, "clip": res.source["clip"]["index"]} if "clip" in res.source else spec
        if "clip" in res.source:
            notes.append(f"drivers[{i}] ({kind}) read {describe_clip(res.source['clip'])}")
        if kind == "blendshapes" and asset.mesh is not None and asset.mesh.morph_names:
            curve.morph_weights = morph_inputs(ctx, played, res.times, asset.mesh.morph_names)
        if lost > 1e-6:
            notes.append(f"drivers[{i}] ({kind}): per-state weights differ by up to {lost:.3g}")
        notes.extend(f"drivers[{i}] ({kind}): {n}" for n in res.notes)
        curves.append(curve)
    return curves, notes


def _in_manifest(exc: InputError, placeholder: str, source: str | Path, i: int) -> InputError:
    """``exc`` with the driver spec's problems placed in the manifest: its file and
    ``drivers[i].KEY`` (problems about another file keep theirs)."""
    if not source:
        return exc
    return InputError(
        [
            Problem(str(source), p.message, f"drivers[{i}]" + (f".{p.key}" if p.key else ""))
            if p.file == placeholder
            else p
            for p in exc.problems
        ]
    )
