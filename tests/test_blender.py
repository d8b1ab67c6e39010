"""Blender 5 imports, plays and renders what wrinklepipe ships (PyPI ``bpy`` 5.x, .venv-blender).

Everything runs in ONE Blender process for the module (tests/blender5.py: tests/blender_session.py
runs each script from Blender's factory settings), on the demo (a 128^2 head with a smooth base),
CesiumMan and RobotExpressive (../shared/data):

- the Blender export's own ``build_wrinkles.py``, run as a user runs it, imports the export's
  glTF, builds the WrinklePipe node group into the wrinkled material, one driver per region and
  the keys of the export's curves;
- tests/blender_import.py: Blender's glTF importer keeps every custom attribute of what
  ``convert`` and ``export`` write (values exact, as FLOAT), here and in three more processes
  under PYTHONHASHSEED 1, 2 and 3 (its importer fails on a primitive whose custom attributes mix
  shapes for most seeds; wrinklepipe writes them all SCALAR FLOAT);
- tests/blender_bake.py: at curve keys, the keys and drivers give the group the curves' weights,
  and Cycles (CPU) bakes the shading normal the Principled BSDF gets (tangent space, one sample
  at each texel centre) equal to the numpy model of the shipped texels at those weights: within
  1 degree mean and 3 degrees p99 on the texels the wrinkled primitives cover; Blender's own
  MikkTSpace tangents equal the TANGENT the glTF ships;
- tests/blender_render.py: the node group alone on a UV-aligned plane, every encoding and policy,
  within 0.5 / 2 degrees.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import blender5
import gltf_reference as gr
import numpy as np
import OpenImageIO as oiio
import pytest
import shader_harness as h
from passthrough import EXTENSION
from test_export_engines import _smooth_base, _source
from wrinkle_setups import ROBOT

from wrinklepipe import model
from wrinklepipe.demo import demo_asset
from wrinklepipe.demo.package import demo_package
from wrinklepipe.geometry.rasterise import rasterise_triangle_ids
from wrinklepipe.gltf.package_write import write_gltf
from wrinklepipe.io import khronos
from wrinklepipe.jobs.export import export
from wrinklepipe.metrics import angle_deg
from wrinklepipe.paths import ROOT
from wrinklepipe.pipeline.drivers import expression_cycle
from wrinklepipe.pipeline.package import PackOptions, package_from_asset
from wrinklepipe.pipeline.prepare import prepare_mesh
from wrinklepipe.sources.validation import LoadOptions, load_input
from wrinklepipe.usd.package_write import write_usd

HERE = Path(__file__).parent
DATA = ROOT.parent / "shared" / "data"
SEEDS = (1, 2, 3)  # each fails the importer on a SCALAR beside a VEC4 custom attribute (measured)
BAKE_DEMO = 128  # the demo's maps are 128^2: one bake texel per map texel
BAKE_ROBOT = 128  # RobotExpressive's wrinkle maps are 64^2: four bake texels per map texel


def _bias_package(tmp: Path) -> Path:
    """The 64^2 demo with painted vertex colours (the dynamic driver's bias), as ``convert``
    writes a package: vertex IDs and the bias are the primitive's custom attributes."""
    a = demo_asset(64)
    rng = np.random.default_rng(46)
    mesh = prepare_mesh(a.mesh)
    mesh = replace(mesh, colors=rng.random((mesh.vertex_count, 4)).astype(np.float32))
    write_gltf(package_from_asset(replace(a, mesh=mesh)), tmp / "bias", "bias")
    return tmp / "bias" / "bias.gltf"


def _cesium(tmp: Path) -> Path | None:
    """CesiumMan with the fidelity fixture's wrinkles, exported for Blender (None without
    ../shared/data)."""
    from wrinklepipe.demo import face_fixture as ff

    mesh = DATA / ff.MESH_RELPATH
    if not mesh.is_file():
        return None
    a = ff.build_fixture(mesh, 256).asset()
    a = replace(a, mesh=prepare_mesh(a.mesh))
    write_gltf(package_from_asset(a, PackOptions(), [expression_cycle(a)]), tmp / "ces", "ces")
    export(tmp / "ces", tmp / "ces_blender", "blender")
    return tmp / "ces_blender"


def _curve(folder: Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The export's first weight curve: times [T], values [T, R], region parameters."""
    setup = json.loads((folder / "wrinkle_setup.json").read_text())
    rel = next(c for c in setup["curves"] if c.endswith(".json"))
    c = json.loads((folder / rel).read_text())
    values = np.reshape(c["values"], (len(c["times"]), c["regionCount"]))
    return np.asarray(c["times"]), values, c["regions"]


def _bake_keys(values: np.ndarray) -> list[int]:
    """Key 0 and the keys where the curve's first two peaking regions peak."""
    peaks = [int(np.argmax(values[:, r])) for r in range(values.shape[1]) if values[:, r].max()]
    return sorted({0, *peaks[:1], *peaks[-1:]})


#: A convert folder's texels as PNGs (``load_input`` prefers its BC copies under compressed/).
PNG = LoadOptions(textures="png")
#: Blender's default scene rate; build_wrinkles.py keys curve time t at frame 1 + t * FPS.
FPS = 24.0


@pytest.fixture(scope="module")
def blender(request, robot_converted_or_none, tmp_path_factory):
    """Every Blender job of the module in one Blender 5 process, plus the seeded imports.
    Returns the jobs' results and what the tests compare them with."""
    blender5.require()
    tmp = tmp_path_factory.mktemp("blender5")
    cases = {}
    demo_src = _source(tmp / "demo", base=_smooth_base())
    export(demo_src, tmp / "demo_blender", "blender")
    cases["demo"] = (demo_src, tmp / "demo_blender", BAKE_DEMO)
    if robot_converted_or_none is not None:
        export(robot_converted_or_none, tmp / "robot_blender", "blender")
        cases["robot"] = (robot_converted_or_none, tmp / "robot_blender", BAKE_ROBOT)
    cesium = _cesium(tmp)
    imports = {"demo": next(demo_src.glob("*.gltf")), "bias": _bias_package(tmp)}
    if "robot" in cases:
        imports["robot"] = next(robot_converted_or_none.glob("*.gltf"))
        imports["robot_blender"] = tmp / "robot_blender" / "robot.gltf"

    jobs = [
        {
            "name": "build_demo",
            "script": tmp / "demo_blender" / "build_wrinkles.py",
            "args": [tmp / "demo_blender" / "wrinkle_setup.json", "--save", tmp / "face.blend"],
        }
    ]
    if cesium is not None:
        jobs.append({"name": "build_cesium", "script": cesium / "build_wrinkles.py", "args": []})
    if "robot" in cases:
        robot = tmp / "robot_blender"
        jobs.append({"name": "build_robot", "script": robot / "build_wrinkles.py", "args": []})
    for name, path in imports.items():
        out = tmp / f"import_{name}.npz"
        jobs.append({"name": f"import_{name}", "script": HERE / "blender_import.py"})
        jobs[-1]["args"] = [out, path]
    bakes = {}
    for name, (_, folder, size) in cases.items():
        times, values, _ = _curve(folder)
        keys = _bake_keys(values)
        out = tmp / f"bake_{name}"
        out.mkdir()
        frames = [1.0 + float(times[k]) * FPS for k in keys]
        jobs.append({"name": f"bake_{name}", "script": HERE / "blender_bake.py"})
        jobs[-1]["args"] = [out, size, folder / "wrinkle_setup.json", *frames]
        bakes[name] = (out, keys)
    usd = {"demo": (tmp / "usd_demo" / "demo.usda", "/demo/Looks/skin")}
    write_usd(demo_package(128), usd["demo"][0])
    colored = demo_asset(64, color=True, mesh_resolution=(48, 32))
    colored = replace(colored, mesh=prepare_mesh(colored.mesh))
    usd["color"] = (tmp / "usd_color" / "demo.usda", "/demo/Looks/skin")
    write_usd(package_from_asset(colored), usd["color"][0])
    if robot_converted_or_none is not None:
        usd["robot"] = (robot_converted_or_none / "robot.usda", "/robot/Looks/skin")
    for name, (layer, material) in usd.items():
        jobs.append({"name": f"usd_{name}", "script": HERE / "blender_usd.py"})
        jobs[-1]["args"] = [tmp / f"usd_{name}.json", layer, material]
    render = tmp / "render"
    setups, inputs, weights = _render_cases(render)
    jobs.append({"name": "render", "script": HERE / "blender_render.py"})
    jobs[-1]["args"] = [render, RENDER_SIZE, render / "weights.json", *setups]
    color = _color_case(tmp / "render_color", weights[0])
    jobs.append({"name": "render_color", "script": HERE / "blender_render.py"})
    jobs[-1]["args"] = [color["out"], RENDER_SIZE, color["weights"], "--color", *color["args"]]
    results = blender5.run_session(jobs, tmp)

    seeded = {}
    for seed in SEEDS:
        args = [tmp / f"seed{seed}_bias.npz", imports["bias"]]
        seeded[seed] = blender5.run_script(
            HERE / "blender_import.py", args, env={"PYTHONHASHSEED": str(seed)}
        )
    return {
        "results": results,
        "tmp": tmp,
        "cases": cases,
        "imports": imports,
        "bakes": bakes,
        "render": (render, inputs, weights),
        "color": color,
        "usd": usd,
        "seeded": seeded,
    }


@pytest.fixture(scope="module")
def robot_converted_or_none(request):
    """RobotExpressive converted (the shared conftest fixture), or None without ../shared/data."""
    if not ROBOT.is_file():
        return None
    return request.getfixturevalue("robot_converted")[0]


def _ok(blender, name: str) -> str:
    code, out, err = blender["results"][name]
    assert code == 0, out[-3000:] + err[-3000:]
    return out


def _summary(stdout: str) -> dict:
    return json.loads(next(x for x in stdout.splitlines() if x.startswith('{"wrinklepipe"')))


def test_blender_script_builds_the_node_group(blender):
    out = _ok(blender, "build_demo")
    assert "Error" not in blender["results"]["build_demo"][2]
    summary = _summary(out)
    assert summary["wrinklepipe"] == "ok" and summary["drivers"] == 8 and summary["keys"] > 8
    assert summary["object"] == "demo" and summary["material"] == "demo_skin"  # the glTF's face
    assert (blender["tmp"] / "face.blend").is_file()


@pytest.mark.shared
def test_blender_script_builds_on_real_characters(blender):
    """CesiumMan's script builds its 8 drivers; RobotExpressive's finds the wrinkled clone of
    'Main' on the Head and its 3 regions."""
    if "build_robot" not in blender["results"]:
        pytest.skip("../shared/data is absent")
    assert _summary(_ok(blender, "build_cesium"))["drivers"] == 8
    robot = _summary(_ok(blender, "build_robot"))
    assert robot["material"] == "Main (wrinkled)" and robot["drivers"] == 3


def _expected_attributes(path: Path) -> dict[str, np.ndarray]:
    """What Blender's importer should give each mesh (values read by pygltflib): per glTF mesh,
    its primitives' vertices in the importer's order (each primitive's used vertices, sorted,
    primitive after primitive), every custom attribute, zeros where a primitive lacks it."""
    g = gr.load(path)
    doc = json.loads(g.to_json())
    out = {}
    for m in doc["meshes"]:
        prims = [p for p in m["primitives"] if "POSITION" in p["attributes"]]
        names = sorted({k for p in prims for k in p["attributes"] if k.startswith("_")})
        used = [np.unique(gr.accessor(g, path, p["indices"]).reshape(-1)) for p in prims]
        for name in names:
            parts = [
                gr.accessor(g, path, p["attributes"][name])[u]
                if name in p["attributes"]
                else np.zeros((len(u), 1))
                for p, u in zip(prims, used)
            ]
            out[f"{m['name']}/{name}"] = np.concatenate(parts).astype(np.float64).reshape(-1, 1)
    return out


def test_blender_imports_every_custom_attribute_exactly(blender):
    """The importer keeps ``_WRINKLE_VERTEX_ID`` and the bias's four channels as FLOAT
    attributes with the values the file holds (pygltflib), on the demo's package, a package
    with a bias, RobotExpressive's converted document and its Blender export; the bias package
    has 0 Khronos validator errors."""
    seen = 0
    for name, path in blender["imports"].items():
        _ok(blender, f"import_{name}")
        got = np.load(blender["tmp"] / f"import_{name}.npz")
        info = json.loads((blender["tmp"] / f"import_{name}.npz.json").read_text())
        want = _expected_attributes(path)
        assert want, name  # every file has custom attributes
        assert sorted(got.files) == sorted(want), (name, got.files, list(want))
        for key, values in want.items():
            np.testing.assert_array_equal(got[key], values, err_msg=f"{name}: {key}")
            mesh, attr = key.split("/")
            assert info[mesh]["attributes"][attr] == "FLOAT"
            seen += 1
    bias = [k for k in np.load(blender["tmp"] / "import_bias.npz").files if "_BIAS_" in k]
    assert len(bias) == 4 and seen >= 4 + 2
    if khronos.available():
        report = khronos.validate_gltf(blender["imports"]["bias"])
        assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]


def test_blender_imports_whatever_the_hash_seed(blender):
    """The bias package imports under PYTHONHASHSEED 1, 2 and 3 with the same values (before
    the bias became four SCALAR attributes, each of these seeds failed the import)."""
    ref = np.load(blender["tmp"] / "import_bias.npz")
    for seed, r in blender["seeded"].items():
        assert r.returncode == 0, (seed, r.stderr[-3000:])
        got = np.load(blender["tmp"] / f"seed{seed}_bias.npz")
        assert sorted(got.files) == sorted(ref.files)
        for k in ref.files:
            np.testing.assert_array_equal(got[k], ref[k])


def _bake(blender, name: str) -> tuple[dict, Path, list[int]]:
    if name not in blender["bakes"]:
        pytest.skip("../shared/data is absent")
    _ok(blender, f"bake_{name}")
    out, keys = blender["bakes"][name]
    return json.loads((out / "bake.json").read_text()), out, keys


@pytest.mark.parametrize("name", ["demo", "robot"])
def test_blender_plays_the_curves_at_their_keys(blender, name):
    """At each baked key's frame, the keyframes and drivers give the group's inputs the
    curve's weights (the export's curve, equal to the glTF's weight animation)."""
    info, _, keys = _bake(blender, name)
    src, folder, _ = blender["cases"][name]
    times, values, params = _curve(folder)
    assert info["parameters"] == params and info["blender"].startswith("5.")
    np.testing.assert_allclose(info["weights"], values[keys], atol=1e-6)
    assert np.max(info["weights"]) > 0.5  # a wrinkled pose among them
    shipped = next(iter(load_input(src).weight_curves.values()))
    np.testing.assert_allclose(values, shipped, atol=1e-6)


def _coverage(folder: Path, size: int) -> np.ndarray:
    """Texels whose centre lies in a triangle of the wrinkled primitives' UV layout."""
    setup = json.loads((folder / "wrinkle_setup.json").read_text())
    path = folder / setup["mesh"]
    g = gr.load(path)
    cov = np.zeros((size, size), bool)
    for m in g.meshes:
        for p in m.primitives:
            if p.material is not None and g.materials[p.material].name in setup["materials"]:
                uvs = gr.accessor(g, path, p.attributes.TEXCOORD_0)
                tris = gr.accessor(g, path, p.indices).reshape(-1, 3)
                cov |= rasterise_triangle_ids(uvs, tris, size) >= 0
    return cov.reshape(-1)


@pytest.mark.parametrize("name", ["demo", "robot"])
def test_cycles_renders_the_wrinkled_poses_as_the_model(blender, name):
    """Cycles' tangent-space bake of the shading normal at each key (the BSDF's Normal input,
    fed by the group through the Normal Map node) equals the numpy model of the shipped PNG
    texels (bilinear at the texel centres) at the curve's weights: mean <= 1 degree, p99 <= 3 on the
    texels the wrinkled primitives cover; the wrinkled keys really move the normal."""
    info, out, keys = _bake(blender, name)
    src, folder, size = blender["cases"][name]
    inp = load_input(src, PNG)  # the PNG texels the Blender export ships, not the BC copies
    a = inp.asset
    _, values, _ = _curve(folder)
    cov = _coverage(folder, size)
    assert cov.mean() > 0.2
    c = (np.arange(size) + 0.5) / size
    u, v = np.meshgrid(c, c)  # EXR row i = glTF v (Blender's v is 1 - glTF's)
    s = h.samples(inp, np.stack([u, v], -1).reshape(-1, 2)[cov].astype(np.float32))
    d = a.region_state_matrix()
    stats = []
    for j, k in enumerate(keys):
        w = values[k]
        ww = w if a.policy == "signed" else w[:, None] * d
        img = oiio.ImageBuf(str(out / f"bake_{j}.exr")).get_pixels(oiio.FLOAT)
        n = img.reshape(-1, 4)[cov, :3] * 2.0 - 1.0
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        ref = model.blend(s.base, s.states, s.masks, ww, a.encoding, a.policy)
        err = angle_deg(n, ref)
        stats.append((k, float(err.mean()), float(np.percentile(err, 99))))
        assert err.mean() <= 1.0 and np.percentile(err, 99) <= 3.0, (name, stats)
        if w.max() > 0.5:
            neutral = model.blend(s.base, s.states, s.masks, ww * 0, a.encoding, a.policy)
            assert np.percentile(angle_deg(n, neutral), 99) > 3.0, (name, k)


@pytest.mark.parametrize("name", ["demo", "robot"])
def test_blenders_tangents_are_the_shipped_ones(blender, name):
    """Blender's MikkTSpace tangent and sign at each corner of the wrinkled object equal the
    glTF's TANGENT at the corner's vertex (Blender's axes: x, -z, y of glTF's): the frame the
    wrinkle maps were made in is the frame Blender decodes them in."""
    _, out, _ = _bake(blender, name)
    _, folder, _ = blender["cases"][name]
    setup = json.loads((folder / "wrinkle_setup.json").read_text())
    path = folder / setup["mesh"]
    g = gr.load(path)
    corners = np.load(out / "corners.npz")
    mesh = next(
        m
        for m in g.meshes
        for p in m.primitives
        if p.material is not None and g.materials[p.material].name in setup["materials"]
    )
    tangent, wrinkled, positions = [], [], []
    for p in (p for p in mesh.primitives if p.attributes.POSITION is not None):
        used = np.unique(gr.accessor(g, path, p.indices).reshape(-1))
        positions.append(gr.accessor(g, path, p.attributes.POSITION)[used])
        on = p.material is not None and g.materials[p.material].name in setup["materials"]
        t = gr.accessor(g, path, p.attributes.TANGENT)[used] if on else np.zeros((len(used), 4))
        tangent.append(t)
        wrinkled.append(np.full(len(used), on))
    to_blender = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], np.float64)
    positions = np.concatenate(positions) @ to_blender.T
    np.testing.assert_allclose(corners["positions"], positions, atol=1e-5)
    tangent, wrinkled = np.concatenate(tangent), np.concatenate(wrinkled)
    vi = corners["vertex"]
    keep = wrinkled[vi]
    want = tangent[vi[keep], :3] @ to_blender.T
    err = angle_deg(corners["tangent"][keep], want)
    assert np.percentile(err, 99) < 0.5 and err.mean() < 0.05, (err.mean(), err.max())
    np.testing.assert_array_equal(corners["sign"][keep], tangent[vi[keep], 3])


