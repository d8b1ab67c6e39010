"""Engine import settings beside the exported textures, read back by independent readers.

Unity: each texture the wrinkle shader samples has a ``.meta`` (parsed by PyYAML) whose
TextureImporter settings are those Unity documents for the job (the base a NormalMap, the strips
Default 2D arrays with one row per layer, sRGB off, mip maps, uncompressed, clamped, trilinear),
a stable GUID and a max size no smaller than the image (read by OpenImageIO). The Custom Function
reads Unity's NormalMap encodings (x in alpha for DXT5nm-style): rendered from a base stored
that way it equals numpy. Godot 4: each has an ``.import`` (parsed by configparser) naming the
importer and type, with only the keys Godot's class reference documents for that importer.
Unreal: ``WP_CustomNodes.t3d`` holds the two Custom nodes as material-editor clipboard text;
read back by the parser in ``engine_imports`` (Begin/End blocks, Unreal's string escapes), each
node's Code is byte for byte the exported ``.hlsl``, its inputs those of ``wrinkle_setup.json``,
and the code taken from the text compiles (glslang -> spirv-cross) and renders equal to numpy.
The demo at 64^2, one export per engine per module.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import shader_harness as h
import yaml
from engine_imports import (
    check_godot_sidecars,
    check_unity_sidecars,
    check_unreal_clipboard,
    godot_uid_id,
    sampled,
    t3d_nodes,
    unquote,
)
from test_export_engines import _exported_texture, _expressions, _input, _source

from wrinklepipe.export import importers
from wrinklepipe.io.png import png_pixels
from wrinklepipe.jobs.export import export
from wrinklepipe.shading import hlsl
from wrinklepipe.validate.inputs import ChannelEntry, Texture
from wrinklepipe.validate.renderer import shader_setup


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("importers")
    src = _source(tmp, size=64)
    return src, {e: (tmp / e, *export(src, tmp / e, e)) for e in ("unity", "godot", "unreal")}


def test_unity_textures_carry_their_import_settings(exported, tmp_path):
    src, out = exported
    folder, files, _ = out["unity"]
    check_unity_sidecars(folder, files, _input(src))
    again, _ = export(src, tmp_path / "again", "unity")
    assert all(again[rel + ".meta"] == files[rel + ".meta"] for rel, _ in sampled(files))
    # the same asset re-exported with other texels (diff encoding): the same GUIDs, so the
    # project's material references survive the update
    other, _ = export(_source(tmp_path, encoding="diff", size=64), tmp_path / "diff", "unity")
    states = sampled(files)[1][0]
    assert other[states] != files[states]
    for rel, _ in sampled(files):
        guid = yaml.safe_load(files[rel + ".meta"])["guid"]
        assert yaml.safe_load(other[rel + ".meta"])["guid"] == guid


def test_godot_textures_carry_their_import_settings(exported, tmp_path):
    src, out = exported
    uids = check_godot_sidecars(out["godot"][1])
    # the same asset re-exported with other texels keeps its UIDs
    other, _ = export(_source(tmp_path, encoding="diff", size=64), tmp_path / "diff", "godot")
    assert check_godot_sidecars(other) == uids


def test_godot_uid_text_is_godots():
    """Godot's own example (core/io/resource_uid.cpp): the largest id 0x7FFFFFFFFFFFFFFF is
    written uid://d4n4ub6itg400; the writer writes it so and the reader here reads it back."""
    assert importers.godot_uid_text(0x7FFFFFFFFFFFFFFF) == "uid://d4n4ub6itg400"
    assert godot_uid_id("uid://d4n4ub6itg400") == 0x7FFFFFFFFFFFFFFF
    assert importers.godot_uid_text(0) == "uid://a"
    for n in (1, 33, 34, 12345678901234567, 2**62 + 7):
        assert godot_uid_id(importers.godot_uid_text(n)) == n


