"""Regions from blend shapes: masks where the skin compresses or stretches, rows, a manifest.

Independent expectations: the per-vertex area change of each target computed with trimesh
(face areas of the rest and target meshes, Oat's clamp, averaged over the welded vertex's
faces by area), sampled against the masks at the vertex UVs; hand-computed texels of a linear
field; a mirror-symmetric point set with a known plane; the snippet through ``convert`` and its
validator.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from wrinklepipe.asset import Mesh
from wrinklepipe.cli import main
from wrinklepipe.geometry.dynamic import sample_bilinear
from wrinklepipe.geometry.rasterise import rasterise_triangle_ids
from wrinklepipe.geometry.symmetry import symmetry_plane
from wrinklepipe.geometry.uv_samples import (
    blur_covered,
    interpolate,
    pad_islands,
    render_sparse,
    resolve,
    uv_samples,
)
from wrinklepipe.io.images import write_image
from wrinklepipe.masks import read_packed, unpack
from wrinklepipe.masks.targets import TargetRegionsOptions, regions_from_targets
from wrinklepipe.pipeline.character import CharacterSource, read_character
from wrinklepipe.presets.facs import action_unit
from wrinklepipe.presets.targets import describe, mirror_name

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "gltf-samples"
ROBOT = DATA / "RobotExpressive" / "RobotExpressive.glb"
STRESS = DATA / "MorphStressTest" / "glTF-Binary" / "MorphStressTest.glb"
SPHERE = DATA / "AnimatedMorphSphere" / "glTF-Binary" / "AnimatedMorphSphere.glb"
shared = pytest.mark.skipif(not ROBOT.is_file(), reason="../shared/data is absent")


# ------------------------------------------------------------------------------------------------
# the texture-space stages


def _quad():
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], np.float64)
    return uv, np.array([[0, 1, 2], [0, 2, 3]])


def test_samples_interpolate_a_linear_field_exactly_at_texel_centres():
    uv, idx = _quad()
    values = 2.0 * uv[:, 0] - 3.0 * uv[:, 1] + 0.5  # linear: interpolation is exact
    s = uv_samples(uv, idx, 8, supersample=1)
    assert s.count == 64
    img, cover = resolve(s, interpolate(s, idx, values))
    c = (np.arange(8) + 0.5) / 8
    expect = 2.0 * c[None, :] - 3.0 * c[:, None] + 0.5  # row = v, column = u
    np.testing.assert_allclose(img[..., 0], expect, atol=1e-12)
    assert (cover == 1.0).all()


def test_supersampling_averages_a_texel_and_keeps_half_covered_texels_undarkened():
    # a triangle covering the lower-left half of a 2 x 2 map, value 1 everywhere
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    idx = np.array([[0, 1, 2]])
    s = uv_samples(uv, idx, 2, supersample=4)
    img, cover = resolve(s, np.ones(s.count))
    # texel (0, 0) fully inside; (0, 1) and (1, 0) cut by the diagonal u + v = 1; (1, 1) out
    assert cover[0, 0] == 1.0 and cover[1, 1] == 0.0
    # samples at (j + 0.5) / 8 per axis; on or below u + v = 1 in texel (0, 1): 10 of 16
    assert cover[0, 1] == pytest.approx(10 / 16) and cover[1, 0] == pytest.approx(10 / 16)
    assert img[0, 1, 0] == 1.0 and img[1, 1, 0] == 0.0


def test_padding_copies_the_nearest_island_texel_and_no_farther():
    img = np.zeros((1, 9, 1))
    img[0, 2, 0] = 5.0
    img[0, 3, 0] = 7.0
    cov = np.zeros((1, 9), bool)
    cov[0, 2:4] = True
    out = pad_islands(img, cov, 2, fill=-1.0)
    assert out[0, :, 0].tolist() == [5.0, 5.0, 5.0, 7.0, 7.0, 7.0, -1.0, -1.0, -1.0]


def test_blur_of_a_constant_island_is_that_constant():
    img = np.zeros((16, 16, 1))
    cov = np.zeros((16, 16))
    cov[4:12, 3:9] = 1.0
    img[cov > 0] = 0.7
    out = blur_covered(img, cov, 2.0)
    np.testing.assert_allclose(out[cov > 0, 0], 0.7, rtol=1e-12)
    assert (out[cov == 0] == 0).all()


def test_sparse_rendering_equals_the_whole_map_computation():
    rng = np.random.default_rng(4)
    # a fine grid of triangles: 12 x 12 quads
    n = 13
    g = np.linspace(0.05, 0.95, n)
    uu, vv = np.meshgrid(g, g)
    uv = np.column_stack([uu.ravel(), vv.ravel()])
    q = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    idx = np.concatenate(
        [np.column_stack([q, q + 1, q + n + 1]), np.column_stack([q, q + n + 1, q + n])]
    )
    values = np.zeros((3, len(uv)))
    values[0, rng.choice(len(uv), 3, replace=False)] = rng.random(3)
    values[1, :20] = rng.random(20)
    values[2] = rng.random(len(uv))  # everywhere
    s = uv_samples(uv, idx, 64, supersample=2)
    fast = render_sparse(s, idx, values, blur=1.5, padding=3)
    img, cover = resolve(s, interpolate(s, idx, values.T))
    whole = pad_islands(blur_covered(img, cover, 1.5), cover > 0, 3)
    np.testing.assert_allclose(fast, np.moveaxis(whole, -1, 0).astype(np.float32), atol=1e-6)


def test_symmetry_plane_of_a_mirrored_point_set():
    rng = np.random.default_rng(11)
    half = rng.normal(size=(300, 3)) * [0.3, 1.0, 0.5]
    half[:, 0] = np.abs(half[:, 0]) + 0.01
    normal = np.array([0.96, 0.2, -0.19])
    normal /= np.linalg.norm(normal)
    # build the set around the plane x = 0, then rotate x onto `normal` and shift by 0.3
    axis = np.cross([1.0, 0, 0], normal)
    angle = np.arccos(normal[0])
    rot = trimesh.transformations.rotation_matrix(angle, axis)[:3, :3]
    pts = np.concatenate([half, half * [-1, 1, 1]]) @ rot.T + 0.3 * normal
    plane = symmetry_plane(pts)
    assert plane.normal @ normal == pytest.approx(1.0, abs=1e-9)
    assert plane.offset == pytest.approx(0.3, abs=1e-9)
    assert plane.residual < 1e-9


# ------------------------------------------------------------------------------------------------
# names


@pytest.mark.parametrize(
    ("name", "area", "side", "twin"),
    [
        ("browDownLeft", "glabella", "left", "browDownRight"),
        ("browInnerUp", "forehead_inner", "center", "browInnerUp"),
        ("mouthSmileRight", "nasolabial", "right", "mouthSmileLeft"),
        ("AU12_L", "nasolabial", "left", "AU12_R"),
        ("au04", "glabella", "center", "au04"),
        ("inner_brow_raiser.R", "forehead_inner", "right", "inner_brow_raiser.L"),
        ("smile_L", None, "left", "smile_R"),
        ("Angry", None, "center", "Angry"),
    ],
)
def test_target_names_give_area_side_and_twin(name, area, side, twin):
    info = describe(name)
    assert (info.area, info.side) == (area, side)
    assert mirror_name(name) == twin


def test_facs_numbers_and_names():
    assert action_unit("AU1") == (1, "center")
    assert action_unit("AU_26") == (26, "center")
    assert action_unit("AU6R") == (6, "right")
    assert action_unit("LipCornerPuller_L") == (12, "left")
    assert action_unit("AU99") is None and action_unit("Angry") is None


# ------------------------------------------------------------------------------------------------
# the independent reference: trimesh


def oat_change_trimesh(mesh: Mesh, delta: np.ndarray) -> np.ndarray:
    """Per render vertex: the area-weighted mean over the welded vertex's faces of
    clamp((A_rest - A_target) / A_rest, -1, 1), faces from trimesh."""
    rest = trimesh.Trimesh(mesh.positions, mesh.indices, process=False)
    target = trimesh.Trimesh(mesh.positions + delta, mesh.indices, process=False)
    a0, a1 = rest.area_faces, target.area_faces
    change = np.clip(np.where(a0 > 0, (a0 - a1) / np.where(a0 > 0, a0, 1.0), 0.0), -1, 1)
    _, weld = np.unique(mesh.positions, axis=0, return_inverse=True)
    weld = weld.reshape(-1)
    num = np.zeros(weld.max() + 1)
    den = np.zeros(weld.max() + 1)
    for c in range(3):
        np.add.at(num, weld[mesh.indices[:, c]], change * a0)
        np.add.at(den, weld[mesh.indices[:, c]], a0)
    return (num / np.maximum(den, 1e-300))[weld]


def owned_vertices(mesh: Mesh, size: int) -> np.ndarray:
    """Vertices whose surface owns the texel under them: the point that texel shows (its
    owning triangle at the texel centre) lies within 1 % of the mesh's size of the vertex
    (overlapping UV islands, as a front projection makes, show one surface per texel)."""
    ids = rasterise_triangle_ids(mesh.uvs, mesh.indices, size)
    y = np.clip((mesh.uvs[:, 1] * size).astype(int), 0, size - 1)
    x = np.clip((mesh.uvs[:, 0] * size).astype(int), 0, size - 1)
    t = ids[y, x]
    ok = t >= 0
    tri_uv = mesh.uvs[mesh.indices[t[ok]]].astype(np.float64)
    centre = np.column_stack([x[ok] + 0.5, y[ok] + 0.5]) / size
    a, b, c = tri_uv[:, 0], tri_uv[:, 1], tri_uv[:, 2]
    m = np.stack([b - a, c - a], axis=-1)
    wb, wc = np.linalg.solve(m, (centre - a)[..., None])[..., 0].T
    tri_p = mesh.positions[mesh.indices[t[ok]]].astype(np.float64)
    shown = (
        (1 - wb - wc)[:, None] * tri_p[:, 0] + wb[:, None] * tri_p[:, 1] + wc[:, None] * tri_p[:, 2]
    )
    size3 = np.ptp(mesh.positions, axis=0).max()
    out = np.zeros(mesh.vertex_count, bool)
    out[ok] = np.linalg.norm(shown - mesh.positions[ok], axis=1) < 0.01 * size3
    return out


def signed_mask(res, target: str, uvs: np.ndarray) -> np.ndarray:
    out = np.zeros(len(uvs))
    for i, r in enumerate(res.regions):
        if r.name.rsplit("_", 1)[0] == target.replace(" ", "_"):
            v = sample_bilinear(res.masks[i], uvs)
            out += v if r.states == ("compress",) else -v
    return out


CASES = [  # (mesh, material, mask size, vertices far from every moved face, at least)
    (ROBOT, "Black", 256, 0),  # the face of a whole character: Angry, Surprised, Sad
    (STRESS, "TestMaterial", 1024, 1000),  # 8 targets on narrow UV islands with seams
    (SPHERE, None, 512, 0),  # no UVs: convert's front projection (islands overlap)
]


@shared
@pytest.mark.shared
@pytest.mark.parametrize(("path", "material", "size", "min_far"), CASES, ids=str)
def test_each_target_mask_follows_the_independent_area_change(path, material, size, min_far):
    mesh, _ = read_character(CharacterSource(path, material))
    res = regions_from_targets(mesh, TargetRegionsOptions(size=size))
    owned = owned_vertices(mesh, size)
    assert owned.mean() > 0.4
    for k, name in enumerate(mesh.morph_names):
        truth = oat_change_trimesh(mesh, mesh.morph_deltas[k].astype(np.float64))
        got = signed_mask(res, name, mesh.uvs)
        corr = np.corrcoef(got[owned], truth[owned])[0, 1]
        assert corr >= 0.9, (name, corr)
        # exactly zero where the target leaves every face around the vertex alone
        still = np.abs(truth) == 0
        far = still & owned & _far_from(mesh, ~still, 3)
        assert far.sum() >= min_far, (name, far.sum())
        assert np.abs(got[far]).max(initial=0.0) == 0.0, name


def _far_from(mesh: Mesh, moved: np.ndarray, rings: int) -> np.ndarray:
    """Vertices more than ``rings`` edge rings (over welded positions) from a moved vertex."""
    _, weld = np.unique(mesh.positions, axis=0, return_inverse=True)
    weld = weld.reshape(-1)
    near = np.zeros(weld.max() + 1, bool)
    near[weld[moved]] = True
    tri = weld[mesh.indices]
    for _ in range(rings):
        near[tri[near[tri].any(axis=1)].ravel()] = True
    return ~near[weld]


def _grid_face(n: int = 21) -> Mesh:
    """A mirror-symmetric patch (x in [-1, 1]) with UVs, mirrored bump targets and a centre one;
    the left (+x) half's UVs are mirrored into the right of the map, as face layouts are."""
    g = np.linspace(-1.0, 1.0, n)
    xx, yy = np.meshgrid(g, g)
    p = np.column_stack([xx.ravel(), yy.ravel(), 0.3 * np.cos(xx.ravel())]).astype(np.float32)
    uv = np.column_stack([(xx.ravel() + 1) / 2, (1 - yy.ravel()) / 2]).astype(np.float32)
    q = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    right = (q % n) < (n - 1) // 2  # quads left of x = 0 (the character's right)
    a = np.column_stack([q, q + 1, q + n + 1])  # diagonals mirrored across x = 0
    b = np.column_stack([q, q + n + 1, q + n])
    c = np.column_stack([q, q + 1, q + n])
    d = np.column_stack([q + 1, q + n + 1, q + n])
    idx = np.concatenate([np.where(right[:, None], a, c), np.where(right[:, None], b, d)])

    def bump(cx: float, cy: float) -> np.ndarray:
        r2 = (p[:, 0] - cx) ** 2 + (p[:, 1] - cy) ** 2
        d = np.zeros_like(p)
        d[:, 0] = -0.15 * (p[:, 0] - cx) * np.exp(-r2 / 0.05)  # pull in: compress
        d[:, 1] = -0.15 * (p[:, 1] - cy) * np.exp(-r2 / 0.05)
        return d

    deltas = np.stack([bump(0.5, 0.4), bump(-0.5, 0.4), bump(0.0, -0.5)]).astype(np.float32)
    return Mesh(
        p,
        idx.astype(np.uint32),
        uv,
        morph_names=("browDownLeft", "browDownRight", "mouthShrugLower"),
        morph_deltas=deltas,
        name="grid",
    )


