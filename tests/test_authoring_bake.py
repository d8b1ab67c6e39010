"""Wrinkle maps baked from sculpts: the analytic slopes of known displacements, one frame.

Independent expectations: a sphere baked from a finer sphere (the tangent-space normal of a
surface onto itself is (0, 0, 1)); the exact PD slopes of analytic wrinkles displaced along
the planar face plate of a real mesh (CesiumMan, ``tests/sculpt_fixture.py``), in the plate's
tangent frame built in the test; byte equality of a state baked from the neutral sculpt; the
baked maps through ``convert`` and its fidelity rules.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import trimesh
from sculpt_fixture import CESIUM, STATES, expected_slopes, make_sculpts

from wrinklepipe.cli import main
from wrinklepipe.geometry.bake import BakeOptions, HighMesh, RayScene, bake_normal_maps
from wrinklepipe.geometry.primitives import uv_sphere
from wrinklepipe.geometry.tangents import mikktspace_tangents
from wrinklepipe.io.images import read_image
from wrinklepipe.masks.from_states import propose_masks
from wrinklepipe.pipeline.character import CharacterSource, read_character

shared = pytest.mark.skipif(not CESIUM.is_file(), reason="../shared/data is absent")


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Degrees between the normals of PD slopes ``a`` and ``b`` ``[..., 2]``."""
    na = np.concatenate([a, np.ones_like(a[..., :1])], axis=-1)
    nb = np.concatenate([b, np.ones_like(b[..., :1])], axis=-1)
    na /= np.linalg.norm(na, axis=-1, keepdims=True)
    nb /= np.linalg.norm(nb, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip((na * nb).sum(axis=-1), -1.0, 1.0)))


def _pd(n: np.ndarray) -> np.ndarray:
    return n[..., :2] / n[..., 2:3]


def _low_sphere():
    low = uv_sphere(48, 24)
    t = mikktspace_tangents(low.positions, low.normals, low.uvs, low.indices)
    return replace(low, tangents=t)


def test_rays_hit_the_first_surface_within_the_distance():
    scene = RayScene(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), np.array([[0, 1, 2]]))
    o = np.array([[0.2, 0.3, 1.0], [0.2, 0.3, 5.0], [2.0, 2.0, 1.0]])
    d = np.array([[0.0, 0.0, -1.0]] * 3)
    tri, u, v, t = scene.first_hit(o, d, 2.0)
    assert tri.tolist() == [0, -1, -1]
    assert (u[0], v[0], t[0]) == pytest.approx((0.2, 0.3, 1.0), abs=1e-6)


def test_a_sphere_baked_from_a_finer_sphere_is_flat():
    low = _low_sphere()
    hi = trimesh.creation.icosphere(subdivisions=5)
    res = bake_normal_maps(low, [HighMesh(hi.vertices, hi.faces)], BakeOptions(size=64))
    n = res.maps[0][res.covered]
    # the icosphere's facets against the low sphere's interpolated normals: within ~0.3 deg
    assert np.degrees(np.arccos(n[:, 2].min())) < 0.5
    assert res.missed_samples == [0]
    # padding: texels beyond the islands are flat too, every texel a unit normal
    np.testing.assert_allclose(np.linalg.norm(res.maps[0], axis=-1), 1.0, atol=1e-6)


def test_a_tilted_surface_bakes_to_its_tangent_space_normal():
    """A flat quad with UVs along x and y, baked from the same quad tilted about y by 10 deg:
    the normal in the (T = +x, B = -y for glTF's v down, N = +z) frame is known."""
    from wrinklepipe.asset import Mesh

    p = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)  # v down: +y is v = 0
    idx = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    nrm = np.tile([0.0, 0.0, 1.0], (4, 1)).astype(np.float32)
    low = Mesh(p, idx, uv, nrm, mikktspace_tangents(p, nrm, uv, idx))
    a = np.radians(10.0)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    hi = p.astype(np.float64) * 3 @ rot.T
    res = bake_normal_maps(low, [HighMesh(hi, idx)], BakeOptions(size=16, max_distance=1.0))
    inner = res.maps[0][4:12, 4:12].reshape(-1, 3)
    want = rot @ [0.0, 0.0, 1.0]  # (sin a, 0, cos a): tilted towards +x, i.e. along T
    np.testing.assert_allclose(inner, np.tile(want, (len(inner), 1)), atol=1e-5)


