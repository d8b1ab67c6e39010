"""Where jobs run: local worker processes, or a Dask distributed cluster.

Both take the same :class:`~wrinklepipe.batch.plan.Job` list, run
:func:`wrinklepipe.batch.worker.run_job` on each and yield one
:class:`~wrinklepipe.batch.results.AssetResult` per job as it finishes, calling
``on_stage(job_id, stage)`` as stages start. The work is the same function on the same data, so
the outputs are byte-identical whichever engine ran them.

**Local** (``--jobs N``): every asset runs in a process of its own, forked from a
``multiprocessing`` fork server that has imported wrinklepipe once, at most N at a time. A
process that dies (a crash in a native library, the OOM killer) or overruns ``timeout`` (a
watchdog, :data:`DEFAULT_TIMEOUT_S` unless told otherwise; counted from its first message, so
the fork server's own start-up is not charged to an asset) fails its own asset only; memory goes
back to the system after every asset. A process stopped early gets SIGTERM first (it removes its
staging folder and lock, as the CLI does), SIGKILL only if it is still there
:data:`STOP_GRACE_S` later.

**Dask** (``--scheduler ADDRESS``): the jobs are submitted to the cluster's scheduler as tasks;
stages come back as worker events (``Worker.log_event`` / ``Client.subscribe_topic``). A task
whose worker dies is retried by Dask on another worker (its ``allowed-failures``), then fails that
asset alone. Workers must run the same wrinklepipe (checked: the code digest of every worker
must equal ours) and see the same file system paths as the client (outputs are checked). A
cluster with no workers (none joined, or every one died) for ``no_workers_s`` seconds
(:data:`DEFAULT_NO_WORKERS_S`) fails the assets not yet done, each saying so, instead of
waiting forever.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import logging
import multiprocessing
import multiprocessing.connection
import os
import signal
import time
import uuid
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from wrinklepipe import staging
from wrinklepipe.batch import worker
from wrinklepipe.batch.fingerprint import tool_fingerprint
from wrinklepipe.batch.plan import Job
from wrinklepipe.batch.results import AssetResult
from wrinklepipe.errors import input_error

StageFn = Callable[[str, str], None]
#: Seconds an asset may run on a local worker before the watchdog stops it (``--timeout``).
DEFAULT_TIMEOUT_S = 3600.0
#: Seconds a process stopped early has to clean up after SIGTERM before SIGKILL.
STOP_GRACE_S = 5.0
#: Seconds a Dask cluster may have no worker before the assets left fail (``--no-workers``).
DEFAULT_NO_WORKERS_S = 60.0
#: Modules the fork server imports once, so each asset's process starts warm (about 2 s of
#: imports per asset otherwise). No GL context or thread is created by importing them.
_PRELOAD = [
    "wrinklepipe.batch.worker",
    "scipy.ndimage",
    "wrinklepipe.masks",
    "wrinklepipe.normals.compress",
    "wrinklepipe.batch.forkserver_warm",  # quicktex's encoder tables, built once
    "wrinklepipe.gltf.package_write",
    "wrinklepipe.usd.package_write",
    "wrinklepipe.validate.render",
    "wrinklepipe.validate.report",
    "moderngl",
    # the USD modules convert writes with (imported where used: ~0.3 s CPU per asset otherwise)
    "pxr.Usd",
    "pxr.UsdGeom",
    "pxr.UsdShade",
    "pxr.UsdSkel",
]


def cpu_count() -> int:
    """Cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def _task_failed(exc: BaseException) -> str:
    """A Dask task's failure in words: the workers that ran it died, it was cancelled (its
    scheduler went away), or the first line of another error."""
    name = type(exc).__name__
    if name == "KilledWorker":
        tries = getattr(exc, "allowed_failures", 0) + 1
        last = getattr(getattr(exc, "last_worker", None), "address", "?")
        return (
            f"every Dask worker that ran the asset died ({tries} tried; the last {last}): "
            "a crash or a worker's memory limit (see the worker's log)"
        )
    if isinstance(exc, concurrent.futures.CancelledError):
        if "connection-lost" in str(getattr(exc, "reason", "")):
            return "the Dask task was cancelled: the connection to its scheduler was lost"
        return "the Dask task was cancelled (its scheduler went away, or it was stopped)"
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    return f"the Dask task failed ({name}: {first})" if first else f"the Dask task failed ({name})"


