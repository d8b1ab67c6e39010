"""Colour states through convert: the manifest keys, the outputs (glTF extension, USD), the
readers, and every bad input refused with one message (exit 2, nothing written)."""

from __future__ import annotations

import json
from pathlib import Path

import color_setups as cs
import numpy as np
import pytest
import usd_checks

from wrinklepipe.cli import main
from wrinklepipe.demo import avatar, colors
from wrinklepipe.gltf.package_read import read_wrinkled
from wrinklepipe.io import khronos
from wrinklepipe.io.images import write_image
from wrinklepipe.io.png import png_bytes, png_pixels
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.normals.dds import read_dds
from wrinklepipe.pipeline.package import asset_from_package
from wrinklepipe.sources.manifest import load_manifest
from wrinklepipe.usd.package_read import read_usd

EXT = "WRINKLEPIPE_wrinkle_maps"


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return cs.write_avatar_color_source(tmp_path_factory.mktemp("colour") / "src")


@pytest.fixture(scope="module")
def converted(source, tmp_path_factory):
    out = tmp_path_factory.mktemp("colour-out") / "out"
    result = convert(source, out, ConvertOptions(render=False, glb=True))
    return out, result


def _gltf(out: Path) -> dict:
    return json.loads((out / "avatar.gltf").read_text(encoding="utf-8"))


def test_the_manifest_reads_colour_keys(source):
    m = load_manifest(source)
    assert [s.color.name if s.color else None for s in m.states] == [
        "color_stretch.png",
        "color_compress.png",
    ]
    assert m.base_color is None and m.has_color
    assert source.parent / "color_stretch.png" in m.input_files


def test_states_name_their_colour_textures_and_the_base_is_the_materials_own(source, converted):
    out, result = converted
    assert result.exit_code == 0
    doc = _gltf(out)
    skin = doc["materials"][0]
    ext = skin["extensions"][EXT]
    src_doc, _ = avatar.avatar_document()
    # the material's own base colour, untouched: same texture, same image (embedded bytes)
    assert skin["pbrMetallicRoughness"] == src_doc["materials"][0]["pbrMetallicRoughness"]
    for k, name in enumerate(("stretch", "compress")):
        state = ext["states"][k]
        assert state["name"] == name
        image = doc["images"][doc["textures"][state["colorTexture"]["index"]]["source"]]
        # full size: the colour map ships as painted, byte for byte
        want = (source.parent / f"color_{name}.png").read_bytes()
        assert (out / image["uri"]).read_bytes() == want
        assert "normal" not in state


@pytest.mark.skipif(not khronos.available(), reason="Khronos validator not installed")
@pytest.mark.parametrize("name", ["avatar.gltf", "avatar.glb"])
def test_output_passes_the_khronos_validator(converted, name):
    report = khronos.validate_gltf(converted[0] / name)
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]


def test_usd_output_reads_the_colours_in_srgb_and_passes_validation(converted):
    from pxr import Usd, UsdShade

    from wrinklepipe.usd.package_write import register_schema

    register_schema()
    out, _ = converted
    stage = Usd.Stage.Open(str(out / "avatar.usda"))
    errors = [e.GetMessage() for e in usd_checks.validation_errors(stage)]
    assert errors == []
    mat = stage.GetPrimAtPath("/avatar/Looks/skin")
    assert list(mat.GetAttribute("wrinkle:colorStates").Get()) == ["stretch", "compress"]
    base = UsdShade.Shader(mat.GetChild("base_color"))
    assert base.GetInput("sourceColorSpace").Get() == "sRGB"
    surf = UsdShade.Shader(mat.GetChild("Surface"))
    src = surf.GetInput("diffuseColor").GetConnectedSources()[0][0]
    assert src.source.GetPath() == base.GetPath()
    for name in ("stretch", "compress"):
        tex = UsdShade.Shader(mat.GetChild(f"color_{name}"))
        assert tex.GetInput("sourceColorSpace").Get() == "sRGB"
        inp = UsdShade.Material(mat).GetInput(f"wrinkle:color:{name}")
        assert inp.Get().path == f"./textures/color_{name}.png"


