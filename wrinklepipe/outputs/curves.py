"""Weight curves as files: ``curves/NAME.csv`` (time, then one column per region) and ``.json``."""

from __future__ import annotations

import numpy as np

from wrinklepipe.atomic import dumps_json
from wrinklepipe.package import WeightCurves, safe_name


def format_float32(x: float) -> str:
    """``x`` as float32 with 9 significant digits (enough to read back the same float32)."""
    return format(float(np.float32(x)), ".9g")


def curve_files(
    curve: WeightCurves, regions: list[str], taken: set[str] | None = None
) -> dict[str, bytes]:
    """A weight curve as ``curves/NAME.json`` and ``curves/NAME.csv`` (time, then the regions)."""
    stem = safe_name(curve.name, taken)  # the name stays exact inside the JSON
    rows = ["time," + ",".join(regions)]
    for t, row in zip(curve.times, curve.values):
        rows.append(",".join([format_float32(t)] + [format_float32(v) for v in row]))
    js = {
        "name": curve.name,
        "regions": regions,
        "times": [float(np.float32(t)) for t in curve.times],
        "weights": [[float(np.float32(v)) for v in row] for row in curve.values],
        "interpolation": "linear",
    }
    return {
        f"curves/{stem}.csv": ("\n".join(rows) + "\n").encode("utf-8"),
        f"curves/{stem}.json": dumps_json(js).encode("utf-8"),
    }
