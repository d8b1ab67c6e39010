"""Issue 11, data loss: nothing of the user's is ever removed or replaced.

Each test reproduces one numbered defect of the issue (it failed before the fix)."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from wrinklepipe import atomic, staging
from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.paths import ROOT


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return write_demo_source(tmp_path_factory.mktemp("src") / "demo", size=32)


def _tree(folder: Path) -> dict[str, bytes]:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def _during_run(monkeypatch, action) -> None:
    """Run ``action`` once in the middle of the next command: right after it has created its
    staging folder (its work and the final rename are still ahead)."""
    real = staging._Staging.__init__
    done = []

    def init(self, parent, name):
        real(self, parent, name)
        if not done:
            done.append(name)
            action()

    monkeypatch.setattr(staging._Staging, "__init__", init)


def _convert(source: Path, out: Path, *extra: str) -> int:
    return main(["convert", str(source), "-o", str(out), "--no-validate", *extra])


# 1 ----------------------------------------------------------------------------------------------


def test_files_added_to_the_output_during_convert_are_kept(source, tmp_path, monkeypatch, capsys):
    """Defect 1: the folder did not exist at the start; the user makes it and puts a file in it
    while convert runs; the run must not replace it (rename onto a non-empty folder fails)."""
    out = tmp_path / "userdir"

    def user():
        out.mkdir()
        (out / "important.txt").write_text("precious")

    _during_run(monkeypatch, user)
    assert _convert(source, out) == 2
    err = capsys.readouterr().err
    assert "changed while this run was writing" in err and "important.txt" in err
    assert _tree(out) == {"important.txt": b"precious"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["userdir"]  # no leftovers


def test_force_replaces_only_the_folder_as_it_was_at_the_start(
    source, tmp_path, monkeypatch, capsys
):
    """Defect 1 with --force: a file added during the run is not destroyed by the replacement."""
    out = tmp_path / "prev"
    assert _convert(source, out) == 0
    before = _tree(out)
    _during_run(monkeypatch, lambda: (out / "added.txt").write_text("mine"))
    assert _convert(source, out, "--force") == 2
    assert "added.txt" in capsys.readouterr().err
    assert _tree(out) == {**before, "added.txt": b"mine"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["prev"]


def test_force_replaces_an_unchanged_previous_output(source, tmp_path):
    out = tmp_path / "prev"
    assert _convert(source, out) == 0
    (out / "stale.txt").write_text("from an earlier run")
    assert _convert(source, out, "--force") == 0
    assert not (out / "stale.txt").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["prev"]


# 2 ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("force", [False, True])
def test_sibling_named_like_the_old_backup_is_untouched(source, tmp_path, force):
    """Defect 2: ``.OUT.old`` beside the output was deleted (it is not the tool's)."""
    out = tmp_path / "proj2"
    out.mkdir()
    if force:
        (out / "previous.txt").write_text("old output")
    backup = tmp_path / ".proj2.old"
    backup.mkdir()
    (backup / "backup.txt").write_text("x")
    partial = tmp_path / ".proj2.abc123.partial"  # a name the old code used for its own folders
    partial.mkdir()
    (partial / "mine.txt").write_text("y")
    assert _convert(source, out, *(["--force"] if force else [])) == 0
    assert _tree(backup) == {"backup.txt": b"x"}
    assert _tree(partial) == {"mine.txt": b"y"}
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        ".proj2.abc123.partial",
        ".proj2.old",
        "proj2",
    ]


# 3 ----------------------------------------------------------------------------------------------

_HOLD = """
import sys
from wrinklepipe.staging import output_lock
with output_lock(sys.argv[1]):
    print("held", flush=True)
    sys.stdin.read()
"""


@contextlib.contextmanager
def _lock_held_elsewhere(target: Path):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-c", _HOLD, str(target)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        assert proc.stdout.readline().strip() == "held"
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()


def test_second_writer_gets_a_clear_error(source, tmp_path, capsys):
    """Defect 3: two converts into one output both succeeded; the second must be refused."""
    out = tmp_path / "out"
    with _lock_held_elsewhere(out) as holder:
        assert _convert(source, out) == 2
        err = capsys.readouterr().err
        assert f"pid {holder.pid}" in err and ".out.wrinklepipe-lock" in err
        assert not out.exists()
    assert _convert(source, out) == 0  # the holder is gone: its lock is stale
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_stale_lock_of_a_killed_run_is_taken_over_and_removed(source, tmp_path):
    out = tmp_path / "out"
    with _lock_held_elsewhere(out) as holder:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
        assert staging.lock_path(out).exists()
    assert _convert(source, out) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_two_real_converts_into_one_output(source, tmp_path):
    """Two processes at once: exactly one writes, the other is refused by the lock (or, if it
    starts after the first has finished, by the non-empty folder); neither overwrites."""
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "wrinklepipe", "convert", str(source), "-o", str(out)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    procs = [
        subprocess.Popen([*cmd, "--no-validate"], stderr=subprocess.PIPE, text=True, env=env)
        for _ in range(2)
    ]
    results = [(p.wait(), p.stderr.read()) for p in procs]
    codes = sorted(code for code, _ in results)
    assert codes == [0, 2], results
    loser = next(err for code, err in results if code == 2)
    assert "wrinklepipe-lock" in loser or "not empty" in loser
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


# 4 ----------------------------------------------------------------------------------------------


def _git(repo: Path, *args: str) -> None:
    subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True)