RENDER_SIZE = 96  # rendered pixels on the 64^2 demo: samples between texels
RENDER_CASES = [  # every encoding, every policy (overlapping masks: the policies differ)
    ("pd", "clamp01"),
    ("diff", "signed"),
    ("full", "additive"),
    ("composite", "renormalize"),
    ("pd", "lerp"),
]


def _render_cases(tmp: Path) -> tuple[list[str], list, list]:
    """The Blender exports of RENDER_CASES (64^2 demos, the policy edited into the glTF) and
    the weight sets each is rendered at (weights.json under ``tmp``)."""
    setups, inputs = [], []
    for encoding, policy in RENDER_CASES:
        src = _source(tmp / f"{encoding}_{policy}", encoding, size=64, overlap=True)
        gltf = src / "demo.gltf"
        doc = json.loads(gltf.read_text())
        doc["materials"][0]["extensions"][EXTENSION]["policy"] = policy
        gltf.write_text(json.dumps(doc))
        folder = tmp / f"blender_{encoding}_{policy}"
        export(src, folder, "blender")
        setups.append(str(folder / "wrinkle_setup.json"))
        inputs.append(load_input(src))
    n = len(inputs[0].asset.regions)
    rng = np.random.default_rng(16)
    weights = []
    for _, policy in RENDER_CASES:
        lo = model.POLICY_WEIGHT_RANGE[policy].low
        sets = [np.zeros(n), np.full(n, 0.9), rng.uniform(lo, 1.0, n), np.full(n, max(lo, -0.6))]
        weights.append([w.astype(np.float32) for w in sets])
    (tmp / "weights.json").write_text(json.dumps([[w.tolist() for w in sets] for sets in weights]))
    return setups, inputs, weights