@contextlib.contextmanager
def _quiet_distributed() -> Iterator[None]:
    """distributed's own log lines (a lost scheduler's reconnect traceback, a dead worker's
    broadcast error) kept off the terminal: each asset's result says what happened in words."""
    import distributed  # noqa: F401 - deferred (about a second); its loggers exist once imported

    loggers = [logging.getLogger("distributed")] + [
        logger
        for name, logger in list(logging.root.manager.loggerDict.items())
        if name.startswith("distributed.") and isinstance(logger, logging.Logger)
    ]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for logger, level in zip(loggers, levels, strict=True):
            logger.setLevel(level)


def _remove_leftovers(job: Job, made_parent: bool = False) -> None:
    """What a worker process killed mid-asset (SIGKILL, the OOM killer, a crash) left beside
    its output: its staging folder and lock, removed now rather than by the next run there
    (:func:`wrinklepipe.staging.remove_dead_leftovers`: only a dead run's, marked as ours);
    with ``made_parent`` (the folder did not exist before this asset, and no other asset
    running writes into it) that folder too, if nothing else is in it."""
    parent = job.output.parent
    with contextlib.suppress(OSError):
        staging.remove_dead_leftovers(parent)
    if made_parent:
        with contextlib.suppress(OSError):
            parent.rmdir()  # (only when empty)


def _lost(job: Job, message: str) -> AssetResult:
    return AssetResult.could_not_run(
        job, [{"file": job.manifest_rel, "key": "", "message": message}]
    )


def _stop(proc: Any) -> None:
    """End a worker process: SIGTERM (it cleans up), SIGKILL after :data:`STOP_GRACE_S`."""
    if proc.exitcode is None:
        proc.terminate()
        proc.join(STOP_GRACE_S)
    if proc.exitcode is None:
        proc.kill()
    proc.join()


