"""UDIM on a head made from a shared sample: CesiumMan (Khronos glTF sample, ``../shared/data``)
written as a USD mesh whose face's +u half is moved to tile 1002, the face fixture's analytic
maps and masks split over the two tiles (tests/udim_setups.py ``write_cesium_udim``), converted
with every choice on auto.

Expectations are independent of the code under test: the triangles on each tile are read from
the source USD by pxr; each tile's shipped maps, decoded and blended by the PD model, are
compared with the fixture's exact wrinkled normal (analytic slopes, no pipeline code); USD's
own validators and UDIM resolver, and the Khronos glTF validator, judge the outputs."""

from __future__ import annotations

import json

import numpy as np
import pytest
from udim_setups import CESIUM, write_cesium_udim

from wrinklepipe import model, udim
from wrinklepipe.io import khronos
from wrinklepipe.io.confine import allowed_roots
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.pipeline.package import asset_from_package
from wrinklepipe.sources.package import read_package

pxr = pytest.importorskip("pxr")
from pxr import Sdf, Usd, UsdGeom, UsdShade  # noqa: E402

pytestmark = pytest.mark.skipif(not CESIUM.is_file(), reason="../shared/data is absent")

SIZE = 256
TILES = (1001, 1002)
#: The fixture's budget (wrinklepipe.demo.face_fixture.BUDGET): PNG, and the shipped copies.
PNG = (0.5, 1.0)
COMPRESSED = (1.0, 2.5)


@pytest.fixture(scope="module")
def head(tmp_path_factory):
    root = tmp_path_factory.mktemp("udim_cesium")
    manifest, info = write_cesium_udim(root / "src", SIZE)
    res = convert(manifest, root / "out", ConvertOptions(render=False))
    return root / "src", root / "out", res, info


def _angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Degrees between the rows of ``a`` and ``b`` (float64, each normalised here)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    a /= np.linalg.norm(a, axis=-1, keepdims=True)
    b /= np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.sum(a * b, -1), -1.0, 1.0)))


