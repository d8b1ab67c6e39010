"""Benchmark ``batch``: the CI conversion step on 8 demo variants at 512^2.

In one run, on the same 8 variants (:mod:`wrinklepipe.demo.studio`: four encodings, five
policies, a second manifest name), each with an empty cache of its own:

* ``--jobs 1, cold`` (the baseline): every asset converted and validated, one process at a time;
* ``--jobs 2, cold``: the same on two worker processes; limit ratio 0.625 (a speed-up of at
  least 1.6x);
* ``--jobs 2, cached rerun``: the second batch again, unchanged: every asset restored from the
  cache, no conversion (checked); limit 5 % of the cold ``--jobs 2`` run.

The outputs of the two cold runs are compared byte for byte (``extra.identical``).
``extra.cpu_s``: each step's CPU seconds (this process and every worker process, all threads),
``extra.busy_cores``: the cores a cold step kept busy on average (CPU over wall). The fork
server is started before the clock runs (it is paid once per batch, not per asset). Each timed
step runs once: a cold batch is minutes of work, and a repeat would no longer be cold.
``--quick``: three of the variants (two PD policies, a diff map) at 32^2, validated without the
render pass (a smoke run of the benchmark, no limits).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from wrinklepipe.batch import Cache, LocalEngine, plan_batch, run_plan
from wrinklepipe.bench import BenchResult, BenchRow, benchmark
from wrinklepipe.demo.studio import write_studio

COLD_1 = "--jobs 1, cold"
COLD_2 = "--jobs 2, cold"
CACHED = "--jobs 2, cached rerun"


def _tree(folder: Path) -> dict[str, bytes]:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@benchmark("batch", "wrinklepipe batch: 8 demo variants, --jobs 2 vs --jobs 1, cached rerun")
def bench_batch(quick: bool = False) -> BenchResult:
    size = 32 if quick else 512
    load_before = os.getloadavg()
    res = BenchResult(
        "batch",
        f"8 demo variants at {size}^2 (4 encodings, 5 policies), convert + validate"
        + (" (quick)" if quick else ""),
        baseline=COLD_1,
    )
    with tempfile.TemporaryDirectory() as work:
        w = Path(work)
        repo = w / "repo"
        write_studio(repo, size, count=3 if quick else None)
        LocalEngine.warm()

        cpu: dict[str, float] = {}

        def timed(
            step: str, out: str, jobs: int, cache: str, force: bool = False
        ) -> tuple[float, object]:
            quick_opts = {"render": False} if quick else {}
            plan = plan_batch([str(repo)], w / out, force=force, cli_options=quick_opts)
            t0, c0 = time.perf_counter(), time.process_time()
            run = run_plan(plan, LocalEngine(jobs), Cache(w / cache))
            # this process (hashing, the cache) + every worker process (all threads)
            cpu[step] = round(time.process_time() - c0 + sum(r.cpu_seconds for r in run.results), 2)
            return time.perf_counter() - t0, run

        t1, run1 = timed(COLD_1, "out1", 1, "cache1")
        t2, run2 = timed(COLD_2, "out2", 2, "cache2")
        t3, run3 = timed(CACHED, "out2", 2, "cache2", force=True)
        identical = _tree(w / "out1") == _tree(w / "out2")
        statuses = sorted({r.status for r in run1.results + run2.results})
    res.rows = [
        BenchRow(COLD_1, t1, note=f"{len(run1.submitted)} converted"),
        BenchRow(COLD_2, t2, note=f"{len(run2.submitted)} converted"),
        BenchRow(CACHED, t3, note=f"{len(run3.submitted)} converted, {run3.cache.hits} from cache"),
    ]
    if not quick:
        res.limits = {COLD_2: 1 / 1.6}
        res.limits_to = {CACHED: (COLD_2, 0.05)}
    res.extra = {
        "size": size,
        "assets": len(run1.results),
        "speedup_jobs2": t1 / t2,
        "cached_fraction_of_cold_jobs2": t3 / t2,
        "converted_in_cached_rerun": len(run3.submitted),
        "identical": identical,
        "statuses": statuses,
        "cores": os.cpu_count(),
        # CPU seconds (all threads) of each step, and the cores each cold step kept busy on
        # average: what a loaded machine cannot inflate much, beside the wall times
        "cpu_s": cpu,
        "busy_cores": {COLD_1: round(cpu[COLD_1] / t1, 2), COLD_2: round(cpu[COLD_2] / t2, 2)},
        "asset_cpu_s_jobs1": {r.id: r.cpu_seconds for r in run1.results},
        "load_average_before": [round(x, 2) for x in load_before],
        "load_average_after": [round(x, 2) for x in os.getloadavg()],
    }
    return res.finish()