@pytest.fixture(scope="module")
def sculpts():
    if not CESIUM.is_file():
        pytest.skip("../shared/data is absent")
    low, _ = read_character(CharacterSource(CESIUM))
    return make_sculpts(low)


@pytest.fixture(scope="module")
def baked(sculpts):
    highs = [HighMesh(m.vertices, m.faces, None, k) for k, m in sculpts.highs.items()]
    return bake_normal_maps(sculpts.low, highs, BakeOptions(size=512, supersample=1))


@shared
@pytest.mark.shared
def test_state_minus_base_matches_the_analytic_slopes(sculpts, baked):
    base = _pd(baked.maps[0])
    for k, state in enumerate(STATES):
        want, inside = expected_slopes(sculpts, state, 512, 1)
        wrinkles = inside & (np.linalg.norm(want, axis=-1) > 0.02)
        assert wrinkles.sum() > 3000 and np.abs(want[wrinkles]).max() > 0.4
        err = _angle(_pd(baked.maps[k + 1]) - base, want)[wrinkles]
        assert np.percentile(err, 99) < 2.0, (state, np.percentile(err, 99))
        # and the base on the plate is the plate itself: flat
        assert _angle(base[inside], np.zeros_like(base[inside])).max() < 0.05


@pytest.fixture(scope="module")
def baked_folder(sculpts, tmp_path_factory):
    """bake-states on sculpts exported as files: (folder, the command line, the stderr)."""
    tmp = tmp_path_factory.mktemp("bake")
    small = make_sculpts(sculpts.low, levels=2)
    src = tmp / "sculpts"
    src.mkdir()
    for name, m in small.highs.items():
        m.export(src / f"{name}.glb")  # any mesh format (OBJ: the bad-input test)
    out = tmp / "maps"
    args = ["bake-states", str(CESIUM), "--neutral", str(src / "neutral.glb")]
    for name in (*STATES, "same"):
        args += ["--state", f"{name}={src / ('neutral' if name == 'same' else name)}.glb"]
    args += ["--size", "128", "--masks", "-o", str(out)]
    assert main(args) == 0
    return out, args


@shared
@pytest.mark.shared
def test_cli_writes_16_bit_maps_and_an_undisplaced_state_equals_the_base(baked_folder, tmp_path):
    out, args = baked_folder
    files = sorted(p.name for p in out.iterdir())
    assert files == [
        "bake.json",
        "base_normal.png",
        "mask_compress.png",
        "mask_same.png",
        "mask_stretch.png",
        "wrinkle_compress.png",
        "wrinkle_same.png",
        "wrinkle_stretch.png",
    ]
    img, info = read_image(out / "base_normal.png")
    assert (info.channels, info.format, info.width) == (3, "uint16", 128)
    # decoded, the map holds unit normals (OpenGL +Y, 0.5 + 0.5 n)
    n = img * 2.0 - 1.0
    assert np.abs(np.linalg.norm(n, axis=-1) - 1.0).max() < 1e-3
    # the same sculpt as a state: the same frame and samples, so the same bytes (0 error)
    assert (out / "wrinkle_same.png").read_bytes() == (out / "base_normal.png").read_bytes()
    same_mask, _ = read_image(out / "mask_same.png")
    assert same_mask.max() == 0.0
    for state in STATES:
        mask, _ = read_image(out / f"mask_{state}.png")
        assert mask.max() == 1.0
    report = json.loads((out / "bake.json").read_text())
    assert [m["missed_samples"] for m in report["maps"]] == [0, 0, 0, 0]
    # a rerun gives the same bytes
    again = tmp_path / "again"
    assert main([*args[:-1], str(again)]) == 0
    for f in files:
        assert (out / f).read_bytes() == (again / f).read_bytes(), f


