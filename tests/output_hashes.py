"""Every output of four conversions, byte for byte: the sha256 of each file, recorded on main
before issue 40 moved the modules into layer folders, so that a move, a split or a merge of
code is shown to change no byte of what convert writes.

The four (each converted once by the test module named, with the options given there):

- ``demo``: ``wrinklepipe demo --size 64`` (validation with the GPU render pass; its render
  PNGs included), ``tests/test_demo.py::test_demo_command``;
- ``avatar``: the generated avatar (``wrinklepipe.demo.avatar``), ``glb=True, render=False``,
  ``tests/test_document_avatar.py``;
- ``robot``: RobotExpressive with ``wrinkle_setups.write_robot_setup``, ``glb=True,
  render=False``, the conftest fixture ``robot_converted``;
- ``tokyo``: LittlestTokyo (Draco) with ``wrinkle_setups.write_tokyo_setup``, ``glb=True,
  render=False``, ``tests/test_document_read.py`` (exit 1: the validator finds the body's
  tangents off MikkTSpace, WP-MESH-002; the bytes are what is compared here).

The lists are ``tests/output_hashes.json``. A change that is meant to change bytes updates
them and names itself in that file's ``changes`` list (commit, what changed, which files):
``python tests/output_hashes.py`` converts the four again and prints what differs;
``--write`` stores the new lists.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import tempfile
from pathlib import Path

HASHES_FILE = Path(__file__).with_name("output_hashes.json")


def folder_hashes(folder: Path) -> dict[str, str]:
    """sha256 of every file under ``folder``, by its path relative to it (posix)."""
    return {
        p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def expected(name: str) -> dict[str, str]:
    return json.loads(HASHES_FILE.read_text(encoding="utf-8"))["outputs"][name]


def differences(want: dict[str, str], got: dict[str, str]) -> list[str]:
    """One line per file that is missing, new or changed."""
    out = [f"missing: {f}" for f in sorted(want.keys() - got.keys())]
    out += [f"new:     {f}" for f in sorted(got.keys() - want.keys())]
    out += [f"changed: {f}" for f in sorted(want.keys() & got.keys()) if want[f] != got[f]]
    return out


def assert_unchanged(name: str, folder: Path) -> None:
    """Every file under ``folder`` has the bytes recorded for ``name``, and no file is missing
    or new."""
    diff = differences(expected(name), folder_hashes(folder))
    assert not diff, (
        f"the {name} conversion's outputs differ from tests/output_hashes.json:\n  "
        + "\n  ".join(diff)
        + "\nif the change is meant, run `python tests/output_hashes.py --write` and name it "
        "in that file's 'changes' list"
    )


def _convert_all(root: Path) -> dict[str, dict[str, str]]:
    """The four conversions as the tests run them, into ``root``: name -> hashes."""
    # deferred: the tests import this module for its checks only
    from wrinkle_setups import ROBOT, TOKYO, write_robot_setup, write_tokyo_setup

    from wrinklepipe.cli import main
    from wrinklepipe.demo import avatar
    from wrinklepipe.io.confine import allowed_roots
    from wrinklepipe.jobs.convert import ConvertOptions, convert

    os.environ["WRINKLEPIPE_CACHE"] = str(root / "cache")
    assert main(["demo", "-o", str(root / "demo"), "--size", "64"]) == 0
    out = {"demo": folder_hashes(root / "demo")}
    opts = ConvertOptions(glb=True, render=False)
    convert(avatar.avatar_source_dir(), root / "avatar", opts)
    out["avatar"] = folder_hashes(root / "avatar")
    for name, source, setup in (
        ("robot", ROBOT, write_robot_setup),
        ("tokyo", TOKYO, write_tokyo_setup),
    ):
        if not source.is_file():
            print(f"{name}: ../shared/data is absent, kept as recorded", file=sys.stderr)
            continue
        with allowed_roots([source.parent]):
            convert(setup(root / f"{name}-src"), root / name, opts)
        out[name] = folder_hashes(root / name)
    return out


if __name__ == "__main__":  # pragma: no cover - refreshes the lists by hand
    sys.path.insert(0, str(Path(__file__).parent))
    with tempfile.TemporaryDirectory() as tmp:
        got = _convert_all(Path(tmp))
    data = json.loads(HASHES_FILE.read_text(encoding="utf-8"))
    for name, hashes in got.items():
        diff = differences(data["outputs"][name], hashes)
        print(
            f"{name}: {len(hashes)} files, " + ("unchanged" if not diff else f"{len(diff)} differ")
        )
        for line in diff:
            print(f"  {line}")
        data["outputs"][name] = hashes
    if "--write" in sys.argv:
        HASHES_FILE.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n", encoding="utf-8")
        print(f"written: {HASHES_FILE} (name the change in its 'changes' list)")
