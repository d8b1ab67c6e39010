"""One asset, run where a worker runs it (a local process or a Dask worker): convert it, or
validate an existing output, and turn whatever happens into an :class:`AssetResult`.

Nothing here raises: a bad input becomes ``status="error"`` with its problems, an unexpected
exception too (with the exception's type and message), so one asset never takes the others down.
"""

from __future__ import annotations

import os
import signal
import socket
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import OpenImageIO
from threadpoolctl import threadpool_limits

from wrinklepipe.batch.plan import Job
from wrinklepipe.batch.results import AssetResult, counts_of, status_for
from wrinklepipe.console import stage_listener
from wrinklepipe.errors import InputError
from wrinklepipe.io.confine import allowed_roots
from wrinklepipe.jobs.convert import convert
from wrinklepipe.reuse import THREADS_ENV
from wrinklepipe.sources.validation import LoadOptions, load_input
from wrinklepipe.validate import validate
from wrinklepipe.validate.config import Config, load_config

T = TypeVar("T")


def _ignore(_stage: str) -> None:
    pass


def _replace_prefix(obj: Any, old: str, new: str) -> Any:
    """``old`` -> ``new`` in every string of a JSON-like value (absolute paths -> relative)."""
    if isinstance(obj, str):
        return obj.replace(old, new)
    if isinstance(obj, dict):
        return {k: _replace_prefix(v, old, new) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_replace_prefix(v, old, new) for v in obj]
    return obj


class _Stages:
    """Seconds per stage from the stage announcements, forwarded to ``emit``."""

    def __init__(self, emit: Callable[[str], None]) -> None:
        self.emit = emit
        self.seconds: dict[str, float] = {}
        self.current: str | None = None
        self.since = time.perf_counter()

    def __call__(self, stage: str) -> None:
        self.close()
        self.current, self.since = stage, time.perf_counter()
        self.emit(stage)

    def close(self) -> None:
        now = time.perf_counter()
        if self.current is not None:
            self.seconds[self.current] = round(
                self.seconds.get(self.current, 0.0) + now - self.since, 4
            )
        self.current, self.since = None, now


def _problems(exc: InputError, job: Job) -> list[dict[str, str]]:
    out = []
    for p in exc.problems:
        out.append({"file": _relative(p.file, job), "key": p.key, "message": p.message})
    return out


def _relative(file: str, job: Job) -> str:
    """A problem's file as the user knows it: relative to the batch root when inside (the
    manifest's folder for a conversion, the output folder for a validation)."""
    if job.kind == "validate":
        base, prefix = job.output, Path(job.id)
    else:
        base, prefix = job.manifest.parent, Path(job.manifest_rel).parent
    try:
        return (prefix / Path(file).relative_to(base)).as_posix()
    except ValueError:
        return str(file)


def _crash(exc: BaseException, job: Job, what: str) -> list[dict[str, str]]:
    last = traceback.extract_tb(exc.__traceback__)[-1:] if exc.__traceback__ else []
    where = f" at {Path(last[0].filename).name}:{last[0].lineno}" if last else ""
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    return [
        {
            "file": job.manifest_rel,
            "key": "",
            "message": f"{what} failed unexpectedly ({type(exc).__name__}: {msg}{where}); "
            "please report",
        }
    ]


def _error_result(job: Job, problems: list[dict[str, str]]) -> AssetResult:
    """The result of a job that could not run here: ``status="error"`` with its problems."""
    return AssetResult.could_not_run(job, problems, worker=socket.gethostname())


def _guarded(job: Job, what: str, work: Callable[[], T]) -> T | AssetResult:
    """``work()``, or the error result of the job when it raises: an InputError's problems,
    any other exception as a crash of ``what`` (one asset never takes the others down)."""
    try:
        return work()
    except InputError as exc:
        return _error_result(job, _problems(exc, job))
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:  # noqa: BLE001 - one asset's crash must not stop the others
        return _error_result(job, _crash(exc, job, what))


def _judged(
    job: Job, name: str, source: str, validation: str, issues: list[dict[str, Any]]
) -> AssetResult:
    """The result of a job that ran: its issues, their counts and the status they give."""
    result = _error_result(job, [])
    result.name = name
    result.source = source
    result.validation = validation
    result.issues = issues
    result.counts = counts_of(issues)
    result.status = status_for(issues, job.options.fail_on)
    return result


