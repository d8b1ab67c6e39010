"""Issue 11, fault test: ``kill -9`` at 10 random moments of ``convert`` and of ``export``.

Each kill leaves the output either absent or complete (byte-identical to an undisturbed run),
never partial; whatever the kill left beside it (a staging folder, a lock file) is gone after
the next run, and nothing else is there. The moments are drawn (seeded, so CI is reproducible)
over the whole run, denser where the files are written. The ten runs go at once, into one
parent folder (so the live ones also meet the dead ones' leftovers), each on its own clock.

Each run is a process of its own running the CLI's ``main``, forked from a ``multiprocessing``
fork server that imported the CLI once (as ``wrinklepipe batch`` starts its assets): SIGKILL
ends it as it ends ``python -m wrinklepipe``, the kill moments fall in the command rather than in
the interpreter's start-up, and the 22 runs skip 22 start-ups (about 1.5 s CPU each).
"""

from __future__ import annotations

import multiprocessing
import os
import random
import sys
import threading
import time
from pathlib import Path

import pytest

from wrinklepipe import staging
from wrinklepipe.batch import engines
from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source

KILLS = 10


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return write_demo_source(tmp_path_factory.mktemp("src") / "demo", size=16)


def _tree(folder: Path) -> dict[str, bytes]:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


#: What the fork server imports once: what ``wrinklepipe batch``'s fork server imports (there is
#: one fork server per process, whichever test starts it), plus the CLI and both commands.
PRELOAD = [
    *engines._PRELOAD,
    "wrinklepipe.cli",
    "wrinklepipe.commands.convert",
    "wrinklepipe.commands.export",
]


def _cli_process(args: list[str]) -> None:
    """The child: ``wrinklepipe ARGS`` with its output discarded, exiting with its exit code."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    sys.exit(main(args))


class CliRun:
    """One CLI run in a process of its own (the slice of ``subprocess.Popen`` the test uses)."""

    def __init__(self, args: list[str]) -> None:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        self.process = ctx.Process(target=_cli_process, args=(args,), name="wrinklepipe")
        self.process.start()

    def poll(self) -> int | None:
        return self.process.exitcode

    def kill(self) -> None:
        self.process.kill()  # SIGKILL

    def wait(self) -> int | None:
        self.process.join()
        return self.process.exitcode

    @property
    def returncode(self) -> int | None:
        return self.process.exitcode


def _timed_run(args: list[str], parent: Path, out: Path) -> tuple[float, float, float]:
    """An undisturbed run: seconds until its staging folder appears, until the output does,
    and until it ends (the moments a kill is drawn from)."""
    t0 = time.monotonic()
    proc = CliRun(args)
    staged = published = None
    while proc.poll() is None:
        now = time.monotonic() - t0
        if staged is None and _staged(parent):
            staged = now
        if published is None and out.exists():
            published = now
        time.sleep(0.002)
    end = time.monotonic() - t0
    assert proc.returncode == 0
    return staged or 0.0, published or end, end


def _staged(parent: Path, name: str = "") -> bool:
    """A staging folder of output ``name`` (any output without it) is in ``parent``: one
    ``listdir``, as the ten killer threads poll this every few milliseconds."""
    prefix = f".{name}." if name else "."
    return any(
        n.startswith(prefix) and n.endswith(staging.STAGING_SUFFIX) for n in os.listdir(parent)
    )


def _kill_plan(seed: int, staged: float, published: float, end: float) -> list[tuple[str, float]]:
    """Half the kills at a random moment of the whole run (from its start), half at a random
    moment of the writing phase (from the moment its staging folder appears: robust to how
    long the interpreter takes to start on a loaded machine)."""
    rng = random.Random(seed)
    plan = [("run", rng.uniform(0.0, end)) for _ in range(KILLS // 2)]
    plan += [("writing", rng.uniform(0.0, published - staged + 0.02)) for _ in range(KILLS // 2)]
    rng.shuffle(plan)
    return plan


def _kill_at(proc: CliRun, parent: Path, name: str, phase: str, delay: float) -> None:
    if phase == "writing":
        deadline = time.monotonic() + 300
        while not _staged(parent, name) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.002)
    time.sleep(delay)
    proc.kill()
    proc.wait()


def _fault_cycle(args_for, parent: Path, rerun, seed: int) -> list[str]:
    """The 10 runs at once (each killed at its own moment, on its own clock), then for each:
    absent or complete; the next run succeeds; no leftovers at all at the end."""
    reference = parent / "reference"
    staged, published, end = _timed_run(args_for(reference), parent, reference)
    want = _tree(reference)
    plan = _kill_plan(seed, staged, published, end)
    outs = [parent / f"out{i}" for i in range(len(plan))]
    procs = [CliRun(args_for(out)) for out in outs]
    killers = [
        threading.Thread(target=_kill_at, args=(proc, parent, out.name, phase, delay))
        for proc, out, (phase, delay) in zip(procs, outs, plan)
    ]
    for k in killers:
        k.start()
    for k in killers:
        k.join()
    outcomes = []
    for i, (out, (phase, delay)) in enumerate(zip(outs, plan)):
        left = any(p.name.startswith(f".{out.name}.") for p in parent.iterdir())
        if out.exists():
            assert _tree(out) == want, f"kill {i} ({phase} +{delay:.3f} s) left a partial output"
        outcomes.append(
            f"{phase}: {'complete' if out.exists() else 'absent'}" + (" + leftovers" * left)
        )
    for out in outs:
        assert rerun(out, out.exists()) == 0
        assert _tree(out) == want
    assert sorted(p.name for p in parent.iterdir()) == sorted(
        ["reference", *(o.name for o in outs)]
    ), "leftovers after the next runs"
    return outcomes


def test_kill_9_during_convert(source, tmp_path):
    def args_for(out: Path) -> list[str]:
        return ["convert", str(source), "-o", str(out), "--no-render"]

    def rerun(out: Path, exists: bool) -> int:
        return main([*args_for(out), *(["--force"] if exists else [])])

    outcomes = _fault_cycle(args_for, tmp_path, rerun, seed=11)
    assert len(outcomes) == KILLS
    assert any("leftovers" in o for o in outcomes)  # the kills did land while it was writing


def test_kill_9_during_export(source, tmp_path_factory):
    converted = tmp_path_factory.mktemp("conv") / "asset"
    assert main(["convert", str(source), "-o", str(converted), "--no-validate"]) == 0
    parent = tmp_path_factory.mktemp("export")

    def args_for(out: Path) -> list[str]:
        return ["export", str(converted), "--engine", "unreal", "-o", str(out)]

    def rerun(out: Path, exists: bool) -> int:
        return main([*args_for(out), *(["--force"] if exists else [])])

    outcomes = _fault_cycle(args_for, parent, rerun, seed=12)
    assert len(outcomes) == KILLS
