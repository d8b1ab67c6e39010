"""xatlas's UV layouts of meshes, made in a child process (:func:`wrinklepipe.readers.meshes.
ensure_uvs_all` runs this file; it imports nothing of wrinklepipe).

Reads ``positions_K`` ``[n, 3]`` float32 and ``indices_K`` ``[m, 3]`` uint32 of meshes
``K = 0, 1, ...`` as an ``.npz`` on stdin, writes each one's ``vmap_K``, ``indices_K`` and
``uvs_K`` (an ``Atlas`` of its own with xatlas's default chart and pack options: what
``xatlas.parametrize`` returns for it) as an ``.npz`` on stdout, and leaves with ``os._exit``
before any atlas is destroyed. xatlas 0.0.11 can hang in that destruction: its
workers wait on a mutex of their own that the shutdown's wake-up does not take, so a wake-up
can be lost and the join waits forever (seen once in about 50 runs). A process that has
written its answer has nothing left to wait for.
"""

from __future__ import annotations

import io
import os
import sys

import numpy as np
import xatlas


def main() -> None:
    with np.load(io.BytesIO(sys.stdin.buffer.read())) as given:
        parts = [(given[f"positions_{k}"], given[f"indices_{k}"]) for k in range(len(given) // 2)]
    made: dict[str, np.ndarray] = {}
    kept = []  # every atlas alive until the process leaves: none is destroyed
    for k, (positions, indices) in enumerate(parts):
        atlas = xatlas.Atlas()
        atlas.add_mesh(positions, indices)
        atlas.generate()
        made[f"vmap_{k}"], made[f"indices_{k}"], made[f"uvs_{k}"] = atlas[0]
        kept.append(atlas)
    out = io.BytesIO()
    np.savez(out, **made)
    sys.stdout.buffer.write(out.getvalue())
    sys.stdout.buffer.flush()
    os._exit(0)  # not atlas's destructor: see the module doc


if __name__ == "__main__":
    main()