def _convert(job: Job, stages: _Stages) -> AssetResult:
    def work() -> Any:
        with stage_listener(stages):
            return convert(job.manifest, job.output, job.options.convert_options(job.force))

    res = _guarded(job, "conversion", work)
    if isinstance(res, AssetResult):
        return res
    validation = res.report.get("validation", {})
    issues = list(validation.get("issues", []))
    name = str(res.report.get("name", ""))
    return _judged(job, name, "converted", str(validation.get("status", "")), issues)


def _validate(job: Job, stages: _Stages) -> AssetResult:
    params: dict[str, Any] = dict(job.params)

    def work() -> Any:
        config = load_config(params["config"]) if params.get("config") else Config()
        options, config = config.run_options(job.options.render, params.get("render_size"))
        stages("loading")
        inp = load_input(job.output, LoadOptions(textures=params.get("textures", "auto")))
        stages("validating")
        return validate(inp, options, config)

    report = _guarded(job, "validation", work)
    if isinstance(report, AssetResult):
        return report
    issues = _replace_prefix([i.to_json() for i in report.issues], str(job.output), ".")
    return _judged(job, str(report.input.get("name", "")), "validated", "ran", issues)


def run_job(job: Job, emit: Callable[[str], None] = _ignore) -> AssetResult:
    """Run one job; ``emit(stage)`` is told each stage as it starts. Never raises (but for
    KeyboardInterrupt / SystemExit)."""
    t0, c0 = time.perf_counter(), time.process_time()
    stages = _Stages(emit)
    with allowed_roots(job.roots):
        result = _validate(job, stages) if job.kind == "validate" else _convert(job, stages)
    stages.close()
    result.stages = stages.seconds
    result.seconds = round(time.perf_counter() - t0, 4)
    result.cpu_seconds = round(time.process_time() - c0, 4)
    return result


# ------------------------------------------------------------------------------------------------
# entry points of the engines


def limit_threads(threads: int) -> None:
    """Let every thread pool of this process use ``threads`` threads: wrinklepipe's own (the
    block encoders' row chunks, PNGs beside other work: ``WRINKLEPIPE_THREADS``), OpenBLAS's
    (numpy's products; it read its count when numpy was imported, so through threadpoolctl),
    llvmpipe's (read when the GL context is made, so before any), OpenImageIO's and USD's
    (its work threads, which spin while they wait). The work is split the same way whatever
    the count, so the outputs do not change."""
    from pxr import Work  # deferred: usd-core, USD only (the fork server has it loaded)

    os.environ[THREADS_ENV] = str(threads)
    os.environ["LP_NUM_THREADS"] = str(threads)
    OpenImageIO.attribute("threads", int(threads))
    threadpool_limits(limits=int(threads), user_api="blas")
    Work.SetConcurrencyLimit(int(threads))


def _exit_on_signal(signum: int, frame: object) -> None:
    """SIGTERM / SIGHUP in a worker process: leave through every ``finally`` (the staging
    folder removed, the lock released), as the CLI does, then exit 128 + the signal."""
    raise SystemExit(128 + signum)


def child_main(job: Job, conn: Any, threads: int | None = None) -> None:
    """A local worker process: run one job, sending ``("stage", name)`` messages and finally
    ``("done", result)`` through ``conn``; ``threads`` caps its thread pools. SIGTERM (the
    engine's watchdog, or the batch stopping) ends it cleanly (:func:`_exit_on_signal`)."""
    for signum in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, _exit_on_signal)
    if threads:
        limit_threads(threads)
    try:
        conn.send(("stage", "started"))
        result = run_job(job, lambda stage: conn.send(("stage", stage)))
        conn.send(("done", result))
    finally:
        conn.close()


def dask_main(job: Job) -> AssetResult:
    """A Dask task: run one job, publishing stages as ``wrinklepipe-batch`` worker events."""
    from distributed import get_worker  # deferred: only Dask workers call this

    worker = get_worker()

    def emit(stage: str) -> None:
        worker.log_event("wrinklepipe-batch", {"job": job.id, "stage": stage})

    return run_job(job, emit)
