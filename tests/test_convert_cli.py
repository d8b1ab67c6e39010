"""``wrinklepipe convert``: pipeline into one folder; determinism; unsafe outputs; full disk."""

from __future__ import annotations

import errno
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import usd_checks

from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.gltf.package_read import read_wrinkled
from wrinklepipe.io import khronos
from wrinklepipe.outputs import folder as output_folder
from wrinklepipe.presets import jimenez
from wrinklepipe.usd.package_read import read_usd


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    """The demo as artist files at 256 (its manifest chooses the wrinkle size against the
    budget: ``wrinkle = "auto"``)."""
    manifest = write_demo_source(tmp_path_factory.mktemp("src") / "demo", size=256)
    assert 'wrinkle = "auto"' in manifest.read_text()
    return manifest


@pytest.fixture(scope="module")
def small_source(tmp_path_factory) -> Path:
    """The demo at 32, for the tests of how a run ends (refused, failed, --json), which do not
    depend on the size: a quarter of the 256 run's cost."""
    return write_demo_source(tmp_path_factory.mktemp("small") / "demo", size=32)


@pytest.fixture(scope="module")
def converted(source, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("conv") / "out"
    # validation runs its rules; its GPU render pass is the validator's own tests' business
    assert main(["convert", str(source), "-o", str(out), "--glb", "--usdz", "--no-render"]) == 0
    return out


def _tree(folder: Path) -> dict[str, bytes]:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def test_folder_contents(converted):
    files = set(_tree(converted))
    name = "demo_head"
    expected = {
        f"{name}.gltf",
        f"{name}.bin",
        f"{name}.glb",
        f"{name}.usda",
        f"{name}.usdz",
        "textures/base_normal.png",
        "textures/wrinkle_stretch.png",
        "textures/wrinkle_compress.png",
        "textures/mask_0.png",
        "textures/mask_1.png",
        "report.json",
        "report.html",
    }
    assert expected <= files
    assert any(f.startswith("curves/") and f.endswith(".csv") for f in files)
    assert not any(".partial" in f or f.startswith(".") for f in files)
    report = json.loads((converted / "report.json").read_text())
    listed = {o["file"] for o in report["outputs"]}
    assert listed == files - {"report.json", "report.html"}
    # "auto": the smallest power of two within the budget inside the active regions (the
    # fidelity search's record says which it tried), or full size
    size = report["asset"]["sizes"]["wrinkle_stretch"][0]
    assert size in (16, 32, 64, 128, 256)
    assert report["asset"]["sizes"]["wrinkle_compress"][0] == size
    fid = report["fidelity"]
    assert fid["wrinkle"] == size and [fid["mask"]] * 2 == report["asset"]["sizes"]["mask_0"][:2]
    assert fid["png"]["poses"] and all(p["p99_deg"] <= 2.0 for p in fid["png"]["poses"])


def test_validation_ran_clean(converted):
    v = json.loads((converted / "report.json").read_text())["validation"]
    assert v["status"] == "ran"
    assert v["counts"]["error"] == 0, v["issues"]
    assert str(converted) not in json.dumps(v)  # paths relative to the output


def test_two_runs_are_byte_identical(source, converted, tmp_path):
    out = tmp_path / "again"
    assert main(["convert", str(source), "-o", str(out), "--glb", "--usdz", "--no-render"]) == 0
    a, b = _tree(converted), _tree(out)
    assert a.keys() == b.keys()
    for rel in a:
        assert a[rel] == b[rel], rel


def test_output_gltf_and_usd_agree(converted):
    g = read_wrinkled(converted / "demo_head.gltf")
    u = read_usd(converted / "demo_head.usda")
    z = read_usd(converted / "demo_head.usdz")
    for other in (u, z):
        assert other.meta == g.meta
        for t in g.textures:
            assert np.array_equal(other.texture(t.name).pixels, t.pixels)
        assert np.array_equal(other.mesh.vertex_ids, g.mesh.vertex_ids)
        assert np.array_equal(other.curves[0].values, g.curves[0].values)
    # the demo's expression driver: at t = 1 s joy is fully on -> Table 1.1 joy row
    c = g.curves[0]
    i = int(np.argmin(np.abs(c.times - 1.0)))
    assert c.times[i] == pytest.approx(1.0)
    assert c.values[i].tolist() == pytest.approx(list(jimenez.TABLE_1_1["joy"]))


@pytest.mark.parametrize("name", ["demo_head.gltf", "demo_head.glb"])
def test_output_passes_khronos_validator(converted, name):
    if not khronos.available():
        pytest.skip("Khronos glTF-Validator not installed")
    issues = khronos.validate_gltf(converted / name)["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]


def test_output_passes_usd_validation(converted):
    from pxr import Usd

    from wrinklepipe.usd.package_write import register_schema

    register_schema()
    for name in ("demo_head.usda", "demo_head.usdz"):
        stage = Usd.Stage.Open(str(converted / name))
        errors = usd_checks.validation_errors(stage)
        assert errors == [], [(e.GetName(), e.GetMessage()) for e in errors]


def test_report_numbers(converted):
    report = json.loads((converted / "report.json").read_text())
    # a power of two, and few texels clipped at that scale
    s = report["pd_scale"]["value"]
    assert s > 0 and np.log2(s) == int(np.log2(s))
    assert sum(report["pd_scale"]["clipped_texels"].values()) < 0.01 * 64 * 64
    # 8-bit PD at scale s: slopes step s / 127.5, so the decode error stays well under a degree
    for st in report["decode_error"].values():
        assert st["mean_deg"] < 0.5 and st["p99_deg"] < 1.0
    html = (converted / "report.html").read_text()
    assert "<h1>demo_head</h1>" in html and "textures/base_normal.png" in html


# ------------------------------------------------------------------------------------------------
# unsafe outputs and failures: exit 2, clear message, nothing partial, previous output intact


def test_output_equal_to_input_folder(source, capsys):
    before = _tree(source.parent)
    assert main(["convert", str(source), "-o", str(source.parent), "--force"]) == 2
    assert "input" in capsys.readouterr().err
    assert _tree(source.parent) == before


def test_output_containing_the_input(source, capsys):
    assert main(["convert", str(source), "-o", str(source.parent.parent), "--force"]) == 2
    assert "input" in capsys.readouterr().err


def test_existing_output_needs_force(small_source, converted, tmp_path, capsys):
    out = tmp_path / "prev"
    shutil.copytree(converted, out)
    (out / "keep.txt").write_text("mine")
    before = _tree(out)
    assert main(["convert", str(small_source), "-o", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert _tree(out) == before
    assert main(["convert", str(small_source), "-o", str(out), "--force", "--no-validate"]) == 0
    assert not (out / "keep.txt").exists()


def test_full_disk_leaves_previous_output_intact(
    small_source, converted, tmp_path, monkeypatch, capsys
):
    out = tmp_path / "prev"
    shutil.copytree(converted, out)
    before = _tree(out)
    real = output_folder.write_bytes
    calls = {"n": 0}

    def failing(path, data, inputs=()):
        calls["n"] += 1
        if calls["n"] == 4:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, data, inputs)

    monkeypatch.setattr(output_folder, "write_bytes", failing)
    assert main(["convert", str(small_source), "-o", str(out), "--force", "--no-validate"]) == 2
    err = capsys.readouterr().err
    assert "No space left on device" in err and "nothing was changed" in err
    assert "Traceback" not in err
    assert calls["n"] == 4
    assert _tree(out) == before
    assert [p.name for p in tmp_path.iterdir()] == ["prev"]  # no temporary folder left


def test_missing_input_file(source, tmp_path, capsys):
    src = tmp_path / "src"
    shutil.copytree(source.parent, src)
    (src / "wrinkle_stretch.png").unlink()
    assert main(["convert", str(src / source.name), "-o", str(tmp_path / "o")]) == 2
    assert "wrinkle_stretch.png" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_json_output(small_source, tmp_path, capsys):
    out = tmp_path / "j"
    assert main(["convert", str(small_source), "-o", str(out), "--json", "--no-validate"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["name"] == "demo_head" and report["validation"]["status"] == "skipped"


def test_piped_json_run_keeps_stdout_for_the_json(small_source, tmp_path):
    """As a CI step reads it: stdout is the JSON alone, the progress lines go to stderr."""
    out = tmp_path / "p"
    proc = subprocess.run(
        [sys.executable, "-m", "wrinklepipe", "convert", str(small_source), "-o", str(out),
         "--json", "--no-validate"],
        capture_output=True,
        text=True,
        timeout=600,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["name"] == "demo_head"  # nothing but the JSON
    assert re.search(r"^\s*\d+\.\d s  reading inputs: done in \d+\.\d s$", proc.stderr, re.M)
    assert "\x1b[" not in proc.stderr + proc.stdout
