"""``--quiet`` and ``--verbose`` as a CI log sees them (a process whose stderr is a pipe):
quiet keeps only warnings and errors, normal adds the progress lines and the summary, verbose
adds the run's notes; the exit code and the outputs do not depend on it."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.io.images import write_image

PROGRESS = re.compile(r"^\s*\d+\.\d s  ", re.M)


def _run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "COLUMNS"}
    return subprocess.run(
        [sys.executable, "-m", "wrinklepipe", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )


@pytest.fixture(scope="module")
def masks(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two 4 x 4 masks, the second empty (a warning)."""
    folder = tmp_path_factory.mktemp("masks")
    brow = np.zeros((4, 4), np.float32)
    brow[:2] = 1.0
    write_image(folder / "brow.png", brow, 8)
    write_image(folder / "chin.png", np.zeros((4, 4), np.float32), 8)
    return folder


WARNING = "warning: region 'chin' covers nothing (its mask is 0 everywhere)"


def test_normal_run_logs_progress_summary_and_warning(masks: Path) -> None:
    r = _run("pack-masks", "brow.png", "chin.png", "-o", "normal", cwd=masks)
    assert r.returncode == 0 and r.stdout == ""
    lines = r.stderr.splitlines()
    assert lines[0].endswith("  wrinklepipe pack-masks brow.png chin.png -o normal")
    assert PROGRESS.search(r.stderr) and "packing 2 masks: done in" in r.stderr
    assert "packed 2 regions into 1 texture (rgba, 4 x 4, 8-bit) -> normal" in lines
    assert WARNING in lines


def test_quiet_keeps_only_warnings_and_errors(masks: Path) -> None:
    r = _run("pack-masks", "brow.png", "chin.png", "-o", "quiet", "--quiet", cwd=masks)
    assert r.returncode == 0 and r.stdout == ""
    assert r.stderr.splitlines() == [WARNING]  # no progress, no summary
    assert (masks / "quiet" / "channels.json").is_file()  # written all the same
    bad = _run("pack-masks", "nope.png", "-o", "none", "-q", cwd=masks)
    assert bad.returncode == 2 and bad.stderr.splitlines() == ["error: nope.png: file not found"]
    assert not (masks / "none").exists()


def test_quiet_and_verbose_together_are_refused(masks: Path) -> None:
    r = _run("pack-masks", "brow.png", "-o", "x", "-q", "-v", cwd=masks)
    assert r.returncode == 2 and "not allowed with argument" in r.stderr


def test_verbose_adds_the_notes_of_a_convert(tmp_path: Path) -> None:
    manifest = write_demo_source(tmp_path / "src", size=32)
    args = ["convert", str(manifest), "--no-validate"]
    normal = _run(*args, "-o", "a", cwd=tmp_path)
    verbose = _run(*args, "-o", "b", "--verbose", cwd=tmp_path)
    quiet = _run(*args, "-o", "c", "--quiet", cwd=tmp_path)
    assert normal.returncode == verbose.returncode == quiet.returncode == 0
    assert quiet.stderr == ""  # a clean run: nothing at all
    note = "note: "
    assert note not in normal.stderr and note in verbose.stderr, verbose.stderr
    assert len(verbose.stderr.splitlines()) > len(normal.stderr.splitlines())
    for name in ("a", "b", "c"):  # the same bytes whatever was printed
        assert (tmp_path / name / "demo_head.gltf").read_bytes() == (
            tmp_path / "a" / "demo_head.gltf"
        ).read_bytes()
