"""Issue 11, fault test: ``kill -9`` at 10 moments of ``convert`` and of ``export``; issue 39:
the moments are steps of the run, so the test is deterministic.

Each kill leaves the output either absent or complete (byte-identical to an undisturbed run),
never partial; whatever the kill left beside it (a staging folder, a lock file) is gone after
the next run, and nothing else is there. The ten runs go at once, into one parent folder (so the
live ones also meet the dead ones' leftovers).

A moment is a *file-system step*: the child counts its calls of ``os.mkdir``, ``os.rename``,
``os.replace``, ``os.unlink``, ``os.rmdir`` and ``os.open`` (every step by which the tool
creates, publishes or removes anything) and sends itself SIGKILL just before step N. An
undisturbed run records its steps; the kills are drawn (seeded) over all of them and over the
writing phase (from the first staging folder to the publishing rename), so every kill lands
where it was meant to, on any machine at any load, and the ones in the writing phase provably
die with their staging folder on disk.

Each run is a process of its own running the CLI's ``main``, forked from a ``multiprocessing``
fork server that imported the CLI once (as ``wrinklepipe batch`` starts its assets): SIGKILL
ends it as it ends ``python -m wrinklepipe``, and the 22 runs skip 22 start-ups (about 1.5 s
CPU each).
"""

from __future__ import annotations

import json
import multiprocessing
import os
import random
import shutil
import signal
import sys
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


#: The file-system steps a child counts (see the module doc).
STEPS = ("mkdir", "rename", "replace", "unlink", "rmdir", "open")


def _cli_process(args: list[str], kill_at: int, record: str) -> None:
    """The child: ``wrinklepipe ARGS`` with its output discarded, killed by SIGKILL just before
    its file-system step ``kill_at`` (0: never); ``record``: a file to write its steps to (JSON
    list of [step, path]) when it ends."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    steps: list[tuple[str, str]] = []
    real = {name: getattr(os, name) for name in STEPS}

    def counted(name: str):  # noqa: ANN202
        def step(*a, **k):  # noqa: ANN002, ANN003
            steps.append(
                (
                    name,
                    os.fsdecode(a[0]) if a and isinstance(a[0], (str, bytes, os.PathLike)) else "",
                )
            )
            if len(steps) == kill_at:
                os.kill(os.getpid(), signal.SIGKILL)
            return real[name](*a, **k)

        return step

    for name in STEPS:
        setattr(os, name, counted(name))
    try:
        code = main(args)
    finally:
        for name in STEPS:
            setattr(os, name, real[name])
        if record:
            Path(record).write_text(json.dumps(steps))
    sys.exit(code)


class CliRun:
    """One CLI run in a process of its own (the slice of ``subprocess.Popen`` the test uses)."""

    def __init__(self, args: list[str], kill_at: int = 0, record: str = "") -> None:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        self.process = ctx.Process(
            target=_cli_process, args=(args, kill_at, record), name="wrinklepipe"
        )
        self.process.start()

    def wait(self) -> int | None:
        self.process.join()
        return self.process.exitcode


def _steps(args: list[str], record: Path) -> list[tuple[str, str]]:
    """An undisturbed run's file-system steps."""
    assert CliRun(args, 0, str(record)).wait() == 0
    return [tuple(x) for x in json.loads(record.read_text())]


def _writing(steps: list[tuple[str, str]], out: Path) -> tuple[int, int]:
    """Steps (1-based) from the output's first staging folder to its publishing rename."""
    stem = f".{out.name}."
    first = next(
        i for i, (op, p) in enumerate(steps, 1) if op == "mkdir" and Path(p).name.startswith(stem)
    )
    published = next(
        i
        for i, (op, p) in enumerate(steps, 1)
        if op == "rename" and i > first and len(p) and Path(p).name == out.name
    )
    return first, published


