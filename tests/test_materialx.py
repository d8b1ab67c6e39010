"""The MaterialX wrinkle material for USD hosts (wrinklepipe.shading.materialx, usd.materialx).

On the demo (a package's USD) and RobotExpressive (its ``convert`` output): the ``.mtlx``
beside the layer validates with MaterialX (standard-library nodes only, no definitions of its
own); MaterialX's own GLSL generator turns its ``normal_ts`` output into a shader that renders
(moderngl, EGL; tests/materialx_render.py) equal to the numpy model of the shipped texels, read
back through wrinklepipe's USD reader, within 0.5 degrees mean / 2 p99 at several weight sets;
the whole material (``normalmap`` into ``standard_surface``) generates GLSL that glslang
compiles; every encoding and policy renders equal to the model; the layer carries the same
network as UsdShade prims with MaterialX ids, its weight inputs animated as the curve, the
UsdPreviewSurface kept. (tests/test_blender.py opens the same layers with a pxr that has
UsdMtlx: 0 UsdValidation errors, every id known, the ``.mtlx`` composes to the same graph.)
"""

from __future__ import annotations

import json
from pathlib import Path

import MaterialX as mx
import materialx_render as mr
import numpy as np
import pytest
import shader_harness as h
from passthrough import EXTENSION
from pxr import Usd, UsdShade
from test_export_engines import _source
from wrinkle_setups import ROBOT

from wrinklepipe import model
from wrinklepipe.demo.package import demo_package
from wrinklepipe.shading import materialx as wmx
from wrinklepipe.sources.validation import load_input
from wrinklepipe.usd.materialx import MATERIALX_ATTRIBUTE, materialx_document
from wrinklepipe.usd.package_write import write_usd
from wrinklepipe.validate.gl import GLUnavailable
from wrinklepipe.validate.renderer import shader_setup

SIZE = 96  # rendered pixels (the maps are 128^2 / 64^2: samples fall between texels)
#: The nodes the document may use: MaterialX's standard library, nothing of its own.
STANDARD = {
    "image", "extract", "multiply", "add", "subtract", "divide", "max", "min", "clamp",
    "absval", "sqrt", "dotproduct", "normalize", "combine3", "constant", "normalmap",
}  # fmt: skip


@pytest.fixture(scope="module")
def outputs(tmp_path_factory, request):
    """name -> (USD layer, its wrinkle material's path): the 128^2 demo package's USD, and
    RobotExpressive's convert output when ../shared/data is there."""
    tmp = tmp_path_factory.mktemp("materialx")
    write_usd(demo_package(128), tmp / "demo" / "demo.usda")
    out = {"demo": (tmp / "demo" / "demo.usda", "/demo/Looks/skin")}
    if ROBOT.is_file():
        folder = request.getfixturevalue("robot_converted")[0]
        out["robot"] = (folder / "robot.usda", "/robot/Looks/skin")
    return out


def _case(outputs, name: str):
    if name not in outputs:
        pytest.skip("../shared/data is absent")
    layer, material = outputs[name]
    stage = Usd.Stage.Open(str(layer))
    mat = stage.GetPrimAtPath(material)
    mtlx = layer.parent / mat.GetAttribute(MATERIALX_ATTRIBUTE).Get()
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(mtlx))
    return layer, stage, mat, mtlx, doc


NAMES = ["demo", "robot"]


@pytest.mark.parametrize("name", NAMES)
def test_the_document_validates_with_standard_nodes_only(outputs, name):
    _, _, _, mtlx, doc = _case(outputs, name)
    assert mtlx.name == f"{name}.mtlx" and mtlx.parent == outputs[name][0].parent
    assert wmx.validate(doc) == ""
    assert doc.getNodeDefs() == [] and doc.getImplementations() == []  # nothing of its own
    full = mr.with_library(doc)
    graph = full.getNodeGraph(wmx.NODEGRAPH)
    categories = {n.getCategory() for n in graph.getNodes()}
    assert categories <= STANDARD, categories - STANDARD
    assert {"image", "normalmap"} <= categories
    for node in graph.getNodes():  # every definition is the standard libraries'
        assert "libraries" in node.getNodeDef().getSourceUri(), node.getName()
    surface = full.getNode(wmx.SHADER)
    assert surface.getCategory() == "standard_surface"
    assert surface.getInput("normal").getNodeGraphString() == wmx.NODEGRAPH
    assert [m.getName() for m in full.getMaterialNodes()] == [wmx.MATERIAL]
    inputs = {i.getName() for i in graph.getInputs()}
    inp = load_input(outputs[name][0])
    assert {wmx.weight_input(r) for r in inp.asset.region_names} <= inputs  # weights as inputs
    assert {"base", "mask_0", "state_0"} <= inputs  # and the maps


