"""atomic.write_files: a job's {relative path: bytes} written as one folder, all or nothing."""

from __future__ import annotations

import pytest

from wrinklepipe.atomic import write_files
from wrinklepipe.errors import InputError


def test_writes_every_file_and_refuses_a_full_folder_without_force(tmp_path):
    files = {"b/c.txt": b"two", "a.bin": bytes(range(5))}
    out = write_files(tmp_path / "out", files)
    got = {p.relative_to(out).as_posix(): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert got == files
    with pytest.raises(InputError):
        write_files(tmp_path / "out", {"x": b"1"})
    write_files(tmp_path / "out", {"x": b"1"}, force=True)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["x"]


def test_a_failed_write_is_one_message_and_leaves_nothing(tmp_path):
    # "a" is a file and "a/b" needs it to be a folder: the OS refuses midway
    with pytest.raises(InputError, match="could not write the export .*nothing was changed"):
        write_files(tmp_path / "out", {"a": b"1", "a/b": b"2"}, what="the export")
    assert list(tmp_path.iterdir()) == []


def test_never_over_an_input(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    (src / "in.txt").write_bytes(b"keep")
    with pytest.raises(InputError):
        write_files(src, {"x": b"1"}, force=True, inputs=[src / "in.txt"])
    assert (src / "in.txt").read_bytes() == b"keep"
