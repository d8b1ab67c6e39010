"""Rule building blocks against hand-computed values and analytic fields."""

from __future__ import annotations

import json
import re
import struct
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.asset import Mesh
from wrinklepipe.demo import demo_asset
from wrinklepipe.errors import InputError
from wrinklepipe.model import height_to_normal, normal_to_pd
from wrinklepipe.sources.validation import check_gltf_claims_wrinkles
from wrinklepipe.validate import textures as tx
from wrinklepipe.validate.catalogue import RULES, make_issue
from wrinklepipe.validate.config import parse_config
from wrinklepipe.validate.context import Context, position_groups
from wrinklepipe.validate.inputs import Texture
from wrinklepipe.validate.issues_table import issues_markdown
from wrinklepipe.validate.renderer import triangle_layer_touch
from wrinklepipe.validate.report import normalized
from wrinklepipe.validate.rules_maps import convention_score
from wrinklepipe.validate.rules_masks import check_masks, side_centroids, stored_step
from wrinklepipe.validate.rules_weights import group_spread
from wrinklepipe.validate.ship import ShipOptions, ship_asset

ROOT = Path(__file__).resolve().parents[1]


# --- catalogue ----------------------------------------------------------------------------------


def test_codes_are_unique_and_well_formed():
    codes = [r.code for r in RULES]
    assert len(codes) == len(set(codes))
    for r in RULES:
        assert re.fullmatch(r"WP-(LOAD|MAP|MASK|WGT|MESH|TEX|RND|FID|COL|USD)-\d{3}", r.code)
        assert r.severity in ("error", "warning", "info")
        assert r.title and r.description


def test_issues_md_is_generated_from_the_catalogue():
    assert (ROOT / "docs" / "ISSUES.md").read_text() == issues_markdown()


def test_make_issue_takes_severity_and_fix_from_the_catalogue():
    i = make_issue("WP-MAP-003", "m", "f#p")
    assert i.severity == "error" and "Flip the green channel" in i.fix


# --- textures -----------------------------------------------------------------------------------


def test_bilinear_matches_gl_linear_clamp_to_edge_by_hand():
    img = np.array([[[0.0], [1.0]], [[2.0], [3.0]]], np.float32)  # 2 x 2
    uv = np.array([[0.25, 0.25], [0.5, 0.5], [0.75, 0.25], [0.0, 0.0], [1.0, 1.0], [0.5, 0.25]])
    got = tx.bilinear(img, uv)[:, 0]
    assert got == pytest.approx([0.0, 1.5, 1.0, 0.0, 3.0, 0.5])


def test_decode_rgba8_and_unorm16_and_bc5_constant_block():
    t = Texture("t", "base", "rgba8", 1, 1, bytes([0, 255, 128, 255]))
    assert tx.decode_values(t)[0, 0] == pytest.approx([0.0, 1.0, 128 / 255, 1.0])
    t16 = Texture("t", "base", "rg16", 1, 1, struct.pack("<HH", 0, 65535))
    assert tx.decode_values(t16)[0, 0] == pytest.approx([0.0, 1.0])
    import etcpak

    rgba = np.zeros((4, 4, 4), np.uint8)
    rgba[..., 0], rgba[..., 1] = 200, 17
    bc5 = Texture("t", "base", "bc5", 4, 4, etcpak.compress_bc5(rgba.tobytes(), 4, 4))
    v = tx.decode_values(bc5)
    assert v.shape == (4, 4, 2)
    assert np.allclose(v[..., 0], 200 / 255) and np.allclose(v[..., 1], 17 / 255)
    with pytest.raises(ValueError, match="needs 16 bytes"):
        tx.decode_values(Texture("t", "base", "bc5", 4, 4, b"\0" * 8))


def test_two_channel_normals_rebuild_z():
    v = np.array([[0.5 + 0.5 * 0.6, 0.5, 0.0, 0.0]], np.float32)  # x = 0.6, y = 0
    n = tx.values_to_normals(v, "rg")[0]
    assert n == pytest.approx([0.6, 0.0, 0.8], abs=1e-6)
    ag = np.array([[1.0, 0.5, 0.0, 0.5 + 0.5 * 0.6]], np.float32)  # DXT5nm: x in alpha
    assert tx.values_to_normals(ag, "ag")[0] == pytest.approx([0.6, 0.0, 0.8], abs=1e-6)


def test_srgb_decode_matches_the_standard_curve():
    assert tx.srgb_to_linear(np.array([0.0, 0.04045, 0.5, 1.0])) == pytest.approx(
        [0.0, 0.04045 / 12.92, 0.21404114, 1.0], rel=1e-5
    )


# --- green convention ---------------------------------------------------------------------------


