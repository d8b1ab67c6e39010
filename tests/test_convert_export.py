"""``wrinklepipe export``: engine presets (Unreal DirectX + BC5; Unity/Godot/Blender +Y)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wrinklepipe.cli import main
from wrinklepipe.demo.package import demo_package
from wrinklepipe.export.textures import to_directx
from wrinklepipe.gltf.package_write import write_gltf
from wrinklepipe.usd.package_write import write_usd


@pytest.fixture(scope="module")
def pkg():
    return demo_package(64)


@pytest.fixture(scope="module")
def written(pkg, tmp_path_factory):
    folder = tmp_path_factory.mktemp("asset")
    write_gltf(pkg, folder, "demo")
    write_usd(pkg, folder / "demo.usdz")
    return folder


def test_directx_negates_y_in_each_maps_value_mapping(pkg):
    from wrinklepipe import codec

    flipped = to_directx(pkg)
    version = pkg.meta.mapping
    for t, f in zip(pkg.textures, flipped.textures, strict=True):
        if t.role == "mask":
            assert np.array_equal(t.pixels, f.pixels)
            continue
        assert np.array_equal(f.pixels[..., [0, 2]], t.pixels[..., [0, 2]])
        q = t.pixels[..., 1].astype(np.int64)
        if t.role == "state" and pkg.meta.encoding in ("pd", "diff") and version == 2:
            expect = np.clip(256 - q, 0, 255)  # v2: 128 + 127 t, so -t is 256 - q
        else:
            expect = 255 - q  # normal maps: 2 v - 1
        assert np.array_equal(f.pixels[..., 1], expect), t.name
        m = codec.mapping(version if t.role == "state" else 1)
        y = m.decode(t.pixels[..., 1], 8)
        inner = np.abs(y) < 1  # the one texel of v2 that is never written (q = 0) aside
        np.testing.assert_array_equal(m.decode(f.pixels[..., 1], 8)[inner], -y[inner])


def test_cli_from_folder_and_usdz_agree(written, tmp_path):
    assert main(["export", str(written), "--engine", "godot", "-o", str(tmp_path / "a")]) == 0
    src = str(written / "demo.usdz")
    assert main(["export", src, "--engine", "godot", "-o", str(tmp_path / "b")]) == 0
    a = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file())
    b = sorted(p.relative_to(tmp_path / "b") for p in (tmp_path / "b").rglob("*") if p.is_file())
    assert a == b
    for rel in a:
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes(), rel


def test_cli_errors(written, tmp_path, capsys):
    assert main(["export", str(tmp_path), "--engine", "unity", "-o", str(tmp_path / "o")]) == 2
    assert "no .gltf" in capsys.readouterr().err
    assert main(["export", str(written), "--engine", "unity", "-o", str(written)]) == 2
    assert "input" in capsys.readouterr().err


def test_cli_refuses_gltf_with_escaping_uri(written, tmp_path, capsys):
    doc = json.loads((written / "demo.gltf").read_text())
    doc["images"][0]["uri"] = "../../secret.png"
    bad = written / "bad.gltf"
    bad.write_text(json.dumps(doc))
    try:
        assert main(["export", str(bad), "--engine", "unity", "-o", str(tmp_path / "o")]) == 2
    finally:
        bad.unlink()
    err = capsys.readouterr().err
    assert "bad.gltf" in err and "/images/0/uri" in err and "'..'" in err
    assert "Traceback" not in err and not (tmp_path / "o").exists()
