"""Issue 11, wrong or misleading answers and paths (defects 10-13): the same input gets the same
answer from every verb; messages say what is wrong and what is allowed, naming the file."""

from __future__ import annotations

import json
import re
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.io.images import write_image

#: A progress line of a run whose stderr is not a terminal (wrinklepipe.console).
PROGRESS = re.compile(r"^ *\d+\.\d s  ")


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return write_demo_source(tmp_path_factory.mktemp("src") / "demo", size=32)


@pytest.fixture(scope="module")
def converted(source, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("conv") / "out"
    assert main(["convert", str(source), "-o", str(out), "--no-validate"]) == 0
    return out


def _copy(folder: Path, tmp_path: Path, name: str = "src") -> Path:
    dst = tmp_path / name
    shutil.copytree(folder, dst)
    return dst


def _errors(capsys) -> list[str]:
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err and "please report" not in err
    return [ln for ln in err.replace("\n ", " ").splitlines() if ln.startswith("error:")]


def _edit(manifest: Path, old: str, new: str) -> None:
    text = manifest.read_text()
    assert old in text, old
    manifest.write_text(text.replace(old, new, 1))


# 10 ---------------------------------------------------------------------------------------------


def test_flat_grey_base_gets_the_same_answer_from_every_verb(source, tmp_path, capsys):
    """Defect 10: (128, 128, 128) everywhere (zero vectors) converted with exit 0, while
    validate-asset on the manifest failed with 3 errors and encode-normals counted non-unit
    texels. One check in the normal-map reader now answers for all three."""
    src = _copy(source.parent, tmp_path)
    write_image(src / "base_normal.png", np.full((32, 32, 3), 128 / 255, np.float32), bits=8)
    runs = {
        "convert": ["convert", str(src / "manifest.toml"), "-o", str(tmp_path / "out")],
        "validate-asset": ["validate-asset", str(src / "manifest.toml"), "--no-render"],
        "encode-normals": [
            "encode-normals",
            str(src / "base_normal.png"),
            "-o",
            str(tmp_path / "e.png"),
        ],
    }
    messages = {}
    for verb, args in runs.items():
        assert main(args) == 2, verb
        errors = _errors(capsys)
        assert len(errors) == 1, errors
        messages[verb] = errors[0][errors[0].index("base_normal.png") :]
    assert len(set(messages.values())) == 1, messages
    assert "1024 of 1024 texels too short to be normals" in messages["convert"]
    assert "flat mid-grey" in messages["convert"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["src"]


# 11 ---------------------------------------------------------------------------------------------


def test_unknown_expression_in_driver_keys_is_found_at_load(source, tmp_path, capsys):
    src = _copy(source.parent, tmp_path)
    m = src / "manifest.toml"
    m.write_text(
        m.read_text()
        + '\n[[drivers]]\nkind = "expressions"\npreset = "jimenez"\n'
        + "[drivers.keys]\nangr = [[0.0, 0.0], [1.0, 1.0]]\n"
    )
    from wrinklepipe.sources.manifest import load_manifest

    with pytest.raises(Exception) as info:
        load_manifest(m)
    text = str(info.value)
    assert "manifest.toml" in text and "unknown expression 'angr'" in text
    assert "did you mean 'anger'?" in text


def test_nan_in_an_exr_base_does_not_suggest_an_option_convert_lacks(source, tmp_path, capsys):
    src = _copy(source.parent, tmp_path)
    n = np.zeros((32, 32, 3), np.float32)
    n[..., 2] = 1.0
    n[3, 4] = np.nan
    write_image(src / "base.exr", n, bits="half")
    _edit(src / "manifest.toml", 'base = "base_normal.png"', 'base = "base.exr"')
    assert main(["convert", str(src / "manifest.toml"), "-o", str(tmp_path / "o")]) == 2
    (err,) = _errors(capsys)
    assert "base.exr" in err and "1 NaN texel, first at row 3, col 4" in err
    assert "use --repair" not in err and "encode-normals --repair" in err


def _nan_position_gltf(converted: Path, tmp_path: Path) -> Path:
    out = _copy(converted, tmp_path, "nan")
    gltf = next(out.glob("*.gltf"))
    doc = json.loads(gltf.read_text())
    acc = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    view = doc["bufferViews"][acc["bufferView"]]
    binp = out / doc["buffers"][view["buffer"]]["uri"]
    data = bytearray(binp.read_bytes())
    struct.pack_into("<f", data, view.get("byteOffset", 0) + acc.get("byteOffset", 0), np.nan)
    binp.write_bytes(bytes(data))
    return out


def test_nan_positions_are_an_input_error_not_a_bug_report(converted, tmp_path, capsys):
    out = _nan_position_gltf(converted, tmp_path)
    assert main(["validate-asset", str(out), "--no-render"]) == 2
    (err,) = _errors(capsys)
    assert ".gltf" in err and "NaN" in err


@pytest.mark.parametrize(
    "meshes",
    [[[]], [{}], [{"primitives": [[]]}], [{"primitives": [{}]}], [{"primitives": "x"}], {}],
)
def test_malformed_mesh_objects_are_named(tmp_path, capsys, meshes):
    """An empty mesh object was "malformed glTF (AttributeError: 'list' object ...)"."""
    p = tmp_path / "m.gltf"
    p.write_text(json.dumps({"asset": {"version": "2.0"}, "meshes": meshes}))
    for verb in (["vertex-ids", str(p)], ["validate-asset", str(p), "--no-render"]):
        assert main(verb) == 2
        (err,) = _errors(capsys)
        assert "m.gltf" in err and "AttributeError" not in err and "object has no" not in err


def test_schema_errors_say_what_is_allowed(source, tmp_path, capsys):
    src = _copy(source.parent, tmp_path)
    m = src / "manifest.toml"
    text = m.read_text()
    text = text.replace('pd_scale = "auto"', "pd_scale = 0").replace(
        'convention = "opengl"', 'convention = "dx"'
    )
    m.write_text(text)
    assert main(["convert", str(m), "-o", str(tmp_path / "o")]) == 2
    errors = _errors(capsys)
    joined = "\n".join(errors)
    assert "not valid under any of the given schemas" not in joined
    assert "[pd_scale]: 0 is out of range" in joined or "[pd_scale]: 0 is not allowed" in joined
    assert "expected 'auto' or a number >= 0.015625 and <= 64" in joined
    assert (
        "[convention]: 'dx' is not allowed; expected one of 'opengl', 'directx', 'auto'" in joined
    )


def test_every_problem_at_once_schema_and_missing_files(source, tmp_path, capsys):
    """A manifest with an unknown key stopped before reporting its missing files."""
    src = _copy(source.parent, tmp_path)
    m = src / "manifest.toml"
    _edit(m, 'name = "demo_head"', 'name = "demo_head"\ncolour = "red"')
    (src / "wrinkle_stretch.png").unlink()
    assert main(["convert", str(m), "-o", str(tmp_path / "o")]) == 2
    errors = _errors(capsys)
    assert any("[colour]: unknown key" in e and "allowed:" in e for e in errors), errors
    assert any("wrinkle_stretch.png" in e and "not found" in e for e in errors), errors


def test_library_noise_is_not_printed_around_the_message(source, tmp_path, capfd):
    src = _copy(source.parent, tmp_path)
    mask = sorted((src / "masks").glob("*.png"))[0]
    data = mask.read_bytes()
    mask.write_bytes(data[: len(data) // 2])
    assert main(["convert", str(src / "manifest.toml"), "-o", str(tmp_path / "o")]) == 2
    err = capfd.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip() and not PROGRESS.match(ln)]
    assert "libpng" not in err
    assert lines[0].startswith("error:") and mask.name in lines[0]
    assert all(ln.startswith(("error:", " ")) for ln in lines), lines


# 12 ---------------------------------------------------------------------------------------------


def test_manifest_paths_are_confined_to_its_folder(source, tmp_path, capsys):
    """Defect 12: ``mask = "../x/chin.png"`` converted; ``/etc/passwd`` was opened."""
    src = _copy(source.parent, tmp_path)
    outside = tmp_path / "x"
    outside.mkdir()
    shutil.copy(src / "masks" / "chin.png", outside / "chin.png")
    m = src / "manifest.toml"
    _edit(m, 'mask = "masks/chin.png"', 'mask = "../x/chin.png"')
    _edit(m, 'map = "wrinkle_stretch.png"', 'map = "/etc/passwd"')
    assert main(["convert", str(m), "-o", str(tmp_path / "o")]) == 2
    errors = _errors(capsys)
    assert any("manifest.toml" in e and "'../x/chin.png' is outside" in e for e in errors), errors
    assert any("'/etc/passwd' is outside" in e for e in errors), errors
    assert all("--allow-root" in e for e in errors if "outside" in e)
    # an allowed root opens the door for that folder only
    args = ["convert", str(m), "-o", str(tmp_path / "o"), "--allow-root", str(outside)]
    assert main(args) == 2
    errors = _errors(capsys)
    assert len(errors) == 1 and "/etc/passwd" in errors[0]
    _edit(m, 'map = "/etc/passwd"', 'map = "wrinkle_stretch.png"')
    assert main([*args, "--no-validate"]) == 0


def _usda(path: Path, sublayer: str) -> None:
    path.write_text(f"#usda 1.0\n(\n    subLayers = [@{sublayer}@]\n)\n")


def test_usd_sublayers_outside_the_asset_folder_are_refused(converted, tmp_path, capsys):
    out = _copy(converted, tmp_path, "asset")
    usda = next(out.glob("*.usda"))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    _usda(elsewhere / "evil.usda", "")
    top = out / "top.usda"
    _usda(top, "../elsewhere/evil.usda")
    text = top.read_text().replace("subLayers = [", f"subLayers = [@./{usda.name}@, ")
    top.write_text(text)
    for verb in (["validate-asset", str(top), "--no-render"], ["vertex-ids", str(top)]):
        assert main(verb) == 2
        (err,) = _errors(capsys)
        assert "top.usda" in err and "evil.usda" in err and "outside" in err
    assert main(["vertex-ids", str(top), "--allow-root", str(elsewhere)]) == 0
    capsys.readouterr()


def test_usd_references_are_confined_too(converted, tmp_path, capsys):
    out = _copy(converted, tmp_path, "asset")
    (tmp_path / "lib.usda").write_text('#usda 1.0\ndef Xform "Lib" {}\n')
    ref = out / "ref.usda"
    ref.write_text('#usda 1.0\ndef Xform "A" (\n    references = @../lib.usda@\n) {}\n')
    assert main(["vertex-ids", str(ref)]) == 2
    (err,) = _errors(capsys)
    assert "ref.usda" in err and "lib.usda" in err and "outside" in err


# 13 ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["..", ".hidden", "-rf", "a/b", "", "x" * 101])
def test_names_must_be_safe_file_stems(source, tmp_path, capsys, name):
    src = _copy(source.parent, tmp_path)
    _edit(src / "manifest.toml", 'name = "demo_head"', f"name = {json.dumps(name)}")
    assert main(["convert", str(src / "manifest.toml"), "-o", str(tmp_path / "o")]) == 2
    (err,) = _errors(capsys)
    assert "[name]" in err and "safe file stem" in err
    assert not (tmp_path / "o").exists()


def test_validate_asset_on_a_manifest_judges_what_convert_ships(source, tmp_path, capsys):
    """The general form of defect 10: steep wrinkles (60-degree slopes, 1.73) need a PD scale
    above 1, which convert chooses (pd_scale = "auto"); validate-asset on the same manifest
    judged them at scale 1 and reported clipping errors convert never had. It now runs
    convert's stages."""
    src = _copy(source.parent, tmp_path)
    n = np.zeros((32, 32, 3), np.float32)
    n[..., 2] = 1.0
    tilt = np.radians(60.0)
    n[8:24, 8:24] = (np.sin(tilt), 0.0, np.cos(tilt))
    write_image(src / "wrinkle_stretch.png", n * 0.5 + 0.5, bits=16)
    m = str(src / "manifest.toml")
    out = tmp_path / "out"
    # PNG textures on both sides (validate-asset packs a manifest as PNG): like with like
    convert_code = main(["convert", m, "-o", str(out), "--no-render", "--no-compress"])
    report = json.loads((out / "report.json").read_text())
    assert report["pd_scale"]["value"] >= np.tan(tilt)  # convert chose a scale that holds them
    assert main(["validate-asset", m, "--no-render", "--json"]) == convert_code == 0
    codes = {i["code"] for i in json.loads(capsys.readouterr().out)["issues"]}
    assert "WP-MAP-004" not in codes  # no clipping at the scale convert chose


def test_auto_pd_scale_meets_the_clipping_rule_on_every_map():
    """Convert's automatic PD scale and the validator's clipping rule (WP-MAP-004: at most 0.1%
    of a map's texels stored at 0 or 255) are one criterion: judged per map (pooling the states
    let one map clip 0.18%: the demo at 128 failed its own validation) and counting the slopes
    that round to the edge in 8 bits."""
    from wrinklepipe.normals import encode as enc

    flat = np.zeros((2, 100, 100, 2), np.float32)
    steep = flat.copy()
    steep[1].reshape(-1, 2)[:15, 0] = 0.3  # 0.15% of map 1 beyond 0.25; 0.075% of the pair
    assert enc.auto_pd_scale(steep[1]) == 0.5
    assert enc.auto_pd_scale(steep) == 0.5  # the stack: the steepest map decides
    edge = flat[0].copy()
    edge.reshape(-1, 2)[:, 0] = 0.25 * (1 - 0.5 / 255)  # below 0.25, but stored as 255
    assert enc.auto_pd_scale(edge) == 0.5
    q, _, _ = enc.encode_pd_u8(np.dstack([edge, np.ones((100, 100, 1))]), 0.25)
    assert q.max() == 255  # which is why