def _bumps(seed: int, n: int = 64) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:n, 0:n] / n
    h = np.zeros((n, n))
    for _ in range(6):
        a, b, c, d = rng.uniform(1, 6, 4)
        h += rng.uniform(1, 3) * np.sin(2 * np.pi * (a * x + c)) * np.sin(2 * np.pi * (b * y + d))
    return h


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000))
def test_curl_score_tells_opengl_from_directx(seed):
    n = height_to_normal(_bumps(seed))
    s = normal_to_pd(n)
    assert convention_score(s) > 0.9
    flipped = s * np.array([1.0, -1.0], np.float32)
    assert convention_score(flipped) < -0.9


def test_curl_score_is_zero_on_a_flat_map():
    assert convention_score(np.zeros((16, 16, 2))) == 0.0


# --- mesh ---------------------------------------------------------------------------------------


def _quad(flip_u: bool = False) -> Mesh:
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)  # glTF: v = 0 at the top
    if flip_u:
        uv[:, 0] = 1 - uv[:, 0]
    nrm = np.tile([0.0, 0.0, 1.0], (4, 1)).astype(np.float32)
    return Mesh(pos, np.array([[0, 1, 2], [0, 2, 3]], np.uint32), uv, nrm)


def _mikk(mesh: Mesh) -> np.ndarray:
    from wrinklepipe.geometry.tangents import mikktspace_tangents

    return mikktspace_tangents(mesh.positions, mesh.normals, mesh.uvs, mesh.indices)


def test_reference_tangents_of_a_quad_by_hand():
    t = _mikk(_quad())
    assert t == pytest.approx(np.tile([1.0, 0.0, 0.0, 1.0], (4, 1)), abs=1e-6)
    m = _mikk(_quad(flip_u=True))  # mirrored UVs: tangent along -X, bitangent still +Y
    assert m == pytest.approx(np.tile([-1.0, 0.0, 0.0, -1.0], (4, 1)), abs=1e-6)


def test_position_groups_and_spread_by_hand():
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 0], [1, 0, 0], [2, 0, 0]], np.float32)
    g = position_groups(pos)
    assert g[0] == g[2] and g[1] == g[3] and len(set(g.tolist())) == 3
    vals = np.array([1.0, 5.0, 1.5, 5.0, 9.0])
    assert group_spread(g, vals[:, None]) == pytest.approx([0.5, 0.0, 0.5, 0.0, 0.0])


def _overlap_issues(levels: list[tuple[float, float, float]]) -> list[str]:
    """WP-MASK-002 messages of an additive asset whose masks forehead_inner_l, forehead_inner_r
    and glabella hold ``levels`` (of 255) at texels (0, 0), (0, 1), ...; every other mask zero."""
    a = demo_asset(16, policy="additive", mesh_resolution=(12, 8))
    m = np.zeros_like(a.masks)
    for x, lv in enumerate(levels):
        m[[2, 3, 6], 0, x] = np.asarray(lv, np.float32) / np.float32(255.0)
    b = replace(a, masks=m)
    ctx = Context(ship_asset(b, ShipOptions(compress=False)))
    return [i.message for i in check_masks(ctx) if i.code == "WP-MASK-002"]


def test_additive_masks_from_8bit_files_may_round_up_where_they_overlap():
    # the studio's 'di' variant at 512: three 8-bit masks meet as 28 + 153 + 75 = 256 levels,
    # a partition of 1 rounded to 8 bits (each mask up to half a level over): not an overlap
    assert stored_step(np.array([28, 153, 75], np.float32) / np.float32(255)) == 1 / 255
    assert stored_step(np.array([28.3, 153, 75], np.float32) / np.float32(255)) == 0.0
    assert _overlap_issues([(28, 153, 75), (100, 100, 55)]) == []
    # 6 levels over with three masks is more than rounding can do: one texel reported
    got = _overlap_issues([(28, 153, 75), (28, 153, 80)])
    assert len(got) == 1 and "source masks sum above 1 at 1 texels" in got[0], got
    # the same 256 levels as float values off the 8-bit grid have no rounding to excuse them
    got = _overlap_issues([(28.25, 153, 75), (100, 100, 55)])
    assert len(got) == 1 and "source masks sum above 1 at 1 texels" in got[0], got


def test_side_centroids_put_a_right_half_mask_on_the_left():
    masks = np.zeros((2, 8, 8), np.float32)
    masks[0, :, 5:] = 1.0  # u > 0.5: the character's left
    masks[1, :, :3] = 1.0
    cent, centre, unit = side_centroids(masks, None)
    assert unit == "u"
    assert centre == pytest.approx(0.5)
    assert cent[0] == pytest.approx(6.5 / 8) and cent[1] == pytest.approx(1.5 / 8)