def test_clustered_left_and_right_masks_mirror_each_other():
    mesh = _grid_face()
    # the chin target compresses the centre and stretches a ring around it: two groups
    res = regions_from_targets(mesh, TargetRegionsOptions(size=128, regions=4))
    names = [r.name for r in res.regions]
    sides = {r.name: r.side for r in res.regions}
    assert sides == {
        "chin_compress": "center",
        "chin_stretch": "center",
        "glabella_l": "left",
        "glabella_r": "right",
    }
    left = res.masks[names.index("glabella_l")]
    right = res.masks[names.index("glabella_r")]
    # the layout maps x -> u linearly, so the mirror is the flipped map
    np.testing.assert_allclose(left, right[:, ::-1], atol=2e-3)
    assert left[:, :60].max() == 0.0 and left.max() > 0.9
    # the rows rebuild each target from its own side's region
    rows = {(r[0], r[1]): r[4] for r in res.rows}
    assert 0.7 < rows[("browDownLeft", "glabella_l:compress")] < 1.3
    assert ("browDownLeft", "glabella_r:compress") not in rows
    # the chin target has regions of its own state by state; the brows share one region for
    # both states at N = 4, and rebuild better with more regions
    assert res.fit["mouthShrugLower"] < 0.05
    finer = regions_from_targets(mesh, TargetRegionsOptions(size=32, regions=8))
    assert finer.fit["browDownLeft"] < 0.5 * res.fit["browDownLeft"]


