"""three.js in a real browser: `wrinklepipe view` rendered by Debian's chromium (headless,
SwiftShader WebGL2, driven by npm's playwright-core) equals the numpy model.

One page load renders every case: for each encoding x policy the page loads the asset, renders
the UV buffer (debug mode 2) and the tangent-space normal (debug mode 1, level-0 sampling) at
several weight sets into float32 targets; Python compares each covered pixel with
``wrinklepipe.model.blend`` on the shipped texels at the pixel's UV (0.5 degrees mean / 2 degrees
p99). The animation check reads the region weights the AnimationMixer gives at times t and
compares them with the curves the glTF stores, interpolated independently (numpy).

Whole characters on the same page: the generated multi-mesh avatar and RobotExpressive
(../shared/data, ``material = "Main"`` on its head), each converted into its source document:
the wrinkled material's debug normal equals numpy, and the lit frame at strong weights equals the
plain GLTFLoader's (no plugin) at every pixel the wrinkled material does not cover.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import shader_harness as h
from wrinkle_setups import ROBOT, write_robot_setup

from wrinklepipe import model
from wrinklepipe.demo import avatar, demo_asset
from wrinklepipe.gltf.package_write import write_gltf
from wrinklepipe.io.confine import allowed_roots
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.paths import ROOT
from wrinklepipe.pipeline.drivers import expression_cycle
from wrinklepipe.pipeline.package import PackOptions, package_from_asset
from wrinklepipe.pipeline.prepare import prepare_mesh
from wrinklepipe.sources.validation import load_input
from wrinklepipe.view.server import Site, ViewServer, find_asset

ENCODINGS = ["pd", "diff", "full", "composite"]
POLICIES = ["clamp01", "signed", "additive", "renormalize", "lerp"]
CHROMIUM = Path("/usr/bin/chromium")
NODE_MODULES = ROOT / "tools" / "node" / "node_modules"
SIZE = 160
CHAR_SIZE = 128  # the whole characters' renders
EXTENSION = "WRINKLEPIPE_wrinkle_maps"


def _missing() -> str:
    if not CHROMIUM.exists():
        return "Debian chromium is not installed (ci/bootstrap.sh installs it)"
    if shutil.which("node") is None:
        return "node is not installed"
    for pkg in ("three", "playwright-core"):
        if not (NODE_MODULES / pkg / "package.json").exists():
            return f"npm {pkg} is not installed under tools/node (ci/bootstrap.sh installs it)"
    return ""


def _asset(encoding: str):
    a = demo_asset(128, encoding=encoding)
    masks = a.masks.copy()
    masks[2] = np.maximum(masks[2], masks[6])  # overlapping regions: every policy differs
    return replace(a, masks=masks, mesh=prepare_mesh(a.mesh))


def _weight_sets(n_regions: int, policy: str) -> dict[str, list[float]]:
    lo = model.POLICY_WEIGHT_RANGE[policy].low
    rng = np.random.default_rng(16)
    sets = {
        "neutral": np.zeros(n_regions),
        "strong": np.full(n_regions, 0.9),
        "random": rng.uniform(lo, 1.0, n_regions),
        "negative": np.full(n_regions, max(-0.7, lo)),
    }
    return {k: [float(x) for x in v.astype(np.float32)] for k, v in sets.items()}


DATA = ROOT.parent / "shared" / "data"


def _real_character(root: Path) -> Path | None:
    """CesiumMan (../shared/data: a skinned Khronos sample) with the fidelity fixture's wrinkles."""
    from wrinklepipe.demo import face_fixture as ff

    mesh = DATA / ff.MESH_RELPATH
    if not mesh.is_file():
        return None
    a = ff.build_fixture(mesh, 256).asset()
    a = replace(a, mesh=prepare_mesh(a.mesh))
    write_gltf(package_from_asset(a, PackOptions(), [expression_cycle(a)]), root / "real", "cesium")
    return root / "real" / "cesium.gltf"


