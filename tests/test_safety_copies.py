"""Issue 39, verdicts on damaged copies: ``validate-asset`` reads every block-compressed copy the
asset lists (DDS and KTX2, every mip level) with the codec; a truncated or damaged copy fails
validation (WP-TEX-004) naming the file, never passes and never stops the run."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.normals.dds import read_dds
from wrinklepipe.normals.ktx2 import read_ktx2


@pytest.fixture(scope="module")
def converted(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("copies")
    src = write_demo_source(root / "src", 64)
    out = root / "out"
    assert main(["convert", str(src), "-o", str(out), "--no-render", "--no-validate"]) == 0
    assert sorted(p.suffix for p in (out / "compressed").iterdir()).count(".ktx2") >= 2
    return out


def _copy(converted: Path, tmp_path: Path) -> Path:
    out = tmp_path / "asset"
    shutil.copytree(converted, out)
    return out


def _validate(folder: Path, capsys) -> tuple[int, list[dict], str]:
    report = folder.parent / "report.json"
    rc = main(["validate-asset", str(folder), "--no-render", "--report", str(report)])
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return rc, json.loads(report.read_text())["issues"], err


def _level_offsets(path: Path) -> list[tuple[int, int]]:
    """(offset, length) of every level's block data in a DDS or KTX2 file."""
    raw = path.read_bytes()
    img = read_dds(path) if path.suffix == ".dds" else read_ktx2(path)
    return [(raw.index(lv), len(lv)) for lv in img.levels]


def test_the_undamaged_copies_pass(converted, tmp_path, capsys):
    rc, issues, _ = _validate(_copy(converted, tmp_path), capsys)
    assert rc == 0 and not [i for i in issues if i["code"] == "WP-TEX-004"]


@pytest.mark.parametrize(
    "damage",
    ["ktx2 truncated", "ktx2 level 0 random", "ktx2 last levels", "dds truncated", "both level 2"],
)
def test_a_damaged_copy_fails_validation_naming_it(converted, tmp_path, capsys, damage):
    out = _copy(converted, tmp_path)
    ktx2 = sorted((out / "compressed").glob("wrinkle_*.ktx2"))[0]
    dds = ktx2.with_suffix(".dds")
    rng = np.random.default_rng(39)
    if damage == "ktx2 truncated":
        ktx2.write_bytes(ktx2.read_bytes()[:-40])
        named = ktx2
    elif damage == "dds truncated":
        dds.write_bytes(dds.read_bytes()[:-40])
        named = dds
    elif damage == "both level 2":  # the same bytes in both: only the decode can tell
        for f in (ktx2, dds):
            off, n = _level_offsets(f)[2]
            raw = bytearray(f.read_bytes())
            raw[off : off + n] = bytes(rng.integers(0, 256, n, dtype=np.uint8))
            f.write_bytes(bytes(raw))
        named = ktx2
    else:
        raw = bytearray(ktx2.read_bytes())
        levels = _level_offsets(ktx2)
        if damage == "ktx2 level 0 random":
            off, _ = levels[0]
            raw[off + 64 : off + 128] = bytes(rng.integers(0, 256, 64, dtype=np.uint8))
        else:  # the smallest levels zeroed
            for off, n in levels[-3:]:
                raw[off : off + n] = bytes(n)
        ktx2.write_bytes(bytes(raw))
        named = ktx2
    rc, issues, err = _validate(out, capsys)
    assert rc == 1, err
    found = [i for i in issues if i["code"] == "WP-TEX-004"]
    assert found and any(named.name in i["message"] for i in found), found
    assert all(i["severity"] == "error" for i in found)


@pytest.mark.parametrize("given", ["demo_head.gltf", "demo_head.usda"])
@pytest.mark.parametrize("damage", ["truncated", "level 0 random"])
def test_the_file_that_lists_a_damaged_copy_fails_too(converted, tmp_path, capsys, given, damage):
    """validate-asset on the .gltf or USD layer alone (not its folder) reads the copies it lists
    too: a damaged KTX2 (listed first) fails the file's validation as it fails the folder's."""
    out = _copy(converted, tmp_path)
    ktx2 = sorted((out / "compressed").glob("wrinkle_*.ktx2"))[0]
    raw = bytearray(ktx2.read_bytes())
    if damage == "truncated":
        raw = raw[:-40]
    else:
        off, _ = _level_offsets(ktx2)[0]
        raw[off + 64 : off + 128] = bytes(np.random.default_rng(39).integers(0, 256, 64, np.uint8))
    ktx2.write_bytes(bytes(raw))
    report = tmp_path / "report.json"
    rc = main(["validate-asset", str(out / given), "--no-render", "--report", str(report)])
    err = capsys.readouterr().err
    found = [i for i in json.loads(report.read_text())["issues"] if i["code"] == "WP-TEX-004"]
    assert rc == 1 and found and all(ktx2.name in i["message"] for i in found), err


@pytest.mark.parametrize("listed", ["/etc/hostname", "../outside.ktx2"])
def test_a_copy_listed_outside_the_folder_is_never_opened(converted, tmp_path, capsys, listed):
    out = _copy(converted, tmp_path)
    (tmp_path / "outside.ktx2").write_bytes(b"outside the asset folder")
    gltf = out / "demo_head.gltf"
    doc = json.loads(gltf.read_text())
    copies = doc["materials"][0]["extensions"]["WRINKLEPIPE_wrinkle_maps"]["compressed"]
    copies[0]["uris"][0] = listed
    gltf.write_text(json.dumps(doc))
    for target in (out, gltf):
        assert main(["validate-asset", str(target), "--no-render"]) == 2
        err = capsys.readouterr().err
        assert "is outside" in err and "Traceback" not in err and "WP-TEX-004" not in err, err
