"""``wrinklepipe batch``: convert many manifests at once, as a studio's CI does on every commit.

Public API::

    from wrinklepipe.batch import plan_batch, run_plan, LocalEngine, DaskEngine, Cache
    plan = plan_batch(["chars/"], "build")              # or a batch file, globs, manifests
    run = run_plan(plan, LocalEngine(jobs=2), Cache("~/.cache/wrinklepipe/batch"))
    run.results, run.exit_code                           # one AssetResult per asset

Layers: :mod:`.plan` (sources -> jobs, output collisions), :mod:`.fingerprint` (cache keys),
:mod:`.cache` (content-addressed entries), :mod:`.worker` (one asset, never raises),
:mod:`.engines` (local processes, Dask), :mod:`.run` (cache + engine), :mod:`.reports`
(JSON, JUnit, SARIF), :mod:`.progress` (terminal).
"""

from __future__ import annotations

from wrinklepipe.batch.cache import Cache, parse_size
from wrinklepipe.batch.engines import DaskEngine, LocalEngine, cpu_count
from wrinklepipe.batch.options import AssetOptions
from wrinklepipe.batch.plan import BatchPlan, Job, load_batch_file, plan_batch
from wrinklepipe.batch.results import AssetResult, worst_exit_code
from wrinklepipe.batch.run import BatchRun, run_plan

__all__ = [
    "AssetOptions",
    "AssetResult",
    "BatchPlan",
    "BatchRun",
    "Cache",
    "DaskEngine",
    "Job",
    "LocalEngine",
    "cpu_count",
    "load_batch_file",
    "parse_size",
    "plan_batch",
    "run_plan",
    "worst_exit_code",
]