def _characters(root: Path) -> dict[str, Path]:
    """The multi-mesh avatar and (with ../shared/data) RobotExpressive, converted into their
    source documents (wrinkled: the avatar's Skin, the robot's Main on its Head)."""
    out = {}
    res = convert(avatar.avatar_source_dir(), root / "avatar", ConvertOptions(render=False))
    assert res.exit_code == 0
    out["avatar"] = root / "avatar" / "avatar.gltf"
    if ROBOT.is_file():
        manifest = write_robot_setup(root / "robot_in")
        with allowed_roots([ROBOT.parent]):
            res = convert(manifest, root / "robot", ConvertOptions(render=False))
        assert res.exit_code == 0
        out["robot"] = root / "robot" / "robot.gltf"
    return out


def _debug_sets(key: str, sets: dict[str, list[float]], size: int, plan: list) -> dict:
    """One call rendering the debug normal (mode 1) at every weight set of ``sets``, one file
    per set (``KEY_SET.f32``), each recorded in ``plan`` for the comparison with numpy."""
    files = [f"{key}_{name}.f32" for name in sets]
    plan += [(key, name, w, f) for (name, w), f in zip(sets.items(), files)]
    return {"fn": "renderDebugSets", "args": [1, list(sets.values()), size], "files": files}


CHAR_TIMES = [0.0, 0.5, 1.25, 2.0, 2.6, 2.95]  # within both clips (the mixer loops)


def _character_calls(name: str, url: str, clip: int, plan: list) -> list[dict]:
    """Focused on the wrinkles: the UV / coverage render, the lit frame at strong weights, the
    debug normal at each weight set, the weights the clip ``clip`` plays at CHAR_TIMES; then the
    same lit frame (same camera) without the plugin."""
    s = CHAR_SIZE
    strong = [0.9] * 3
    calls = [
        {"fn": "load", "args": [url]},
        {"fn": "focusWrinkles", "args": []},
        {"fn": "renderDebug", "args": [2, None, s], "file": f"{name}_uv.f32"},
        {"fn": "renderColor", "args": [strong, s], "file": f"{name}_lit_strong.u8"},
    ]
    calls.append(_debug_sets(name, _weight_sets(3, "clamp01"), s, plan))
    calls.append({"fn": "sampleWeights", "args": [clip, CHAR_TIMES], "character": name})
    calls.append({"fn": "load", "args": [url, {"plugin": False, "keepCamera": True}]})
    calls.append({"fn": "renderColor", "args": [None, s], "file": f"{name}_lit_plain.u8"})
    return calls


def _with_occluder(gltf: Path) -> Path:
    """The asset plus a second part with a plain material (no wrinkles) in front of the face:
    a two-material scene, as characters are."""
    doc = json.loads(gltf.read_text())
    doc["materials"].append(
        {"name": "visor", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1]}}
    )
    prim = dict(doc["meshes"][0]["primitives"][0])
    prim.pop("targets", None)
    prim["material"] = len(doc["materials"]) - 1
    doc["meshes"].append({"name": "visor", "primitives": [prim]})
    doc["nodes"].append(
        {
            "name": "visor",
            "mesh": len(doc["meshes"]) - 1,
            "translation": [0.0, 0.05, 0.3],
            "scale": [0.35, 0.2, 0.35],
        }
    )
    doc["scenes"][doc.get("scene", 0)]["nodes"].append(len(doc["nodes"]) - 1)
    out = gltf.with_name("demo_multi.gltf")
    out.write_text(json.dumps(doc))
    return out


def _color_asset(root: Path) -> Path:
    """The demo with colour states (pale where the skin stretches, flushed where it
    compresses), pd / clamp01."""
    a = demo_asset(128, color=True)
    a = replace(a, mesh=prepare_mesh(a.mesh))
    write_gltf(package_from_asset(a, PackOptions(), [expression_cycle(a)]), root / "color", "demo")
    return root / "color" / "demo.gltf"


