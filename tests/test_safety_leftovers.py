"""Issue 11, leftovers (defects 6 and 7): a later run removes what a dead run left, and only
that; a failure at the final rename leaves nothing behind and says so truthfully."""

from __future__ import annotations

import errno
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from wrinklepipe import staging
from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.io import png
from wrinklepipe.paths import ROOT


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return write_demo_source(tmp_path_factory.mktemp("src") / "demo", size=32)


def _convert(source: Path, out: Path, *extra: str) -> int:
    return main(["convert", str(source), "-o", str(out), "--no-validate", *extra])


def _staging(folder: Path) -> list[Path]:
    return sorted(folder.glob(f".*{staging.STAGING_SUFFIX}"))


#: A child running ``python -m wrinklepipe ARGS`` that kills itself (SIGKILL) right after its
#: first staging folder appears (the rename of ``...-new`` onto the staging name): the moment
#: is a step of the run, not a guess of a poller racing it on a loaded machine.
_KILL_AT_STAGING = """
import os, runpy, signal, sys
real = os.rename
def rename(src, dst, *a, **k):
    real(src, dst, *a, **k)
    if os.fsdecode(dst).endswith(suffix):
        os.kill(os.getpid(), signal.SIGKILL)
os.rename = rename
suffix, sys.argv = sys.argv[1], ["wrinklepipe", *sys.argv[2:]]
runpy.run_module("wrinklepipe", run_name="__main__", alter_sys=True)
"""


def _kill_once_staging_appears(args: list[str]) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-c", _KILL_AT_STAGING, staging.STAGING_SUFFIX, *args]
    proc = subprocess.run(cmd, env=env, capture_output=True, timeout=900)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode(errors="replace")


def test_later_run_removes_what_a_killed_run_left(source, tmp_path):
    """Defect 6: kill -9 left ``.OUT.<random>.partial`` folders that no later run removed."""
    out = tmp_path / "out"
    _kill_once_staging_appears(["convert", str(source), "-o", str(out), "--no-validate"])
    left = _staging(tmp_path)
    assert left and not out.exists()  # the kill left its staging folder, never a partial output
    marker = json.loads((left[0] / staging.STAGING_MARKER).read_text())
    assert marker["tool"] == "wrinklepipe" and marker["host"] == socket.gethostname()
    assert _convert(source, out) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def _fake_staging(folder: Path, name: str, owner: dict | None) -> Path:
    d = folder / f".{name}.x{staging.STAGING_SUFFIX}"
    d.mkdir()
    (d / "data.bin").write_bytes(b"keep")
    if owner is not None:
        (d / staging.STAGING_MARKER).write_text(json.dumps(owner))
    return d


def test_only_provably_dead_runs_leftovers_are_removed(source, tmp_path):
    """A folder with the staging suffix is removed only when its marker names a process on this
    host that is gone; no marker, a live process or another host: left alone."""
    host = socket.gethostname()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    live = os.getppid()
    base = {"tool": "wrinklepipe", "start": ""}
    d_dead = _fake_staging(tmp_path, "a", {**base, "pid": dead.pid, "host": host})
    keep = [
        _fake_staging(tmp_path, "b", None),
        _fake_staging(tmp_path, "c", {**base, "pid": live, "host": host}),
        _fake_staging(tmp_path, "d", {**base, "pid": dead.pid, "host": host + "-elsewhere"}),
        _fake_staging(tmp_path, "e", {"tool": "other", "pid": dead.pid, "host": host}),
    ]
    (tmp_path / "f.wrinklepipe-partial").mkdir()  # no leading dot: not even a candidate
    assert _convert(source, tmp_path / "out") == 0
    assert not d_dead.exists()
    for d in keep:
        assert (d / "data.bin").read_bytes() == b"keep"
    assert (tmp_path / "f.wrinklepipe-partial").is_dir()


def test_failure_at_the_final_rename_leaves_nothing(source, tmp_path, monkeypatch, capsys):
    """Defect 7: the final rename failing (a busy mount point) left the complete staging folder
    behind while the message said nothing was changed."""
    out = tmp_path / "out"
    real = os.replace

    def busy(src, dst, *a, **k):
        if Path(dst) == out:
            raise OSError(errno.EBUSY, "Device or resource busy", str(dst))
        return real(src, dst, *a, **k)

    monkeypatch.setattr(os, "rename", busy)
    monkeypatch.setattr(os, "replace", busy)
    assert _convert(source, out) == 2
    err = capsys.readouterr().err
    assert "busy" in err and "nothing was changed" in err
    assert list(tmp_path.iterdir()) == []


def test_failure_at_the_final_rename_with_force_keeps_the_old_output(
    source, tmp_path, monkeypatch, capsys
):
    out = tmp_path / "out"
    assert _convert(source, out) == 0
    before = sorted(p.relative_to(out) for p in out.rglob("*"))
    real = os.replace
    calls = []

    def busy_second(src, dst, *a, **k):
        if Path(dst) == out:
            calls.append(src)
            if len(calls) == 2:  # the first (onto the non-empty folder) fails as it should
                raise OSError(errno.EBUSY, "Device or resource busy", str(dst))
        return real(src, dst, *a, **k)

    monkeypatch.setattr(os, "rename", busy_second)
    monkeypatch.setattr(os, "replace", busy_second)
    assert _convert(source, out, "--force") == 2
    assert "nothing was changed" in capsys.readouterr().err
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_mount_point_output_is_refused_before_any_work(source, tmp_path, monkeypatch, capsys):
    out = tmp_path / "mnt"
    out.mkdir()
    real = os.path.ismount
    monkeypatch.setattr(os.path, "ismount", lambda p: Path(p) == out or real(p))
    assert _convert(source, out) == 2
    assert "mount point" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mnt"]


