"""Benchmark ``scale``: convert + validate-asset of the film-scale head case at 1K to 8K.

The case is :mod:`wrinklepipe.bench.head_case` (CesiumMan's UV layout, a synthetic base and two
wrinkle states at the size, eight full-size masks, every choice on ``auto``), generated once per
size into the cache. For each size, in one run and one at a time:

* ``convert`` (which validates what it wrote, with the render pass) in a process of its own;
* ``validate-asset`` of the written folder against the source manifest, in another.

Each process's peak resident memory is its own (``os.wait4``'s ``ru_maxrss``), so the figures
are what one such command needs, not this process's. Rows: the wall time of both commands per
size; the baseline is the 4096² case, so the 8192² row's ratio is the 8K/4K growth (limit 4.2,
linear in texels with a margin). ``extra``: per size the peak RSS of each command, its CPU
seconds and exit code, the working set (``WRINKLEPIPE_WORKING_SET``, docs/scale.md) and the
load average; a peak over :data:`RSS_LIMIT_MB` at 8192² or a non-zero exit is a failure.

``WRINKLEPIPE_SCALE_SIZES`` (comma-separated) picks other sizes; ``--quick``: 128² and 256²
without the render pass (a smoke run, no limits). The case needs ``../shared/data``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from wrinklepipe.bench import BenchResult, BenchRow, benchmark
from wrinklepipe.bench.head_case import MESH, head_case_dir

SIZES = (1024, 2048, 4096, 8192)
QUICK_SIZES = (128, 256)
#: The peak a command may reach on the 8192² case, in MB of 10**6 bytes: issue 42's 4 GB.
RSS_LIMIT_MB = 4000
#: The 8192² wall time over the 4096² one may be at most this (texels x4, with a margin).
GROWTH_LIMIT = 4.2


def _run(argv: list[str]) -> tuple[float, float, int, int]:
    """Run ``wrinklepipe ARGV`` in a child process: wall s, CPU s, peak RSS in MB (10**6
    bytes; ``ru_maxrss`` is in KiB), exit code."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "wrinklepipe", *argv],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    peak_mb = int(usage.ru_maxrss * 1024 // 10**6)
    return wall, usage.ru_utime + usage.ru_stime, peak_mb, proc.returncode


def _sizes(quick: bool) -> tuple[int, ...]:
    given = os.environ.get("WRINKLEPIPE_SCALE_SIZES", "").strip()
    if given:
        return tuple(int(s) for s in given.split(","))
    return QUICK_SIZES if quick else SIZES


def _step(size: int) -> str:
    return f"{size}^2 convert + validate-asset"


@benchmark("scale", "convert + validate-asset of an 8K-capable head case: peak RSS and wall")
def bench_scale(quick: bool = False) -> BenchResult:
    sizes = _sizes(quick)
    base_size = 4096 if 4096 in sizes else sizes[0]
    res = BenchResult(
        "scale",
        "head case (CesiumMan UVs, 2 states, 8 masks, all auto) at "
        + ", ".join(f"{s}^2" for s in sizes)
        + (" (quick, no render pass)" if quick else ""),
        baseline=_step(base_size),
    )
    root = str(MESH.parent)
    extra: dict[str, dict[str, object]] = {}
    failed: list[str] = []
    render = ["--no-render"] if quick else []
    with tempfile.TemporaryDirectory() as work:
        for size in sizes:
            manifest = head_case_dir(size)
            out = Path(work) / f"out{size}"
            load = os.getloadavg()
            conv = _run(["convert", str(manifest), "-o", str(out), "--allow-root", root, "-q"]
                        + render)  # fmt: skip
            val = _run(["validate-asset", str(out), "--source", str(manifest),
                        "--allow-root", root, "-q"] + render)  # fmt: skip
            res.rows.append(
                BenchRow(
                    _step(size),
                    conv[0] + val[0],
                    mpix_per_s=size * size / 1e6 / (conv[0] + val[0]),
                    note=f"peak RSS {max(conv[2], val[2])} MB",
                )
            )
            extra[str(size)] = {
                "convert": dict(zip(("wall_s", "cpu_s", "peak_rss_mb", "exit"), conv)),
                "validate_asset": dict(zip(("wall_s", "cpu_s", "peak_rss_mb", "exit"), val)),
                "load_average_before": [round(x, 2) for x in load],
            }
            for name, got in (("convert", conv), ("validate-asset", val)):
                if got[3] != 0:
                    failed.append(f"scale: {name} at {size}^2 exited {got[3]}")
                if size >= 8192 and got[2] > RSS_LIMIT_MB:
                    failed.append(
                        f"scale: {name} at {size}^2 peaked at {got[2]} MB > {RSS_LIMIT_MB} MB"
                    )
    if not quick and 8192 in sizes and 4096 in sizes:
        res.limits = {_step(8192): GROWTH_LIMIT}
    res.extra = {
        "sizes": extra,
        "working_set": os.environ.get("WRINKLEPIPE_WORKING_SET", "default"),
        "cores": os.cpu_count(),
        "failed": failed,
    }
    res.extra_failures = failed
    return res.finish()
