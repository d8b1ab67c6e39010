"""Bake a driver: weight curves as JSON and CSV, and pre-blended normal maps per keyframe.

Pure parts: :func:`changed_frames` (which frames need a new map), :func:`weights_csv`,
:func:`blend_frames` (the maps through :func:`wrinklepipe.model.blend`), :func:`encode_states`
(full wrinkled normals -> what the encoding stores). I/O lives in :func:`load_maps` and
:func:`bake_manifest`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.drivers.base import DriverContext, DriverResult, evaluate, frame_times
from wrinklepipe.errors import InputError, input_error
from wrinklepipe.model import blend, normal_to_diff, normal_to_pd, pd_to_normal


@dataclass(frozen=True)
class BakeOptions:
    """``driver``: kind to bake (None: the manifest's first driver). ``maps``: also blend maps.
    ``fps``/``start``/``end``: sampling (None: the driver's own keys and fps). ``tolerance``:
    largest weight change that still counts as unchanged (0: exact). ``size``: map size (None:
    the base map's)."""

    driver: str | None = None
    maps: bool = False
    fps: float | None = None
    start: float | None = None
    end: float | None = None
    tolerance: float = 0.0
    size: int | None = None


def changed_frames(weights: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
    """Index of the rendered frame each frame uses ``[F]``: a frame is rendered when its weights
    differ from the last rendered frame's by more than ``tolerance`` (max abs)."""
    w = np.asarray(weights, np.float64).reshape(weights.shape[0], -1)
    use = np.zeros(w.shape[0], np.int64)
    last = 0
    for f in range(1, w.shape[0]):  # frames, not texels: a short loop
        if np.max(np.abs(w[f] - w[last]), initial=0.0) > tolerance:
            last = f
        use[f] = last
    return use


def weights_csv(res: DriverResult) -> str:
    """``time,<region>:<state>,...`` then one row per frame (6 decimals, deterministic)."""
    labels = (
        res.regions if not res.per_vertex else tuple(str(i) for i in range(res.weights.shape[1]))
    )
    cols = [f"{r}:{s}" for r in labels for s in res.states]
    lines = [",".join(["time", *cols])]
    flat = np.round(res.weights.reshape(res.weights.shape[0], -1).astype(np.float64), 6) + 0.0
    for t, row in zip(res.times, flat):
        lines.append(",".join([f"{t:.6f}", *(f"{v:.6f}" for v in row)]))
    return "\n".join(lines) + "\n"


def encode_states(
    base: np.ndarray, states: np.ndarray, encoding: str, include_base: bool = True
) -> np.ndarray:
    """Unit normals of the wrinkled face (``include_base``) or of the wrinkles alone -> what
    :func:`wrinklepipe.model.combine` takes for ``encoding``."""
    b = np.asarray(base, np.float32)
    w = np.asarray(states, np.float32)
    if not include_base:  # wrinkle-only normals: add their slopes to the base's
        w = pd_to_normal(normal_to_pd(b)[None] + normal_to_pd(w))
    if encoding == "pd":
        return (normal_to_pd(w) - normal_to_pd(b)[None]).astype(np.float32)
    if encoding == "diff":
        return normal_to_diff(w, b[None])
    if encoding == "full":
        return w
    if encoding == "composite":
        return pd_to_normal(normal_to_pd(w) - normal_to_pd(b)[None])
    raise ValueError(f"unknown encoding {encoding!r}")


def blend_frames(
    base: np.ndarray,
    states: np.ndarray,
    masks: np.ndarray,
    weights: np.ndarray,
    use: np.ndarray,
    encoding: str = "pd",
    policy: str = "clamp01",
) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(frame, normals [H, W, 3])`` for every frame that is rendered (``use[f] == f``)."""
    for f in np.flatnonzero(use == np.arange(len(use))):
        w = weights[f][:, 0] if policy == "signed" else weights[f]
        yield int(f), blend(base, states, masks, w, encoding, policy)


def load_maps(manifest: Any, size: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Base ``[H, W, 3]``, encoded states ``[K, H, W, C]`` and masks ``[R, H, W]`` at one size
    (the base's unless ``size``), read as ``convert`` reads them and resampled in PD space."""
    from wrinklepipe.io.package import resize_normals_pd
    from wrinklepipe.masks import resample_masks
    from wrinklepipe.pipeline.ingest import read_maps

    base, states, masks, _ = read_maps(manifest)
    h, w = (size, size) if size else base.shape[:2]
    base = resize_normals_pd(base, h, w)
    states = np.stack([resize_normals_pd(s, h, w) for s in states])
    masks = resample_masks(masks, (h, w))
    # read_maps returns the wrinkled face, so the states always include the base here
    return base, encode_states(base, states, manifest.encoding, True), masks


def load_mesh_for_drivers(path: Path | None) -> Mesh | None:
    """The manifest's mesh (morph names, skin) through :func:`wrinklepipe.io.mesh.load_mesh`."""
    if path is None:
        return None
    from wrinklepipe.io.mesh import load_mesh

    return load_mesh(path)


def _pick_driver(manifest: Any, kind: str | None) -> tuple[int, dict[str, Any]]:
    for i, d in enumerate(manifest.drivers):
        if kind is None or d.get("kind") == kind:
            return i, dict(d)
    have = sorted({str(d.get("kind")) for d in manifest.drivers}) or ["none"]
    want = f"kind = {kind!r}" if kind else "any kind"
    raise input_error(
        manifest.path, f"the manifest has no [[drivers]] of {want} (it has: {', '.join(have)})"
    )


def bake_manifest(
    manifest_path: Path, out: Path, options: BakeOptions | None = None, force: bool = False
) -> dict[str, Any]:
    """Load the manifest, evaluate its driver, write the output folder; return a summary."""
    from wrinklepipe.atomic import dumps_json, staged_folder, write_bytes
    from wrinklepipe.console import track
    from wrinklepipe.io.images import write_image
    from wrinklepipe.manifest import load_manifest

    opt = options or BakeOptions()
    manifest = load_manifest(manifest_path)
    index, spec = _pick_driver(manifest, opt.driver)
    kind = str(spec["kind"])
    needs_mesh = kind in ("blendshapes", "bones", "dynamic")
    mesh = load_mesh_for_drivers(manifest.mesh) if needs_mesh else None
    ctx = DriverContext.from_manifest(manifest, mesh)
    ctx.source = f"{manifest.path} [drivers[{index}]]"
    if opt.fps is not None:
        if opt.fps <= 0:
            raise InputError(f"--fps must be positive, got {opt.fps}", "<arguments>")
        spec["fps"] = opt.fps
    times = None
    if opt.start is not None or opt.end is not None:
        probe = evaluate(kind, ctx, spec)
        t0 = opt.start if opt.start is not None else float(probe.times[0])
        t1 = opt.end if opt.end is not None else float(probe.times[-1])
        times = frame_times(t0, t1, float(spec.get("fps", ctx.fps)))
    res = evaluate(kind, ctx, spec, times)
    if opt.maps and res.per_vertex:
        raise input_error(
            manifest.path,
            f"the {kind} driver gives per-vertex weights (no masks to blend); bake it without "
            "--maps",
            f"drivers[{index}]",
        )
    doc = res.to_json()
    doc["policy"] = manifest.policy
    doc["name"] = manifest.name
    doc["driver_index"] = index
    summary: dict[str, Any] = {
        "kind": kind,
        "frames": int(res.weights.shape[0]),
        "regions": int(res.weights.shape[1]),
        "states": int(res.weights.shape[2]),
        "per_vertex": res.per_vertex,
        "notes": list(res.notes),
        "output": str(out),
    }
    inputs = manifest.input_files
    with staged_folder(out, force=force, inputs=inputs) as tmp:
        if opt.maps:
            base, enc, masks = load_maps(manifest, opt.size)
            use = changed_frames(res.weights, opt.tolerance)
            files = {}
            rendered = np.flatnonzero(use == np.arange(len(use)))
            frames = blend_frames(
                base, enc, masks, res.weights, use, manifest.encoding, manifest.policy
            )
            for f, normals in track(frames, "blending maps", total=len(rendered)):
                name = f"maps/frame_{f:05d}.png"
                write_image(tmp / name, normals * 0.5 + 0.5, 16)
                files[f] = name
            doc["maps"] = {
                "files": [files[int(u)] for u in use],
                "rendered": len(rendered),
                "skipped": int(len(use) - len(rendered)),
                "encoding": "0.5 + 0.5 n, 16-bit RGB, OpenGL (+Y)",
            }
            summary["maps_rendered"] = len(rendered)
            summary["maps_skipped"] = int(len(use) - len(rendered))
        write_bytes(tmp / "weights.json", dumps_json(doc).encode("utf-8"))
        write_bytes(tmp / "weights.csv", weights_csv(res).encode("utf-8"))
    return summary