def _write_assets(root: Path) -> dict[str, Path]:
    """One package per encoding, one .gltf per policy (the extension's policy edited)."""
    out = {}
    for enc in ENCODINGS:
        a = _asset(enc)
        pkg = package_from_asset(a, PackOptions(), [expression_cycle(a)])
        folder = root / enc
        write_gltf(pkg, folder, "demo")
        doc = json.loads((folder / "demo.gltf").read_text())
        for pol in POLICIES:
            ext = doc["materials"][0]["extensions"]["WRINKLEPIPE_wrinkle_maps"]
            ext["policy"] = pol
            path = folder / f"demo_{pol}.gltf"
            path.write_text(json.dumps(doc))
            out[f"{enc}-{pol}"] = path
    return out


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    reason = _missing()
    if reason:
        pytest.skip(reason)
    root = tmp_path_factory.mktemp("view_assets")
    assets = _write_assets(root)
    out = tmp_path_factory.mktemp("view_out")
    calls, plan = [], []
    n_regions = 8
    for enc in ENCODINGS:
        for pol in POLICIES:
            key = f"{enc}-{pol}"
            url = "/asset/" + assets[key].relative_to(root).as_posix()
            calls.append({"fn": "load", "args": [url]})
            if pol == POLICIES[0]:
                calls.append(
                    {"fn": "renderDebug", "args": [2, None, SIZE], "file": f"{enc}_uv.f32"}
                )
            calls.append(_debug_sets(key, _weight_sets(n_regions, pol), SIZE, plan))
    multi = _with_occluder(assets["pd-clamp01"])
    calls.append({"fn": "load", "args": ["/asset/" + multi.relative_to(root).as_posix()]})
    calls.append({"fn": "renderDebug", "args": [2, None, SIZE], "file": "multi_uv.f32"})
    calls.append(_debug_sets("multi", _weight_sets(8, "clamp01"), SIZE, plan))
    real = _real_character(root)
    if real is not None:
        calls.append({"fn": "load", "args": ["/asset/" + real.relative_to(root).as_posix()]})
        calls.append({"fn": "focusWrinkles", "args": []})
        calls.append({"fn": "renderDebug", "args": [2, None, SIZE], "file": "real_uv.f32"})
        calls.append(_debug_sets("real", _weight_sets(8, "clamp01"), SIZE, plan))
    color = _color_asset(root)
    calls.append({"fn": "load", "args": ["/asset/" + color.relative_to(root).as_posix()]})
    calls.append({"fn": "renderDebug", "args": [2, None, SIZE], "file": "color_uv.f32"})
    color_sets = _weight_sets(n_regions, "clamp01")
    color_files = [f"color_{name}.f32" for name in color_sets]
    calls.append(
        {
            "fn": "renderDebugSets",
            "args": [4, list(color_sets.values()), SIZE],
            "files": color_files,
        }
    )
    calls.append(
        {"fn": "renderColor", "args": [color_sets["strong"], SIZE], "file": "color_lit.u8"}
    )
    characters = _characters(root)
    for name, path in characters.items():
        doc = json.loads(path.read_text())
        ext = next(
            m for m in doc["materials"] if "extensions" in m and EXTENSION in m["extensions"]
        )
        clip = ext["extensions"][EXTENSION]["weightCurves"][0]["animation"]
        url = "/asset/" + path.relative_to(root).as_posix()
        calls += _character_calls(name, url, clip, plan)
    times = [0.0, 0.25, 0.5, 1.0, 1.6, 2.75, 3.3, 5.9]
    first = "/asset/" + assets["pd-clamp01"].relative_to(root).as_posix()
    calls += [{"fn": "load", "args": [first]}, {"fn": "sampleWeights", "args": [0, times]}]
    strong = _weight_sets(n_regions, POLICIES[0])["strong"]  # alone, as renderDebugSets did it
    calls.append({"fn": "renderDebug", "args": [1, strong, SIZE], "file": "single_strong.f32"})
    folder, gltf = find_asset(root)
    with ViewServer(Site(folder, gltf, NODE_MODULES / "three")) as srv:
        job = {
            "url": srv.url + "?still",
            "playwright": str(NODE_MODULES / "playwright-core"),
            "chromium": str(CHROMIUM),
            "out": str(out),
            "calls": calls,
        }
        (out / "job.json").write_text(json.dumps(job))
        r = subprocess.run(
            ["node", str(Path(__file__).parent / "browser_driver.mjs"), str(out / "job.json")],
            capture_output=True,
            text=True,
            timeout=600,
        )
    res = json.loads((out / "results.json").read_text())
    assert r.returncode == 0 and "error" not in res, (r.stderr[-2000:], res.get("error"))
    errors = [x for x in res["log"] if x.startswith(("error", "pageerror"))]
    assert not errors, errors
    return {
        "assets": assets,
        "color": color,
        "color_sets": color_sets,
        "multi": multi,
        "real": real,
        "characters": characters,
        "calls": calls,
        "out": out,
        "plan": plan,
        "results": res["results"],
        "times": times,
    }