def _kill_plan(seed: int, total: int, first: int, published: int) -> list[tuple[str, int]]:
    """Half the kills at a step of the whole run, half at a step of the writing phase."""
    rng = random.Random(seed)
    plan = [("run", rng.randint(1, total)) for _ in range(KILLS // 2)]
    plan += [("writing", rng.randint(first + 1, published)) for _ in range(KILLS // 2)]
    rng.shuffle(plan)
    return plan


def _fault_cycle(args_for, parent: Path, rerun, seed: int) -> list[str]:
    """The 10 runs at once (each killed at its own step), then for each: absent or complete;
    the next run succeeds; no leftovers at all at the end."""
    parent.mkdir(exist_ok=True)
    reference = parent / "reference"
    steps = _steps(args_for(reference), parent.parent / f"{parent.name}.steps.json")
    want = _tree(reference)
    first, published = _writing(steps, reference)
    plan = _kill_plan(seed, len(steps), first, published)
    outs = [parent / f"out{i}" for i in range(len(plan))]
    procs = [CliRun(args_for(out), kill_at) for out, (_, kill_at) in zip(outs, plan)]
    codes = [p.wait() for p in procs]
    outcomes = []
    for i, (out, (phase, kill_at), code) in enumerate(zip(outs, plan, codes)):
        # a step is a step on any machine: every kill lands (writing: with staging on disk)
        assert code == -signal.SIGKILL, f"kill {i} ({phase} step {kill_at}) did not land: {code}"
        if out.exists():
            assert _tree(out) == want, f"kill {i} ({phase} step {kill_at}) left a partial output"
        outcomes.append(f"{phase} step {kill_at}: {'complete' if out.exists() else 'absent'}")
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

    outcomes = _fault_cycle(args_for, tmp_path / "runs", rerun, seed=11)
    assert len(outcomes) == KILLS


def test_kill_9_during_export(source, tmp_path_factory):
    converted = tmp_path_factory.mktemp("conv") / "asset"
    assert main(["convert", str(source), "-o", str(converted), "--no-validate"]) == 0
    parent = tmp_path_factory.mktemp("export") / "runs"

    def args_for(out: Path) -> list[str]:
        return ["export", str(converted), "--engine", "unreal", "-o", str(out)]

    def rerun(out: Path, exists: bool) -> int:
        return main([*args_for(out), *(["--force"] if exists else [])])

    outcomes = _fault_cycle(args_for, parent, rerun, seed=12)
    assert len(outcomes) == KILLS


def test_a_kill_while_a_staging_folder_is_removed_leaves_nothing_unowned(source, tmp_path):
    """Issue 39: a run killed between removing its staging folder's marker and the folder
    (the folder empty and unmarked, listed only in the run's lock) left it for good once
    another run in the same folder had removed the dead run's lock. Now whichever run removes
    a dead lock first removes every staging folder it lists that is empty or marked by it."""
    parent = tmp_path / "runs"
    parent.mkdir()
    args = ["convert", str(source), "-o", str(parent / "out1"), "--no-validate"]
    steps = _steps(args, tmp_path / "steps.json")
    marker = max(
        i
        for i, (op, p) in enumerate(steps, 1)
        if op == "unlink" and Path(p).name == staging.STAGING_MARKER
    )
    assert steps[marker][0] == "rmdir"  # the next step removes the (now empty) folder
    for p in parent.iterdir():  # the recording run's output and leftovers: start afresh
        if p.is_dir():
            shutil.rmtree(p)
    assert CliRun(args, marker + 1).wait() == -signal.SIGKILL  # killed before that rmdir
    left = [p.name for p in parent.iterdir()]
    assert "out1" in left and any(n.endswith(staging.STAGING_SUFFIX) for n in left), left
    # another run writing beside it meets the dead run's lock first
    assert main(["convert", str(source), "-o", str(parent / "out2"), "--no-validate"]) == 0
    assert main([*args, "--force"]) == 0
    assert sorted(p.name for p in parent.iterdir()) == ["out1", "out2"]


def test_a_kill_between_the_renames_of_force_keeps_the_previous_output(source, tmp_path):
    """``--force`` moves the previous output into its staging folder, then renames the new one
    in. Killed between the two, the run left no output and the previous one only inside its
    staging folder, which the next run there removed as a dead run's: the output was lost.
    Now it is put back when that staging folder is removed."""
    parent = tmp_path / "runs"
    parent.mkdir()
    out = parent / "out"
    args = ["convert", str(source), "-o", str(out), "--no-validate", "--force"]
    assert main(args) == 0
    previous = _tree(out)
    (out / "mine.txt").write_text("the previous output, as it was\n")  # tell it apart
    previous["mine.txt"] = (out / "mine.txt").read_bytes()
    steps = _steps(args, tmp_path / "steps.json")  # (replaces it: the same, without mine.txt)
    (out / "mine.txt").write_text("the previous output, as it was\n")
    aside = next(i for i, (op, p) in enumerate(steps, 1) if op == "rename" and p == str(out))
    publish = next(i for i, (op, _) in enumerate(steps, 1) if op == "rename" and i > aside)
    assert CliRun(args, publish).wait() == -signal.SIGKILL  # killed before the new one is in
    assert not out.exists()
    # the next run beside it meets the dead run's lock and staging folder
    assert main(["convert", str(source), "-o", str(parent / "out2"), "--no-validate"]) == 0
    assert _tree(out) == previous
    assert sorted(p.name for p in parent.iterdir()) == ["out", "out2"]