def _color_case(tmp: Path, weights: list) -> dict:
    """The demo with colour states (64^2), its Blender export, and the weights (those of the
    first render case) written for tests/blender_render.py --color."""
    a = demo_asset(64, color=True, mesh_resolution=(48, 32))
    a = replace(a, mesh=prepare_mesh(a.mesh))
    src = tmp / "src"
    write_gltf(package_from_asset(a, PackOptions(), [expression_cycle(a)]), src, "demo")
    export(src, tmp / "blender", "blender")
    out = tmp / "out"
    out.mkdir(parents=True)
    (tmp / "weights.json").write_text(json.dumps([[w.tolist() for w in weights]]))
    setup = tmp / "blender" / "wrinkle_setup.json"
    base = src / "textures" / "base_color.png"
    return {"out": out, "weights": tmp / "weights.json", "args": [base, setup], "src": src,
            "sets": weights}  # fmt: skip


def test_blender_node_group_blends_the_colour_as_the_model(blender):
    """The group's Color output (the colour states over the base colour, sRGB images decoded
    before filtering) rendered by Cycles equals the numpy colour model of the exported texels:
    CIEDE2000 p99 <= 1 at every weight set; strong weights move the colour."""
    from wrinklepipe.codec import srgb
    from wrinklepipe.metrics import delta_e
    from wrinklepipe.validate import textures as tx
    from wrinklepipe.validate.renderer import color_textures

    _ok(blender, "render_color")
    color = blender["color"]
    inp = load_input(color["src"])
    c = (np.arange(RENDER_SIZE) + 0.5) / RENDER_SIZE
    u, v = np.meshgrid(c, c)
    uv = np.stack([u, v], -1).reshape(-1, 2).astype(np.float32)
    s = h.samples(inp, uv)
    base_t, states_t = color_textures(inp)

    def lin(t):
        return srgb.decode_texels(np.frombuffer(t.data, np.uint8).reshape(t.height, t.width, -1))

    cb = tx.bilinear(lin(base_t)[..., :3], uv)
    cs = np.stack([tx.bilinear(lin(t)[..., :3], uv) for _, t in states_t])
    d = inp.asset.region_state_matrix()
    for k, w in enumerate(color["sets"]):
        act = model.activations(s.masks, np.asarray(w, np.float32)[:, None] * d, "clamp01")
        ref = model.combine_color(cb, cs, act[[j for j, _ in states_t]])
        img = oiio.ImageBuf(str(color["out"] / f"0_{k}.exr")).get_pixels(oiio.FLOAT)
        got = img.reshape(-1, img.shape[-1])[:, :3]
        err = delta_e(got, ref)
        assert float(np.percentile(err, 99)) <= 1.0, (k, float(err.mean()), float(err.max()))
        if k == 1:
            assert float(delta_e(got, cb).max()) > 5.0  # the flush is there