def _image(b, file: str, size: int = SIZE) -> np.ndarray:
    if file.endswith(".u8"):
        return np.fromfile(b["out"] / file, np.uint8).reshape(size, size, 4)
    return np.fromfile(b["out"] / file, np.float32).reshape(size, size, 4)


@pytest.mark.parametrize("policy", POLICIES)
@pytest.mark.parametrize("encoding", ENCODINGS)
def test_threejs_viewer_renders_the_model(browser, encoding, policy):
    key = f"{encoding}-{policy}"
    uvimg = _image(browser, f"{encoding}_uv.f32")
    cov = uvimg[..., 3] > 0.5
    assert cov.sum() > 0.2 * SIZE * SIZE  # the face fills the frame
    inp = load_input(browser["assets"][key])
    assert inp.asset.policy == policy
    s = h.samples(inp, uvimg[cov][:, :2].astype(np.float32))
    d = inp.asset.region_state_matrix()
    for k, name, w, file in browser["plan"]:
        if k != key:
            continue
        w = np.asarray(w, np.float32)
        ww = w if policy == "signed" else w[:, None] * d
        ref = model.blend(s.base, s.states, s.masks, ww, inp.asset.encoding, policy)
        st = h.compare(_image(browser, file)[cov][None], ref)
        assert st["mean"] <= 0.5 and st["p99"] <= 2.0, (key, name, st)
        if name == "strong":  # the wrinkles are really there
            base_ref = model.blend(s.base, s.states, s.masks, ww * 0, inp.asset.encoding, policy)
            assert h.compare(_image(browser, file)[cov][None], base_ref)["p99"] > 2.0


def test_a_set_of_debug_renders_equals_the_same_renders_one_by_one(browser):
    """renderDebugSets (the weight sets of one load in one call, render targets kept between
    renders) gives the bytes a lone renderDebug of the same weights gives."""
    one = (browser["out"] / "single_strong.f32").read_bytes()
    assert len(one) == SIZE * SIZE * 16
    assert one == (browser["out"] / f"{ENCODINGS[0]}-{POLICIES[0]}_strong.f32").read_bytes()


def test_only_the_wrinkled_material_writes_the_debug_buffers(browser):
    """A second part with a plain material in front of the face: in debug renders it occludes
    and writes 0, so every pixel read back is the wrinkled material's and equals numpy."""
    uvimg = _image(browser, "multi_uv.f32")
    plain = _image(browser, "pd_uv.f32")
    cov = uvimg[..., 3] > 0.5
    assert 0 < cov.sum() < (plain[..., 3] > 0.5).sum()  # the visor hides part of the face
    inp = load_input(browser["multi"])
    s = h.samples(inp, uvimg[cov][:, :2].astype(np.float32))
    d = inp.asset.region_state_matrix()
    for k, name, w, file in browser["plan"]:
        if k != "multi":
            continue
        ww = np.asarray(w, np.float32)[:, None] * d
        ref = model.blend(s.base, s.states, s.masks, ww, "pd", "clamp01")
        st = h.compare(_image(browser, file)[cov][None], ref)
        assert st["mean"] <= 0.5 and st["p99"] <= 2.0, (name, st)