def test_ci_outputs_are_unique_by_construction(tmp_path):
    """Defect 4: ``chars/good`` and ``props/good`` both went to ``$OUT/good``. The script now
    hands the changed manifests to ``wrinklepipe batch``, whose outputs are the manifest paths
    without ``.toml``; outputs that would meet stop the batch before anything is written."""
    from wrinklepipe.batch import plan_batch

    repo = tmp_path / "repo"
    repo.mkdir()
    _git(repo, "init", "-q", "-b", "main")
    _git(
        repo,
        "-c",
        "user.email=a@b",
        "-c",
        "user.name=a",
        "commit",
        "-q",
        "--allow-empty",
        "-m",
        "0",
    )
    for rel in (
        "chars/good/manifest.toml",
        "props/good/manifest.toml",
        "x.toml",
        "x/manifest.toml",
    ):
        (repo / rel).parent.mkdir(parents=True, exist_ok=True)
        (repo / rel).write_text('schema = "wrinklepipe/manifest@1"\n')
    _git(repo, "add", ".")
    _git(repo, "-c", "user.email=a@b", "-c", "user.name=a", "commit", "-q", "-m", "1")
    out = tmp_path / "out"
    plan = plan_batch([str(repo / "chars"), str(repo / "props")], out, root=repo)
    assert [j.output for j in plan.jobs] == [
        out / "chars/good/manifest",
        out / "props/good/manifest",
    ]
    wp = shutil.which("wrinklepipe", path=str(Path(sys.executable).parent))
    env = {**os.environ, "BASE": "HEAD~1", "OUT": str(out), "WRINKLEPIPE": wp}
    env["REPORTS"] = str(tmp_path / "reports")
    script = ROOT / "ci" / "asset_conversion.sh"
    res = subprocess.run(["bash", str(script)], cwd=repo, env=env, capture_output=True, text=True)
    # x.toml -> out/x and x/manifest.toml -> out/x/manifest would nest: an error, not an overwrite
    assert res.returncode == 2
    assert "lies inside 'x', the output of x.toml" in " ".join(res.stderr.split())
    assert not out.exists() or not any(out.iterdir())


# 5 ----------------------------------------------------------------------------------------------


def test_html_report_never_deletes_a_files_folder_it_did_not_write(tmp_path, capsys):
    """Defect 5: ``--html docs/summary.html`` deleted an existing ``docs/summary_files/``."""
    docs = tmp_path / "docs"
    (docs / "summary_files").mkdir(parents=True)
    (docs / "summary_files" / "notes.txt").write_text("mine")
    html = docs / "summary.html"
    args = ["validate-asset", "demo:pd@32", "--no-render", "--html", str(html)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "summary_files" in err and "not written by wrinklepipe" in err
    assert _tree(docs) == {"summary_files/notes.txt": b"mine"}
    # its own folder (every file shown by the report beside it) is replaced on a rerun
    (docs / "summary_files" / "notes.txt").unlink()
    assert main(args) == 0
    first = _tree(docs)
    assert main(args) == 0
    assert _tree(docs) == first
    assert sorted(p.name for p in docs.iterdir()) == ["summary.html", "summary_files"]
    # a file the user adds to it makes it theirs again
    (docs / "summary_files" / "mine.png").write_bytes(b"x")
    assert main(args) == 2
    assert _tree(docs) == {**first, "summary_files/mine.png": b"x"}


def _entries(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*")}


def test_a_file_written_inside_a_staged_folder_is_replaced_in_place(tmp_path):
    """Inside a folder being built the per-file temporary is a hidden sibling, not a marked
    staging folder of its own; it is renamed over the name on success (a rewrite replaces the
    bytes), and on failure neither it nor a folder it needed is left to be published."""
    target = tmp_path / "out"
    with atomic.staged_folder(target) as new:
        atomic.write_bytes(new / "a" / "one.bin", b"first")
        with atomic.temp_path(new / "a" / "one.bin") as tmp:
            assert tmp.parent == new / "a" and tmp.suffix == ".bin" and tmp.name != "one.bin"
            assert _entries(new) == {"a", "a/one.bin"}  # no staging folder inside
            tmp.write_bytes(b"second")
        assert (new / "a" / "one.bin").read_bytes() == b"second"
        with pytest.raises(RuntimeError), atomic.temp_path(new / "b" / "two.png") as tmp:
            tmp.write_bytes(b"partial")
            raise RuntimeError("writer failed")
        assert _entries(new) == {"a", "a/one.bin"}
        [aside] = [p for p in tmp_path.iterdir() if p.name.endswith(staging.STAGING_SUFFIX)]
        assert new.parent == aside
    assert _entries(target) == {"a", "a/one.bin"}
    assert {p.name for p in tmp_path.iterdir()} == {"out"}  # staging folder and lock gone
    assert oct((target / "a" / "one.bin").stat().st_mode & 0o777) == oct(atomic.default_mode())


def test_a_file_beside_a_staged_folder_still_gets_its_own_staging(tmp_path):
    """A name that only starts like an open staging folder's is outside it."""
    target = tmp_path / "out"
    with atomic.staged_folder(target) as new:
        aside = new.parent
        outside = aside.with_name(aside.name + "x") / "f.txt"
        with atomic.temp_path(outside) as tmp:
            assert tmp.name == "f.txt" and tmp.parent.name.endswith(staging.STAGING_SUFFIX)
            tmp.write_bytes(b"x")
        assert outside.read_bytes() == b"x"