# --- render helpers -----------------------------------------------------------------------------


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 10_000))
def test_triangle_layer_touch_equals_brute_force(seed):
    rng = np.random.default_rng(seed)
    h = w = 16
    mask = (rng.random((h, w, 4)) > 0.97).astype(np.uint8) * 255
    layer = Texture("m", "mask", "rgba8", w, h, mask.tobytes())
    uv = rng.random((30, 2)).astype(np.float32)
    tris = rng.integers(0, 30, (40, 3)).astype(np.uint32)
    mesh = Mesh(np.zeros((30, 3), np.float32), tris, uv)
    got = triangle_layer_touch([layer], mesh)[:, 0]
    # brute force: sample densely inside each triangle's UV box with bilinear taps
    nz = mask.max(axis=-1) > 0
    for t, tri in enumerate(tris):
        lo, hi = uv[tri].min(0), uv[tri].max(0)
        uu, vv = np.meshgrid(np.linspace(lo[0], hi[0], 40), np.linspace(lo[1], hi[1], 40))
        x = uu.ravel() * w - 0.5
        y = vv.ravel() * h - 0.5
        xs = np.clip(np.stack([np.floor(x), np.floor(x) + 1]), 0, w - 1).astype(int)
        ys = np.clip(np.stack([np.floor(y), np.floor(y) + 1]), 0, h - 1).astype(int)
        touched = any(nz[ys[a], xs[b]].any() for a in (0, 1) for b in (0, 1))
        if touched:
            assert got[t]  # conservative: never misses a texel a sample can reach


# --- config, loader, report ---------------------------------------------------------------------


def test_config_accepts_both_key_styles_and_rejects_unknown_codes():
    c = parse_config({"validate": {"ignore": ["WP-TEX-007"], "severity": {"WP-MAP-001": "info"}}})
    assert c.ignore == {"WP-TEX-007"} and c.severity == {"WP-MAP-001": "info"}
    k = parse_config(
        {"ignoredIssues": ["WP-TEX-006"], "severityOverrides": {"WP-TEX-007": 3, "WP-MAP-001": 1}}
    )
    assert k.ignore == {"WP-TEX-006", "WP-TEX-007"} and k.severity == {"WP-MAP-001": "warning"}
    with pytest.raises(InputError, match="WP-XXX-001"):
        parse_config({"ignore": ["WP-XXX-001"]})
    with pytest.raises(InputError, match="unknown option"):
        parse_config({"options": {"speed": 3}})


def test_run_options_lay_the_command_line_over_the_config():
    c = parse_config({"ignore": ["WP-TEX-007"], "options": {"render_size": 96, "grid": 32}})
    options, rest = c.run_options()
    assert (options.render, options.render_size, options.grid) == (True, 96, 32)
    assert rest.ignore == {"WP-TEX-007"} and rest.options == {}  # applied: not applied twice
    options, _ = c.run_options(render=False, render_size=200)
    assert (options.render, options.render_size, options.grid) == (False, 200, 32)


def _glb(doc: dict) -> bytes:
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    return (
        struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(js))
        + struct.pack("<II", len(js), 0x4E4F534A)
        + js
    )


def test_glb_must_claim_the_extension(tmp_path):
    ok = tmp_path / "ok.glb"
    ok.write_bytes(
        _glb({"asset": {"version": "2.0"}, "extensionsUsed": ["WRINKLEPIPE_wrinkle_maps"]})
    )
    check_gltf_claims_wrinkles(ok)
    no = tmp_path / "no.glb"
    no.write_bytes(_glb({"asset": {"version": "2.0"}}))
    with pytest.raises(InputError, match="carries no wrinkle data"):
        check_gltf_claims_wrinkles(no)
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"glTF" + b"\2\0\0\0" + b"\xff" * 4)
    with pytest.raises(InputError, match="truncated"):
        check_gltf_claims_wrinkles(bad)


def test_normalized_report_hides_gpu_numbers():
    doc = {
        "tool": {"name": "x", "version": "1"},
        "input": {"path": "/a/b.wpv", "textures": [{"name": "t", "pointer": "/a/b"}]},
        "issues": [
            {"code": "WP-RND-001", "message": "worst mean 0.61, p99 2.5", "pointer": "/a/b.wpv"},
            {"code": "WP-MAP-003", "message": "score -0.987", "pointer": "/x/b.wpv#/textures/t"},
        ],
        "timings": {"maps": 1.0},
        "render": {},
        "metrics": {},
    }
    n = normalized(doc)
    assert n["issues"][0]["message"] == "worst mean #, p99 #"
    assert n["issues"][1]["message"] == "score -1.0"
    assert n["issues"][1]["pointer"] == "b.wpv#/textures/t"
    assert "timings" not in n and "path" not in n["input"]