@pytest.mark.shared
def test_threejs_viewer_renders_a_real_skinned_character(browser):
    """CesiumMan (skinned, real UV layout) through GLTFLoader's SkinnedMesh path: the debug
    normal at every covered pixel equals numpy; the face's wrinkles move it."""
    if browser["real"] is None:
        pytest.skip("../shared/data is absent")
    uvimg = _image(browser, "real_uv.f32")
    cov = uvimg[..., 3] > 0.5
    assert cov.sum() > 0.05 * SIZE * SIZE
    inp = load_input(browser["real"])
    s = h.samples(inp, uvimg[cov][:, :2].astype(np.float32))
    d = inp.asset.region_state_matrix()
    moved = 0.0
    for k, name, w, file in browser["plan"]:
        if k != "real":
            continue
        ww = np.asarray(w, np.float32)[:, None] * d
        ref = model.blend(s.base, s.states, s.masks, ww, inp.asset.encoding, inp.asset.policy)
        img = _image(browser, file)[cov][None]
        st = h.compare(img, ref)
        assert st["mean"] <= 0.5 and st["p99"] <= 2.0, (name, st)
        if name == "strong":
            base_ref = model.blend(s.base, s.states, s.masks, ww * 0, "pd", inp.asset.policy)
            moved = h.compare(img, base_ref)["max"]
    assert moved > 2.0  # the viewer found the face, and its wrinkles are there
    focus = next(r for r in browser["results"] if r["fn"] == "focusWrinkles")
    assert focus["value"] > 0


def test_weights_animation_plays_the_curves(browser):
    """KHR_animation_pointer channels became tracks of the glTF animation's clip: the weights
    the mixer gives at t equal the stored curve, linearly interpolated (numpy)."""
    from wrinklepipe.gltf.package_read import read_wrinkled

    loads = [r for r in browser["results"] if r["fn"] == "load"]
    anim = loads[-1]["value"]["animations"]
    assert anim[0]["tracks"] == 8 and anim[0]["duration"] > 0
    samples = [r for r in browser["results"] if r["fn"] == "sampleWeights"]
    got = np.asarray(samples[-1]["value"])  # the demo's (the last load)
    curve = read_wrinkled(browser["assets"]["pd-clamp01"]).curves[0]
    times = np.asarray(browser["times"])
    expect = np.stack(
        [np.interp(times, curve.times, curve.values[:, r]) for r in range(curve.values.shape[1])],
        axis=1,
    )
    assert np.abs(expect).max() > 0.5  # the cycle reaches full expressions
    np.testing.assert_allclose(got, expect, atol=1e-5)


@pytest.mark.parametrize("name", ["avatar", "robot"])
def test_threejs_renders_a_whole_character(browser, name):
    """The avatar (Head/Eyes/Teeth/Body, 4 materials, 20-joint skin) and RobotExpressive (14
    meshes, 2 skins) converted into their documents: the wrinkled material's debug normal at
    every pixel it covers equals numpy; the lit frame at strong weights equals the plain
    GLTFLoader's (same camera, no plugin) wherever the wrinkled material is not (plain parts
    unaffected, byte for byte) and differs where its masks are (the wrinkles are in the artist's
    lit view)."""
    if name not in browser["characters"]:
        pytest.skip("../shared/data is absent")
    size = CHAR_SIZE
    uvimg = _image(browser, f"{name}_uv.f32", size)
    cov = uvimg[..., 3] > 0.5
    assert cov.sum() > 0.05 * size * size
    inp = load_input(browser["characters"][name])
    s = h.samples(inp, uvimg[cov][:, :2].astype(np.float32))
    d = inp.asset.region_state_matrix()
    moved = 0.0
    for k, wname, w, file in browser["plan"]:
        if k != name:
            continue
        ww = np.asarray(w, np.float32)[:, None] * d
        ref = model.blend(s.base, s.states, s.masks, ww, inp.asset.encoding, inp.asset.policy)
        img = _image(browser, file, size)[cov][None]
        st = h.compare(img, ref)
        assert st["mean"] <= 0.5 and st["p99"] <= 2.0, (name, wname, st)
        if wname == "strong":
            base = model.blend(s.base, s.states, s.masks, ww * 0, inp.asset.encoding, "clamp01")
            moved = h.compare(img, base)["p99"]
    assert moved > 2.0
    # plain parts unaffected: the same camera with and without the plugin
    face = cov
    lit = _image(browser, f"{name}_lit_strong.u8", size).astype(np.int16)
    plain = _image(browser, f"{name}_lit_plain.u8", size).astype(np.int16)
    assert 0 < face.sum() and (~face).sum() > 0
    background = (plain == plain[0, 0]).all(-1)
    assert (~face & ~background).sum() > 0.01 * size * size  # plain parts are in the frame
    np.testing.assert_array_equal(lit[~face], plain[~face])
    # the wrinkles show in the lit frame, where the masks are (numpy's, at the pixels' UVs)
    diff = np.abs(lit - plain)[..., :3].max(-1)[face]
    masked = s.masks.max(0) > 0.25
    assert diff[masked].mean() > 1.0 and diff[masked].mean() > 5 * diff[~masked].mean()