@shared
@pytest.mark.shared
def test_robot_clustered_pairs_mirror_at_mirror_vertices():
    mesh, _ = read_character(CharacterSource(ROBOT, "Black"))
    res = regions_from_targets(mesh, TargetRegionsOptions(size=512, regions=4))
    p = mesh.positions.astype(np.float64)
    mirrored = res.plane.reflect(p)
    dist, partner = cKDTree(p).query(mirrored)
    assert np.median(dist) < 1e-5 * np.ptp(p, axis=0).max()  # the plane is a true symmetry
    names = [r.name for r in res.regions]
    pairs = [(n, n[:-2] + "_r") for n in names if n.endswith("_l")]
    assert pairs
    owned = owned_vertices(mesh, 512) & (dist < 1e-4)
    for left, right in pairs:
        lv = sample_bilinear(res.masks[names.index(left)], mesh.uvs)
        rv = sample_bilinear(res.masks[names.index(right)], mesh.uvs)
        a, b = lv[owned], rv[partner[owned]]
        # sampled from the maps: the front projection of this tilted face is not a mirror
        # image in UV, so texels sample the two sides differently
        assert np.corrcoef(a, b)[0, 1] > 0.99 and np.abs(a - b).mean() < 0.01
        # per vertex, before rendering: mirror images
        vl = res.vertex_masks[names.index(left)]
        vr = res.vertex_masks[names.index(right)]
        near = dist < 1e-4
        np.testing.assert_allclose(vl[near], vr[partner[near]], atol=1e-6)


