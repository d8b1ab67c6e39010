"""Where jobs run: local worker processes, or a Dask distributed cluster.

Both take the same :class:`~wrinklepipe.batch.plan.Job` list, run
:func:`wrinklepipe.batch.worker.run_job` on each and yield one
:class:`~wrinklepipe.batch.results.AssetResult` per job as it finishes, calling
``on_stage(job_id, stage)`` as stages start. The work is the same function on the same data, so
the outputs are byte-identical whichever engine ran them.

**Local** (``--jobs N``): every asset runs in a process of its own, forked from a
``multiprocessing`` fork server that has imported wrinklepipe once, at most N at a time. A
process that dies (a crash in a native library, the OOM killer) or overruns ``timeout`` (counted
from its first message, so the fork server's own start-up is not charged to an asset) fails its
own asset only; memory goes back to the system after every asset.

**Dask** (``--scheduler ADDRESS``): the jobs are submitted to the cluster's scheduler as tasks;
stages come back as worker events (``Worker.log_event`` / ``Client.subscribe_topic``). A task
whose worker dies is retried by Dask on another worker (its ``allowed-failures``), then fails that
asset alone. Workers must run the same wrinklepipe (checked: the code digest of every worker
must equal ours) and see the same file system paths as the client (outputs are checked).
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
import signal
import time
import uuid
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from wrinklepipe.batch import worker
from wrinklepipe.batch.fingerprint import tool_fingerprint
from wrinklepipe.batch.plan import Job
from wrinklepipe.batch.results import AssetResult
from wrinklepipe.errors import input_error

StageFn = Callable[[str, str], None]
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


def _lost(job: Job, message: str) -> AssetResult:
    return AssetResult.could_not_run(
        job, [{"file": job.manifest_rel, "key": "", "message": message}]
    )


class LocalEngine:
    """``jobs`` worker processes on this machine; ``timeout``: seconds per asset (None: none).
    ``target(job, conn, threads)`` is what each process runs (default
    :func:`worker.child_main`)."""

    def __init__(
        self,
        jobs: int | None = None,
        timeout: float | None = None,
        target: Callable[[Job, Any, int], None] | None = None,
    ) -> None:
        self.jobs = max(1, int(jobs or cpu_count()))
        self.timeout = timeout
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
        try:
            while pending or running:
                while pending and len(running) < self.jobs:
                    job = pending.popleft()
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
                yield from self._overdue(running)
        finally:
            for conn, (proc, _, _) in running.items():
                proc.kill()
                proc.join()
                conn.close()

    def _wait(self) -> float | None:
        return None if self.timeout is None else 0.5

    def _overdue(self, running: dict[Any, tuple[Any, Job, float]]) -> Iterator[AssetResult]:
        if self.timeout is None:
            return
        now = time.monotonic()
        for conn in [c for c, (_, _, t0) in running.items() if now - t0 > self.timeout]:
            proc, job, _ = running.pop(conn)
            proc.kill()
            proc.join()
            conn.close()
            yield _lost(job, f"stopped after the {self.timeout:g} s timeout (--timeout)")


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


class DaskEngine:
    """The jobs as tasks on the Dask distributed scheduler at ``address``."""

    TOPIC = "wrinklepipe-batch"

    def __init__(self, address: str, connect_s: float = 30) -> None:
        self.address = address
        self.connect_s = connect_s
        self.description = f"Dask scheduler {address}"

    def _client(self) -> Any:
        # Deferred on purpose: distributed takes about a second to import and only this
        # engine needs it.
        from distributed import Client

        try:
            return Client(self.address, timeout=self.connect_s, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise input_error(
                "--scheduler", f"cannot reach the Dask scheduler at {self.address}: {exc}"
            ) from None

    def _check_workers(self, client: Any) -> None:
        ours = tool_fingerprint()
        theirs = client.run(tool_fingerprint)
        if not theirs:
            raise input_error("--scheduler", f"the Dask cluster at {self.address} has no workers")
        differ = sorted(addr for addr, fp in theirs.items() if fp != ours)
        if differ:
            raise input_error(
                "--scheduler",
                f"workers {', '.join(differ)} run a different wrinklepipe or library versions "
                "than this client; outputs would not be byte-identical (install the same on all)",
            )

    def run(self, jobs: Sequence[Job], on_stage: StageFn) -> Iterator[AssetResult]:
        from distributed import as_completed  # deferred: Dask engine only (above)

        client = self._client()
        try:
            self._check_workers(client)

            def handler(event: Any) -> None:
                _, msg = event
                if isinstance(msg, dict):
                    on_stage(str(msg.get("job", "")), str(msg.get("stage", "")))

            client.subscribe_topic(self.TOPIC, handler)
            run_id = uuid.uuid4().hex[:8]
            futures = {}
            for job in jobs:
                fut = client.submit(
                    worker.dask_main, job, key=f"wrinklepipe-{run_id}-{job.id}", pure=False
                )
                futures[fut] = job
                on_stage(job.id, "queued")
            for fut in as_completed(list(futures), loop=client.loop):
                job = futures[fut]
                try:
                    result = fut.result()
                except Exception as exc:  # noqa: BLE001 - KilledWorker, lost data: this asset only
                    result = _lost(job, f"the Dask task failed ({type(exc).__name__}: {exc})")
                if result.source == "converted" and not job.output.is_dir():
                    result = _lost(
                        job,
                        f"worker {result.worker} wrote {job.output}, which this machine cannot "
                        "see: the workers and the client need a shared file system",
                    )
                yield result
        finally:
            client.unsubscribe_topic(self.TOPIC)
            client.close()