@shared
@pytest.mark.shared
def test_baked_maps_convert_within_the_fidelity_budget(baked_folder, tmp_path):
    out, _ = baked_folder
    manifest = out.parent / "manifest.toml"
    lines = [
        'name = "cesium_sculpted"',
        f"mesh = {json.dumps(str(CESIUM))}",
        'base = "maps/base_normal.png"',
        "[budget]",
        "max_mean_deg = 0.5",
        "max_p99_deg = 2.0",
    ]
    for state in STATES:
        lines += ["[[states]]", f'name = "{state}"', f'map = "maps/wrinkle_{state}.png"']
    for state in STATES:
        lines += ["[[regions]]", f'name = "{state}_area"', f'mask = "maps/mask_{state}.png"']
        lines += [f'states = ["{state}"]']
    lines += [
        "[expressions]",
        "frown = { compress_area = 1.0 }",
        "surprise = { stretch_area = 1.0 }",
    ]
    manifest.write_text("\n".join(lines) + "\n")
    build = tmp_path / "build"
    args = ["convert", str(manifest), "-o", str(build), "--no-render", "--no-compress"]
    assert main([*args, "--allow-root", str(CESIUM.parent)]) == 0
    report = json.loads((build / "report.json").read_text())
    assert report["validation"]["counts"]["error"] == 0
    fid = [i for i in report["validation"]["issues"] if i["code"].startswith("WP-FID")]
    assert not [i for i in fid if i["severity"] == "error"], fid
    poses = report["fidelity"]["png"]["poses"]
    assert {p["pose"] for p in poses} >= {"frown", "surprise"}
    for p in poses:
        assert p["p99_deg"] <= 2.0 and p["mean_deg"] <= 0.5, p


def test_masks_proposed_where_the_state_differs():
    base = np.zeros((32, 32, 3))
    base[..., 2] = 1.0
    state = base.copy()
    state[10:14, 5:20] = [np.sin(0.2), 0.0, np.cos(0.2)]  # 11.5 degrees: above 'high'
    cov = np.ones((32, 32), bool)
    m = propose_masks(base, state[None], cov)[0]
    assert m[11, 10] == pytest.approx(1.0) and m[30, 30] == 0.0


def test_bad_inputs_exit_2_with_one_line(tmp_path, capsys):
    low = tmp_path / "low.obj"
    low.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n")
    far = tmp_path / "far.obj"
    far.write_text("v 0 0 9\nv 1 0 9\nv 0 1 9\nf 1 2 3\n")
    cases = [
        (["--neutral", str(tmp_path / "none.obj"), "--state", f"a={far}"], "not found"),
        (["--neutral", str(far), "--state", "bad name=" + str(far)], "letters, digits"),
        (["--neutral", str(far), "--state", f"a={far}", "--state", f"a={far}"], "twice"),
        (["--neutral", str(far), "--state", "nosculpt"], "NAME=SCULPT"),
        (["--neutral", str(far), "--state", f"a={far}", "--max-distance", "0.1"], "no surface"),
    ]
    for extra, words in cases:
        out = tmp_path / "out"
        code = main(["bake-states", str(low), *extra, "--size", "16", "-o", str(out)])
        assert code == 2
        msg = capsys.readouterr().err
        assert words in msg, msg
        assert not out.exists()


def test_bake_bench_quick_runs():
    from wrinklepipe.bench import load_all

    res = load_all()["bake-states"][1](True)
    assert {r.step for r in res.rows} == {"rays alone (Embree)", "bake 1 state"}
    assert res.extra["missed_samples"] == 0 and res.extra["samples"] > 0
    assert all(r.median_s > 0 for r in res.rows)


def test_tiles_bake_what_the_whole_map_bakes(monkeypatch):
    import wrinklepipe.geometry.bake as bake_module

    low = _low_sphere()
    hi = trimesh.creation.icosphere(subdivisions=4)
    high = [HighMesh(hi.vertices * 1.01, hi.faces)]
    opts = BakeOptions(size=48, max_distance=0.05)
    whole = bake_normal_maps(low, high, opts)
    monkeypatch.setattr(bake_module, "TILE", 20)  # 3 x 3 tiles, the last ones partial
    tiled = bake_normal_maps(low, high, opts)
    assert tiled.samples == whole.samples
    np.testing.assert_allclose(tiled.maps[0], whole.maps[0], atol=1e-6)
    assert (tiled.covered == whole.covered).all()
