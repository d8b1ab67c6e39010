"""Ingest of a manifest with UDIM tiles: one asset per tile, over the tile's triangles.

The mesh (USD or OBJ; a glTF mesh cannot carry tiles: the manifest refuses it) is read once,
whole, with its UDIM UVs. Each tile is then read as an ordinary asset
(:func:`wrinklepipe.pipeline.ingest.read_maps` on :meth:`Manifest.tile`): its base, states
and masks, over the mesh of the triangles that lie in it with their UVs moved into [0, 1]
(:func:`wrinklepipe.udim.tile_mesh`). Every later per-texel stage runs on these tile assets
unchanged; the whole mesh goes to the drivers and the writers.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wrinklepipe import udim
from wrinklepipe.asset import Mesh, WrinkleAsset
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.rasterise import rasterise_triangle_ids
from wrinklepipe.io.images import read_header
from wrinklepipe.names import noun
from wrinklepipe.pipeline.ingest import _asset, _load_mesh, _regions, read_maps
from wrinklepipe.readers.registry import format_of
from wrinklepipe.usd.source import UsdSource, read_usd_source


@dataclass
class TiledIngest:
    """What ingest read for a tiled manifest: ``whole``, the asset over the whole mesh (UDIM
    UVs; its maps are the first tile's, there for the drivers' sake: nothing per texel reads
    them), ``tiles`` one asset per tile that has wrinkled triangles (maps of that tile, mesh
    of its triangles), notes, and for a USD source its wrinkled meshes."""

    whole: WrinkleAsset
    tiles: dict[int, WrinkleAsset]
    notes: list[str] = field(default_factory=list)
    usd: UsdSource | None = None


def _mask_size(manifest: Any) -> tuple[int, int]:
    """The one size of every mask file (the manifest checked they share it)."""
    for key, got in manifest.tile_paths.items():
        if key.startswith("regions") and got:
            info = read_header(next(iter(got.values())))
            return info.height, info.width
    raise input_error(manifest.path, "no region names a mask file on any tile", "regions")


def read_tile(
    manifest: Any, tile: int, stats: dict[str, Any]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """One tile's maps (:func:`read_maps` on the tile's manifest): base, states, and the
    masks of every region (zero where a region has no mask on this tile)."""
    one = manifest.tile(tile)
    present = [i for i, r in enumerate(one.regions) if r.mask is not None]
    if present:
        sub = replace(one, regions=[one.regions[i] for i in present])
        base, states, got, notes = read_maps(sub, None, stats)
        h, w = got.shape[1:]
    else:  # no mask on this tile: read the normal maps with one region standing in
        base, states, _, notes = read_maps(replace(one, regions=[]), None, stats)
        h, w = _mask_size(manifest)
        got = np.zeros((0, h, w), np.float32)
    masks = np.zeros((len(one.regions), h, w), np.float32)
    masks[present] = got
    return base, states, masks, [f"tile {tile}: {n}" for n in notes]


def check_tiled_masks_on_mesh(tiles: dict[int, WrinkleAsset], manifest: Any) -> None:
    """Every region's mask touches the wrinkled triangles on some tile (a texel of a UV
    triangle of that tile); one message naming the regions that touch none."""
    touched = np.zeros(len(manifest.regions), bool)
    for a in tiles.values():
        r, h, w = a.masks.shape
        if not r or a.mesh is None or a.mesh.uvs is None:
            continue
        size = max(h, w)
        ids = rasterise_triangle_ids(a.mesh.uvs, a.mesh.indices, size)
        rows = np.minimum((np.arange(h) + 0.5) / h * size, size - 1).astype(np.int64)
        cols = np.minimum((np.arange(w) + 0.5) / w * size, size - 1).astype(np.int64)
        covered = ids[rows][:, cols] >= 0
        touched |= (a.masks > 0)[:, covered].any(axis=1)
    missing = [reg.name for reg, t in zip(manifest.regions, touched) if not t]
    if missing:
        raise input_error(
            manifest.path,
            f"the {noun(len(missing), 'mask')} of {noun(len(missing), 'region')} "
            f"{', '.join(map(repr, missing))} {noun(len(missing), 'falls', 'fall')} on no "
            f"wrinkled triangle of any tile ({', '.join(map(str, sorted(tiles)))})",
            "regions",
        )


def ingest_tiles(manifest: Any) -> TiledIngest:
    """Read a tiled manifest (see the module doc)."""
    if manifest.mesh is None:
        raise input_error(manifest.path, "the manifest names no mesh; UDIM tiles need one", "mesh")
    fmt = format_of(manifest.mesh)
    usd = None
    if fmt is not None and fmt.name == "usd":
        usd = read_usd_source(manifest)
        mesh: Mesh = usd.mesh
        notes = list(usd.notes)
    else:
        mesh = _load_mesh(manifest.mesh)
        notes = []
    where = f"{manifest.mesh.name} (the wrinkled meshes)"
    if mesh.uvs is None:
        raise input_error(manifest.mesh, "the wrinkled meshes have no UVs (UDIM tiles need them)")
    tri = udim.triangle_tiles(mesh.uvs, mesh.indices, where)
    used = sorted(int(t) for t in np.unique(tri))
    lacking = [t for t in used if t not in manifest.tiles]
    if lacking:
        raise input_error(
            manifest.path,
            f"the wrinkled meshes have triangles on "
            f"{noun(len(lacking), 'tile')} {', '.join(map(str, lacking))}, "
            f"which the base has no file for (its tiles: {', '.join(map(str, manifest.tiles))})",
            "base",
        )
    unused = [t for t in manifest.tiles if t not in used]
    if unused:
        notes.append(
            f"{noun(len(unused), 'tile')} {', '.join(map(str, unused))}: no wrinkled triangle "
            "lies there; not converted"
        )
    regions, warnings = _regions(manifest)
    stats: dict[str, Any] = {}
    tiles: dict[int, WrinkleAsset] = {}
    for t in used:
        tile_stats: dict[str, Any] = {}
        base, states, masks, n = read_tile(manifest, t, tile_stats)
        notes += n
        one = manifest.tile(t)
        asset = _asset(one, base, states, masks, udim.tile_mesh(mesh, t, tri), regions)
        asset.provenance["maps"] = tile_stats
        asset.provenance["warnings"] = list(warnings)
        asset.provenance["tile"] = t
        asset.color_only = tuple(k for k, s in enumerate(manifest.states) if s.map is None)
        if usd is not None and usd.problems:  # the validator reports them (WP-USD-xxx)
            asset.provenance["usd_composition"] = [p.to_json() for p in usd.problems]
        tiles[t] = asset
        stats[str(t)] = tile_stats
    check_tiled_masks_on_mesh(tiles, manifest)
    first = tiles[used[0]]
    whole = replace(first, mesh=mesh, provenance={**first.provenance, "maps": stats})
    whole.provenance.pop("tile", None)
    return TiledIngest(whole, tiles, notes, usd)