def test_the_source_has_two_tiles_read_by_pxr(head):
    src, _, _, info = head
    stage = Usd.Stage.Open(str(src / "head.usda"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Head/Mesh"))
    st = np.asarray(UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st").Get(), np.float64).reshape(-1, 3, 2)
    col = np.floor(st[..., 0])
    assert (col == col[:, :1]).all() and (st[..., 1] >= 0).all() and (st[..., 1] <= 1).all()
    on_1002 = col[:, 0] == 1
    assert on_1002.sum() == info["moved"].sum() == 256  # the face's +u half of 572 triangles
    assert len(on_1002) == 4672


def test_convert_exits_0_with_every_choice_on_auto(head):
    _, out, res, _ = head
    assert res.exit_code == 0, res.report["validation"]["issues"]
    assert res.report["udim"] == {"tiles": list(TILES)}
    for stem in ("base_normal", "wrinkle_stretch", "wrinkle_compress", "mask_0", "mask_1"):
        for t in TILES:
            assert (out / "textures" / f"{stem}.{t}.png").is_file()


def test_each_tile_matches_the_exact_wrinkles_within_budget(head):
    """Per tile and expression, the shipped maps (read back from the USD, decoded, blended
    by the PD model with the shipped masks) against the fixture's exact normal under the
    same expression with that tile's masks: mean and p99 within the PNG budget."""
    src, out, _, info = head
    fx, keep = info["fixture"], info["keep"]
    with allowed_roots([src]):
        pkg = read_package(out / "cesium_face.usda")
    assert pkg.tiles == TILES
    worst = {t: (0.0, 0.0) for t in TILES}
    texels = {}
    for t in TILES:
        shipped = asset_from_package(udim.tile_package(pkg, t))
        pb = model.normal_to_pd(shipped.base)
        deltas = model.normal_to_pd(shipped.states) - pb[None]
        for e in sorted(fx.expressions):
            w = fx.asset().expression_weights({e: 1.0})
            act = model.activations(fx.masks * keep[t][None], w, "clamp01")
            truth = model.pd_to_normal(
                fx.base_slopes + np.einsum("k...,k...c->...c", act, fx.wrinkle_slopes)
            )
            got_act = model.activations(
                shipped.masks, shipped.expression_weights({e: 1.0}), shipped.policy
            )
            got = model.pd_to_normal(pb + np.einsum("k...,k...c->...c", got_act, deltas))
            sel = act.max(axis=0) > 0
            texels[t, e] = int(sel.sum())
            if not sel.any():
                continue
            ang = _angles(got[sel], truth[sel])
            mean, p99 = float(ang.mean()), float(np.percentile(ang, 99))
            assert mean <= PNG[0] and p99 <= PNG[1], (t, e, mean, p99)
            worst[t] = (max(worst[t][0], mean), max(worst[t][1], p99))
    # the masks are split: crow_L (wink_L) is painted on 1002 only, the others on both
    assert texels[1001, "wink_L"] == 0 and texels[1002, "wink_L"] > 200
    assert all(texels[t, e] > 50 for t in TILES for e in fx.expressions if e != "wink_L")
    assert all(0.0 < p99 for _, p99 in worst.values())


def test_the_validator_measures_each_tile_and_the_face_within_budget(head):
    _, _, res, _ = head
    v = res.report["validation"]
    assert v["counts"]["error"] == 0
    rows = v["fidelity"]
    poses = sorted(res.report["fidelity"]["tiles"]["1001"]["png"]["poses"], key=str)
    names = [p["pose"] for p in poses]
    for who in ("1001", "1002", "face"):
        for pose in names:
            row = rows[f"{who} {pose}"]
            assert row["mean_deg"] <= COMPRESSED[0] and row["p99_deg"] <= COMPRESSED[1], row
    for pose in names:
        both = rows[f"1001 {pose}"]["texels"] + rows[f"1002 {pose}"]["texels"]
        assert rows[f"face {pose}"]["texels"] == both
    for t in TILES:
        png = res.report["fidelity"]["tiles"][str(t)]["png"]["poses"]
        assert all(p["mean_deg"] <= PNG[0] and p["p99_deg"] <= PNG[1] for p in png), png


def test_usd_validation_has_0_errors_on_every_tile(head):
    """UsdValidation on the USD outputs: the one error is the normal-map validator's
    InvalidFile for the base's ``<UDIM>`` path (a UsdStage resolves no ``<UDIM>``: renderers
    resolve tiles through UsdShade's UDIM utilities); with the path set to each tile's file
    (a session-layer opinion), every validator finds 0 errors."""
    from usd_checks import validation_errors

    _, out, _, _ = head
    for name in ("cesium_face.usda", "cesium_face.usdz"):
        stage = Usd.Stage.Open(str(out / name))
        found = [(e.GetIdentifier(), e.GetMessage()) for e in validation_errors(stage)]
        assert len(found) == 1, found
        assert found[0][0] == "usdShadeValidators:NormalMapTextureValidator.InvalidFile"
        assert "base_normal.<UDIM>.png" in found[0][1]
        shader = UsdShade.Shader(stage.GetPrimAtPath("/Head/Looks/Skin/base_normal"))
        path = shader.GetInput("file").Get().path
        resolved = UsdShade.UdimUtils.ResolveUdimTilePaths(path, stage.GetRootLayer())
        assert [int(t) for _, t in resolved] == list(TILES) and all(p for p, _ in resolved)
        for t in TILES:
            with Usd.EditContext(stage, stage.GetSessionLayer()):
                shader.GetInput("file").Set(Sdf.AssetPath(udim.pattern_path(path, t)))
            assert validation_errors(stage) == [], (name, t)


def test_the_gltf_has_one_primitive_and_material_per_tile(head):
    """As docs/scale.md says: one primitive and material per tile, UVs in [0, 1], the tile
    in the extension block; the glTF reader gives the UDIM layout back."""
    src, out, _, info = head
    doc = json.loads((out / "cesium_face.gltf").read_text())
    mats = doc["materials"]
    assert [m["extensions"]["WRINKLEPIPE_wrinkle_maps"]["tile"] for m in mats] == list(TILES)
    prims = doc["meshes"][0]["primitives"]
    assert [p["material"] for p in prims] == [0, 1]
    counts = [doc["accessors"][p["indices"]]["count"] // 3 for p in prims]
    moved = int(info["moved"].sum())
    assert counts == [4672 - moved, moved]
    blob = (out / doc["buffers"][0]["uri"]).read_bytes()
    for p in prims:  # every primitive's UVs in [0, 1], read from the buffer by hand
        acc = doc["accessors"][p["attributes"]["TEXCOORD_0"]]
        view = doc["bufferViews"][acc["bufferView"]]
        assert acc["componentType"] == 5126 and acc["type"] == "VEC2"
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        stride = (view.get("byteStride", 8), 4)
        uv = np.ndarray((acc["count"], 2), "<f4", buffer=blob, offset=start, strides=stride)
        assert uv.min() >= 0.0 and uv.max() <= 1.0
    with allowed_roots([src]):
        pkg = read_package(out / "cesium_face.gltf")
    assert pkg.tiles == TILES
    tiles = udim.triangle_tiles(pkg.mesh.uvs, pkg.mesh.indices)
    assert (tiles == 1002).sum() == moved
    if khronos.available():
        report = khronos.validate_gltf(out / "cesium_face.gltf")
        assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]
