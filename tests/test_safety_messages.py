"""Issue 11, tracebacks and messages: every bad input ends in one clear message (exit 2) that
names the file; never a traceback (defects 8, 9, 11)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source

DEEP = 200_000


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return write_demo_source(tmp_path_factory.mktemp("src") / "demo", size=32)


def _copy_source(source: Path, tmp_path: Path) -> Path:
    src = tmp_path / "src"
    shutil.copytree(source.parent, src)
    return src / source.name


def _one_error(capsys, *needles: str) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, err
    for n in needles:
        assert n in err, err
    return err


def _deep_json() -> str:
    return "[" * DEEP + "]" * DEEP


def _deep_gltf(tmp_path: Path) -> Path:
    p = tmp_path / "deep.gltf"
    p.write_text('{"asset": {"version": "2.0"}, "extras": ' + _deep_json() + "}")
    return p


def _deep_glb(tmp_path: Path) -> Path:
    import struct

    js = ('{"asset": {"version": "2.0"}, "extras": ' + _deep_json() + "}").encode()
    js += b" " * (-len(js) % 4)
    data = struct.pack("<4sII", b"glTF", 2, 20 + len(js)) + struct.pack("<II", len(js), 0x4E4F534A)
    p = tmp_path / "deep.glb"
    p.write_bytes(data + js)
    return p


# 8 ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["gltf", "glb"])
@pytest.mark.parametrize(
    "verb",
    [
        ["validate-asset", "{f}", "--no-render"],
        ["vertex-ids", "{f}"],
        ["dynamic", "{f}", "--time", "0", "-o", "{out}/w.npy"],
    ],
    ids=["validate-asset", "vertex-ids", "dynamic"],
)
def test_deeply_nested_gltf_is_one_message(tmp_path, capsys, verb, kind):
    """Defect 8: JSON nested 200,000 deep crashed with a RecursionError traceback."""
    f = _deep_gltf(tmp_path) if kind == "gltf" else _deep_glb(tmp_path)
    args = [a.format(f=f, out=tmp_path) for a in verb]
    assert main(args) == 2
    _one_error(capsys, f.name, "nested more than")
    assert not (tmp_path / "w.npy").exists()


def test_deeply_nested_mesh_of_a_manifest(source, tmp_path, capsys):
    manifest = _copy_source(source, tmp_path)
    deep = _deep_glb(manifest.parent)
    text = manifest.read_text().replace('mesh = "head.glb"', f'mesh = "{deep.name}"')
    assert deep.name in text
    manifest.write_text(text)
    assert main(["convert", str(manifest), "-o", str(tmp_path / "out"), "--no-validate"]) == 2
    _one_error(capsys, "deep.glb", "nested more than")
    assert not (tmp_path / "out").exists()


def test_deeply_nested_manifest(tmp_path, capsys):
    m = tmp_path / "manifest.toml"
    m.write_text('name = "x"\nextra = ' + "[" * DEEP + "]" * DEEP + "\n")
    assert main(["convert", str(m), "-o", str(tmp_path / "out")]) == 2
    _one_error(capsys, "manifest.toml", "nested more than")


def test_deeply_nested_validate_config(tmp_path, capsys):
    cfg = tmp_path / "config.json"
    cfg.write_text('{"ignore": ' + _deep_json() + "}")
    assert main(["validate-asset", "demo:pd@32", "--no-render", "--config", str(cfg)]) == 2
    _one_error(capsys, "config.json", "nested more than")


def test_deeply_nested_curves_driver(source, tmp_path, capsys):
    manifest = _copy_source(source, tmp_path)
    (manifest.parent / "curves.json").write_text('{"fps": 30, "regions": ' + _deep_json() + "}")
    manifest.write_text(
        manifest.read_text() + '\n[[drivers]]\nkind = "curves"\nfile = "curves.json"\n'
    )
    assert main(["convert", str(manifest), "-o", str(tmp_path / "out"), "--no-validate"]) == 2
    _one_error(capsys, "curves.json", "nested more than")


# 9 ----------------------------------------------------------------------------------------------


def test_manifest_path_that_is_a_folder(tmp_path, capsys):
    """Defect 9: ``convert DIR/manifest.toml`` where that is a folder: IsADirectoryError."""
    d = tmp_path / "manifest.toml"
    d.mkdir()
    assert main(["convert", str(d), "-o", str(tmp_path / "out")]) == 2
    _one_error(capsys, "manifest.toml", "is a folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["manifest.toml"]


def test_folder_given_for_the_manifest_suggests_the_file_inside(source, capsys):
    assert main(["convert", str(source.parent), "-o", "unused"]) == 2
    _one_error(capsys, "is a folder", "manifest.toml")


# 11 (messages) ----------------------------------------------------------------------------------


def test_truncated_glb_is_called_truncated_by_every_verb(source, tmp_path, capsys):
    """validate-asset called a truncated GLB "not UTF-8 text"; vertex-ids said the length field
    lies. One GLB container parser now answers for both."""
    glb = tmp_path / "cut.glb"
    data = (source.parent / "head.glb").read_bytes()
    glb.write_bytes(data[: len(data) // 2])
    for verb in (["validate-asset", str(glb), "--no-render"], ["vertex-ids", str(glb)]):
        assert main(verb) == 2
        _one_error(capsys, "cut.glb", f"GLB length field {len(data)} != file size {len(data) // 2}")


def test_folder_where_a_file_should_be(source, tmp_path, capsys):
    manifest = _copy_source(source, tmp_path)
    (manifest.parent / "wrinkle_stretch.png").unlink()
    (manifest.parent / "wrinkle_stretch.png").mkdir()
    assert main(["convert", str(manifest), "-o", str(tmp_path / "out")]) == 2
    _one_error(capsys, "is a folder, expected a file", "wrinkle_stretch.png")
