"""The conversion pipeline: manifest -> WrinkleAsset -> stages -> one output folder.

``convert(manifest_path, out, options)`` runs, in order::

    ingest        manifest + files -> WrinkleAsset (maps +Y, float unit normals; masks [R, H, W])
    resample      states and masks to the manifest's resolutions
    mesh          tangents (MikkTSpace) and spatial-hash vertex IDs on the render mesh
    drivers       weight curves [T, R] from the manifest's drivers
    package       encode + pack (wrinklepipe.io.package)
    write         glTF (+GLB), USD (.usda, +.usdc/.usdz), PNG textures, DDS/KTX2, curves
    validate      wrinklepipe.validate on what was written (when available)
    report        report.json + report.html

Everything is written into a temporary sibling folder that is renamed into place only when
complete (:func:`wrinklepipe.atomic.staged_folder`); inputs are never written; reruns are
byte-identical. Each stage is a plain function, usable on its own.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from wrinklepipe.asset import Mesh, WrinkleAsset
from wrinklepipe.errors import input_error
from wrinklepipe.io.package import (
    WeightCurves,
    WrinklePackage,
    package_from_asset,
)

# ------------------------------------------------------------------------------------------------
# mesh stage


def _fallback_tangents(mesh: Mesh) -> np.ndarray:
    """Per-vertex tangents from UV derivatives (area-weighted, Gram-Schmidt, w = handedness).

    Used only when :mod:`wrinklepipe.geometry.tangents` (MikkTSpace) is not installed.
    """
    p = mesh.positions.astype(np.float64)
    uv = mesh.uvs.astype(np.float64) * np.array([1.0, -1.0])  # v up for the tangent frame
    n = mesh.normals.astype(np.float64)
    tri = mesh.indices.astype(np.int64)
    e1 = p[tri[:, 1]] - p[tri[:, 0]]
    e2 = p[tri[:, 2]] - p[tri[:, 0]]
    d1 = uv[tri[:, 1]] - uv[tri[:, 0]]
    d2 = uv[tri[:, 2]] - uv[tri[:, 0]]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    r = np.where(np.abs(det) > 1e-20, 1.0 / np.where(det == 0, 1.0, det), 0.0)[:, None]
    t = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * r
    b = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * r
    tacc = np.zeros_like(p)
    bacc = np.zeros_like(p)
    for c in range(3):
        np.add.at(tacc, tri[:, c], t)
        np.add.at(bacc, tri[:, c], b)
    tacc -= n * np.einsum("ij,ij->i", n, tacc)[:, None]
    norm = np.linalg.norm(tacc, axis=1, keepdims=True)
    # Degenerate: any vector perpendicular to n.
    alt = np.cross(n, np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    tacc = np.where(norm > 1e-12, tacc / np.maximum(norm, 1e-30), alt)
    tacc /= np.linalg.norm(tacc, axis=1, keepdims=True)
    w = np.where(np.einsum("ij,ij->i", np.cross(n, tacc), bacc) < 0.0, -1.0, 1.0)
    return np.concatenate([tacc, w[:, None]], axis=1).astype(np.float32)


def _fallback_vertex_ids(positions: np.ndarray) -> np.ndarray:
    """IDs shared by bit-identical positions, numbered by first appearance."""
    _, first, inverse = np.unique(positions, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return rank[inverse.reshape(-1)].astype(np.int64)


def prepare_mesh(mesh: Mesh) -> Mesh:
    """Give the render mesh what the writers need: normals, tangents (always) and vertex IDs."""
    notes = list(mesh.notes)
    if mesh.uvs is None:
        raise input_error(mesh.name, "mesh has no UVs (wrinkle maps need a UV layout)")
    if mesh.normals is None:
        from wrinklepipe.demo.character import vertex_normals

        mesh = replace(mesh, normals=vertex_normals(mesh.positions, mesh.indices))
        notes.append("computed area-weighted vertex normals")
    if mesh.tangents is None:
        try:
            from wrinklepipe.geometry.tangents import mikktspace_tangents

            tangents = mikktspace_tangents(mesh.positions, mesh.normals, mesh.uvs, mesh.indices)
            notes.append("computed MikkTSpace tangents")
        except ImportError:
            tangents = _fallback_tangents(mesh)
            notes.append("computed per-vertex UV tangents (MikkTSpace stage not installed)")
        mesh = replace(mesh, tangents=np.asarray(tangents, np.float32))
    if mesh.vertex_ids is None:
        try:
            from wrinklepipe.geometry.vertex_ids import compute_vertex_ids

            ids = compute_vertex_ids(mesh.positions)
            notes.append("computed spatial-hash vertex IDs")
        except ImportError:
            ids = _fallback_vertex_ids(mesh.positions)
            notes.append("computed vertex IDs by exact position (vertex-ids stage not installed)")
        mesh = replace(mesh, vertex_ids=np.asarray(ids, np.int64))
    return replace(mesh, notes=notes)


# ------------------------------------------------------------------------------------------------
# weights


def expression_cycle(asset: WrinkleAsset, seconds_per_expression: float = 1.0) -> WeightCurves:
    """Region weights ``[T, R]`` that visit each expression of the asset's table in turn.

    Keys: neutral at t = 0, expression i fully on at ``t = (i + 1) * seconds_per_expression``
    (linear in between, like the demo manifest's expression keys); rows are the table's region
    weights (Jimenez Table 1.1 for the demo).
    """
    names = asset.region_names
    exprs = list(asset.expressions)
    rows = [np.zeros(len(names), np.float32)]
    for e in exprs:
        rows.append(np.array([asset.expressions[e].get(r, 0.0) for r in names], np.float32))
    times = np.arange(len(rows), dtype=np.float32) * np.float32(seconds_per_expression)
    return WeightCurves("expressions", times, np.stack(rows))


def demo_package(size: int = 256, encoding: str = "pd") -> WrinklePackage:
    """The demo character, prepared and packaged (no files read): what the writers' tests use."""
    from wrinklepipe.demo import demo_asset

    asset = demo_asset(size, encoding=encoding)
    asset = replace(asset, mesh=prepare_mesh(asset.mesh))
    return package_from_asset(asset, curves=[expression_cycle(asset)])
