"""Wavefront OBJ ingest: ``v``/``vt``/``vn``/``f`` with ``o``/``g`` parts -> Meshes.

Render vertices are the distinct ``(v, vt, vn)`` corner triples of a part (the vertex split
that UV seams and hard edges need); polygons are fan-triangulated (OBJ faces are planar and
convex in practice; the count is noted); negative (relative) indices are resolved. OBJ's V
axis points up, so ``v`` is flipped to the glTF convention (noted). The text is parsed line by
line (file parsing); every per-vertex step is vectorised.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.polygons import drop_degenerate, fan_triangles, weld_corners
from wrinklepipe.names import plural


def _floats(rows: list[list[str]], width: int, file: str, what: str) -> np.ndarray:
    if not rows:
        return np.zeros((0, width))
    try:
        return np.array([r[:width] + ["0"] * (width - len(r[:width])) for r in rows], float)
    except ValueError:
        raise input_error(file, f"a {what} line has a value that is not a number") from None


#: The largest magnitude a mesh value may have: meshes are stored as float32 (glTF, USD).
FLOAT32_MAX = float(np.finfo(np.float32).max)


def _check_float32(rows: np.ndarray, file: str, what: str, key: str) -> None:
    """Every value finite and inside float32's range (a larger one would become infinite)."""
    if not len(rows):
        return
    nonfinite = ~np.isfinite(rows).all(axis=1)
    if nonfinite.any():
        bad = int(np.flatnonzero(nonfinite)[0])
        raise input_error(file, f"{what} {bad + 1} is NaN or infinite", key=f"{key} {bad + 1}")
    huge = (np.abs(rows) > FLOAT32_MAX).any(axis=1)
    if huge.any():
        bad = int(np.flatnonzero(huge)[0])
        raise input_error(
            file,
            f"{what} {bad + 1} has a value beyond float32's range (|x| > {FLOAT32_MAX:.4g})",
            key=f"{key} {bad + 1}",
        )


def read_obj_meshes(path: str | Path) -> list[Mesh]:
    """One :class:`Mesh` per ``o``/``g`` part that has faces."""
    file = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise input_error(file, f"cannot read: {exc}") from None
    v: list[list[str]] = []
    vt: list[list[str]] = []
    vn: list[list[str]] = []
    parts: list[tuple[str, list[list[str]]]] = [("default", [])]
    for line in text.splitlines():
        tok = line.split()
        if not tok:
            continue
        head = tok[0]
        if head == "v":
            v.append(tok[1:4])
        elif head == "vt":
            vt.append(tok[1:3])
        elif head == "vn":
            vn.append(tok[1:4])
        elif head == "f":
            parts[-1][1].append(tok[1:])
        elif head in ("o", "g"):
            name = " ".join(tok[1:]) or head
            if parts[-1][1]:
                parts.append((name, []))
            else:
                parts[-1] = (name, [])
    pos_all = _floats(v, 3, file, "v")
    uv_all = _floats(vt, 2, file, "vt")
    nrm_all = _floats(vn, 3, file, "vn")
    for rows, what, key in (
        (pos_all, "position", "v"),
        (uv_all, "UV", "vt"),
        (nrm_all, "normal", "vn"),
    ):
        _check_float32(rows, file, what, key)
    out = []
    for name, faces in parts:
        if not faces:
            continue
        out.append(_part(file, name, faces, pos_all, uv_all, nrm_all))
    if not out:
        raise input_error(file, "no faces (f lines)")
    return out


def _part(
    file: str,
    name: str,
    faces: list[list[str]],
    pos_all: np.ndarray,
    uv_all: np.ndarray,
    nrm_all: np.ndarray,
) -> Mesh:
    counts = np.array([len(f) for f in faces])
    if counts.min() < 3:
        raise input_error(file, f"part {name!r} has a face with fewer than 3 corners")
    corners = [c.split("/") for f in faces for c in f]
    try:
        trip = np.array(
            [[int(c[0]), int(c[1]) if len(c) > 1 and c[1] else 0,
              int(c[2]) if len(c) > 2 and c[2] else 0] for c in corners],
            dtype=np.int64,
        )  # fmt: skip
    except ValueError:
        raise input_error(file, f"part {name!r} has a face index that is not an integer") from None
    sizes = np.array([len(pos_all), len(uv_all), len(nrm_all)])
    # 1-based; negative = relative to the end; 0 = absent (-1 after this).
    trip = np.where(trip > 0, trip - 1, np.where(trip < 0, sizes + trip, -1))
    has = trip >= 0
    bad = (trip >= sizes) | ((trip < 0) & (trip != -1))
    if bad.any():
        k = int(np.flatnonzero(bad.any(axis=1))[0])
        raise input_error(file, f"part {name!r}: face index out of range at corner {k}")
    if not has[:, 0].all():
        raise input_error(file, f"part {name!r}: a face corner has no position index")
    use_uv = bool(has[:, 1].all()) and len(uv_all) > 0
    use_n = bool(has[:, 2].all()) and len(nrm_all) > 0
    key = trip * np.array([1, int(use_uv), int(use_n)])
    # Render vertices by first appearance (stable, file order); every polygon a fan.
    corner_vertex, src = weld_corners(key)
    verts = key[src]
    tris = corner_vertex[fan_triangles(counts)]
    positions = pos_all[verts[:, 0]].astype(np.float32)
    tris, n_degen = drop_degenerate(positions, tris)
    notes = []
    if (counts > 3).any():
        notes.append(f"fan-triangulated {plural(int((counts > 3).sum()), 'polygon')}")
    if n_degen:
        notes.append(f"skipped {plural(n_degen, 'degenerate triangle')}")
    if len(tris) == 0:
        raise input_error(file, f"part {name!r}: every triangle is degenerate")
    uvs = None
    if use_uv:
        uvs = uv_all[verts[:, 1]].astype(np.float32)
        uvs[:, 1] = 1.0 - uvs[:, 1]
        notes.append("flipped V (OBJ v up -> glTF v down)")
    normals = nrm_all[verts[:, 2]].astype(np.float32) if use_n else None
    return Mesh(
        positions=positions,
        indices=tris.astype(np.uint32),
        uvs=uvs,
        normals=normals,
        name=name,
        notes=notes,
    )