@pytest.mark.gpu
def test_unity_reads_its_dxt5nm_normal_map_encoding(exported):
    """The exported WrinkleMaps.hlsl with the base stored as Unity stores a NormalMap on
    DXT5nm-style platforms ((1, y, y, x): x in alpha) equals numpy on the exported texels."""
    if h.missing_tools():
        pytest.skip(f"{h.missing_tools()} not installed")
    import test_engine_shaders as ts

    src, out = exported
    _, files, _ = out["unity"]
    doc = json.loads(files["wrinkle_setup.json"])

    def texture(name, role, px, **kw):
        fmt = {3: "rgb8", 4: "rgba8"}[px.shape[-1]]
        return Texture(name, role, fmt, px.shape[1], px.shape[0], px.tobytes(), **kw)

    base = png_pixels(files[doc["base"]["file"]])
    textures = [texture("base", "base", base, layout="rg2")]
    n_states = doc["statesArray"]["layers"]
    states = np.split(png_pixels(files[doc["statesArray"]["file"]]), n_states, axis=0)
    for k, layer in enumerate(states):
        name = doc["states"][k]["name"]
        textures.append(texture(name, "state", layer, state=name, mapping=doc["mapping"]))
    masks = np.split(png_pixels(files[doc["masks"]["file"]]), doc["masks"]["layers"], axis=0)
    textures += [texture(f"mask_{i}", "mask", m) for i, m in enumerate(masks)]
    inp = replace(_input(src), textures=textures, has_source=False)
    setup = shader_setup(inp)
    x, y = base[..., 0], base[..., 1]
    dxt5nm = np.stack([np.full_like(x, 255), y, y, x], axis=-1)
    try:
        gpu = h.UVRenderer(64)
    except Exception as exc:  # noqa: BLE001
        pytest.skip(f"no OpenGL: {exc}")
    try:
        prefix = "SPIRV_Cross_Combined_"
        samplers = {
            f"{prefix}BaseMapsampler_BaseMap": (
                gpu.upload([texture("base", "base", dxt5nm)], array=False),
                False,
            ),
            f"{prefix}Statessampler_BaseMap": (gpu.upload(textures[1 : 1 + n_states], True), True),
            f"{prefix}Maskssampler_BaseMap": (gpu.upload(textures[1 + n_states :], True), True),
        }
        glsl = h.hlsl_to_glsl(ts.UNITY_PRELUDE + files["WrinkleMaps.hlsl"].decode() + ts.UNITY_MAIN)
        prog = gpu.program(glsl)
        block = next(b for b in ("_Globals", "_Global", "type_Globals") if b in glsl)
        s = h.samples(inp, gpu.uvs())
        for expr in [None, *_expressions(inp)]:
            wv = setup.weight_vectors(h.region_weights(inp, expr))
            data = np.concatenate([wv.ravel(), setup.used_vectors().ravel()]).astype(np.float32)
            img = gpu.draw(prog, samplers, blocks={block: data.tobytes()})
            st = h.compare(img, h.blend(inp, s, expr))
            assert st["mean"] <= 0.5 and st["p99"] <= 2.0, (expr, st)
    finally:
        gpu.release()


def test_unreal_clipboard_text_holds_the_two_custom_nodes(exported):
    check_unreal_clipboard(exported[1]["unreal"][1])


@pytest.mark.gpu
def test_unreal_clipboard_code_renders_the_model(exported):
    """The Code taken out of the clipboard text, wrapped as Unreal wraps Custom nodes, through
    glslang -> spirv-cross -> moderngl on the exported texels equals numpy with y negated."""
    if h.missing_tools():
        pytest.skip(f"{h.missing_tools()} not installed")
    import test_engine_shaders as ts

    src, out = exported
    _, files, _ = out["unreal"]
    doc = json.loads(files["wrinkle_setup.json"])
    ref_in = _input(src)
    base = doc["base"]["file"]
    textures = [_exported_texture("base", "base", base, files[base])]
    for st in doc["states"]:
        textures.append(
            _exported_texture(
                st["name"], "state", st["file"], files[st["file"]], st["name"], doc["mapping"]
            )
        )
    for i, f in enumerate(doc["masks"]["files"]):
        px = png_pixels(files[f])
        textures.append(
            Texture(f"mask{i}", "mask", "rgba8", px.shape[1], px.shape[0], px.tobytes())
        )
    table = [
        ChannelEntry(e["region"], f"mask{e['texture']}", "rgba".index(e["channel"]))
        for e in doc["masks"]["table"]
    ]
    inp = replace(ref_in, textures=textures, channel_table=table, has_source=False)
    setup = replace(shader_setup(inp), output="directx")
    decode, wrinkle = (unquote(o["props"]["Code"]) for o in t3d_nodes(files))
    made = hlsl.unreal_nodes(setup)
    nodes = replace(
        made, decode=replace(made.decode, code=decode), wrinkle=replace(made.wrinkle, code=wrinkle)
    )
    try:
        gpu = h.UVRenderer(64)
    except Exception as exc:  # noqa: BLE001
        pytest.skip(f"no OpenGL: {exc}")
    try:
        prog = gpu.program(
            h.hlsl_to_glsl(ts.unreal_material(nodes, setup.n_states, setup.n_layers))
        )
        names = ["Base", *(f"State{k}" for k in range(setup.n_states))]
        names += [f"Mask{k}" for k in range(setup.n_layers)]
        samplers = {
            f"SPIRV_Cross_Combined{n}{n}Sampler": (gpu.upload([t], array=False), False)
            for n, t in zip(
                names, [textures[0], *inp.state_textures(), *h.mask_layers(inp)], strict=True
            )
        }
        s = h.samples(inp, gpu.uvs())
        flip = np.array([1.0, -1.0, 1.0], np.float32)
        for expr in [None, *_expressions(inp)]:
            w = h.region_weights(inp, expr)
            pad = np.zeros(((len(w) + 3) // 4) * 4, np.float32)
            pad[: len(w)] = w
            img = gpu.draw(prog, samplers, blocks={"WPHarness": pad.tobytes()})
            st = h.compare(img, h.blend(inp, s, expr) * flip)
            assert st["mean"] <= 0.5 and st["p99"] <= 2.0, (expr, st)
    finally:
        gpu.release()
