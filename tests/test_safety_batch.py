"""Issue 39, faults in the cache and the farm: a full or read-only cache volume, a damaged cache
entry, a hanging asset, a Dask cluster whose workers all die. None of them stops a batch: every
asset gets a result, the summary is always written, the cache degrades to what it can still do
with one warning, and nothing is left behind."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from wrinklepipe import atomic, staging
from wrinklepipe.batch import DaskEngine, LocalEngine, plan_batch, run_plan
from wrinklepipe.batch import worker as batch_worker
from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.paths import ROOT

WP = [sys.executable, "-m", "wrinklepipe"]


@pytest.fixture(scope="module")
def sources(tmp_path_factory) -> Path:
    """Two small characters, ``src/a`` and ``src/b``."""
    root = tmp_path_factory.mktemp("batch") / "src"
    for name in ("a", "b"):
        m = write_demo_source(root / name, 16)
        m.write_text(m.read_text() + f"# character {name}\n")  # two cache keys
    return root


def _copy(sources: Path, tmp_path: Path) -> Path:
    src = tmp_path / "src"
    shutil.copytree(sources, src)
    return src


def _leftovers(*folders: Path) -> list[str]:
    """Staging folders and lock files anywhere under ``folders``."""
    found = []
    for folder in folders:
        for p in folder.rglob("*"):
            if p.name.endswith((staging.STAGING_SUFFIX, staging.STAGING_NEW_SUFFIX)) or (
                p.name.endswith(staging.LOCK_SUFFIX)
            ):
                found.append(str(p))
    return found


def _in_namespace(script: str, *args: str) -> subprocess.CompletedProcess:
    """``sh -c SCRIPT`` in a user + mount namespace of its own (root there: it may mount a
    tmpfs, unprivileged), with the project on the path."""
    if shutil.which("unshare") is None:
        pytest.skip("no unshare(1): cannot mount a small volume here")
    probe = subprocess.run(
        ["unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=4k tmpfs /mnt 2>/dev/null"],
        capture_output=True,
    )
    if probe.returncode != 0:
        pytest.skip("user and mount namespaces are not available: cannot mount a tmpfs")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        ["unshare", "-rm", "sh", "-c", script, "sh", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )


def _batch_args(src: Path, out: Path, cache: Path, summary: Path) -> list[str]:
    return [
        *WP,
        "batch",
        str(src),
        "-o",
        str(out),
        "--cache",
        str(cache),
        "--jobs",
        "1",
        "--no-render",
        "--summary",
        str(summary),
        "--force",
    ]


def test_a_full_cache_volume_degrades_to_no_cache_with_one_warning(sources, tmp_path):
    src = _copy(sources, tmp_path)
    out, cache, summary = tmp_path / "out", tmp_path / "cache", tmp_path / "summary.json"
    cache.mkdir()
    # a 48 KiB tmpfs: the first entry (a demo folder is ~150 KB) fills it
    proc = _in_namespace(
        'mount -t tmpfs -o size=48k tmpfs "$1" && shift && exec "$@"',
        str(cache),
        *_batch_args(src, out, cache, summary),
    )
    assert proc.returncode in (0, 1), proc.stderr
    doc = json.loads(summary.read_text())
    assert [a["id"] for a in doc["assets"]] == ["a/manifest", "b/manifest"]
    assert all(a["source"] == "converted" and a["status"] != "error" for a in doc["assets"])
    assert "No space left on device" in doc["cache"]["warning"] and doc["cache"]["stored"] == 0
    warnings = [ln for ln in proc.stderr.splitlines() if ln.startswith("warning: the cache")]
    assert len(warnings) == 1, proc.stderr
    assert "Traceback" not in proc.stderr and not _leftovers(out, tmp_path)
    for name in ("a", "b"):
        assert (out / name / "manifest" / "demo_head.gltf").is_file()


def test_a_read_only_cache_still_serves_its_entries(sources, tmp_path):
    src = _copy(sources, tmp_path)
    out, cache, summary = tmp_path / "out", tmp_path / "cache", tmp_path / "summary.json"
    args = _batch_args(src, out, cache, summary)
    assert main(args[3:]) in (0, 1)  # fills the cache (in this process)
    assert json.loads(summary.read_text())["cache"]["stored"] == 2
    text = (src / "b" / "manifest.toml").read_text()
    (src / "b" / "manifest.toml").write_text(text + "\n# changed\n")  # b converts again
    proc = _in_namespace(
        'mount --bind "$1" "$1" && mount -o remount,bind,ro "$1" && shift && exec "$@"',
        str(cache),
        *args,
    )
    assert proc.returncode in (0, 1), proc.stderr
    doc = json.loads(summary.read_text())
    assert [(a["id"], a["source"]) for a in doc["assets"]] == [
        ("a/manifest", "cache"),
        ("b/manifest", "converted"),
    ]
    assert "Read-only file system" in doc["cache"]["warning"]
    assert doc["cache"]["hits"] == 1 and doc["cache"]["stored"] == 0
    assert sum(ln.startswith("warning: the cache") for ln in proc.stderr.splitlines()) == 1
    assert not _leftovers(out, tmp_path)


@pytest.mark.parametrize("damage", ["file", "entry.json"])
def test_a_damaged_cache_entry_is_replaced(sources, tmp_path, capsys, damage):
    src = _copy(sources, tmp_path)
    out, cache, summary = tmp_path / "out", tmp_path / "cache", tmp_path / "summary.json"
    args = _batch_args(src, out, cache, summary)[3:]
    assert main(args) in (0, 1)
    entries = sorted((cache / "entries").glob("*/*"))
    assert len(entries) == 2
    victim = entries[0]
    if damage == "file":
        gltf = next((victim / "files").rglob("*.gltf"))
        gltf.write_bytes(gltf.read_bytes()[:-10])  # truncated
    else:
        (victim / "entry.json").write_text('["not an entry"]')
    assert main(args) in (0, 1)
    second = json.loads(summary.read_text())
    assert sorted(a["source"] for a in second["assets"]) == ["cache", "converted"]
    assert second["cache"]["stored"] == 1  # the damaged entry replaced, and counted once
    assert main(args) in (0, 1)
    third = json.loads(summary.read_text())
    assert [a["source"] for a in third["assets"]] == ["cache", "cache"], third["cache"]
    assert third["cache"]["stored"] == 0 and third["cache"]["unusable"] == 0
    assert not list((cache / "tmp").iterdir())


# ------------------------------------------------------------------------------------------------
# the watchdog


def _hang(job, conn, threads=None) -> None:  # noqa: ANN001
    """A worker whose asset ``b`` hangs (a loop that never ends) after it says hello, the way
    the PD scale search did; asset ``a`` is done at once."""
    if job.id.startswith("a/"):
        # a healthy asset: its result is its first message, so the watchdog's clock (which
        # starts at an asset's first message) never runs for it, whatever the machine's load
        conn.send(("done", batch_worker._judged(job, "a", "converted", "ran", [])))
        conn.close()
        return
    conn.send(("stage", "started"))
    while True:
        time.sleep(0.01)


def test_the_watchdog_stops_a_hanging_asset_and_the_batch_goes_on(sources, tmp_path):
    src = _copy(sources, tmp_path)
    plan = plan_batch([str(src)], tmp_path / "out", force=True)
    engine = LocalEngine(jobs=2, timeout=3.0, target=_hang)
    t0 = time.monotonic()
    run = run_plan(plan, engine, None)
    assert time.monotonic() - t0 < 120
    by_id = {r.id: r for r in run.results}
    assert by_id["a/manifest"].status != "error"
    lost = by_id["b/manifest"]
    assert lost.status == "error" and "watchdog" in lost.problems[0]["message"]
    assert not _leftovers(tmp_path / "out")


def test_batch_has_a_watchdog_by_default():
    from wrinklepipe.batch.engines import DEFAULT_TIMEOUT_S

    assert LocalEngine().timeout == DEFAULT_TIMEOUT_S
    assert LocalEngine(timeout=0).timeout is None


def _killed_while_writing(job, conn, threads=None) -> None:  # noqa: ANN001
    """A worker killed (SIGKILL, as the OOM killer does) while it builds asset ``b``'s output:
    its lock and marked staging folder, with a file in it, are on disk; asset ``a`` is done."""
    if job.id.startswith("a/"):
        conn.send(("done", batch_worker._judged(job, "a", "converted", "ran", [])))
        conn.close()
        return
    conn.send(("stage", "started"))
    with atomic.staged_folder(job.output) as tmp:
        (tmp / "half.gltf").write_text("{")
        os.kill(os.getpid(), signal.SIGKILL)


def test_a_killed_workers_staging_folder_and_lock_are_removed_at_once(sources, tmp_path):
    """The batch sees the worker die and removes what it left beside its output (its staging
    folder, its lock, the folder made for it), not leaving them for a later run there."""
    src = _copy(sources, tmp_path)
    plan = plan_batch([str(src)], tmp_path / "out", force=True)
    run = run_plan(plan, LocalEngine(jobs=1, target=_killed_while_writing), None)
    by_id = {r.id: r for r in run.results}
    assert by_id["a/manifest"].status != "error"
    lost = by_id["b/manifest"]
    assert lost.status == "error", lost
    assert lost.problems[0]["message"] == "the worker process died (killed by SIGKILL)"
    assert not _leftovers(tmp_path / "out")
    assert not (tmp_path / "out" / "b").exists()  # made for the asset, empty: removed too


# ------------------------------------------------------------------------------------------------
# a Dask cluster whose worker pool is killed


def _dask(*args: str) -> subprocess.Popen:
    dask = Path(sys.executable).parent / "dask"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [str(dask), *args],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )


def _scheduler_address(file: Path, scheduler: subprocess.Popen) -> str:
    """The address a ``dask scheduler --scheduler-file FILE`` listens on, once it has written
    the file (whole: it is read until it parses)."""
    for _ in range(6000):  # up to 10 minutes on a loaded machine; the scheduler is polled
        if scheduler.poll() is not None:
            pytest.fail(f"the Dask scheduler ended (exit {scheduler.returncode})")
        try:
            return str(json.loads(file.read_text())["address"])
        except (OSError, ValueError, KeyError):
            time.sleep(0.1)
    pytest.fail("the Dask scheduler wrote no scheduler file in 10 minutes")


def test_a_killed_dask_worker_pool_fails_the_assets_clearly(sources, tmp_path):
    pytest.importorskip("distributed")
    from distributed import Client

    src = _copy(sources, tmp_path)
    # port 0: the scheduler takes a free port and says which in its file (a fixed port may be
    # taken by another process, or by this test running in another checkout at the same time)
    file = tmp_path / "scheduler.json"
    scheduler = _dask(
        "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
        "--scheduler-file", str(file),
    )  # fmt: skip
    workers = []
    try:
        address = _scheduler_address(file, scheduler)
        with Client(address, timeout=60) as client:
            workers = [
                _dask("worker", address, "--no-nanny", "--nthreads", "1", "--no-dashboard")
                for _ in range(2)
            ]
            client.wait_for_workers(2, timeout=60)
        plan = plan_batch([str(src)], tmp_path / "out", force=True)
        stages: list[tuple[str, str]] = []

        def on_stage(job: str, stage: str) -> None:
            stages.append((job, stage))
            if stage == "queued" and len([s for s in stages if s[1] == "queued"]) == 2:
                for w in workers:  # the whole pool dies before any asset is done
                    os.killpg(w.pid, signal.SIGKILL)

        engine = DaskEngine(address, no_workers_s=3.0)
        t0 = time.monotonic()
        run = run_plan(plan, _Staged(engine, on_stage), None)
        took = time.monotonic() - t0
    finally:
        for p in [*workers, scheduler]:
            with_suppress_kill(p)
    assert took < 120
    assert [r.id for r in run.results] == ["a/manifest", "b/manifest"]
    for r in run.results:
        assert r.status == "error", r
        message = r.problems[0]["message"]
        assert "had no workers for 3 s" in message, message


class _Staged:
    """An engine that also reports its stages to ``on_stage``."""

    def __init__(self, inner, on_stage) -> None:  # noqa: ANN001
        self.inner, self.on_stage = inner, on_stage
        self.description = inner.description

    def run(self, jobs, on_stage):  # noqa: ANN001, ANN201
        def both(job: str, stage: str) -> None:
            on_stage(job, stage)
            self.on_stage(job, stage)

        yield from self.inner.run(jobs, both)


def with_suppress_kill(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait()


@contextlib.contextmanager
def _cluster(tmp_path: Path, n_workers: int) -> Iterator[tuple[str, subprocess.Popen, list]]:
    """A Dask scheduler (on a free port) and ``n_workers`` worker processes without nannies
    (a worker killed stays dead), each a process group of its own; all killed at the end."""
    pytest.importorskip("distributed")
    from distributed import Client

    file = tmp_path / "scheduler.json"
    scheduler = _dask(
        "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
        "--scheduler-file", str(file),
    )  # fmt: skip
    workers: list[subprocess.Popen] = []
    try:
        address = _scheduler_address(file, scheduler)
        with Client(address, timeout=60) as client:
            workers = [
                _dask("worker", address, "--no-nanny", "--nthreads", "1", "--no-dashboard")
                for _ in range(n_workers)
            ]
            if n_workers:
                client.wait_for_workers(n_workers, timeout=60)
        yield address, scheduler, workers
    finally:
        for p in [*workers, scheduler]:
            with_suppress_kill(p)


class _DiesWhereItIsRun:
    """Called here: the real fingerprint. Sent to a worker (pickled): the worker, unpickling it,
    ends at once (``os._exit``), as a worker killed while it answers the engine's check."""

    def __init__(self, real: Callable[[], str]) -> None:
        self.real = real

    def __call__(self) -> str:
        return self.real()

    def __reduce__(self):  # noqa: ANN204
        return (os._exit, (3,))


