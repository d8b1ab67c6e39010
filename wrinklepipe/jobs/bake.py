"""``bake``: evaluate a manifest's driver over its animation and write the curves (JSON, CSV)
and, optionally, a pre-blended normal map per keyframe, into one staged folder.

The pure parts are :mod:`wrinklepipe.drivers.bake`; maps are read as ``convert`` reads them
(:func:`wrinklepipe.pipeline.ingest.read_maps`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.atomic import dumps_json, staged_folder, write_bytes
from wrinklepipe.console import track
from wrinklepipe.drivers.bake import blend_frames, changed_frames, encode_states, weights_csv
from wrinklepipe.drivers.base import DriverContext, TooManyFrames, evaluate, frame_times
from wrinklepipe.errors import InputError, input_error
from wrinklepipe.gltf.animation import read_morph_clips, read_morph_tracks
from wrinklepipe.io.images import write_image
from wrinklepipe.masks import resample_masks
from wrinklepipe.pipeline.ingest import read_maps
from wrinklepipe.pipeline.package import resize_normals_pd
from wrinklepipe.readers.meshes import load_mesh
from wrinklepipe.readers.rig import GltfRig
from wrinklepipe.sources.manifest import load_manifest

#: The blended maps' side (``--size``): the range a manifest's ``[resolution]`` allows.
MIN_MAP_SIDE, MAX_MAP_SIDE = 4, 8192


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


def load_maps(manifest: Any, size: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Base ``[H, W, 3]``, encoded states ``[K, H, W, C]`` and masks ``[R, H, W]`` at one size
    (the base's unless ``size``), read as ``convert`` reads them and resampled in PD space."""
    base, states, masks, _ = read_maps(manifest)
    h, w = (size, size) if size else base.shape[:2]
    base = resize_normals_pd(base, h, w)
    states = np.stack([resize_normals_pd(s, h, w) for s in states])
    masks = resample_masks(masks, (h, w))
    # read_maps returns the wrinkled face, so the states always include the base here
    return base, encode_states(base, states, manifest.encoding, True), masks


def load_mesh_for_drivers(path: Path | None) -> Mesh | None:
    """The manifest's mesh (morph names, skin) through
    :func:`wrinklepipe.readers.meshes.load_mesh`."""
    if path is None:
        return None
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
    opt = options or BakeOptions()
    if opt.size is not None and not MIN_MAP_SIDE <= opt.size <= MAX_MAP_SIDE:  # before any read
        raise input_error(
            "--size",
            f"{opt.size} is out of range; expected {MIN_MAP_SIDE}..{MAX_MAP_SIDE} (the sizes "
            "[resolution] allows)",
        )
    manifest = load_manifest(manifest_path)
    index, spec = _pick_driver(manifest, opt.driver)
    kind = str(spec["kind"])
    needs_mesh = kind in ("blendshapes", "bones", "dynamic")
    mesh = load_mesh_for_drivers(manifest.mesh) if needs_mesh else None
    ctx = DriverContext.from_manifest(
        manifest,
        mesh,
        read_rig=GltfRig,
        read_morph_tracks=read_morph_tracks,
        read_morph_clips=read_morph_clips,
    )
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
        try:
            times = frame_times(t0, t1, float(spec.get("fps", ctx.fps)))
        except TooManyFrames as exc:
            raise InputError(f"{kind} driver: {exc}", "--start/--end") from None
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