class LocalEngine:
    """``jobs`` worker processes on this machine; ``timeout``: seconds per asset (the
    watchdog, :data:`DEFAULT_TIMEOUT_S`; None or 0: none). ``target(job, conn, threads)`` is
    what each process runs (default :func:`worker.child_main`)."""

    def __init__(
        self,
        jobs: int | None = None,
        timeout: float | None = DEFAULT_TIMEOUT_S,
        target: Callable[[Job, Any, int], None] | None = None,
    ) -> None:
        self.jobs = max(1, int(jobs or cpu_count()))
        self.timeout = timeout or None
        self.target = target or worker.child_main
        #: threads each worker's thread pools (wrinklepipe's, OpenBLAS, llvmpipe, OpenImageIO)
        #: may use: the cores shared out, so N workers do not start N x cores threads
        self.threads = max(1, cpu_count() // self.jobs)
        self.description = f"{self.jobs} local worker process{'es' if self.jobs > 1 else ''}"

    @staticmethod
    def _context() -> Any:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(_PRELOAD)
        return ctx

    @classmethod
    def warm(cls) -> None:
        """Start the fork server (and its imports) now rather than with the first asset."""
        proc = cls._context().Process(target=_nothing)
        proc.start()
        proc.join()

    def run(self, jobs: Sequence[Job], on_stage: StageFn) -> Iterator[AssetResult]:
        ctx = self._context()
        pending = deque(jobs)
        running: dict[Any, tuple[Any, Job, float]] = {}
        fresh: dict[str, bool] = {}  # a job's output folder's parent did not exist before it

        def made(job: Job) -> bool:
            others = {j.output.parent for _, j, _ in running.values() if j is not job}
            return fresh.get(job.id, False) and job.output.parent not in others

        try:
            while pending or running:
                while pending and len(running) < self.jobs:
                    job = pending.popleft()
                    fresh[job.id] = not job.output.parent.exists()
                    recv, send = ctx.Pipe(duplex=False)
                    proc = ctx.Process(
                        target=self.target,
                        args=(job, send, self.threads),
                        name=f"wrinklepipe {job.id}",
                    )
                    proc.start()
                    send.close()
                    running[recv] = (proc, job, float("inf"))  # the clock starts at its hello
                    on_stage(job.id, "starting")
                ready = multiprocessing.connection.wait(list(running), timeout=self._wait())
                for conn in ready:
                    proc, job, _ = running[conn]
                    try:
                        kind, payload = conn.recv()
                    except (EOFError, OSError):
                        proc.join()
                        del running[conn]
                        conn.close()
                        _remove_leftovers(job, made(job))
                        yield _lost(job, f"the worker process died ({_exit_text(proc.exitcode)})")
                        continue
                    if kind == "stage":
                        if running[conn][2] == float("inf"):
                            running[conn] = (proc, job, time.monotonic())
                        on_stage(job.id, payload)
                    else:
                        proc.join()
                        del running[conn]
                        conn.close()
                        yield payload
                yield from self._overdue(running, made)
        finally:
            for conn, (proc, _, _) in running.items():
                _stop(proc)
                conn.close()
            for _, job, _ in running.values():  # (every one stopped: none writes any more)
                _remove_leftovers(job, fresh.get(job.id, False))

    def _wait(self) -> float | None:
        return None if self.timeout is None else 0.5

    def _overdue(
        self, running: dict[Any, tuple[Any, Job, float]], made: Callable[[Job], bool]
    ) -> Iterator[AssetResult]:
        if self.timeout is None:
            return
        now = time.monotonic()
        for conn in [c for c, (_, _, t0) in running.items() if now - t0 > self.timeout]:
            proc, job, _ = running.pop(conn)
            _stop(proc)
            conn.close()
            _remove_leftovers(job, made(job))  # (SIGKILLed when SIGTERM did not end it)
            yield _lost(
                job,
                f"stopped by the watchdog after {self.timeout:g} s (--timeout S sets it, "
                "--timeout 0 turns it off)",
            )


def _nothing() -> None:
    pass


def _exit_text(code: int | None) -> str:
    if code is None:
        return "no exit status"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit status {code}"


#: The address schemes distributed speaks; those with a host and port.
_DASK_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx", "inproc")
_HOST_PORT_SCHEMES = ("tcp", "tls", "ws", "wss")


def check_scheduler_address(address: str) -> None:
    """Refuse, in words, an address distributed cannot connect to (``not a url``,
    ``http://...``, ``tcp://farm`` with no port) before a client is made: distributed's own
    refusal is a ValueError, and its half-made client then waits a minute at exit and prints
    a traceback."""
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address  # (distributed's default)
    why = ""
    if scheme not in _DASK_SCHEMES:
        why = f"unknown scheme {scheme!r}; Dask speaks {', '.join(_DASK_SCHEMES)}"
    elif scheme in _HOST_PORT_SCHEMES:
        host, colon, port = rest.rpartition(":")
        if not colon or not host.strip("[]"):
            why = "no host and port"
        elif not (port.isdigit() and 0 < int(port) < 65536):
            why = f"{port!r} is not a port number"
        elif any(c.isspace() for c in rest) or "/" in rest:
            why = f"{rest!r} is not a host and port"
    if why:
        raise input_error(
            "--scheduler",
            f"{address} is not a Dask scheduler address ({why}); expected tcp://HOST:PORT, "
            "e.g. tcp://farm:8786",
        )


class DaskEngine:
    """The jobs as tasks on the Dask distributed scheduler at ``address``."""

    TOPIC = "wrinklepipe-batch"

    def __init__(
        self, address: str, connect_s: float = 30, no_workers_s: float = DEFAULT_NO_WORKERS_S
    ) -> None:
        self.address = address
        self.connect_s = connect_s
        self.no_workers_s = no_workers_s
        self.description = f"Dask scheduler {address}"

    def _client(self) -> Any:
        # Deferred on purpose: distributed takes about a second to import and only this
        # engine needs it.
        from distributed import Client

        check_scheduler_address(self.address)
        try:
            return Client(self.address, timeout=self.connect_s, set_as_default=False)
        except OSError as exc:  # a TimeoutError, or distributed's "Timed out trying to connect"
            timed_out = isinstance(exc, TimeoutError) or str(exc).startswith("Timed out")
            why = f"no answer in {self.connect_s:g} s" if timed_out else exc.strerror or exc
            raise input_error(
                "--scheduler", f"cannot reach the Dask scheduler at {self.address}: {why}"
            ) from None

    def _no_workers(self) -> str:
        return (
            f"the Dask cluster at {self.address} had no workers for {self.no_workers_s:g} s "
            "(none joined, or every one died); the asset did not run (--no-workers S sets the "
            "wait)"
        )

    def _lost_scheduler(self) -> str:
        return (
            f"the connection to the Dask scheduler at {self.address} was lost (the scheduler "
            "stopped, or the network between it and this machine failed); the asset did not finish"
        )

    def _check_workers(self, client: Any) -> None:
        """Wait for a worker (up to ``no_workers_s``) and check that every worker runs our
        code. A worker that dies while it answers is left out (``on_error="ignore"``; its
        connection error was the asset's message); none left is a wait for another."""
        ours = tool_fingerprint()
        deadline = time.monotonic() + self.no_workers_s
        while True:
            try:
                client.wait_for_workers(1, timeout=max(0.0, deadline - time.monotonic()))
            except TimeoutError:
                raise input_error("--scheduler", self._no_workers()) from None
            theirs = client.run(tool_fingerprint, on_error="ignore")
            if theirs:
                break
            if time.monotonic() >= deadline:
                raise input_error("--scheduler", self._no_workers())
            time.sleep(0.2)
        differ = sorted(addr for addr, fp in theirs.items() if fp != ours)
        if differ:
            raise input_error(
                "--scheduler",
                f"workers {', '.join(differ)} run a different wrinklepipe or library versions "
                "than this client; outputs would not be byte-identical (install the same on all)",
            )

    @staticmethod
    def _result(fut: Any, job: Job) -> AssetResult:
        try:
            result = fut.result()
        except Exception as exc:  # noqa: BLE001 - KilledWorker, lost data: this asset only
            result = _lost(job, _task_failed(exc))
        if result.source == "converted" and not job.output.is_dir():
            result = _lost(
                job,
                f"worker {result.worker} wrote {job.output}, which this machine cannot "
                "see: the workers and the client need a shared file system",
            )
        return result

    def run(self, jobs: Sequence[Job], on_stage: StageFn) -> Iterator[AssetResult]:
        with _quiet_distributed():
            try:
                yield from self._run(jobs, on_stage)
            except OSError:  # CommClosedError, a call that timed out: the scheduler went away
                raise input_error("--scheduler", self._lost_scheduler()) from None

    def _run(self, jobs: Sequence[Job], on_stage: StageFn) -> Iterator[AssetResult]:
        client = self._client()
        subscribed = False
        try:
            self._check_workers(client)

            def handler(event: Any) -> None:
                _, msg = event
                if isinstance(msg, dict):
                    on_stage(str(msg.get("job", "")), str(msg.get("stage", "")))

            client.subscribe_topic(self.TOPIC, handler)
            subscribed = True
            run_id = uuid.uuid4().hex[:8]
            futures = {}
            for job in jobs:
                fut = client.submit(
                    worker.dask_main, job, key=f"wrinklepipe-{run_id}-{job.id}", pure=False
                )
                futures[fut] = job
                on_stage(job.id, "queued")
            pending = list(futures)
            alone_since: float | None = None
            while pending:
                done = [f for f in pending if f.done()]
                for fut in done:
                    pending.remove(fut)
                    yield self._result(fut, futures[fut])
                if not pending or done:
                    continue
                # every worker gone (killed, or the pool shut down): the tasks would wait for
                # one forever; after no_workers_s without any, the assets left fail
                if client.nthreads():
                    alone_since = None
                else:
                    now = time.monotonic()
                    alone_since = now if alone_since is None else alone_since
                    if now - alone_since >= self.no_workers_s:
                        for fut in pending:
                            fut.cancel()
                            yield _lost(futures[fut], self._no_workers())
                        pending = []
                        continue
                time.sleep(0.2)
        finally:
            with contextlib.suppress(OSError):  # (a scheduler gone: nothing to unsubscribe from)
                if subscribed:  # (unsubscribing a topic never subscribed raises, hiding the reason)
                    client.unsubscribe_topic(self.TOPIC)
            client.close()