def _weight_sets(n: int, policy: str) -> list[np.ndarray]:
    lo = model.POLICY_WEIGHT_RANGE[policy].low
    rng = np.random.default_rng(46)
    return [np.zeros(n), np.full(n, 0.9), rng.uniform(lo, 1.0, n), np.full(n, max(lo, -0.6))]


def _render_and_compare(doc, folder: Path, inp, weight_sets, label: str) -> list[dict]:
    """Render ``normal_ts`` at each weight set; assert each within 0.5 / 2 degrees of the
    numpy model on the same texels and that strong weights move the normal."""
    a = inp.asset
    uniforms = [
        {wmx.weight_input(r): float(w[i]) for i, r in enumerate(a.region_names)}
        for w in weight_sets
    ]
    images = mr.render_output(doc, folder, "normal_ts", uniforms, SIZE)
    s = h.samples(inp, h.uv_grid(SIZE))
    d = a.region_state_matrix()
    stats = []
    for k, (w, img) in enumerate(zip(weight_sets, images, strict=True)):
        ww = w if a.policy == "signed" else w[:, None] * d
        st = h.compare(img[None], model.blend(s.base, s.states, s.masks, ww, a.encoding, a.policy))
        stats.append(st)
        assert st["mean"] <= 0.5 and st["p99"] <= 2.0, (label, k, st)
        if k == 1:
            neutral = model.blend(s.base, s.states, s.masks, ww * 0, a.encoding, a.policy)
            assert h.compare(img[None], neutral)["p99"] > 2.0, (label, "the weights move nothing")
    return stats


@pytest.mark.gpu
@pytest.mark.parametrize("name", NAMES)
def test_materialx_glsl_renders_the_model(outputs, name):
    """MaterialX's GLSL of the document, on the files it names, equals the numpy model of the
    USD's texels (wrinklepipe's USD reader) at four weight sets and at the curve's peak."""
    layer, _, _, mtlx, doc = _case(outputs, name)
    inp = load_input(layer)
    a = inp.asset
    sets = _weight_sets(len(a.region_names), a.policy)
    curve = next(iter(inp.weight_curves.values()), None)
    if curve is not None:
        sets.append(np.asarray(curve[int(np.argmax(np.abs(curve).sum(axis=1)))], np.float64))
    try:
        _render_and_compare(doc, mtlx.parent, inp, sets, name)
    except GLUnavailable as exc:
        pytest.skip(f"no OpenGL: {exc}")


def test_the_whole_material_generates_glsl_glslang_compiles(outputs):
    """The material (the graph's ``normalmap`` into ``standard_surface``) through MaterialX's
    GLSL generator: both stages compile with glslang."""
    if h.missing_tools():
        pytest.skip(f"{h.missing_tools()} not installed")
    *_, doc = _case(outputs, "demo")
    full = mr.with_library(doc)
    vs, ps = mr.generate(full, full.getNode(wmx.MATERIAL))
    assert "mx_normalmap" in ps or "normalmap" in ps
    assert h.glsl_compiles(vs, "vert") == "" and h.glsl_compiles(ps, "frag") == ""


CASES = [  # every encoding, every policy (overlapping masks: the policies differ)
    ("pd", "clamp01"),
    ("diff", "signed"),
    ("full", "additive"),
    ("composite", "renormalize"),
    ("pd", "lerp"),
]


@pytest.mark.gpu
@pytest.mark.parametrize("encoding, policy", CASES)
def test_every_encoding_and_policy_renders_the_model(tmp_path, encoding, policy):
    """The document of a 64^2 demo in each encoding and policy (the policy edited into its
    glTF), on the glTF's own files, renders equal to the model."""
    src = _source(tmp_path, encoding, size=64, overlap=True)
    gltf = src / "demo.gltf"
    doc_json = json.loads(gltf.read_text())
    doc_json["materials"][0]["extensions"][EXTENSION]["policy"] = policy
    gltf.write_text(json.dumps(doc_json))
    inp = load_input(src)
    setup = shader_setup(inp)
    ext = doc_json["materials"][0]["extensions"][EXTENSION]
    uri = [im["uri"] for im in doc_json["images"]]
    files = wmx.MapFiles(
        uri[doc_json["textures"][doc_json["materials"][0]["normalTexture"]["index"]]["source"]],
        tuple(uri[doc_json["textures"][s["texture"]["index"]]["source"]] for s in ext["states"]),
        tuple(uri[doc_json["textures"][m["index"]]["source"]] for m in ext["masks"]["textures"]),
    )
    doc = wmx.wrinkle_document(setup, files)
    assert wmx.validate(doc) == ""
    _render_and_compare(doc, src, inp, _weight_sets(len(setup.region_names), policy), policy)