def test_a_worker_that_dies_while_it_is_checked_is_waited_for(
    sources, tmp_path, capfd, monkeypatch
):
    """The only worker dies while it answers the version check: the assets fail with the
    no-workers wait's message, not distributed's 'CommClosedError: in <TCP (closed) ...>'."""
    from wrinklepipe.batch import engines

    src = _copy(sources, tmp_path)
    with _cluster(tmp_path, 1) as (address, _, workers):
        monkeypatch.setattr(
            engines, "tool_fingerprint", _DiesWhereItIsRun(engines.tool_fingerprint)
        )
        plan = plan_batch([str(src)], tmp_path / "out", force=True)
        run = run_plan(plan, DaskEngine(address, no_workers_s=2.0), None)
        assert workers[0].wait(60) == 3  # it died in the check, as meant
    for r in run.results:
        assert r.status == "error", r
        message = r.problems[0]["message"]
        assert "had no workers for 2 s" in message and "Error" not in message, message
    assert "Traceback" not in capfd.readouterr().err


def test_a_scheduler_that_goes_away_fails_the_assets_in_words(sources, tmp_path, capfd):
    """The scheduler is killed once both assets are queued: every asset fails saying the
    scheduler went away, in one line of the tool's words; distributed's reconnect traceback
    never reaches the terminal."""
    src = _copy(sources, tmp_path)
    with _cluster(tmp_path, 1) as (address, scheduler, _):
        plan = plan_batch([str(src)], tmp_path / "out", force=True)
        queued: list[str] = []

        def on_stage(job: str, stage: str) -> None:
            if stage == "queued":
                queued.append(job)
                if len(queued) == 2:
                    os.killpg(scheduler.pid, signal.SIGKILL)
                    scheduler.wait()

        run = run_plan(plan, _Staged(DaskEngine(address, no_workers_s=600), on_stage), None)
    assert [r.id for r in run.results] == ["a/manifest", "b/manifest"]
    for r in run.results:
        assert r.status == "error", r
        message = r.problems[0]["message"]
        assert "scheduler" in message and ("went away" in message or "was lost" in message)
        assert "Error" not in message and "<" not in message and "\n" not in message, message
    err = capfd.readouterr().err
    assert "Traceback" not in err and "distributed." not in err, err


