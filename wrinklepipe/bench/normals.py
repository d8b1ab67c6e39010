"""``wrinklepipe bench normals``: 4096^2 normal map -> PD -> BC5 -> decode -> error report.

Steps are timed one by one (each over the whole map) and as the fused whole
(:func:`wrinklepipe.normals.compress.pd_compress_check`, what ``encode-normals`` runs), with the
bare ``etcpak.compress_bc5`` call on the same packed map as the same-run baseline. The file
read is timed and shown but is not part of "whole". Limit: whole <= 4x the bare codec call.
Repeats are interleaved (baseline, whole, steps, baseline, ...) so load from other processes
hits all rows alike; the median of each row is reported, and each row's note adds its process
CPU time and best wall time, each as a ratio to the bare call (CPU time does not depend on
what else the machine runs; the fused whole spends about 3.5x the codec's CPU, and with two
cores free finishes in well under 4x its wall time).
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
    from wrinklepipe.normals._chunks import threads as _threads
    from wrinklepipe.normals.read import ReadOptions, read_normal_map

    size = QUICK_SIZE if quick else SIZE
    repeat = 3 if quick else 7
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
        # the file read is slow and not part of the limit: timed twice, outside the loop
        read_times = []
        for _ in range(2):
            t0 = time.perf_counter()
            read_normal_map(src, opts)
            read_times.append(time.perf_counter() - t0)
        steps = {
            "bare etcpak.compress_bc5": lambda: etcpak.compress_bc5(rgba, size, size),
            "PD encode + pack": lambda: cmp.pd_pack(normals, scale, "bc5"),
            "BC5 encode": lambda: cmp.encode_bc(rgba, "bc5"),
            "decode (texture2ddecoder)": lambda: cmp.decode_bc_bgra(data, size, size, "bc5"),
            "error report": lambda: cmp.pd_decode_error(bgra, normals, scale, "bc5"),
            "whole (fused, no read)": lambda: cmp.pd_compress_check(normals, scale, "bc5"),
        }
        times: dict[str, list[float]] = {k: [] for k in steps}
        cpu: dict[str, list[float]] = {k: [] for k in steps}
        for fn in steps.values():  # warm-up
            fn()
        for _ in range(repeat):
            for name, fn in steps.items():
                c0, t0 = time.process_time(), time.perf_counter()
                fn()
                times[name].append(time.perf_counter() - t0)
                cpu[name].append(time.process_time() - c0)
        check = cmp.pd_compress_check(normals, scale, "bc5")
    res = BenchResult(
        name="normals",
        description=f"{size}^2 normal map -> PD -> BC5 -> decode -> error report",
        baseline="bare etcpak.compress_bc5",
        # the limit is about the 4096^2 run; at the quick size fixed costs dominate
        limits={} if quick else {"whole (fused, no read)": 4.0},
    )
    res.rows.append(
        BenchRow(
            step="read 16-bit PNG (excluded)",
            median_s=float(np.median(read_times)),
            mpix_per_s=mp / float(np.median(read_times)),
            note="OpenImageIO decode + normal decode; not part of 'whole'",
        )
    )
    base_cpu = float(np.median(cpu["bare etcpak.compress_bc5"]))
    base_min = float(np.min(times["bare etcpak.compress_bc5"]))
    for name, ts in times.items():
        med = float(np.median(ts))
        c = float(np.median(cpu[name]))
        note = (
            f"cpu {c * 1e3:.0f} ms ({c / base_cpu:.2f}x bare), "
            f"best wall {np.min(ts) * 1e3:.0f} ms ({np.min(ts) / base_min:.2f}x bare)"
        )
        res.rows.append(BenchRow(step=name, median_s=med, mpix_per_s=mp / med, note=note))
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
    whole = "whole (fused, no read)"
    res.extra = {
        "cpu_ratio_whole": float(np.median(cpu[whole])) / base_cpu,
        "best_wall_ratio_whole": float(np.min(times[whole])) / base_min,
        "threads": _threads(),
        "size": size,
        "scale": scale,
        "clipped": check.clipped,
        "error": check.error.to_json(),
        "bytes": len(check.data),
    }
    return res.finish()