def test_dynamic_weights_are_continuous_with_good_ids_and_jump_with_broken_ones():
    import sys

    sys.path.insert(0, str(ROOT / "tests" / "corpus"))
    import generate

    from wrinklepipe.geometry.vertex_ids import compute_vertex_ids
    from wrinklepipe.validate.rules_weights import dynamic_weights

    broken = generate.c_dynamic_seam().asset.mesh
    good = broken.__class__(
        **{**broken.__dict__, "vertex_ids": compute_vertex_ids(broken.positions)}
    )
    groups = position_groups(good.positions)
    w_good = dynamic_weights(good)["dynamic:back_squash"]
    w_bad = dynamic_weights(broken)["dynamic:back_squash"]
    assert np.abs(w_good).max() > 0.5  # the morph does wrinkle the back of the head
    assert group_spread(groups, w_good[:, None]).max() < 1e-5
    assert group_spread(groups, w_bad[:, None]).max() > 0.1


SAMPLE = ROOT.parent / "shared" / "data" / "gltf-samples" / "NormalTangentMirrorTest"


@pytest.mark.shared
@pytest.mark.skipif(not SAMPLE.is_dir(), reason="../shared/data is absent")
def test_exported_mikktspace_tangents_pass_and_rotated_ones_fail():
    from dataclasses import replace

    from wrinklepipe.asset import WrinkleAsset
    from wrinklepipe.readers.meshes import load_mesh
    from wrinklepipe.validate.context import Context
    from wrinklepipe.validate.inputs import ValidationInput
    from wrinklepipe.validate.rules_mesh import check_mesh

    mesh = load_mesh(SAMPLE / "glTF" / "NormalTangentMirrorTest.gltf")
    assert mesh.tangents is not None and (mesh.tangents[:, 3] < 0).any()  # mirrored UVs

    def codes(m: Mesh) -> list[str]:
        a = WrinkleAsset(
            "t",
            np.zeros((4, 4, 3), np.float32),
            np.zeros((0, 4, 4, 3)),
            (),
            np.zeros((0, 4, 4)),
            (),
            mesh=m,
        )
        return [i.code for i in check_mesh(Context(ValidationInput(a)))]

    assert codes(mesh) == []
    t = mesh.tangents.astype(np.float64).copy()
    n = mesh.normals.astype(np.float64)
    b = np.cross(n, t[:, :3])
    ang = np.radians(20.0)  # rotate every tangent 20 degrees about its normal
    t[:, :3] = np.cos(ang) * t[:, :3] + np.sin(ang) * b
    assert codes(replace(mesh, tangents=t.astype(np.float32))) == ["WP-MESH-002"]
    flipped = mesh.tangents.copy()
    flipped[:, 3] *= -1
    assert codes(replace(mesh, tangents=flipped)) == ["WP-MESH-002"]


def test_bundle_round_trip_and_inheritance(tmp_path):
    from wrinklepipe.demo import demo_asset
    from wrinklepipe.validate.loader import bundle_arrays, bundle_bytes, read_bundle
    from wrinklepipe.validate.ship import ShipOptions, ship_asset

    inp = ship_asset(demo_asset(32), ShipOptions(compress=True))
    inp.vertex_weights = {"bias": np.arange(inp.asset.mesh.vertex_count, dtype=np.float32)}
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "x.wpv").write_bytes(bundle_bytes(inp))
    assert bundle_bytes(inp) == bundle_bytes(inp)  # deterministic (fixed zip dates)
    back = read_bundle(tmp_path / "a" / "x.wpv")
    assert [t.data for t in back.textures] == [t.data for t in inp.textures]
    assert [(t.fmt, t.layout, t.state) for t in back.textures] == [
        (t.fmt, t.layout, t.state) for t in inp.textures
    ]
    assert np.array_equal(back.asset.mesh.tangents, inp.asset.mesh.tangents)
    assert back.channel_table == inp.channel_table and back.has_source
    # a bundle that stores only what differs from another one
    inp.asset.expressions = {"joy": {"chin": 0.5}}
    inp.textures[0].srgb = True
    (tmp_path / "b").mkdir()
    small = bundle_bytes(inp, "../a/x.wpv", bundle_arrays(read_bundle(tmp_path / "a" / "x.wpv")))
    (tmp_path / "b" / "y.wpv").write_bytes(small)
    assert len(small) < 0.1 * len(bundle_bytes(inp))
    y = read_bundle(tmp_path / "b" / "y.wpv")
    assert y.textures[0].srgb and y.asset.expressions == {"joy": {"chin": 0.5}}
    assert np.array_equal(y.asset.base, inp.asset.base)
    (tmp_path / "a" / "x.wpv").unlink()
    with pytest.raises(InputError, match="inherits"):
        read_bundle(tmp_path / "b" / "y.wpv")
