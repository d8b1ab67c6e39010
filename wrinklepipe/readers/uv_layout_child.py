"""xatlas's UV layout of one mesh, made in a child process (:func:`wrinklepipe.readers.meshes.
ensure_uvs` runs this file; it imports nothing of wrinklepipe).

Reads ``positions`` ``[n, 3]`` float32 and ``indices`` ``[m, 3]`` uint32 as an ``.npz`` on
stdin, writes ``vmap``, ``indices`` and ``uvs`` (xatlas's ``Atlas`` with its default chart and
pack options: what ``xatlas.parametrize`` returns) as an ``.npz`` on stdout, and leaves with
``os._exit`` before the atlas is destroyed. xatlas 0.0.11 can hang in that destruction: its
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
        positions, indices = given["positions"], given["indices"]
    atlas = xatlas.Atlas()
    atlas.add_mesh(positions, indices)
    atlas.generate()
    vmap, faces, uvs = atlas[0]
    out = io.BytesIO()
    np.savez(out, vmap=vmap, indices=faces, uvs=uvs)
    sys.stdout.buffer.write(out.getvalue())
    sys.stdout.buffer.flush()
    os._exit(0)  # not atlas's destructor: see the module doc


if __name__ == "__main__":
    main()
