"""The ``vertex-ids`` job: spatial-hash vertex IDs of a mesh file and their summary (Oat).

:func:`mesh_vertex_ids` reads the mesh (every part merged, no UV generation), runs
:func:`wrinklepipe.geometry.vertex_ids.compute_vertex_ids` and returns the IDs and the summary
the command prints and writes beside them (:mod:`wrinklepipe.outputs.per_vertex`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.errors import input_error
from wrinklepipe.geometry.vertex_ids import VertexIdOptions, compute_vertex_ids
from wrinklepipe.readers.meshes import LoadOptions, load_mesh


def mesh_vertex_ids(
    path: str | Path, options: VertexIdOptions | None = None
) -> tuple[np.ndarray, dict[str, Any]]:
    """IDs ``[V]`` (int64) of the render vertices of the mesh ``path`` and the summary (counts
    of IDs and of the split vertices sharing one, the tolerance used, the reader's notes)."""
    o = options or VertexIdOptions()
    if o.tolerance is not None and not o.tolerance >= 0:
        raise input_error("<arguments>", f"--tolerance must be >= 0, got {o.tolerance}")
    if not o.relative_tolerance >= 0:
        raise input_error("<arguments>", f"--relative must be >= 0, got {o.relative_tolerance}")
    mesh = load_mesh(path, LoadOptions(generate_uvs=False))
    p = mesh.positions.astype(np.float64)
    tol = (
        o.tolerance
        if o.tolerance is not None
        else float(np.linalg.norm(p.max(0) - p.min(0))) * o.relative_tolerance
    )
    ids = compute_vertex_ids(mesh.positions, options=o, source=str(path))
    counts = np.bincount(ids)
    summary = {
        "mesh": str(path),
        "vertices": int(len(ids)),
        "ids": int(counts.size),
        "shared_ids": int((counts > 1).sum()),
        "vertices_sharing": int(counts[counts > 1].sum()),
        "tolerance": float(tol),
        "notes": list(mesh.notes),
    }
    return ids, summary
