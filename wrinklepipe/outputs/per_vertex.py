"""Per-vertex arrays (vertex IDs, dynamic wrinkle weights) written as .npy, .json or .txt/.csv:
the one writer the ``vertex-ids`` and ``dynamic`` commands share."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.atomic import dumps_json, write_output
from wrinklepipe.errors import input_error


def per_vertex_bytes(path: Path, values: np.ndarray, meta: dict[str, Any]) -> bytes:
    """The bytes of ``values`` [V] in the format ``path``'s suffix names (.json: ``meta`` plus
    ``values``; .txt/.csv: one value a line, floats to 9 significant digits)."""
    suffix = path.suffix.lower()
    if suffix == ".npy":
        buf = io.BytesIO()
        np.save(buf, values, allow_pickle=False)
        return buf.getvalue()
    if suffix == ".json":
        return dumps_json({**meta, "values": values.tolist()}).encode()
    if suffix in (".txt", ".csv"):
        if values.dtype.kind == "f":
            lines = np.char.mod("%.9g", values.astype(np.float64))
        else:
            lines = values.astype(str)
        return ("\n".join(lines.tolist()) + "\n").encode()
    raise input_error(path, "output must end in .npy, .json, .txt or .csv")


def write_per_vertex(path: Path, values: np.ndarray, meta: dict[str, Any], inputs: list) -> None:
    """Write a per-vertex array as .npy, .json or .txt/.csv atomically (never over an input)."""
    write_output(path, per_vertex_bytes(path, values, meta), inputs=inputs)