def test_a_task_whose_workers_all_died_is_said_in_words():
    pytest.importorskip("distributed")
    from types import SimpleNamespace

    from distributed import KilledWorker

    from wrinklepipe.batch.engines import _task_failed

    exc = KilledWorker("wrinklepipe-1-a", SimpleNamespace(address="tcp://10.0.0.7:4000"), 3)
    assert _task_failed(exc) == (
        "every Dask worker that ran the asset died (4 tried; the last tcp://10.0.0.7:4000): "
        "a crash or a worker's memory limit (see the worker's log)"
    )
    assert _task_failed(ValueError("bad\nsecond line")) == "the Dask task failed (ValueError: bad)"


def test_an_unreachable_scheduler_still_writes_the_summary(sources, tmp_path):
    from wrinklepipe.batch.publish import run_and_publish
    from wrinklepipe.console import err

    src = _copy(sources, tmp_path)
    summary = tmp_path / "summary.json"
    plan = plan_batch([str(src)], tmp_path / "out")
    engine = DaskEngine("tcp://127.0.0.1:9", connect_s=2)
    run, _ = run_and_publish(
        plan, engine, None, command="batch", console=err, summary_path=str(summary)
    )
    assert run.exit_code == 2
    doc = json.loads(summary.read_text())
    assert [a["status"] for a in doc["assets"]] == ["error", "error"]
    for a in doc["assets"]:
        assert a["problems"][0]["message"] == (
            "did not run: cannot reach the Dask scheduler at tcp://127.0.0.1:9: no answer in 2 s"
        )


