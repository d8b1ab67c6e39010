"""Sculpts with known wrinkles, made from a real mesh: CesiumMan's face plate subdivided and
displaced along its normal by analytic heights in UV space.

The face plate of CesiumMan (``../shared/data``) is planar (its face and vertex normals agree to
0 degrees), so the displaced surface ``S = p + H(u, v) n`` has the exact normal
``normalize(n - grad_s H)``: in any tangent frame of the plate, the PD slopes of a wrinkle are
``(-grad_s H . T, -grad_s H . B)``, with ``grad_s H = J (J^T J)^-1 (H_u, H_v)`` and ``J`` the
plate's 3 x 2 Jacobian ``dp / d(u, v)``. Heights are :class:`wrinklepipe.demo.fields.Field`
values, so ``H_u`` and ``H_v`` are exact.

- ``compress``: creases across the face (along u), ``stretch``: creases down it (along v), each
  a period of ``PERIOD`` disc units inside a soft square window; ``DEPTH`` UV units deep, times
  the plate's mesh units per UV unit (so slopes in the tangent frame are about the UV slopes).
- The sculpt is the low mesh with the plate's triangles replaced by their ``LEVELS``-times
  midpoint subdivision (own vertices; T-junctions at the plate's border lie where ``H = 0``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from wrinklepipe.asset import Mesh
from wrinklepipe.demo import fields as F
from wrinklepipe.demo.face_fixture import FaceDisc, face_disc

CESIUM = (
    Path(__file__).resolve().parents[1].parent
    / "shared"
    / "data"
    / "gltf-samples"
    / "CesiumMan"
    / "glTF-Binary"
    / "CesiumMan.glb"
)
LEVELS = 4
PERIOD = 0.2  # disc units (the disc's radius is 1)
DEPTH = 0.0035  # UV units
STATES = ("compress", "stretch")


def heights(u: F.Field, v: F.Field, disc: FaceDisc, state: str | None) -> F.Field:
    """The state's height (UV units) at the points ``u``, ``v``; 0 for the neutral (None)."""
    if state is None:
        return F.const(u, 0.0)
    fx = (u - disc.cu) / disc.ru
    fy = (v - disc.cv) / disc.rv
    window = F.box(fx, -0.5, 0.5, 0.12) * F.box(fy, -0.5, 0.5, 0.12)
    q = fy if state == "compress" else fx
    lines = ((1.0 + F.cos(q * (2.0 * np.pi / PERIOD))) * 0.5).pow(2)
    return -lines * window * DEPTH


def _field(x: np.ndarray, du: float, dv: float) -> F.Field:
    return F.Field(x, np.full_like(x, du), np.full_like(x, dv))


@dataclass
class Sculpts:
    """The low mesh, the plate's disc and triangles, the scale (mesh units per UV unit) and
    the high meshes (neutral and each state) as trimesh meshes."""

    low: Mesh
    disc: FaceDisc
    plate: np.ndarray  # [P] indices of the plate's triangles in low.indices
    scale: float
    highs: dict[str, trimesh.Trimesh]


def make_sculpts(low: Mesh, levels: int = LEVELS) -> Sculpts:
    """The neutral sculpt and one per state (see the module doc)."""
    disc = face_disc(low)
    uv = np.asarray(low.uvs, np.float64)
    fx = (uv[:, 0] - disc.cu) / disc.ru
    fy = (uv[:, 1] - disc.cv) / disc.rv
    inside = (fx * fx + fy * fy) < 0.9
    idx = np.asarray(low.indices, np.int64)
    plate = np.flatnonzero(inside[idx].all(axis=1))
    rest = np.setdiff1d(np.arange(len(idx)), plate)
    p = np.asarray(low.positions, np.float64)
    tri = p[idx[plate]]
    a3 = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    t = uv[idx[plate]]
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    auv = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    scale = float(np.sqrt(a3 / auv))
    n = np.asarray(low.normals, np.float64)
    n_plate = n[idx[plate]].mean(axis=(0, 1))
    n_plate /= np.linalg.norm(n_plate)
    # the plate's triangles with their own vertices, subdivided
    flat = idx[plate].reshape(-1)
    v, f = p[flat], np.arange(len(flat)).reshape(-1, 3)
    attrs = {"uv": uv[flat]}
    for _ in range(levels):
        v, f, attrs = trimesh.remesh.subdivide(v, f, vertex_attributes=attrs)
    highs = {}
    for state in (None, *STATES):
        h = heights(_field(attrs["uv"][:, 0], 1, 0), _field(attrs["uv"][:, 1], 0, 1), disc, state)
        disp = v + (h.f * scale)[:, None] * n_plate[None, :]
        pos = np.concatenate([p, disp])
        faces = np.concatenate([idx[rest], f + len(p)])
        highs[state or "neutral"] = trimesh.Trimesh(pos, faces, process=False)
    return Sculpts(low, disc, plate, scale, highs)


def expected_slopes(s: Sculpts, state: str, size: int, supersample: int) -> tuple:
    """The analytic PD slopes of ``state`` at every sample of a ``size`` map (the samples the
    baker takes: ``(x + (j + 0.5) / s) / size``) inside the plate, in the plate's tangent frame
    (T from the low mesh's tangents, orthonormalised; B = cross(N, T) w), averaged per texel
    as unit normals: ``(slopes [H, W, 2], texels inside the plate [H, W] bool)``."""
    low = s.low
    idx = np.asarray(low.indices, np.int64)
    n_ss = size * supersample
    c = (np.arange(n_ss) + 0.5) / n_ss
    uu, vv = np.meshgrid(c, c)
    h = heights(_field(uu, 1, 0), _field(vv, 0, 1), s.disc, state)
    # the plate's Jacobian and frame (constant: the plate is planar; any plate triangle)
    t0 = idx[s.plate[0]]
    p = np.asarray(low.positions, np.float64)[t0]
    uv = np.asarray(low.uvs, np.float64)[t0]
    duv = np.stack([uv[1] - uv[0], uv[2] - uv[0]], axis=1)  # [2, 2]: columns are edges
    dp = np.stack([p[1] - p[0], p[2] - p[0]], axis=1)  # [3, 2]
    jac = dp @ np.linalg.inv(duv)  # dp / d(u, v)
    n = np.cross(dp[:, 0], dp[:, 1])
    n /= np.linalg.norm(n)
    tang = np.asarray(low.tangents, np.float64)[t0].mean(axis=0)
    n_low = np.asarray(low.normals, np.float64)[t0].mean(axis=0)
    n = n if n @ n_low > 0 else -n
    tt = tang[:3] - n * (n @ tang[:3])
    tt /= np.linalg.norm(tt)
    b = np.cross(n, tt) * (-1.0 if tang[3] < 0 else 1.0)
    grad_uv = np.stack([h.du, h.dv], axis=-1) * s.scale  # mesh units per UV unit
    g = grad_uv @ (jac @ np.linalg.inv(jac.T @ jac)).T  # [.., 3]
    nrm = n - g
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    ts = np.stack([nrm @ tt, nrm @ b, nrm @ n], axis=-1)
    ts = ts.reshape(size, supersample, size, supersample, 3).mean(axis=(1, 3))
    ts /= np.linalg.norm(ts, axis=-1, keepdims=True)
    fx = ((np.arange(size) + 0.5) / size - s.disc.cu) / s.disc.ru
    fy = ((np.arange(size) + 0.5) / size - s.disc.cv) / s.disc.rv
    inside = (fx[None, :] ** 2 + fy[:, None] ** 2) < 0.8
    return ts[..., :2] / ts[..., 2:3], inside