def test_glTF_and_USD_readers_give_the_same_colour_package(source, converted):
    out, _ = converted
    g = read_wrinkled(out / "avatar.gltf")
    u = read_usd(out / "avatar.usda")
    base = cs.avatar_skin_color()
    for pkg in (g, u):
        meta = pkg.meta
        assert meta.base_color == "base_color" and meta.color_factor == (1.0, 1.0, 1.0)
        assert [s.color is not None for s in meta.states] == [True, True]
        np.testing.assert_array_equal(pkg.texture("base_color").pixels[..., :3], base[..., :3])
        for s, want in zip(meta.states, (colors.pale(base), colors.flushed(base))):
            np.testing.assert_array_equal(pkg.texture(s.color).pixels, want)
        c = asset_from_package(pkg).color
        assert c is not None and c.state_index == (0, 1)


# ------------------------------------------------------------------------------------------------
# bad input: one message, exit 2, nothing written


def _refused(capsys, manifest: Path, tmp_path: Path, *needles: str) -> str:
    out = tmp_path / "out"
    code = main(["convert", str(manifest), "-o", str(out), "--no-validate"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, err
    for n in needles:
        assert n in err, err
    assert not out.exists()
    return err


def test_a_colour_map_of_another_size_is_refused(tmp_path, capsys):
    base = cs.avatar_skin_color()
    big = np.repeat(np.repeat(colors.pale(base), 2, axis=0), 2, axis=1)
    m = cs.write_avatar_color_source(tmp_path / "src", {"stretch": big})
    _refused(capsys, m, tmp_path, "color_stretch.png", "32x32", "16x16", "UV layout")


def test_colour_maps_of_different_sizes_are_refused_at_load(tmp_path, capsys):
    base = cs.avatar_skin_color()
    big = np.repeat(np.repeat(colors.pale(base), 2, axis=0), 2, axis=1)
    m = cs.write_avatar_color_source(
        tmp_path / "src", {"stretch": big, "compress": colors.flushed(base)}
    )
    _refused(capsys, m, tmp_path, "colour maps have different sizes", "32x32", "16x16")


def test_an_rgba_normal_map_given_as_colour_is_refused(tmp_path, capsys):
    n = avatar.skin_normals(16)
    rgba = np.concatenate([0.5 + 0.5 * n, np.ones_like(n[..., :1])], axis=-1)
    q = np.rint(rgba * 255).astype(np.uint8)
    m = cs.write_avatar_color_source(tmp_path / "src", {"stretch": q})
    _refused(capsys, m, tmp_path, "color_stretch.png", "normal map", "map = FILE")


def test_a_colour_image_given_as_a_normal_map_is_refused(tmp_path, capsys):
    m = cs.write_avatar_color_source(tmp_path / "src")
    text = m.read_text().replace('map = "wrinkle_stretch.png"', 'map = "color_stretch.png"', 1)
    text = text.replace('color = "color_stretch.png"\n', "", 1)
    m.write_text(text)
    _refused(capsys, m, tmp_path, "color_stretch.png", "looks like a colour image", "color = FILE")


def test_a_state_needs_a_normal_map_or_a_colour_map(tmp_path, capsys):
    m = cs.write_avatar_color_source(tmp_path / "src")
    text = m.read_text()
    text = text.replace('color = "color_stretch.png"\n', "").replace(
        'map = "wrinkle_stretch.png"\n', ""
    )
    m.write_text(text)
    _refused(capsys, m, tmp_path, "states[0]", "map or color")


def test_a_base_colour_without_colour_states_is_refused(tmp_path, capsys):
    base = cs.avatar_skin_color()
    m = cs.write_avatar_color_source(
        tmp_path / "src", {}, 'base_color = "base_color.png"', {"base_color.png": png_bytes(base)}
    )
    _refused(capsys, m, tmp_path, "base_color", "no state has a colour map")


def test_a_float_colour_map_is_refused(tmp_path, capsys):
    m = cs.write_avatar_color_source(tmp_path / "src")
    lin = np.full((16, 16, 3), 0.4, np.float32)
    write_image(m.parent / "color_float.exr", lin, 32)
    m.write_text(m.read_text().replace("color_stretch.png", "color_float.exr"))
    _refused(capsys, m, tmp_path, "color_float.exr", "8- or 16-bit sRGB")


def test_a_material_without_a_base_colour_asks_for_base_color(tmp_path, capsys):
    def drop(doc, data, folder):
        del doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]

    from wrinkle_setups import avatar_variant

    m = avatar_variant(tmp_path, drop)
    base = cs.avatar_skin_color()
    (m.parent / "color_stretch.png").write_bytes(png_bytes(colors.pale(base)))
    m.write_text(cs.with_colors(m.read_text(), {"stretch": "color_stretch.png"}))
    _refused(capsys, m, tmp_path, "no baseColorTexture", 'base_color = "FILE"')


# ------------------------------------------------------------------------------------------------
# a manifest base colour replaces the material's, and a colour-only state


@pytest.fixture(scope="module")
def own_base(tmp_path_factory):
    base = cs.avatar_skin_color()[..., :3].copy()
    base[:8] = colors.pale(base)[:8]  # a base of our own: not the material's
    folder = tmp_path_factory.mktemp("own") / "src"
    m = cs.write_avatar_color_source(
        folder,
        {"compress": colors.flushed(base)},
        'base_color = "my_base.png"',
        {"my_base.png": png_bytes(base)},
    )
    # stretch: colour only (no normal map)
    text = m.read_text().replace('map = "wrinkle_stretch.png"\n', 'color = "pale.png"\n', 1)
    (folder / "pale.png").write_bytes(png_bytes(colors.pale(base)))
    m.write_text(text)
    out = folder.parent / "out"
    return base, convert(m, out, ConvertOptions(render=False)), out


def test_a_manifest_base_colour_becomes_the_materials_base_colour(own_base):
    base, result, out = own_base
    assert result.exit_code == 0, result.report["validation"]
    doc = _gltf(out)
    skin = doc["materials"][0]
    index = skin["pbrMetallicRoughness"]["baseColorTexture"]["index"]
    image = doc["images"][doc["textures"][index]["source"]]
    np.testing.assert_array_equal(png_pixels((out / image["uri"]).read_bytes()), base)
    assert any("baseColorTexture" in n and "replaced" in n for n in result.report["notes"])


def test_a_colour_only_state_ships_a_normal_map_that_adds_nothing(own_base):
    base, result, out = own_base
    ext = _gltf(out)["materials"][0]["extensions"][EXT]
    assert ext["states"][0]["normal"] is False and "colorTexture" in ext["states"][0]
    pkg = read_wrinkled(out / "avatar.gltf")
    assert [s.normal for s in pkg.meta.states] == [False, True]
    stored = pkg.texture(pkg.meta.states[0].texture).pixels
    # pd, mapping 2: zero slopes are exactly 128
    assert np.all(stored[..., :2] == 128)
    u = read_usd(out / "avatar.usda")
    assert [s.normal for s in u.meta.states] == [False, True]


def test_colour_copies_are_srgb_blocks_chosen_by_ciede2000(converted):
    out, result = converted
    choice = result.report["compression"]["color"]
    assert choice["chosen"] in ("bc1", "bc7") and choice["tried"][-1]["within"]
    fid = choice["fidelity"]
    assert max(p["p99_delta_e"] for p in fid["poses"]) <= 2.3
    ext = _gltf(out)["materials"][0]["extensions"][EXT]
    doc = _gltf(out)
    copies = {
        doc["images"][doc["textures"][c["texture"]["index"]]["source"]].get("name"): c
        for c in ext["compressed"]
    }
    for name in ("color_stretch", "color_compress"):
        c = copies[name]
        assert c["colorSpace"] == "srgb" and c["format"] == choice["chosen"]
        assert c["uris"] == [f"compressed/{name}.ktx2", f"compressed/{name}.dds"]
        assert read_dds(out / c["uris"][1]).srgb
    # the base colour (the material's own texture) has its copy too
    base_index = doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["index"]
    assert any(c["texture"]["index"] == base_index for c in ext["compressed"])
    # USD records the same copies with their colour spaces
    u = read_usd(out / "avatar.usda")
    spaces = {c.texture: c.color_space for c in u.meta.compressed}
    assert spaces["color_stretch"] == "srgb" and spaces["wrinkle_stretch"] == "linear"
