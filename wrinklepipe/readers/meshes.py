"""Mesh ingest by file extension -> :class:`wrinklepipe.asset.Mesh`.

- :func:`load_meshes` returns one Mesh per glTF triangle primitive (per node instance), per USD
  ``Mesh`` prim, or per OBJ object/group.
- :func:`load_mesh` merges them into ONE Mesh (what the wrinkle pipeline wants for a face):
  indices are offset, morph targets are unioned by name (a part without a target gets zero
  deltas), skins are unioned by joint name, and an attribute only some parts have is filled
  (UVs 0, normals computed, tangents dropped so they are recomputed) and noted.

Both triangulate, keep the vertex splits that UV seams and hard edges need, skip degenerate
triangles with a counted note, and give meshes without UVs an xatlas layout (noted).
Bad input raises :class:`wrinklepipe.errors.InputError` naming the file (and key).
"""

from __future__ import annotations

import io
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.geometry.merge import merge_meshes
from wrinklepipe.readers.registry import LoadOptions as LoadOptions  # re-exported: callers' options
from wrinklepipe.readers.registry import read_meshes


def load_meshes(path: str | Path, options: LoadOptions | None = None) -> list[Mesh]:
    """Every mesh part of ``path`` as its own triangulated :class:`Mesh` (the reader of its
    suffix in :data:`wrinklepipe.readers.registry.READERS`)."""
    opts = options or LoadOptions()
    meshes = read_meshes(path, opts)
    if opts.generate_uvs:
        meshes = ensure_uvs_all(meshes)
    return meshes


def load_mesh(path: str | Path, options: LoadOptions | None = None) -> Mesh:
    """All parts of ``path`` merged into one :class:`Mesh` (see the module doc)."""
    meshes = load_meshes(path, options)
    if len(meshes) == 1:
        return meshes[0]
    merged = merge_meshes(meshes)
    merged.name = Path(path).stem
    return merged


#: The child that runs xatlas (a script: it imports only numpy and xatlas).
UV_LAYOUT_CHILD = Path(__file__).with_name("uv_layout_child.py")
#: Seconds the child may take: this plus :data:`UV_LAYOUT_SECONDS_PER_TRIANGLE` a triangle.
UV_LAYOUT_SECONDS = 120.0
UV_LAYOUT_SECONDS_PER_TRIANGLE = 1e-3
#: The arrays given to the child per part, and those it makes (``NAME_K`` for part ``K``).
_GIVEN = ("positions", "indices")
_MADE = ("vmap", "indices", "uvs")


def _uv_layouts(parts: list[tuple[np.ndarray, np.ndarray]]) -> list[tuple[np.ndarray, ...]]:
    """xatlas's layout of each ``(positions, indices)`` part (``vmap``, ``indices``, ``uvs``:
    what ``xatlas.parametrize`` returns for it), made in one child process that leaves before
    xatlas shuts its threads down (they can hang there:
    :mod:`wrinklepipe.readers.uv_layout_child`). A child that does not answer in time is
    stopped and tried once more; a child that fails raises its last line."""
    if not parts:
        return []
    given = io.BytesIO()
    arrays = {f"{name}_{k}": a for k, part in enumerate(parts) for name, a in zip(_GIVEN, part)}
    np.savez(given, **arrays)
    triangles = sum(len(indices) for _, indices in parts)
    limit = UV_LAYOUT_SECONDS + UV_LAYOUT_SECONDS_PER_TRIANGLE * triangles
    for _ in range(2):
        try:
            done = subprocess.run(
                [sys.executable, str(UV_LAYOUT_CHILD)],
                input=given.getvalue(),
                capture_output=True,
                timeout=limit,
                check=False,
            )
        except subprocess.TimeoutExpired:
            continue  # the child is killed; one more try
        if done.returncode != 0:
            last = (done.stderr.decode("utf-8", "replace").strip().splitlines() or ["?"])[-1]
            raise RuntimeError(f"xatlas could not lay out UVs ({triangles} triangles): {last}")
        with np.load(io.BytesIO(done.stdout)) as got:
            return [tuple(got[f"{name}_{k}"] for name in _MADE) for k in range(len(parts))]
    raise RuntimeError(f"xatlas did not lay out UVs ({triangles} triangles) in {limit:.0f} s")


def ensure_uvs_all(meshes: list[Mesh]) -> list[Mesh]:
    """Every mesh without UVs given an xatlas parametrisation (:func:`ensure_uvs`), all of
    them laid out by one child process; meshes with UVs as they are."""
    todo = [k for k, m in enumerate(meshes) if m.uvs is None]
    layouts = _uv_layouts(
        [
            (
                np.ascontiguousarray(meshes[k].positions, np.float32),
                np.ascontiguousarray(meshes[k].indices, np.uint32),
            )
            for k in todo
        ]
    )
    out = list(meshes)
    for k, layout in zip(todo, layouts, strict=True):
        out[k] = _laid_out(meshes[k], *layout)
    return out


def ensure_uvs(mesh: Mesh) -> Mesh:
    """Give a mesh without UVs an xatlas parametrisation (splits vertices along chart seams;
    every per-vertex attribute follows). Noted in ``mesh.notes``."""
    return ensure_uvs_all([mesh])[0]


def _laid_out(mesh: Mesh, vmap: np.ndarray, idx: np.ndarray, uvs: np.ndarray) -> Mesh:
    """``mesh`` with xatlas's layout: vertices split along chart seams (``vmap``: each new
    vertex's old one), every per-vertex attribute following, and a note."""
    vmap = vmap.astype(np.int64)

    def take(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.ascontiguousarray(a[vmap])

    note = (
        f"generated UVs with xatlas ({len(vmap)} vertices from {mesh.vertex_count};"
        f" {len(vmap) - mesh.vertex_count} added along chart seams)"
    )
    if mesh.tangents is not None:
        note += "; supplied tangents dropped (recompute them for the new UVs)"
    return replace(
        mesh,
        positions=take(mesh.positions),
        indices=idx.astype(np.uint32),
        uvs=uvs.astype(np.float32),
        normals=take(mesh.normals),
        tangents=None,
        morph_deltas=None if mesh.morph_deltas is None else mesh.morph_deltas[:, vmap],
        joints=take(mesh.joints),
        skin_weights=take(mesh.skin_weights),
        vertex_ids=take(mesh.vertex_ids),
        colors=take(mesh.colors),
        notes=[*mesh.notes, note],
    )
