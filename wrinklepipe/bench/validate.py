"""Benchmark ``validate``: the whole validation of the demo, and the wrinkle shader's cost.

``validate demo``: load the demo at 512x512 (BC5 normal maps, 8-bit masks, as ``convert``
ships them) and run every rule plus the render pass (neutral and the 6 expressions of Jimenez
Table 1.1 at 512x512); limit 20 s (folded into a ratio to the baseline).

Shader cost, measured interleaved in the same run on the same mesh, target and textures: the
plain normal-map shader (``wrinklepipe.shading.glsl.validator_fragment(setup, plain=True)``, the
baseline) against the wrinkle shader drawing the 6 expressions. Two wrinkle rows: the
validator's split draw (the wrinkle shader on the triangles a weighted mask reaches, the plain
shader elsewhere: the same image) with the 1.5x limit, and the wrinkle shader on every triangle
(reported, no limit). A CPU rasteriser (llvmpipe) runs both sides of a branch for a whole SIMD
group, so on it every texture fetch of the wrinkle shader is paid on every fragment; a GPU skips
them per wave.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from wrinklepipe.bench import BenchResult, BenchRow, benchmark
from wrinklepipe.sources.validation import load_input
from wrinklepipe.validate import ValidateOptions, validate
from wrinklepipe.validate import gl as glw
from wrinklepipe.validate.context import expression_weights
from wrinklepipe.validate.renderer import Renderer


def _interleaved(fns: dict[str, Callable[[], Any]], repeat: int) -> dict[str, float]:
    for fn in fns.values():
        fn()
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeat):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t0)
    return {k: float(np.median(v)) for k, v in times.items()}


@benchmark("validate", "validate-asset on the demo (512^2, 7 poses); wrinkle vs plain shader")
def bench_validate(quick: bool = False) -> BenchResult:
    size = 128 if quick else 512
    spec = f"demo:pd@{size}+bc"
    opts = ValidateOptions(render_size=size)

    def whole() -> Any:
        return validate(load_input(spec), opts)

    t0 = time.perf_counter()
    report = whole()
    first = time.perf_counter() - t0
    runs = [first]
    for _ in range(0 if quick else 2):
        t0 = time.perf_counter()
        whole()
        runs.append(time.perf_counter() - t0)
    validate_s = float(np.median(runs))

    inp = load_input(spec)
    try:
        r = Renderer(inp, size)
    except glw.GLUnavailable as exc:  # pragma: no cover - no GL on this machine
        res = BenchResult("validate", f"render skipped: {exc}", baseline="validate demo")
        res.rows.append(BenchRow("validate demo", validate_s))
        return res.finish()
    a = inp.asset
    weights = [expression_weights(a, e) for e in sorted(a.expressions)]
    try:
        t = _interleaved(
            {
                "plain normal-map shader": lambda: [
                    r.draw(None, plain=True, read=False) for _ in weights
                ],
                "wrinkle shader (validator: split draw)": lambda: [
                    r.draw(w, read=False) for w in weights
                ],
                "wrinkle shader (every triangle)": lambda: [
                    r.draw(w, read=False, split=False) for w in weights
                ],
            },
            5 if quick else 15,
        )
        active = float(np.mean([r.active_triangles(w).mean() for w in weights]))
        renderer = r.info.get("renderer", "")
    finally:
        r.release()

    base = t["plain normal-map shader"]
    res = BenchResult(
        "validate",
        f"demo {size}x{size}, {len(weights)} expressions, {renderer}"
        + (" (quick)" if quick else ""),
        baseline="plain normal-map shader",
    )
    n = len(weights)
    res.rows.append(
        BenchRow("plain normal-map shader", base, note=f"{base / n * 1e3:.1f} ms per pose")
    )
    split = t["wrinkle shader (validator: split draw)"]
    every = t["wrinkle shader (every triangle)"]
    res.rows.append(
        BenchRow(
            "wrinkle shader (validator: split draw)",
            split,
            note=f"{split / n * 1e3:.1f} ms per pose; {100 * active:.0f}% of triangles",
        )
    )
    res.rows.append(
        BenchRow(
            "wrinkle shader (every triangle)", every, note=f"{every / n * 1e3:.1f} ms per pose"
        )
    )
    res.rows.append(
        BenchRow(
            "validate demo (load + rules + render 7 poses)",
            validate_s,
            note=f"{validate_s:.2f} s (limit 20 s)",
        )
    )
    if not quick:
        res.limits = {"wrinkle shader (validator: split draw)": 1.5}
        res.limits_s = {"validate demo (load + rules + render 7 poses)": 20.0}
    gpu = report.metrics.get("gpu_vs_reference_deg", {})
    res.extra = {
        "renderer": renderer,
        "size": size,
        "wrinkle_vs_plain_split": split / base,
        "wrinkle_vs_plain_every_triangle": every / base,
        "active_triangle_fraction": active,
        "validate_seconds": validate_s,
        "validate_timings": report.timings,
        "gpu_vs_reference_worst_mean_deg": max((s["mean"] for s in gpu.values()), default=None),
        "gpu_vs_reference_worst_p99_deg": max((s["p99"] for s in gpu.values()), default=None),
        "issues": sorted({i.code for i in report.issues}),
    }
    return res.finish()
