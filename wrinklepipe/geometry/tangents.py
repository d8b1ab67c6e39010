"""MikkTSpace-compatible tangents (Mikkelsen 2008), vectorised in numpy.

What it reproduces of the reference implementation (mikktspace.c), per corner of each triangle:

- the face tangent ``vOs = t31.y * d1 - t21.y * d2`` normalised and multiplied by the sign of
  the signed UV area ``t21.x * t31.y - t21.y * t31.x`` (so mirrored UVs give the same direction
  of increasing u), and the orientation flag ``area > 0``;
- projection of the face tangent onto the plane of the vertex normal, then weighting by the
  corner angle measured in that plane;
- vertices are welded by identical (position, normal, UV) and accumulated per (welded vertex,
  orientation), so triangles with mirrored UVs never average with unmirrored ones;
- the result is normalised; ``w = +1`` for orientation-preserving, ``-1`` otherwise, then, as
  glTF viewers do with glTF's top-left UV origin (three.js ``negateSign``), ``w`` is negated,
  so ``bitangent = cross(normal, tangent.xyz) * w`` points along increasing *glTF* v... upward
  in the texture, i.e. towards decreasing glTF v (the OpenGL +Y normal-map convention).

Simplifications (documented, measured against supplied tangents in the tests): triangles with
zero UV area contribute nothing (mikktspace gives them their neighbours' frame); a render vertex
shared by both orientations takes the group with the larger angle weight; vertices with no
usable triangle get a tangent perpendicular to the normal (``fallback_vertices``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.reuse import reused

NAME = "tangents"


@dataclass
class TangentReport:
    """What :func:`mikktspace_tangents_report` had to approximate."""

    degenerate_uv_triangles: int = 0
    mixed_orientation_vertices: int = 0
    fallback_vertices: int = 0


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    ok = n[..., 0] > 1e-20
    return np.where(ok[..., None], v / np.where(ok[..., None], n, 1.0), 0.0), ok


def mikktspace_tangents(
    positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray, indices: np.ndarray
) -> np.ndarray:
    """Per-vertex tangents ``[V, 4]`` float32 (xyz unit, w = +-1), glTF conventions."""
    return mikktspace_tangents_report(positions, normals, uvs, indices)[0]


def mikktspace_tangents_report(
    positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray, indices: np.ndarray
) -> tuple[np.ndarray, TangentReport]:
    """:func:`mikktspace_tangents` plus a :class:`TangentReport` of the approximations."""
    # indices in one dtype, so that a mesh read back with uint32 indices is the same key
    idx = np.asarray(indices).astype(np.int64, copy=False).reshape(-1, 3)
    return _mikktspace(np.asarray(positions), np.asarray(normals), np.asarray(uvs), idx)


@reused  # the tangents convert computes are the validator's reference (the same written mesh)
def _mikktspace(
    positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray, idx: np.ndarray
) -> tuple[np.ndarray, TangentReport]:
    p = np.asarray(positions, dtype=np.float64)
    n_in = np.asarray(normals, dtype=np.float64)
    uv = np.asarray(uvs, dtype=np.float64)
    nv = len(p)
    if n_in.shape != (nv, 3) or uv.shape != (nv, 2):
        raise input_error("mesh", f"normals [V,3] and uvs [V,2] must match {nv} positions")
    if len(idx) and (idx.min() < 0 or idx.max() >= nv):
        raise input_error("mesh", "indices out of range")
    rep = TangentReport()
    nrm, _ = _unit(n_in)

    # Weld by identical (position, normal, uv), as mikktspace does internally.
    key = np.concatenate([p, nrm, uv], axis=1) + 0.0
    _, weld = np.unique(key, axis=0, return_inverse=True)
    weld = weld.reshape(-1)

    tri_p = p[idx]
    tri_uv = uv[idx]
    d1 = tri_p[:, 1] - tri_p[:, 0]
    d2 = tri_p[:, 2] - tri_p[:, 0]
    t21 = tri_uv[:, 1] - tri_uv[:, 0]
    t31 = tri_uv[:, 2] - tri_uv[:, 0]
    area = t21[:, 0] * t31[:, 1] - t21[:, 1] * t31[:, 0]
    v_os = t31[:, 1:2] * d1 - t21[:, 1:2] * d2
    v_os, ok_os = _unit(v_os)
    v_os *= np.sign(area)[:, None]
    usable = ok_os & (area != 0)
    rep.degenerate_uv_triangles = int((~usable).sum())
    orient = area > 0  # orientation preserving

    acc_key = np.zeros((len(idx), 3), dtype=np.int64)
    contrib = np.zeros((len(idx), 3, 3))
    weight = np.zeros((len(idx), 3))
    for c in range(3):  # the three corners of every triangle (not a loop over vertices)
        vi = idx[:, c]
        nc = nrm[vi]
        proj = v_os - nc * np.einsum("ij,ij->i", nc, v_os)[:, None]
        proj, okp = _unit(proj)
        e_a = tri_p[:, (c + 1) % 3] - tri_p[:, c]
        e_b = tri_p[:, (c + 2) % 3] - tri_p[:, c]
        e_a = e_a - nc * np.einsum("ij,ij->i", nc, e_a)[:, None]
        e_b = e_b - nc * np.einsum("ij,ij->i", nc, e_b)[:, None]
        e_a, _ = _unit(e_a)
        e_b, _ = _unit(e_b)
        ang = np.arccos(np.clip(np.einsum("ij,ij->i", e_a, e_b), -1.0, 1.0))
        w = np.where(usable & okp, ang, 0.0)
        contrib[:, c] = proj * w[:, None]
        weight[:, c] = w
        acc_key[:, c] = weld[vi] * 2 + orient

    n_groups = 2 * (int(weld.max()) + 1 if nv else 0)
    flat_key = acc_key.reshape(-1)
    acc = np.stack(
        [np.bincount(flat_key, contrib[:, :, k].reshape(-1), n_groups) for k in range(3)], -1
    )
    wsum = np.bincount(flat_key, weight.reshape(-1), n_groups)

    # Per render vertex: its welded vertex's group with the larger angle weight.
    w_pos = wsum[weld * 2 + 1]
    w_neg = wsum[weld * 2]
    use_pos = w_pos >= w_neg
    rep.mixed_orientation_vertices = int(((w_pos > 0) & (w_neg > 0)).sum())
    g = weld * 2 + use_pos.astype(np.int64)
    t, ok = _unit(acc[g])
    sign = np.where(use_pos, 1.0, -1.0)
    # Fallback: any direction perpendicular to the normal.
    bad = ~ok
    rep.fallback_vertices = int(bad.sum())
    if bad.any():
        nb = nrm[bad]
        axis = np.where(
            (np.abs(nb[:, 0]) < 0.9)[:, None], np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
        )
        fb = axis - nb * np.einsum("ij,ij->i", nb, axis)[:, None]
        t[bad] = _unit(fb)[0]
        sign[bad] = 1.0
    # glTF's UV origin is top-left: negate w (three.js negateSign, Blender's exporter).
    out = np.concatenate([t, -sign[:, None]], axis=1)
    return out.astype(np.float32), rep


def ensure_tangents(mesh: Mesh) -> Mesh:
    """Keep supplied tangents; otherwise compute MikkTSpace tangents (noted in ``notes``)."""
    if mesh.tangents is not None:
        return mesh
    if mesh.uvs is None or mesh.normals is None:
        raise input_error(mesh.name, "tangents need UVs and normals")
    t, rep = mikktspace_tangents_report(mesh.positions, mesh.normals, mesh.uvs, mesh.indices)
    note = "computed MikkTSpace tangents"
    extra = [f"{v} {k.replace('_', ' ')}" for k, v in vars(rep).items() if v]
    if extra:
        note += " (" + ", ".join(extra) + ")"
    return replace(mesh, tangents=t, notes=[*mesh.notes, note])
