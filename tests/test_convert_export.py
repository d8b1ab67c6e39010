"""``wrinklepipe export``: engine presets (Unreal DirectX + BC5; Unity/Godot/Blender +Y)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wrinklepipe.cli import main
from wrinklepipe.demo.package import demo_package
from wrinklepipe.export.files import export_files, flip_green
from wrinklepipe.io.gltf_write import write_gltf
from wrinklepipe.io.package import png_pixels
from wrinklepipe.io.usd_write import write_usd


@pytest.fixture(scope="module")
def pkg():
    return demo_package(64)


@pytest.fixture(scope="module")
def written(pkg, tmp_path_factory):
    folder = tmp_path_factory.mktemp("asset")
    write_gltf(pkg, folder, "demo")
    write_usd(pkg, folder / "demo.usdz")
    return folder


def test_flip_green_negates_y_exactly(pkg):
    flipped = flip_green(pkg)
    for t, f in zip(pkg.textures, flipped.textures):
        if t.role == "mask":
            assert np.array_equal(t.pixels, f.pixels)
            continue
        assert np.array_equal(f.pixels[..., 1], 255 - t.pixels[..., 1])
        assert np.array_equal(f.pixels[..., [0, 2]], t.pixels[..., [0, 2]])
    # decoded: y -> -y (0.5 + 0.5 (-y) = 1 - (0.5 + 0.5 y))
    q = pkg.texture("base_normal").pixels[..., 1].astype(np.float64)
    y = 2 * q / 255 - 1
    y_dx = 2 * (255 - q) / 255 - 1
    assert np.allclose(y_dx, -y, atol=1e-12)
    # its own inverse
    back = flip_green(flipped)
    assert all(np.array_equal(a.pixels, b.pixels) for a, b in zip(pkg.textures, back.textures))


def test_unreal_preset(pkg):
    files, notes = export_files(pkg, "unreal")
    setup = json.loads(files["unreal/wrinkle_setup.json"])
    assert setup["convention"] == "directx"
    assert "unreal/wrinkle.hlsl" in files
    assert not any(f.endswith(".gltf") for f in files)
    base = setup["base"]
    if base.endswith(".dds"):
        from wrinklepipe.normals import compress, dds

        img = dds.read_dds(files[base])
        assert img.format == "bc5"
        rgba = compress.decode_bc(img.levels[0], img.width, img.height, "bc5")
        g_src = pkg.texture("base_normal").pixels[..., 1].astype(int)
        # BC5 keeps G within a few levels of 255 - G (the DirectX green)
        assert np.abs(rgba[..., 1].astype(int) - (255 - g_src)).max() <= 8
    else:
        px = png_pixels(files[base])
        assert np.array_equal(px[..., 1], 255 - pkg.texture("base_normal").pixels[..., 1])
        assert any("compression" in n for n in notes)
    # masks are never converted
    assert np.array_equal(png_pixels(files["unreal/mask_0.png"]), pkg.texture("mask_0").pixels)


@pytest.mark.parametrize("engine, shader", [("unity", "hlsl"), ("godot", "glsl"), ("blender", "")])
def test_plus_y_presets_keep_the_maps(pkg, engine, shader):
    files, _ = export_files(pkg, engine)
    setup = json.loads(files[f"{engine}/wrinkle_setup.json"])
    assert setup["convention"] == "opengl"
    assert "demo.gltf" in files and "demo.bin" in files
    for t in pkg.textures:
        assert np.array_equal(png_pixels(files[f"{engine}/{t.name}.png"]), t.pixels), t.name
    assert (f"{engine}/wrinkle.{shader}" in files) == bool(shader)
    assert setup["masks"]["table"] == pkg.meta["masks"]["table"]


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
