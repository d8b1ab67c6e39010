"""UDIM tiles: numbering, file patterns, a mesh and a package seen one tile at a time.

A UDIM texture is a set of tiles, one image per unit square of UV space: tile ``1001`` covers
``u`` in [0, 1] and USD's ``t`` (``v`` up) in [0, 1], ``1002`` the next square to the right,
``1011`` the square above ``1001`` (ten tiles to a row)::

    tile = 1001 + floor(u) + 10 floor(t)          t = 1 - v   (v: glTF's, down, as stored here)

File names carry the tile number where a pattern says ``<UDIM>`` (``face.<UDIM>.png`` ->
``face.1001.png``, ``face.1002.png`` ...), as USD, MaterialX, Mari and Houdini write them.

Every per-texel stage runs on one tile at a time: a tile is an ordinary single-texture
asset whose mesh is the triangles of that tile with their UVs moved into [0, 1]
(:func:`tile_mesh`). A tiled :class:`~wrinklepipe.package.WrinklePackage` (``tiles`` set)
holds every tile's textures under ``NAME.TILE`` (``base_normal.1001``); its description names
them ``NAME`` and its writers write ``NAME.<UDIM>`` where a format has UDIM (USD, MaterialX);
:func:`tile_package` is one tile of it as a plain package, with the tile's textures and
mesh, what every single-texture consumer (the validator, the glTF writer per primitive, the
block copies) takes. Plain data and numpy only (core).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import replace

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.metadata import CompressedCopy, MaskMeta, StateMeta, WrinkleMeta
from wrinklepipe.names import noun, plural
from wrinklepipe.package import PackedTexture, WrinklePackage

#: The token a file pattern names the tile number with.
TOKEN = "<UDIM>"
FIRST = 1001
#: The last tile number (ten tiles to a row, 900 rows: what a 4-digit number holds).
LAST = 9999
#: How far a vertex of a triangle may lie outside its tile's square (float32 UVs on a border).
EDGE = 1e-5
_TILE_SUFFIX = re.compile(r"^(?P<stem>.+)\.(?P<tile>[1-9][0-9]{3})$")


def valid(tile: int) -> bool:
    """Whether ``tile`` is a UDIM tile number (1001 .. 9999)."""
    return FIRST <= int(tile) <= LAST


def tile_number(column: int, row: int) -> int:
    """The tile of UV square ``column`` (floor of u, 0..9), ``row`` (floor of USD's t)."""
    if not 0 <= column <= 9 or row < 0:
        raise ValueError(f"UV square ({column}, {row}) has no UDIM tile (u in 0..10, t >= 0)")
    return FIRST + column + 10 * row


def tile_square(tile: int) -> tuple[int, int]:
    """``(column, row)`` of a tile: its square is u in [column, column + 1], USD t in
    [row, row + 1] (glTF v in [-row, 1 - row])."""
    if not valid(tile):
        raise ValueError(f"{tile} is not a UDIM tile number (1001..9999)")
    k = int(tile) - FIRST
    return k % 10, k // 10


def to_tile(uvs: np.ndarray, tile: int) -> np.ndarray:
    """UVs (glTF convention) of tile ``tile`` moved into [0, 1]: ``(u - column, v + row)``."""
    col, row = tile_square(tile)
    out = np.array(uvs, dtype=np.float32, copy=True)
    out[:, 0] -= np.float32(col)
    out[:, 1] += np.float32(row)
    return out


def from_tile(uvs: np.ndarray, tile: int) -> np.ndarray:
    """Inverse of :func:`to_tile`: UVs in [0, 1] placed on tile ``tile``."""
    col, row = tile_square(tile)
    out = np.array(uvs, dtype=np.float32, copy=True)
    out[:, 0] += np.float32(col)
    out[:, 1] -= np.float32(row)
    return out


def pattern_path(pattern: str, tile: int) -> str:
    """``pattern`` with its ``<UDIM>`` replaced by the tile number."""
    return pattern.replace(TOKEN, str(int(tile)))


def tiled_name(stem: str, tile: int) -> str:
    """The name of a tile's texture in a tiled package: ``stem.TILE``."""
    return f"{stem}.{int(tile)}"


def split_name(name: str) -> tuple[str, int | None]:
    """``stem.TILE`` -> ``(stem, TILE)``; a name without a tile suffix -> ``(name, None)``."""
    m = _TILE_SUFFIX.match(name)
    if m is None or not valid(int(m["tile"])):
        return name, None
    return m["stem"], int(m["tile"])


# ------------------------------------------------------------------------------------------------
# the mesh, one tile at a time


def triangle_tiles(uvs: np.ndarray, indices: np.ndarray, where: str = "mesh") -> np.ndarray:
    """The tile of each triangle ``[T]`` (by the centre of its UVs), refusing a triangle
    whose corners lie in two tiles (a UDIM layout keeps every face inside one square) or
    outside every tile (u < 0 or u >= 10, t < 0)."""
    uv = np.asarray(uvs, np.float64)[np.asarray(indices, np.int64)]  # [T, 3, 2]
    u, t = uv[..., 0], 1.0 - uv[..., 1]
    col = np.floor(u.mean(axis=1))
    row = np.floor(t.mean(axis=1))
    outside = (col < 0) | (col > 9) | (row < 0) | (row > (LAST - FIRST) // 10)
    if outside.any():
        k = int(np.flatnonzero(outside)[0])
        raise input_error(
            where,
            f"{plural(int(outside.sum()), 'triangle')} {noun(int(outside.sum()), 'lies', 'lie')} "
            f"outside the UDIM tiles (u in [0, 10), t >= 0), "
            f"the first at UV ({u[k].mean():.4g}, {t[k].mean():.4g})",
        )
    spans = (
        (u < col[:, None] - EDGE).any(1)
        | (u > col[:, None] + 1 + EDGE).any(1)
        | (t < row[:, None] - EDGE).any(1)
        | (t > row[:, None] + 1 + EDGE).any(1)
    )
    tiles = (FIRST + col + 10 * row).astype(np.int64)
    if spans.any():
        k = int(np.flatnonzero(spans)[0])
        corners = ", ".join(f"({a:.4g}, {b:.4g})" for a, b in zip(u[k], t[k]))
        raise input_error(
            where,
            f"{plural(int(spans.sum()), 'triangle')} {noun(int(spans.sum()), 'spans', 'span')} "
            f"two UDIM tiles (a face must lie inside one "
            f"tile's square); the first, in tile {tiles[k]}, has UVs {corners}",
        )
    return tiles


def mesh_tiles(mesh: Mesh, where: str = "") -> tuple[int, ...]:
    """The tiles the mesh's triangles lie in, ascending."""
    if mesh.uvs is None:
        raise input_error(where or mesh.name, "mesh has no UVs (UDIM tiles need a UV layout)")
    return tuple(
        int(t) for t in np.unique(triangle_tiles(mesh.uvs, mesh.indices, where or mesh.name))
    )


def tile_mesh(mesh: Mesh, tile: int, tiles: np.ndarray | None = None) -> Mesh:
    """The triangles of ``tile`` as a mesh of their own: the vertices they use (in their
    order), every per-vertex array cut alike, UVs moved into [0, 1] (:func:`to_tile`).
    ``tiles``: :func:`triangle_tiles` of the mesh (computed when not given). The source
    ``parts`` keep their runs (corner maps, which address the whole prim, are dropped)."""
    if mesh.uvs is None:
        raise input_error(mesh.name, "mesh has no UVs (UDIM tiles need a UV layout)")
    tri = triangle_tiles(mesh.uvs, mesh.indices, mesh.name) if tiles is None else tiles
    idx = np.asarray(mesh.indices)[tri == tile]
    keep = np.unique(idx)
    remap = np.full(mesh.vertex_count, -1, np.int64)
    remap[keep] = np.arange(keep.size)

    def cut(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.asarray(a)[keep]

    parts = []
    for p in mesh.parts:
        lo, hi = np.searchsorted(keep, [p.start, p.start + p.count])
        if hi > lo:
            parts.append(replace(p, start=int(lo), count=int(hi - lo), corners=None))
    return replace(
        mesh,
        positions=np.asarray(mesh.positions)[keep],
        indices=remap[idx].astype(np.asarray(mesh.indices).dtype),
        uvs=to_tile(np.asarray(mesh.uvs)[keep], tile),
        normals=cut(mesh.normals),
        tangents=cut(mesh.tangents),
        morph_deltas=None if mesh.morph_deltas is None else np.asarray(mesh.morph_deltas)[:, keep],
        joints=cut(mesh.joints),
        skin_weights=cut(mesh.skin_weights),
        vertex_ids=cut(mesh.vertex_ids),
        colors=cut(mesh.colors),
        parts=tuple(parts),
        notes=[],  # what ingest did is the whole mesh's, said once
    )


# ------------------------------------------------------------------------------------------------
# a tiled package and its tiles


def _renamed(
    meta: WrinkleMeta, name: Callable[[str], str], path: Callable[[str], str]
) -> WrinkleMeta:
    """``meta`` with every texture name through ``name`` and every copy's file through
    ``path``."""
    return replace(
        meta,
        states=tuple(
            StateMeta(s.name, name(s.texture), None if s.color is None else name(s.color), s.normal)
            for s in meta.states
        ),
        masks=MaskMeta(
            meta.masks.layout, tuple(name(n) for n in meta.masks.textures), meta.masks.table
        ),
        compressed=tuple(
            replace(
                c,
                texture=name(c.texture),
                ktx2=path(c.ktx2) if c.ktx2 else "",
                dds=path(c.dds) if c.dds else "",
            )
            for c in meta.compressed
        ),
        base_color=None if meta.base_color is None else name(meta.base_color),
    )


def tile_package(pkg: WrinklePackage, tile: int) -> WrinklePackage:
    """One tile of a tiled package as a plain package: that tile's textures (named
    ``NAME.TILE``, as the files are), the description naming them so, the copies' files
    with the tile number for ``<UDIM>``, and the mesh of the tile's triangles
    (:func:`tile_mesh`). A plain package is returned as it is."""
    if not pkg.tiles:
        return pkg
    if tile not in pkg.tiles:
        raise input_error(
            pkg.name, f"tile {tile} is not one of the package's tiles {list(pkg.tiles)}"
        )
    textures = [t for t in pkg.textures if split_name(t.name)[1] == tile]
    meta = _renamed(pkg.meta, lambda n: tiled_name(n, tile), lambda p: pattern_path(p, tile))
    return WrinklePackage(pkg.name, tile_mesh(pkg.mesh, tile), textures, meta, pkg.curves)


def join_tiles(packages: Mapping[int, WrinklePackage], mesh: Mesh) -> WrinklePackage:
    """Plain packages, one per tile, joined into one tiled package over the whole ``mesh``
    (UDIM UVs): every texture renamed ``NAME.TILE``, one description for all (a tile's
    names may already carry its number, as a tile of a written asset does). The tiles must
    describe the wrinkles alike (encoding, scale, states, regions, the mask layout and
    channel table, the copies' formats): what one material can say for every tile."""
    tiles = sorted(packages)
    if not tiles:
        raise ValueError("join_tiles needs at least one tile")
    metas = {t: _untiled(packages[t].meta, t) for t in tiles}
    first = packages[tiles[0]]
    meta = metas[tiles[0]]
    for t in tiles[1:]:
        if _shared(metas[t]) != _shared(meta):
            raise input_error(
                first.name,
                f"tile {t} is described differently from tile {tiles[0]} ("
                + ", ".join(_differences(_shared(meta), _shared(metas[t])))
                + "): one material holds one description for every tile",
            )
    textures = [
        PackedTexture(tiled_name(_strip(tex.name, t), t), tex.pixels, tex.role)
        for t in tiles
        for tex in packages[t].textures
    ]
    return WrinklePackage(first.name, mesh, textures, meta, first.curves, tuple(tiles))


def _strip(name: str, tile: int) -> str:
    """``stem.TILE`` -> ``stem`` (a name without this tile's number: as it is)."""
    stem, t = split_name(name)
    return stem if t == tile else name


def _untiled(meta: WrinkleMeta, tile: int) -> WrinkleMeta:
    """A tile's description with its names freed of the tile number and its copies' files
    as ``<UDIM>`` patterns."""

    return _renamed(meta, lambda n: _strip(n, tile), lambda p: _copy_pattern(p, tile))


def untiled_copies(copies: Iterable[CompressedCopy]) -> tuple[CompressedCopy, ...]:
    """The records of a tiled package's block copies, made one per tile texture
    (``base_normal.1001``, files ``compressed/base_normal.1001.dds``), as the package's
    description holds them: one per map (``base_normal``, ``compressed/base_normal.<UDIM>.dds``),
    every tile's alike (format, layout, levels: one UDIM set), sorted by texture."""
    out: dict[str, CompressedCopy] = {}
    for c in copies:
        stem, tile = split_name(c.texture)
        if tile is None:
            out[c.texture] = c
            continue
        joined = replace(
            c,
            texture=stem,
            ktx2=_copy_pattern(c.ktx2, tile) if c.ktx2 else "",
            dds=_copy_pattern(c.dds, tile) if c.dds else "",
        )
        if stem in out and out[stem] != joined:
            raise input_error(
                stem,
                f"the tiles' block copies differ ({out[stem].to_json()} vs {joined.to_json()}): "
                "one UDIM set has one format, layout and mip count",
            )
        out[stem] = joined
    return tuple(out[k] for k in sorted(out))


def _copy_pattern(path: str, tile: int) -> str:
    """A tile's copy file (``compressed/base_normal.1001.dds``) as the ``<UDIM>`` pattern."""
    head, dot, ext = path.rpartition(".")
    folder, slash, stem = head.rpartition("/")
    return f"{folder}{slash}{_strip(stem, tile)}.{TOKEN}{dot}{ext}"


def _shared(meta: WrinkleMeta) -> dict[str, object]:
    """What every tile's description must say alike."""
    return {
        "encoding": meta.encoding,
        "scale": meta.scale,
        "mapping": meta.mapping,
        "policy": meta.policy,
        "states": meta.states,
        "masks": meta.masks,
        "regions": meta.regions,
        "expressions": meta.expressions,
        "drivers": meta.drivers,
        "weights": meta.weights,
        "copies": tuple(
            (c.texture, c.format, c.layout, c.mapping, c.color_space) for c in meta.compressed
        ),
        "base_color": meta.base_color,
        "color_factor": meta.color_factor,
    }


def _differences(a: Mapping[str, object], b: Mapping[str, object]) -> list[str]:
    return [f"{k}: {a[k]!r} vs {b[k]!r}"[:160] for k in a if a[k] != b[k]]


def tile_files(pattern_or_paths: str | Mapping[int, str], found: Iterable[str]) -> dict[int, str]:
    """The tiles a ``<UDIM>`` pattern names among ``found`` (file names or relative paths,
    as a folder listing gives them): ``{tile: path}``, ascending."""
    if not isinstance(pattern_or_paths, str):
        return {int(k): str(v) for k, v in sorted(pattern_or_paths.items())}
    pattern = pattern_or_paths
    head, token, tail = pattern.partition(TOKEN)
    if not token:
        raise ValueError(f"{pattern!r} has no {TOKEN}")
    rx = re.compile(re.escape(head) + r"([1-9][0-9]{3})" + re.escape(tail) + r"$")
    out = {}
    for f in found:
        m = rx.match(f)
        if m is not None and valid(int(m[1])):
            out[int(m[1])] = f
    return dict(sorted(out.items()))
