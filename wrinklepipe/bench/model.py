"""Benchmarks of the wrinkle model at production scales.

Baseline: one ``np.einsum("rp,rk->kp", masks, weights)`` over the same mask stack, i.e. the
region sum alone written the obvious way. The whole blend (activations, policy, PD combine,
normalisation) is reported as a ratio to it; the issue asks for at most 4x at MetaHuman scale.
"""

from __future__ import annotations

import numpy as np

from wrinklepipe import model
from wrinklepipe.bench import BenchResult, BenchRow, benchmark, median_time


def _scene(size: int, k: int, r: int, seed: int = 7) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    masks = rng.random((r, size, size), dtype=np.float32)
    masks /= masks.sum(axis=0, keepdims=True)  # a partition, as painted masks are
    weights = rng.uniform(-1, 1, (r, k)).astype(np.float32)
    base = model.pd_to_normal(rng.normal(0, 0.2, (size, size, 2)).astype(np.float32))
    states = rng.normal(0, 0.3, (k, size, size, 2)).astype(np.float32)
    return base, states, masks, weights


def _run(name: str, size: int, k: int, r: int, quick: bool) -> BenchResult:
    base, states, masks, weights = _scene(size, k, r)
    flat = masks.reshape(r, -1)
    repeat = 3 if quick else 5
    description = f"{size}^2, K={k}, R={r}" + (" (quick: limits not checked)" if quick else "")
    res = BenchResult(name, description, baseline="einsum over mask stack")
    t_einsum = median_time(lambda: np.einsum("rp,rk->kp", flat, weights), repeat)
    t_act = median_time(lambda: model.activations(masks, weights, "clamp01"), repeat)
    act = model.activations(masks, weights, "clamp01")
    t_comb = median_time(lambda: model.combine(base, states, act, "pd"), repeat)
    t_blend = median_time(
        lambda: model.blend(base, states, masks, weights, "pd", "clamp01"), repeat
    )
    mpix = size * size / 1e6
    for step, t in (
        ("einsum over mask stack", t_einsum),
        ("activations (matmul + clamp01)", t_act),
        ("combine (pd)", t_comb),
        ("blend (whole model)", t_blend),
    ):
        res.rows.append(BenchRow(step, t, mpix_per_s=mpix / t))
    if not quick:  # the limit is about production sizes; tiny maps are overhead-bound
        res.limits = {"blend (whole model)": 4.0}
    res.extra = {"size": size, "states": k, "regions": r}
    return res.finish()


@benchmark("model-metahuman", "wrinkle model at MetaHuman scale: 2048^2, K=3 states, R=37 regions")
def bench_metahuman(quick: bool = False) -> BenchResult:
    size = 256 if quick else 2048
    return _run("model-metahuman", size, 3, 37, quick)


@benchmark("model-unity", "wrinkle model at Unity Digital Human scale: 1024^2, K=15, R=135")
def bench_unity(quick: bool = False) -> BenchResult:
    size = 128 if quick else 1024
    return _run("model-unity", size, 15, 135, quick)