def test_blender_node_group_renders_the_model(blender):
    """The exported build_wrinkles.py's node group, rendered by Cycles (tests/blender_render.py:
    emission on a UV-aligned plane, one centred sample per pixel, float EXR read by
    OpenImageIO) equals numpy on the exported texels, for every encoding and policy; strong
    weights move the normal."""
    _ok(blender, "render")
    out, inputs, weights = blender["render"]
    c = (np.arange(RENDER_SIZE) + 0.5) / RENDER_SIZE
    u, v = np.meshgrid(c, c)  # EXR row i = glTF v (Blender's v is 1 - glTF's)
    uv = np.stack([u, v], -1).reshape(-1, 2).astype(np.float32)
    for e, ((encoding, policy), inp) in enumerate(zip(RENDER_CASES, inputs, strict=True)):
        a = inp.asset
        assert (a.encoding, a.policy) == (encoding, policy)
        s = h.samples(inp, uv)
        d = a.region_state_matrix()
        for k, w in enumerate(weights[e]):
            ww = w if policy == "signed" else w[:, None] * d
            img = oiio.ImageBuf(str(out / f"{e}_{k}.exr")).get_pixels(oiio.FLOAT)
            normal = img * 2.0 - 1.0  # (the harness's compare reads x, y, z of RGBA)
            ref = model.blend(s.base, s.states, s.masks, ww, encoding, policy)
            st = h.compare(normal[None], ref)
            assert st["mean"] <= 0.5 and st["p99"] <= 2.0, (encoding, policy, k, st)
            if k == 1:
                neutral = model.blend(s.base, s.states, s.masks, ww * 0, encoding, policy)
                assert h.compare(normal[None], neutral)["p99"] > 2.0, (encoding, policy)


