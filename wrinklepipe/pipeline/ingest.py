"""Ingest: a loaded manifest and the files it names -> a :class:`WrinkleAsset`.

Maps come back as float32 unit normals (+Y), wrinkle states as the whole wrinkled face, masks as
``[R, H, W]`` in [0, 1]; the mesh through :func:`wrinklepipe.io.mesh.load_mesh`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import masks as wm
from wrinklepipe import model
from wrinklepipe.asset import Mesh, Region, WrinkleAsset
from wrinklepipe.errors import input_error
from wrinklepipe.io.images import read_image
from wrinklepipe.io.mesh import load_mesh
from wrinklepipe.normals.read import ReadOptions, read_normal_map


def _read_normals(path: Path, convention: str) -> tuple[np.ndarray, list[str]]:
    """A normal map file -> unit normals ``[H, W, 3]`` (+Y) and notes (wrinklepipe.normals.read)."""
    nm = read_normal_map(path, ReadOptions(convention=convention))
    notes = [f"{path.name}: {nm.source_format}, convention {nm.convention}"]
    return np.asarray(nm.normals, np.float32), notes


def _load_mesh(path: Path) -> Mesh:
    """The render mesh (:func:`wrinklepipe.io.mesh.load_mesh`: glTF, USD, OBJ)."""
    return load_mesh(path)


def read_maps(manifest: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """The manifest's maps as read: base ``[H, W, 3]``, wrinkled-face states ``[K, H, W, 3]``
    (unit normals, +Y; wrinkle-only maps get the base added in PD space), masks ``[R, h, w]``,
    and notes on what was read."""
    notes: list[str] = []
    base, n = _read_normals(manifest.base, manifest.convention)
    notes += n
    states = []
    for s in manifest.states:
        st, n = _read_normals(s.map, manifest.convention)
        notes += n
        if st.shape != base.shape:
            raise input_error(
                s.map,
                f"size {st.shape[1]}x{st.shape[0]} differs from the base map "
                f"{base.shape[1]}x{base.shape[0]}",
            )
        if not manifest.states_include_base:  # wrinkle-only normals: add the base in PD space
            st = model.pd_to_normal(model.normal_to_pd(base) + model.normal_to_pd(st))
        states.append(st)
    channels = [r.channel for r in manifest.regions]
    if any(c is not None for c in channels):
        masks = []
        for r in manifest.regions:
            m, _ = wm.read_mask(r.mask) if r.channel is None else (_mask_channel(r), None)
            masks.append(m)
        mask_arr = np.stack(masks).astype(np.float32)
    else:
        ms = wm.read_masks(
            [r.mask for r in manifest.regions], names=[r.name for r in manifest.regions]
        )
        mask_arr = np.asarray(ms.masks, np.float32)
    return base, np.stack(states), mask_arr, notes


def ingest(manifest: Any) -> tuple[WrinkleAsset, list[str]]:
    """Read every file a manifest names into a :class:`WrinkleAsset` (float maps, +Y)."""
    base, states, mask_arr, notes = read_maps(manifest)
    mesh = _load_mesh(manifest.mesh) if manifest.mesh is not None else None
    if mesh is None:
        raise input_error(
            manifest.path, "the manifest names no mesh; glTF/USD output needs one", "mesh"
        )
    asset = WrinkleAsset(
        name=manifest.name,
        base=base,
        states=states,
        state_names=tuple(s.name for s in manifest.states),
        masks=mask_arr,
        regions=tuple(Region(r.name, r.side, tuple(r.states)) for r in manifest.regions),
        expressions={e: dict(row) for e, row in manifest.expressions.items()},
        encoding=manifest.encoding,
        policy=manifest.policy,
        pd_scale=1.0 if manifest.pd_scale == "auto" else float(manifest.pd_scale),
        mesh=mesh,
        drivers=[dict(d) for d in manifest.drivers],
        budget=dict(manifest.budget),
        resolution={k: v for k, v in manifest.resolution.items() if isinstance(v, int)},
        provenance={
            "manifest": manifest.path.name,
            "auto_resolution": sorted(k for k, v in manifest.resolution.items() if v == "auto"),
        },
    )
    return asset, notes


def _mask_channel(region: Any) -> np.ndarray:
    values, _ = read_image(region.mask)
    return values[..., "rgba".index(region.channel)].astype(np.float32)
