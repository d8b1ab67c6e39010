"""Benchmark ``geometry``: spatial-hash vertex IDs and dynamic wrinkle weights.

Vertex IDs for a 1M-vertex UV sphere (seam column and pole vertices split, as an exporter writes
them; once in file order and once shuffled) against ``trimesh.grouping.unique_rows`` on the same
positions quantised to the tolerance, measured interleaved in the same run (CPU time). Limits:
at most the baseline's time (ratio <= 1) and at most 0.5 s.

Dynamic weights for a 100k-triangle sphere: one frame (the edge operator in index form, the
area arithmetic and the smoothing CSR product, float32, one thread: numpy gathers and scipy's
sparse products are single-threaded) against one sparse mat-vec with the smoothing operator
(``S @ w``); limit 2 ms a frame, reported also as the ratio to that mat-vec. The build of the
operators is reported, not limited.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from wrinklepipe.bench import BenchResult, BenchRow, benchmark
from wrinklepipe.geometry.dynamic import DynamicWeights
from wrinklepipe.geometry.primitives import uv_sphere
from wrinklepipe.geometry.vertex_ids import compute_vertex_ids


def _interleaved(fns: dict[str, Callable[[], Any]], repeat: int) -> dict[str, float]:
    """Median CPU times of several functions measured round-robin.

    CPU time of this process (``time.process_time``), not wall time: every step here is
    single-threaded, and CPU time is not inflated when other processes share the cores; the
    round-robin order exposes the baseline and the steps to the same cache and load conditions.
    """
    for fn in fns.values():
        fn()
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeat):
        for k, fn in fns.items():
            t0 = time.process_time()
            fn()
            times[k].append(time.process_time() - t0)
    return {k: float(np.median(v)) for k, v in times.items()}


@benchmark("geometry", "vertex IDs (1M vertices) vs unique_rows; dynamic weights (100k tris)")
def bench_geometry(quick: bool = False) -> BenchResult:
    import trimesh  # deferred: ~1.7 s, this baseline only

    n_lon, n_lat = (100, 99) if quick else (1000, 999)
    sphere = uv_sphere(n_lon, n_lat)
    p = sphere.positions
    shuffled = p[np.random.default_rng(0).permutation(len(p))]
    tol = 1e-6 * float(np.linalg.norm(p.max(0).astype(np.float64) - p.min(0)))

    def quantised(x: np.ndarray) -> np.ndarray:
        return np.floor((x.astype(np.float64) - x.min(0)) / tol).astype(np.int64)

    qp, qs = quantised(p), quantised(shuffled)
    repeat = 3 if quick else 7
    t = _interleaved(
        {
            "quantise + unique_rows": lambda: trimesh.grouping.unique_rows(quantised(p)),
            "unique_rows (file order)": lambda: trimesh.grouping.unique_rows(qp),
            "vertex IDs (file order)": lambda: compute_vertex_ids(p),
            "unique_rows (shuffled)": lambda: trimesh.grouping.unique_rows(qs),
            "vertex IDs (shuffled)": lambda: compute_vertex_ids(shuffled),
        },
        repeat,
    )
    ids = compute_vertex_ids(p)
    n_unique = len(trimesh.grouping.unique_rows(qp)[0])

    # Dynamic weights: a sphere with ~100k triangles.
    dl = (40, 30) if quick else (225, 224)
    dyn = uv_sphere(*dl)
    t0 = time.perf_counter()
    op = DynamicWeights.build(dyn.positions, dyn.indices)
    build_s = time.perf_counter() - t0
    squash = (dyn.positions * np.array([1.0, 0.8, 1.1], np.float32)).astype(np.float32)
    w_t = op.triangle_frame(squash)
    dt = _interleaved(
        {
            "sparse mat-vec S @ w": lambda: op.smooth @ w_t,
            "dynamic frame": lambda: op.frame(squash),
        },
        20 if quick else 200,
    )

    base = t["unique_rows (file order)"]
    res = BenchResult(
        "geometry",
        f"{len(p)} vertices, {len(dyn.indices)} triangles" + (" (quick)" if quick else ""),
        baseline="unique_rows (file order)",
    )
    for k in ("unique_rows (file order)", "quantise + unique_rows", "vertex IDs (file order)"):
        res.rows.append(BenchRow(k, t[k]))
    ratio_shuffled = t["vertex IDs (shuffled)"] / t["unique_rows (shuffled)"]
    res.rows.append(BenchRow("unique_rows (shuffled)", t["unique_rows (shuffled)"]))
    res.rows.append(
        BenchRow(
            "vertex IDs (shuffled)",
            t["vertex IDs (shuffled)"],
            note=f"{ratio_shuffled:.2f}x of unique_rows (shuffled)",
        )
    )
    frame_ratio = dt["dynamic frame"] / dt["sparse mat-vec S @ w"]
    res.rows.append(BenchRow("dynamic build (once)", build_s))
    res.rows.append(BenchRow("sparse mat-vec S @ w", dt["sparse mat-vec S @ w"]))
    res.rows.append(
        BenchRow(
            "dynamic frame",
            dt["dynamic frame"],
            note=f"{dt['dynamic frame'] * 1e3:.2f} ms/frame, {frame_ratio:.1f}x one S @ w",
        )
    )
    if not quick:
        # no slower than unique_rows in the same run, and absolute times
        res.limits = {"vertex IDs (file order)": 1.0}
        res.limits_s = {"vertex IDs (file order)": 0.5, "dynamic frame": 0.002}
    res.extra = {
        "vertices": int(len(p)),
        "distinct_ids": int(ids.max() + 1),
        "unique_rows_groups": int(n_unique),
        "tolerance": tol,
        "vertex_ids_vs_unique_rows": {
            "file_order": t["vertex IDs (file order)"] / base,
            "file_order_vs_quantise_plus_unique_rows": t["vertex IDs (file order)"]
            / t["quantise + unique_rows"],
            "shuffled": ratio_shuffled,
        },
        "vertex_ids_seconds": t["vertex IDs (file order)"],
        "dynamic_triangles": int(len(dyn.indices)),
        "dynamic_frame_ms": dt["dynamic frame"] * 1e3,
        "dynamic_frame_vs_matvec": frame_ratio,
    }
    return res.finish()