@pytest.mark.parametrize("name", ["demo", "robot", "color"])
def test_a_pxr_with_usdmtlx_composes_the_materialx_material(blender, name):
    """Blender's pxr (USD 25.x with UsdMtlx) opens the USD output (the demo package's, and
    RobotExpressive's convert output): UsdValidation 0 errors of any kind, every shader id is
    a node its registry knows, the material's ``mtlx`` surface is ``ND_standard_surface`` and
    its universal one the UsdPreviewSurface; the network in the layer is the one UsdMtlx reads
    from the ``.mtlx`` beside it, node for node; a layer referencing that file's material
    composes it."""
    if name not in blender["usd"]:
        pytest.skip("../shared/data is absent")
    _ok(blender, f"usd_{name}")
    got = json.loads((blender["tmp"] / f"usd_{name}.json").read_text())
    assert got["usd"].startswith("0.2")
    assert got["errors"] == [] and got["unknown_ids"] == [] and got["shader_ids"] >= 15
    material = blender["usd"][name][1]
    assert got["surface"] == [f"{material}/SR_wrinkle", "ND_standard_surface_surfaceshader"]
    assert got["preview"] == [f"{material}/Surface", "UsdPreviewSurface"]
    assert len(got["layer_graph"]) > 20 and got["layer_graph"] == got["mtlx_graph"]
    assert got["referenced"] == "ND_standard_surface_surfaceshader"