@pytest.mark.parametrize("name", ["avatar", "robot"])
def test_a_whole_characters_weights_play_with_its_morphs(browser, name):
    """The converted document's weight animation (its blendshapes driver's curves, in the clip
    that also plays the morph weights): the mixer's weights at t equal the stored curve."""
    from wrinklepipe.sources.package import read_package

    if name not in browser["characters"]:
        pytest.skip("../shared/data is absent")
    calls = [c for c in browser["calls"] if c["fn"] == "sampleWeights"]
    k = next(i for i, c in enumerate(calls) if c.get("character") == name)
    got = np.asarray([r for r in browser["results"] if r["fn"] == "sampleWeights"][k]["value"])
    curve = read_package(browser["characters"][name]).curves[0]
    times = np.asarray(CHAR_TIMES)
    expect = np.stack(
        [np.interp(times, curve.times, curve.values[:, r]) for r in range(curve.values.shape[1])],
        axis=1,
    )
    assert np.abs(expect).max() > 0.5
    np.testing.assert_allclose(got, expect, atol=1e-5)


def test_threejs_viewer_blends_the_colour_as_the_model(browser):
    """Colour states through the plugin: the blended base colour (debug mode 4: three's
    diffuseColor after the blend, linear) equals the numpy colour model of the shipped texels
    (decoded, then sampled bilinearly) at every covered pixel, CIEDE2000 p99 <= 1; at strong
    weights the colour visibly moves."""
    from wrinklepipe.codec import srgb
    from wrinklepipe.metrics import delta_e
    from wrinklepipe.validate import textures as tx
    from wrinklepipe.validate.renderer import color_textures

    uvimg = _image(browser, "color_uv.f32")
    cov = uvimg[..., 3] > 0.5
    uv = uvimg[cov][:, :2].astype(np.float32)
    inp = load_input(browser["color"])
    s = h.samples(inp, uv)
    base_t, states_t = color_textures(inp)

    def lin(t):
        return srgb.decode_texels(np.frombuffer(t.data, np.uint8).reshape(t.height, t.width, -1))

    cb = tx.bilinear(lin(base_t)[..., :3], uv)
    cs = np.stack([tx.bilinear(lin(t)[..., :3], uv) for _, t in states_t])
    d = inp.asset.region_state_matrix()
    for name, w in browser["color_sets"].items():
        act = model.activations(s.masks, np.asarray(w, np.float32)[:, None] * d, "clamp01")
        ref = model.combine_color(cb, cs, act[[k for k, _ in states_t]])
        got = _image(browser, f"color_{name}.f32")[cov][:, :3]
        err = delta_e(got, ref)
        assert float(np.percentile(err, 99)) <= 1.0, (name, float(err.mean()), float(err.max()))
        if name == "strong":
            assert float(delta_e(got, cb).max()) > 5.0  # the flush is there