@pytest.mark.parametrize("name", NAMES)
def test_the_usd_layer_carries_the_network_and_keeps_the_preview(outputs, name):
    """The material's ``mtlx`` surface is ``SR_wrinkle`` (``ND_standard_surface``) fed by the
    layer's NodeGraph, whose Shader prims are the document's nodes with their MaterialX node
    definitions as ids; the universal surface is still the UsdPreviewSurface; the weight inputs
    carry the curve's keys; the ``.mtlx`` is the document the writer makes."""
    layer, stage, prim, mtlx, doc = _case(outputs, name)
    mat = UsdShade.Material(prim)
    surface = mat.ComputeSurfaceSource("mtlx")[0]
    assert surface.GetIdAttr().Get() == "ND_standard_surface_surfaceshader"
    assert mat.ComputeSurfaceSource()[0].GetIdAttr().Get() == "UsdPreviewSurface"
    full = mr.with_library(doc)
    graph_mx = full.getNodeGraph(wmx.NODEGRAPH)
    graph = stage.GetPrimAtPath(prim.GetPath().AppendChild(wmx.NODEGRAPH))
    ids = {p.GetName(): UsdShade.Shader(p).GetIdAttr().Get() for p in graph.GetChildren()}
    assert ids == {n.getName(): n.getNodeDef().getName() for n in graph_mx.getNodes()}
    conn = surface.GetInput("normal").GetAttr().GetConnections()
    assert [str(c) for c in conn] == [f"{graph.GetPath()}.outputs:normal"]
    inp = load_input(layer)
    curve_name, values = next(iter(inp.weight_curves.items()))
    regions = inp.asset.region_names
    attr = graph.GetAttribute(f"inputs:{wmx.weight_input(regions[0])}")
    times = attr.GetTimeSamples()
    assert len(times) == len(values)
    k = int(np.argmax(values[:, 0]))
    for r, region in enumerate(regions):
        a = graph.GetAttribute(f"inputs:{wmx.weight_input(region)}")
        assert a.Get(times[k]) == pytest.approx(float(values[k, r]), abs=1e-6)
    weights = prim.GetAttribute("wrinkle:weights").Get(times[k])
    assert list(weights) == pytest.approx([float(v) for v in values[k]], abs=1e-6)
    if name == "demo":  # the package's own document, byte for byte
        pkg = demo_package(128)
        assert mtlx.read_bytes() == wmx.to_xml(materialx_document(pkg))


@pytest.mark.gpu
def test_materialx_blends_the_colour_as_the_model(tmp_path):
    """With colour states the document's ``color`` output (sRGB colour maps converted to
    linear by MaterialX's colour management, blended with the normals' activations) equals the
    numpy colour model of the USD's texels, rendered at the texel centres (MaterialX converts
    after it filters, a GPU's sRGB sampler before: the same at texel centres): CIEDE2000 p99
    <= 1 at every weight set; strong weights move the colour. SR_wrinkle's base_color reads it."""
    from dataclasses import replace

    from wrinklepipe.codec import srgb
    from wrinklepipe.demo import demo_asset
    from wrinklepipe.metrics import delta_e
    from wrinklepipe.pipeline.package import package_from_asset
    from wrinklepipe.pipeline.prepare import prepare_mesh
    from wrinklepipe.validate import textures as tx
    from wrinklepipe.validate.renderer import color_textures

    a = demo_asset(64, color=True, mesh_resolution=(48, 32))
    a = replace(a, mesh=prepare_mesh(a.mesh))
    layer = tmp_path / "demo.usda"
    write_usd(package_from_asset(a), layer)
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(tmp_path / "demo.mtlx"))
    surface = doc.getNode(wmx.SHADER)
    assert surface.getInput("base_color").getOutputString() == "color"
    inp = load_input(layer)
    sets = _weight_sets(len(inp.asset.region_names), "clamp01")
    uniforms = [
        {wmx.weight_input(r): float(w[i]) for i, r in enumerate(inp.asset.region_names)}
        for w in sets
    ]
    try:
        images = mr.render_output(doc, tmp_path, "color", uniforms, 64)
    except GLUnavailable as exc:
        pytest.skip(f"no OpenGL: {exc}")
    uv = h.uv_grid(64)
    s = h.samples(inp, uv)
    base_t, states_t = color_textures(inp)

    def lin(t):
        return srgb.decode_texels(np.frombuffer(t.data, np.uint8).reshape(t.height, t.width, -1))

    cb = tx.bilinear(lin(base_t)[..., :3], uv)
    cs = np.stack([tx.bilinear(lin(t)[..., :3], uv) for _, t in states_t])
    d = inp.asset.region_state_matrix()
    for k, (w, img) in enumerate(zip(sets, images, strict=True)):
        act = model.activations(s.masks, np.asarray(w, np.float32)[:, None] * d, "clamp01")
        ref = model.combine_color(cb, cs, act[[j for j, _ in states_t]])
        err = delta_e(img.reshape(-1, 4)[:, :3], ref)
        assert float(np.percentile(err, 99)) <= 1.0, (k, float(err.mean()), float(err.max()))
        if k == 1:
            assert float(delta_e(img.reshape(-1, 4)[:, :3], cb).max()) > 5.0
