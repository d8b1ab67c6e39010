"""Small analytic meshes for tests and benchmarks: a UV sphere with a seam, a capped-less tube.

Both are render meshes in the glTF sense: the seam column is a bit-identical copy of the first
column (different UVs), as an exporter writes it.
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.asset import Mesh


def _grid_indices(rows: int, cols: int) -> np.ndarray:
    """Two counter-clockwise triangles per quad of a ``rows x cols`` vertex grid."""
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = (r * cols + c).reshape(-1)
    b = a + 1
    d = a + cols
    e = d + 1
    tris = np.stack([np.stack([a, d, b], -1), np.stack([b, d, e], -1)], axis=1)
    return tris.reshape(-1, 3).astype(np.uint32)


def uv_sphere(n_lon: int = 32, n_lat: int = 16, radius: float = 1.0) -> Mesh:
    """Lat-long sphere with a UV seam at longitude 0 (column duplicated) and pole vertices per
    column (so each polar fan triangle has its own UV). Outward normals, glTF UVs."""
    theta = np.linspace(0.0, np.pi, n_lat + 1)  # includes the poles: rows 0 and n_lat
    phi = np.linspace(0.0, 2.0 * np.pi, n_lon + 1)
    t, ph = np.meshgrid(theta, phi, indexing="ij")
    st = np.sin(t)
    st[0, :] = 0.0
    st[-1, :] = 0.0
    ct = np.cos(t)
    ct[0, :] = 1.0
    ct[-1, :] = -1.0
    x = st * np.cos(ph)
    z = st * np.sin(ph)
    x[:, -1] = x[:, 0]  # bit-identical seam twins
    z[:, -1] = z[:, 0]
    n = np.stack([x, ct, -z], axis=-1).reshape(-1, 3)
    pos = (radius * n).astype(np.float32)
    uv = np.stack([ph / (2 * np.pi), t / np.pi], axis=-1).reshape(-1, 2).astype(np.float32)
    idx = _grid_indices(n_lat + 1, n_lon + 1)
    tri = pos[idx].astype(np.float64)
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    idx = idx[area2 > 1e-12 * radius * radius]  # drop the degenerate halves of polar quads
    tri = pos[idx].astype(np.float64)
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("ij,ij->i", nrm, tri.mean(axis=1)) < 0
    idx[flip] = idx[flip][:, [0, 2, 1]]
    return Mesh(
        positions=pos,
        indices=idx,
        uvs=uv,
        normals=n.astype(np.float32),
        name="uv_sphere",
    )


def tube(n_around: int = 32, n_along: int = 8, radius: float = 1.0, length: float = 2.0) -> Mesh:
    """Open cylinder along +Y with a UV seam (first column duplicated), outward normals."""
    phi = np.linspace(0.0, 2.0 * np.pi, n_around + 1)
    y = np.linspace(0.0, length, n_along + 1)
    yy, ph = np.meshgrid(y, phi, indexing="ij")
    x = np.cos(ph)
    z = np.sin(ph)
    x[:, -1] = x[:, 0]
    z[:, -1] = z[:, 0]
    pos = np.stack([radius * x, yy, -radius * z], axis=-1).reshape(-1, 3).astype(np.float32)
    nrm = np.stack([x, 0 * yy, -z], axis=-1).reshape(-1, 3).astype(np.float32)
    uv = np.stack([ph / (2 * np.pi), 1.0 - yy / length], axis=-1).reshape(-1, 2)
    idx = _grid_indices(n_along + 1, n_around + 1)
    tri = pos[idx].astype(np.float64)
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    radial = tri.mean(axis=1) * np.array([1.0, 0.0, 1.0])
    flip = np.einsum("ij,ij->i", cr, radial) < 0
    idx[flip] = idx[flip][:, [0, 2, 1]]
    return Mesh(positions=pos, indices=idx, uvs=uv.astype(np.float32), normals=nrm, name="tube")