# ------------------------------------------------------------------------------------------------
# the command


def _maps(folder: Path, size: int = 64) -> Path:
    """A flat base and two states with ridges: what a bake-states folder holds."""
    folder.mkdir(parents=True, exist_ok=True)
    c = (np.arange(size) + 0.5) / size
    n = np.zeros((size, size, 3))
    n[..., 2] = 1.0
    write_image(folder / "base_normal.png", 0.5 + 0.5 * n, 16)
    for name, freq in (("compress", 9.0), ("stretch", 5.0)):
        s = n.copy()
        s[..., 1] = 0.3 * np.sin(2 * np.pi * freq * c)[:, None]
        s /= np.linalg.norm(s, axis=-1, keepdims=True)
        write_image(folder / f"wrinkle_{name}.png", 0.5 + 0.5 * s, 16)
    return folder


@shared
@pytest.mark.shared
def test_snippet_converts_and_validates_with_no_error(tmp_path, capsys):
    maps = _maps(tmp_path / "maps")
    out = tmp_path / "regions"
    args = ["regions", str(ROBOT), "--material", "Black", "--size", "128", "--maps", str(maps)]
    assert main([*args, "-o", str(out)]) == 0
    lines = capsys.readouterr().err
    assert "3 regions (per target and state)" in lines and "convert it:" in lines
    snippet = tomllib.loads((out / "manifest_snippet.toml").read_text())
    assert [s["name"] for s in snippet["states"]] == ["stretch", "compress"]
    assert {r["name"] for r in snippet["regions"]} == {
        "Angry_compress",
        "Surprised_stretch",
        "Sad_compress",
    }
    # the masks on disk are the regions' masks (independent decode of the packed PNGs)
    packed = read_packed(out)
    names, masks = unpack(packed.textures, packed.table)
    mesh, _ = read_character(CharacterSource(ROBOT, "Black"))
    res = regions_from_targets(mesh, TargetRegionsOptions(size=128))
    assert names == tuple(r.name for r in res.regions)
    np.testing.assert_array_equal(np.rint(masks * 255), np.rint(res.masks * 255))
    code = main(
        [
            "convert",
            str(out / "manifest_snippet.toml"),
            "-o",
            str(tmp_path / "build"),
            "--no-render",
            "--no-compress",
            "--allow-root",
            str(ROBOT.parent),
            "--allow-root",
            str(maps),
        ]
    )
    assert code == 0
    report = json.loads((tmp_path / "build" / "report.json").read_text())
    assert report["validation"]["counts"]["error"] == 0
    # a rerun gives the same bytes
    again = tmp_path / "again"
    assert main([*args, "-o", str(again)]) == 0
    for f in sorted(p.name for p in out.iterdir()):
        if f != "manifest_snippet.toml":  # paths inside are relative to each folder
            assert (out / f).read_bytes() == (again / f).read_bytes(), f


