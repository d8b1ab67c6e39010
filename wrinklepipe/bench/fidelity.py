"""Benchmark of the automatic choices by fidelity on the 2048² demo.

Baseline (same run): one full-resolution blend of every pose the searches judge
(:func:`wrinklepipe.model.blend` of the demo's source maps, once per expression). Measured: the
whole search of :func:`wrinklepipe.fidelity.search.search` (preparing the source, the size,
PD-scale and mask-size searches, the block-format searches for base and states); the issue asks
for at most 2x the baseline, checked on the wall-time medians of the same run and on the
process CPU seconds (two more rows, and ``extra.cpu_ratio``): on a shared machine the load
inflates wall times, and unevenly between two steps; CPU seconds much less.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from wrinklepipe import fidelity as fd
from wrinklepipe import model
from wrinklepipe.bench import BenchResult, BenchRow, benchmark, median_time
from wrinklepipe.demo import demo_asset
from wrinklepipe.fidelity import search as fs

CPU_BLEND = "full-resolution blend of every pose, CPU"
CPU_SEARCH = "automatic searches, CPU"


def _cpu(fn: Callable[[], Any], repeat: int) -> float:
    """Median process CPU seconds (all threads) of ``fn()``."""
    times = []
    for _ in range(repeat):
        c0 = time.process_time()
        fn()
        times.append(time.process_time() - c0)
    return float(np.median(times))


@benchmark("fidelity", "automatic choices by fidelity (size, scale, masks, formats), demo 2048^2")
def bench_fidelity(quick: bool = False) -> BenchResult:
    size = 256 if quick else 2048
    a = demo_asset(size)
    poses = fd.expression_poses(a.region_names, a.region_state_matrix(), a.expressions)
    slopes = model.normal_to_pd(a.states) - model.normal_to_pd(a.base)[None]
    fp = fd.footprint(a.mesh.uvs, a.mesh.indices, (size, size))
    src = fs.Source(a.base, slopes, a.masks, poses, a.region_names, footprint=fp)
    budget = fd.Budget.from_dict(a.budget)
    repeat = 1 if quick else 3

    def blend_all() -> None:
        for p in poses:
            model.blend(a.base, slopes, a.masks, p.weights, "pd", a.policy)

    res = BenchResult(
        "fidelity",
        f"demo {size}^2, {len(poses)} poses" + (" (quick: limits not checked)" if quick else ""),
        baseline="full-resolution blend of every pose",
    )
    t_blend = median_time(blend_all, repeat, warmup=0)
    c_blend = _cpu(blend_all, repeat)
    choice = fs.search(src, budget)
    t_search = median_time(lambda: fs.search(src, budget), repeat, warmup=0)
    c_search = _cpu(lambda: fs.search(src, budget), repeat)
    res.rows.append(BenchRow("full-resolution blend of every pose", t_blend))
    res.rows.append(
        BenchRow(
            "automatic searches (size, scale, masks, formats)",
            t_search,
            note=f"chose {choice.wrinkle_size}^2 states, {choice.mask_size}^2 masks, scale "
            f"{choice.pd_scale:g}, base {choice.base_format}, states {choice.state_format}",
        )
    )
    # the same two in process CPU seconds (all threads): what a loaded machine inflates least
    res.rows.append(BenchRow(CPU_BLEND, c_blend, note="CPU seconds"))
    res.rows.append(BenchRow(CPU_SEARCH, c_search, note="CPU seconds"))
    if not quick:
        res.limits = {"automatic searches (size, scale, masks, formats)": 2.0}
        res.limits_to = {CPU_SEARCH: (CPU_BLEND, 2.0)}
    res.extra = {
        "size": size,
        "poses": len(poses),
        "cpu_s": {"blend": round(c_blend, 3), "search": round(c_search, 3)},
        "cpu_ratio": round(c_search / c_blend, 3) if c_blend > 0 else None,
        "choice": choice.to_json()["tried"],
    }
    return res.finish()
