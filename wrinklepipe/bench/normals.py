"""``wrinklepipe bench normals``: 4096^2 normal map -> PD -> BC5 -> decode -> error report.

Steps are timed one by one (each over the whole map) and as the fused whole
(:func:`wrinklepipe.normals.compress.pd_compress_check`, what ``encode-normals`` runs), with the
bare ``etcpak.compress_bc5`` call on the same packed map as the same-run baseline. The file
read is timed and shown but is not part of "whole". Limit: whole <= 4x the bare codec call.
Repeats are interleaved (baseline, whole, steps, baseline, ...) so load from other processes
hits all rows alike; the median of each row is reported.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import etcpak
import numpy as np

from wrinklepipe.bench import BenchResult, BenchRow, benchmark

SIZE = 4096
QUICK_SIZE = 512


def bench_map(size: int) -> np.ndarray:
    """A deterministic wrinkle-like normal map [size, size, 3] (float32, unit, +Y).

    The demo's 512^2 wrinkle and pore heights magnified to ``size`` (so the slope statistics
    match a real wrinkle map: folds, pores, flat areas), plus fine seeded noise.
    """
    from wrinklepipe.demo import character
    from wrinklepipe.model import height_to_normal
    from wrinklepipe.normals.resample import resize

    base = min(size, 512)
    d = character.generate(base)
    h = (d.base_height + d.wrinkle_heights[1]).astype(np.float32)
    if size != base:
        h = resize(h, size, "blackman-harris") * np.float32(size / base)
    rng = np.random.default_rng(4096)
    h += rng.standard_normal(h.shape).astype(np.float32) * np.float32(0.05)
    return height_to_normal(h).astype(np.float32)


@benchmark("normals", "4096^2 map -> PD -> BC5 -> decode -> error; whole <= 4x bare BC5")
def bench_normals(quick: bool) -> BenchResult:
    from wrinklepipe.io.images import write_image
    from wrinklepipe.normals import compress as cmp
    from wrinklepipe.normals import encode as enc
    from wrinklepipe.normals.read import ReadOptions, read_normal_map

    size = QUICK_SIZE if quick else SIZE
    repeat = 3 if quick else 5
    mp = size * size / 1e6
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "normal16.png"
        write_image(src, bench_map(size) * np.float32(0.5) + np.float32(0.5), bits=16)
        opts = ReadOptions(convention="opengl", detect=False)
        normals = read_normal_map(src, opts).normals
        scale = enc.auto_pd_scale(normals)
        rgba, _ = cmp.pd_pack(normals, scale, "bc5")
        data = etcpak.compress_bc5(rgba, size, size)
        bgra = cmp.decode_bc_bgra(data, size, size, "bc5")
        steps = {
            "read 16-bit PNG (excluded)": lambda: read_normal_map(src, opts),
            "bare etcpak.compress_bc5": lambda: etcpak.compress_bc5(rgba, size, size),
            "PD encode + pack": lambda: cmp.pd_pack(normals, scale, "bc5"),
            "BC5 encode": lambda: cmp.encode_bc(rgba, "bc5"),
            "decode (texture2ddecoder)": lambda: cmp.decode_bc_bgra(data, size, size, "bc5"),
            "error report": lambda: cmp.pd_decode_error(bgra, normals, scale, "bc5"),
            "whole (fused, no read)": lambda: cmp.pd_compress_check(normals, scale, "bc5"),
        }
        times: dict[str, list[float]] = {k: [] for k in steps}
        for fn in steps.values():  # warm-up
            fn()
        for _ in range(repeat):
            for name, fn in steps.items():
                t0 = time.perf_counter()
                fn()
                times[name].append(time.perf_counter() - t0)
        check = cmp.pd_compress_check(normals, scale, "bc5")
    res = BenchResult(
        name="normals",
        description=f"{size}^2 normal map -> PD -> BC5 -> decode -> error report",
        baseline="bare etcpak.compress_bc5",
        limits={"whole (fused, no read)": 4.0},
    )
    for name, ts in times.items():
        med = float(np.median(ts))
        res.rows.append(BenchRow(step=name, median_s=med, mpix_per_s=mp / med))
    serial = sum(
        float(np.median(times[k]))
        for k in ("PD encode + pack", "BC5 encode", "decode (texture2ddecoder)", "error report")
    )
    res.rows.append(
        BenchRow(
            step="sum of the separate steps",
            median_s=serial,
            mpix_per_s=mp / serial,
            note="the same work unfused, for comparison",
        )
    )
    res.extra = {
        "size": size,
        "scale": scale,
        "clipped": check.clipped,
        "error": check.error.to_json(),
        "bytes": len(check.data),
    }
    return res.finish()