_KILLED_WHILE_STAGING = """
import os, signal, sys
from pathlib import Path
from wrinklepipe import staging

target, step = Path(sys.argv[1]), sys.argv[2]
real_open, real_rename = os.open, os.rename

def die():
    os.kill(os.getpid(), signal.SIGKILL)

def open_(path, *a, **k):
    if step == "mkdir" and str(path).endswith(staging.STAGING_MARKER):
        die()  # the -new folder exists, its marker not yet
    return real_open(path, *a, **k)

def rename(src, dst, *a, **k):
    if step == "rename" and str(src).endswith(staging.STAGING_NEW_SUFFIX):
        die()  # the marker is complete, the folder not yet renamed
    return real_rename(src, dst, *a, **k)

os.open, os.rename = open_, rename
with staging.output_lock(target):
    staging._Staging(target.parent, target.name)
    if step == "renamed":
        die()
"""


def _run_killed(script: str, *args: str) -> int:
    """Run ``script`` (which SIGKILLs itself) in a Python of its own; return its pid."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-c", script, *args], env=env)
    assert proc.wait() == -signal.SIGKILL
    return proc.pid


@pytest.mark.parametrize("step", ["mkdir", "rename", "renamed"])
def test_a_kill_while_the_staging_folder_is_made(tmp_path, step):
    """The staging folder appears by a rename with its complete marker inside (never without
    it); a kill at any step of making it leaves only what the next run on that output removes."""
    target = tmp_path / "out"
    pid = _run_killed(_KILLED_WHILE_STAGING, str(target), step)
    left = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".out."))
    want = staging.STAGING_SUFFIX if step == "renamed" else staging.STAGING_NEW_SUFFIX
    assert len(left) == 2 and left[0].endswith(want) and left[1] == ".out.wrinklepipe-lock"
    marker = tmp_path / left[0] / staging.STAGING_MARKER
    if step == "mkdir":
        assert not marker.exists()
    else:  # the marker names the killed run
        owner = json.loads(marker.read_text())
        assert owner["tool"] == "wrinklepipe" and owner["pid"] == pid
        assert owner["host"] == socket.gethostname()
    assert _staging(tmp_path) == ([tmp_path / left[0]] if step == "renamed" else [])
    with staging.output_lock(target):
        assert sorted(p.name for p in tmp_path.iterdir()) == [".out.wrinklepipe-lock"]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("step", ["mkdir", "rename", "renamed"])
def test_a_run_on_another_output_removes_a_killed_runs_staging_with_its_lock(tmp_path, step):
    """A run on another output in the same folder removes the dead run's lock file; the staging
    folders that lock lists go with it (a ``-new`` folder killed before its marker was written
    has no other proof that it is ours, and would be left for good: the flaky failure of
    ``test_kill_9_during_convert``, where ten runs share one folder)."""
    target = tmp_path / "out"
    _run_killed(_KILLED_WHILE_STAGING, str(target), step)
    assert len([p for p in tmp_path.iterdir() if p.name.startswith(".out.")]) == 2
    with staging.output_lock(tmp_path / "other"):
        assert sorted(p.name for p in tmp_path.iterdir()) == [".other.wrinklepipe-lock"]
    assert list(tmp_path.iterdir()) == []


def test_a_run_killed_while_removing_a_dead_runs_staging_leaves_it_recorded(tmp_path):
    """The next holder of a dead run's lock records that run's staging folders as its own before
    it removes them: killed in between, the run after it still finds them in the record."""
    target = tmp_path / "out"
    _run_killed(_KILLED_WHILE_STAGING, str(target), "mkdir")
    [new] = [p for p in tmp_path.iterdir() if p.name.endswith(staging.STAGING_NEW_SUFFIX)]
    second = _run_killed(_KILLED_WHILE_REMOVING, str(target))
    assert new.is_dir()  # the second run died before removing it
    record = json.loads((tmp_path / ".out.wrinklepipe-lock").read_text())
    assert record["pid"] == second and new.name in record["staging"]
    with staging.output_lock(target):
        assert sorted(p.name for p in tmp_path.iterdir()) == [".out.wrinklepipe-lock"]
    assert list(tmp_path.iterdir()) == []


_KILLED_WHILE_REMOVING = """
import os, signal, sys
from pathlib import Path
from wrinklepipe import staging

def die(*a, **k):
    os.kill(os.getpid(), signal.SIGKILL)

staging._remove_recorded = die  # the lock is taken and written, the dead run's folder not removed
with staging.output_lock(Path(sys.argv[1])):
    pass
"""


def test_decoding_an_embedded_png_puts_nothing_on_disk(tmp_path, monkeypatch):
    """A glTF's or USD package's PNG bytes are decoded from an anonymous memory file: nothing
    is in the temporary folder while OpenImageIO reads it (a temporary file there was left by
    every run killed at that moment: dozens piled up in /tmp under the fault tests)."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    seen: list[list[str]] = []
    real_open = oiio.ImageInput.open

    def watched(*args):  # noqa: ANN002, ANN202
        seen.append(sorted(p.name for p in tmp_path.iterdir()))
        return real_open(*args)

    monkeypatch.setattr(png.oiio.ImageInput, "open", watched)
    pixels = np.arange(48, dtype=np.uint8).reshape(4, 4, 3)
    assert (png.png_pixels(png.png_bytes(pixels)) == pixels).all()
    assert seen == [[]] and list(tmp_path.iterdir()) == []
