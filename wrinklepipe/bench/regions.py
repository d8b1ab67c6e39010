"""Benchmarks of mask packing and the weight drivers.

``masks-pack``: packing MetaHuman's 37 masks into 10 RGBA textures (+ an array) and unpacking them,
against a same-run baseline of one plain copy of the mask stack (``np.stack``), i.e. the cost of
touching every texel once. ``drivers``: the RigLogic row table at ARKit scale and Dutreve's bones
at production mesh scale, against the dense matmul that beta is (skin x theta(alpha)).
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.bench import BenchResult, BenchRow, benchmark, median_time
from wrinklepipe.drivers.blendshapes import Row, evaluate_rows
from wrinklepipe.drivers.bones import pose_influence, vertex_influence
from wrinklepipe.masks import pack, unpack
from wrinklepipe.presets import arkit, metahuman


@benchmark("masks-pack", "pack/unpack 37 MetaHuman masks (10 RGBA + array) at 1024^2")
def bench_masks_pack(quick: bool = False) -> BenchResult:
    size = 64 if quick else 1024
    rng = np.random.default_rng(3)
    masks = rng.random((37, size, size), dtype=np.float32)
    names = list(metahuman.REGIONS)
    repeat = 3 if quick else 5
    res = BenchResult(
        "masks-pack", f"R=37, {size}^2" + (" (quick)" if quick else ""), baseline="copy stack"
    )
    p = pack(masks, names, "metahuman")
    lr_names = [f"area{i // 2}_{'lr'[i % 2]}" for i in range(36)]
    side = (np.arange(size) < size // 2)[None, None, :]
    lr_masks = np.where(np.array([i % 2 == 0 for i in range(36)])[:, None, None], side, ~side)
    lr_masks = (masks[:36] * lr_masks).astype(np.float32)
    steps = (
        ("copy stack", lambda: np.stack(list(masks))),
        ("pack metahuman (rgba + array)", lambda: pack(masks, names, "metahuman")),
        ("unpack rgba", lambda: unpack(p.textures, p.table)),
        ("pack lr-split (36 sided)", lambda: pack(lr_masks, lr_names, "lr-split")),
    )
    mpix = 37 * size * size / 1e6
    for step, fn in steps:
        t = median_time(fn, repeat)
        res.rows.append(BenchRow(step, t, mpix_per_s=mpix / t))
    if not quick:
        res.limits = {"pack metahuman (rgba + array)": 8.0, "unpack rgba": 8.0}
    res.extra = {"regions": 37, "size": size}
    return res.finish()


@benchmark("drivers", "blend-shape rows (ARKit 52 -> regions) and bones (20k vertices)")
def bench_drivers(quick: bool = False) -> BenchResult:
    rng = np.random.default_rng(5)
    frames = 100 if quick else 2000
    x = rng.random((frames, 52))
    rows = [Row(*r) for r in arkit.ROWS] * 8  # 152 rows: a denser table than the preset
    outs = list(dict.fromkeys(r.output for r in rows))
    dense = rng.random((52, len(outs)))
    v, j, p = (2000, 30, 2) if quick else (20000, 60, 4)
    f_b = 10 if quick else 100
    neutral = rng.random((j, 3))
    ref = neutral[None] + rng.normal(0, 0.1, (p, j, 3))
    cur = neutral[None] + rng.normal(0, 0.05, (f_b, j, 3))
    skin = np.where(rng.random((v, j)) < 4 / j, rng.random((v, j)), 0.0)
    alpha = pose_influence(neutral, ref, cur)
    repeat = 3 if quick else 5
    res = BenchResult(
        "drivers",
        f"{frames} frames x 52 shapes x {len(rows)} rows; {v} vertices, {j} bones, {p} poses, "
        f"{f_b} frames" + (" (quick)" if quick else ""),
        baseline="dense matmul V x J @ J x (F P)",
    )
    theta_flat = rng.random((j, f_b * p))
    steps = (
        ("dense matmul V x J @ J x (F P)", lambda: skin @ theta_flat),
        ("dense matmul frames x 52 -> regions", lambda: x @ dense),
        ("blendshape rows (RigLogic)", lambda: evaluate_rows(x, arkit.NAMES, rows, outs)),
        ("bones alpha (pose influence)", lambda: pose_influence(neutral, ref, cur)),
        ("bones beta (per vertex)", lambda: vertex_influence(alpha, skin)),
    )
    for step, fn in steps:
        res.rows.append(BenchRow(step, median_time(fn, repeat)))
    if not quick:
        res.limits = {"bones beta (per vertex)": 4.0}
    res.extra = {"frames": frames, "rows": len(rows), "vertices": v, "bones": j, "poses": p}
    return res.finish()