def test_usd_blend_shapes_give_masks(tmp_path):
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

    mesh = _grid_face(11)
    stage = Usd.Stage.CreateNew(str(tmp_path / "face.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    root = UsdSkel.Root.Define(stage, "/Face")
    geom = UsdGeom.Mesh.Define(stage, "/Face/Mesh")
    geom.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, v)) for v in mesh.positions]))
    geom.CreateFaceVertexCountsAttr([3] * mesh.triangle_count)
    geom.CreateFaceVertexIndicesAttr([int(i) for i in mesh.indices.ravel()])
    st = UsdGeom.PrimvarsAPI(geom).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
    )
    st.Set(Vt.Vec2fArray([Gf.Vec2f(float(u), 1.0 - float(v)) for u, v in mesh.uvs]))
    binding = UsdSkel.BindingAPI.Apply(geom.GetPrim())
    targets = []
    for name, d in zip(mesh.morph_names, mesh.morph_deltas):
        shape = UsdSkel.BlendShape.Define(stage, f"/Face/Mesh/{name}")
        shape.CreateOffsetsAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, v)) for v in d]))
        targets.append(shape.GetPath())
    binding.CreateBlendShapesAttr([str(t.name) for t in targets])
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)
    stage.SetDefaultPrim(root.GetPrim())
    stage.GetRootLayer().Save()
    out = tmp_path / "out"
    assert main(["regions", str(tmp_path / "face.usda"), "--size", "64", "-o", str(out)]) == 0
    report = json.loads((out / "regions.json").read_text())
    assert report["targets"] == list(mesh.morph_names)
    sides = {r["name"]: r["side"] for r in report["regions"]}
    assert sides["browDownLeft_compress"] == "left"
    assert sides["browDownRight_compress"] == "right"


def test_bad_inputs_exit_2_with_one_line_and_no_output(tmp_path, capsys):
    plain = tmp_path / "plain.obj"
    plain.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n")
    cases = [
        (["regions", str(plain), "-o", str(tmp_path / "a")], "no morph targets"),
        (["regions", str(tmp_path / "missing.glb"), "-o", str(tmp_path / "b")], "not found"),
        (["regions", str(plain), "--regions", "0", "-o", str(tmp_path / "c")], "--regions"),
    ]
    for args, words in cases:
        assert main(args) == 2
        msg = capsys.readouterr().err
        assert words in msg, msg
        assert not Path(args[-1]).exists()


@shared
@pytest.mark.shared
def test_maps_without_the_driven_state_is_refused(tmp_path, capsys):
    maps = _maps(tmp_path / "maps")
    (maps / "wrinkle_stretch.png").unlink()
    args = ["regions", str(ROBOT), "--material", "Black", "--size", "32", "--maps", str(maps)]
    assert main([*args, "-o", str(tmp_path / "o")]) == 2
    assert "wrinkle_stretch.png" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