@pytest.mark.parametrize(
    ("address", "why"),
    [
        ("not a url", "no host and port"),
        ("http://127.0.0.1:8786", "unknown scheme 'http'"),
        ("tcp://farm", "no host and port"),
        ("tcp://farm:86x", "'86x' is not a port number"),
    ],
)
def test_a_scheduler_address_dask_cannot_use_is_one_message(sources, tmp_path, capfd, address, why):
    """Refused before anything runs, in words (distributed's ValueError reached each asset, and
    its half-made client waited a minute at exit and printed a traceback)."""
    code = main(["batch", str(sources), "-o", str(tmp_path / "out"), "--scheduler", address])
    err = capfd.readouterr().err
    assert code == 2
    lines = [ln for ln in err.splitlines() if ln.startswith("error")]
    assert len(lines) == 1, err
    assert lines[0].startswith(
        f"error: --scheduler: {address} is not a Dask scheduler address ({why}"
    )
    assert "expected tcp://HOST:PORT" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_a_cluster_without_workers_fails_each_asset_with_the_reason(sources, tmp_path):
    """No worker at the start (none joined yet, or all gone before the batch): each asset fails
    with the wait's message, not with an error about the event topic the engine never
    subscribed to (it hid the reason: 'ValueError: No event handler known for topic')."""
    pytest.importorskip("distributed")
    from distributed import LocalCluster

    src = _copy(sources, tmp_path)
    plan = plan_batch([str(src)], tmp_path / "out", force=True)
    with LocalCluster(n_workers=0, processes=False, dashboard_address=None) as cluster:
        run = run_plan(plan, DaskEngine(cluster.scheduler_address, no_workers_s=0.5), None)
    assert [r.status for r in run.results] == ["error", "error"]
    for r in run.results:
        message = r.problems[0]["message"]
        assert "had no workers for 0.5 s" in message and "Error" not in message, message


class _RacingWorkers:
    """Two workers as the local engine runs them: each makes its output's missing parents
    (``atomic._make_parents``: the batch's output folder too, when it is not there yet), then
    both fail (a full disk) and remove what they made (``atomic._remove_created``)."""

    description = "two racing workers"

    def run(self, jobs, on_stage):  # noqa: ANN001, ANN201
        made = {j.id: atomic._make_parents(j.output.parent) for j in jobs}
        for j in jobs:
            atomic._remove_created(made[j.id])
            yield batch_worker._error_result(j, [{"file": str(j.output), "message": "full"}])


def test_an_output_folder_every_asset_failed_in_is_removed(sources, tmp_path):
    """The first worker made the batch's output folder, the second found it there; the first
    failed first (its folder not empty yet), the second did not make it: an empty output
    folder stayed behind. The batch makes it before any asset and removes it if still empty."""
    src = _copy(sources, tmp_path)
    plan = plan_batch([str(src)], tmp_path / "out" / "batch")
    run = run_plan(plan, _RacingWorkers(), None)
    assert [r.status for r in run.results] == ["error", "error"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["src"]
