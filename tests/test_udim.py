"""UDIM tiles: numbering, a mesh cut by tile, a manifest naming tiles, and a two-tile face
converted, read back from every output and validated tile by tile and over the face.

Expectations are independent of the code under test: tile numbers and UV squares by hand, the
face's UVs read from its USD by pxr, shipped texels read by Pillow and compared with the maps
the test drew (tests/udim_setups.py), pooled statistics computed on hand-made samples."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from udim_setups import tile_maps, write_udim_setup

from wrinklepipe import fidelity as fd
from wrinklepipe import udim
from wrinklepipe.asset import Mesh
from wrinklepipe.cli import main
from wrinklepipe.errors import InputError
from wrinklepipe.io import khronos
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.metadata import CompressedCopy
from wrinklepipe.metrics import weighted_stats
from wrinklepipe.sources.manifest import load_manifest
from wrinklepipe.sources.package import read_package

pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdShade  # noqa: E402

# ------------------------------------------------------------------------------------------------
# numbering and meshes


def test_tile_numbers_and_squares_by_hand():
    assert udim.tile_number(0, 0) == 1001
    assert udim.tile_number(1, 0) == 1002
    assert udim.tile_number(9, 0) == 1010
    assert udim.tile_number(0, 1) == 1011
    assert udim.tile_square(1002) == (1, 0)
    assert udim.tile_square(1013) == (2, 1)
    with pytest.raises(ValueError):
        udim.tile_number(10, 0)
    assert udim.pattern_path("maps/face.<UDIM>.png", 1012) == "maps/face.1012.png"
    assert udim.split_name("base_normal.1002") == ("base_normal", 1002)
    assert udim.split_name("wrinkle_v2.0") == ("wrinkle_v2.0", None)
    # glTF v (down) of tile 1011 (USD t in [1, 2]) lies in [-1, 0]
    local = udim.to_tile(np.array([[2.25, -0.75]], np.float32), 1013)
    np.testing.assert_allclose(local, [[0.25, 0.25]])
    np.testing.assert_allclose(udim.from_tile(local, 1013), [[2.25, -0.75]])


def test_tile_files_of_a_pattern():
    found = ["face.1001.png", "face.1002.png", "face.1011.png", "face.0999.png", "face.png"]
    got = udim.tile_files("face.<UDIM>.png", found)
    assert got == {1001: "face.1001.png", 1002: "face.1002.png", 1011: "face.1011.png"}


def _two_quads() -> Mesh:
    """Quad A on tile 1001 (u 0..1), quad B on tile 1002 (u 1..2), glTF v (down)."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]] * 2, np.float32)
    pos[4:, 0] += 2
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]] * 2, np.float32)
    uv[4:, 0] += 1
    idx = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]], np.uint32)
    ids = np.arange(8, dtype=np.int64)
    return Mesh(pos, idx, uvs=uv, vertex_ids=ids)


def test_a_mesh_cut_by_tile():
    m = _two_quads()
    assert udim.mesh_tiles(m) == (1001, 1002)
    np.testing.assert_array_equal(udim.triangle_tiles(m.uvs, m.indices), [1001, 1001, 1002, 1002])
    b = udim.tile_mesh(m, 1002)
    assert b.vertex_count == 4 and b.triangle_count == 2
    np.testing.assert_array_equal(b.vertex_ids, [4, 5, 6, 7])
    np.testing.assert_array_equal(b.indices, [[0, 1, 2], [0, 2, 3]])
    np.testing.assert_allclose(b.uvs, [[0, 1], [1, 1], [1, 0], [0, 0]])
    np.testing.assert_allclose(b.positions[:, 0], [2, 3, 3, 2])


def test_a_triangle_across_two_tiles_is_refused():
    m = _two_quads()
    m.uvs[1, 0] = 1.5  # quad A's corner moved into tile 1002
    with pytest.raises(InputError, match="1 triangle spans two UDIM tiles"):
        udim.triangle_tiles(m.uvs, m.indices, "face")


def test_copies_of_tiles_are_one_record_per_map():
    made = [
        CompressedCopy(f"base_normal.{t}", "bc5", "rg", 1, 7, f"compressed/base_normal.{t}.ktx2",
                       f"compressed/base_normal.{t}.dds")
        for t in (1001, 1002)
    ]  # fmt: skip
    (rec,) = udim.untiled_copies(made)
    assert rec.texture == "base_normal"
    assert rec.ktx2 == "compressed/base_normal.<UDIM>.ktx2"
    assert rec.dds == "compressed/base_normal.<UDIM>.dds"
    other = [made[0], CompressedCopy(**{**made[1].__dict__, "format": "bc7"})]
    with pytest.raises(InputError, match="one UDIM set"):
        udim.untiled_copies(other)


def test_the_face_pools_every_tile_by_area():
    """Tile A (a 2x2 grid: a texel is 1/4 of its square) with errors 1, 1; tile B (1x1) with
    error 3: the face mean is (1 x 1/4 x 2 + 3 x 1) / (2/4 + 1) = 7/3; the base likewise."""
    stats = weighted_stats(np.array([1.0]), np.array([1.0]))
    a = fd.Fidelity(
        [fd.PoseFidelity("joy", stats)],
        samples={"joy": (np.array([1.0, 1.0]), np.array([1.0, 1.0]))},
    )
    b = fd.Fidelity(
        [fd.PoseFidelity("joy", stats)], samples={"joy": (np.array([3.0]), np.array([1.0]))}
    )
    face = fd.pooled([(a, 0.25), (b, 1.0)])
    assert face.poses[0].overall.mean == pytest.approx(7.0 / 3.0)
    assert face.poses[0].overall.max == 3.0
    assert face.poses[0].overall.texels == 3


# ------------------------------------------------------------------------------------------------
# manifests


def test_manifest_tiles_from_a_pattern_and_a_table(tmp_path):
    path = write_udim_setup(tmp_path, size=16, mask_size=8)
    m = load_manifest(path)
    assert m.tiles == (1001, 1002)
    assert sorted(m.tile_paths["regions[0].mask"]) == [1002]  # brow_L is painted on 1002
    one = m.tile(1001)
    assert one.base.name == "base.1001.png" and not one.tiles
    assert one.regions[0].mask is None and one.regions[1].mask.name == "brow_R.1001.png"
    assert len(m.input_files) == 1 + 1 + 6 + 4  # manifest, mesh, 3 maps x 2 tiles, 4 masks
    text = path.read_text().replace(
        'base = "maps/base.<UDIM>.png"',
        'base = { 1001 = "maps/base.1001.png", 1002 = "maps/base.1002.png" }',
    )
    path.write_text(text)
    assert load_manifest(path).tiles == (1001, 1002)


@pytest.mark.parametrize(
    ("change", "said"),
    [
        (
            ('map = "maps/stretch.<UDIM>.png"', 'map = "maps/stretch.1001.png"'),
            "one file for a tiled base",
        ),
        (('base = "maps/base.<UDIM>.png"', 'base = "maps/base.1001.png"'), "the base does not"),
        (('mesh = "face.usda"', 'mesh = "face.glb"'), "glTF has no UDIM"),
        (('base = "maps/base.<UDIM>.png"', 'base = "maps/nothing.<UDIM>.png"'), "no tile matches"),
    ],
)
def test_bad_tiled_manifests_say_what_is_wrong(tmp_path, change, said):
    path = write_udim_setup(tmp_path, size=16, mask_size=8)
    (tmp_path / "face.glb").write_bytes(b"glTF")
    path.write_text(path.read_text().replace(*change))
    with pytest.raises(InputError, match=said):
        load_manifest(path)


@pytest.mark.parametrize("tiled_colors", [True, False])
def test_colour_maps_with_tiles_are_refused_in_one_message(tmp_path, tiled_colors):
    """Colour states do not take tiles: a tiled manifest with colour maps (tiled or one file
    each) is refused by one problem naming every colour map, before anything is read."""
    path = write_udim_setup(tmp_path, size=16, mask_size=8)
    for t in (1001, 1002):
        Image.new("RGB", (16, 16), (200, 150, 120)).save(tmp_path / "maps" / f"skin.{t}.png")
        Image.new("RGB", (16, 16), (220, 120, 110)).save(tmp_path / "maps" / f"flush.{t}.png")
    tile = "<UDIM>" if tiled_colors else "1001"
    text = path.read_text().replace(
        'base = "maps/base.<UDIM>.png"',
        f'base = "maps/base.<UDIM>.png"\nbase_color = "maps/skin.{tile}.png"',
    )
    text = text.replace(
        'map = "maps/compress.<UDIM>.png"',
        f'map = "maps/compress.<UDIM>.png"\ncolor = "maps/flush.{tile}.png"',
    )
    path.write_text(text)
    with pytest.raises(InputError) as err:
        load_manifest(path)
    problems = err.value.problems
    assert len(problems) == 1, [p.message for p in problems]
    assert problems[0].key == "base_color"
    assert problems[0].message.startswith(
        "colour maps do not take UDIM tiles yet (base_color, states[1].color)"
    )
    code = main(["convert", str(path), "-o", str(tmp_path / "out")])
    assert code == 2 and not (tmp_path / "out").exists()


def test_a_state_tile_the_base_lacks_and_tiles_of_two_sizes(tmp_path):
    path = write_udim_setup(tmp_path, size=16, mask_size=8)
    Image.new("RGB", (16, 16), (128, 128, 255)).save(tmp_path / "maps" / "stretch.1003.png")
    Image.new("RGB", (8, 8), (128, 128, 255)).save(tmp_path / "maps" / "compress.1002.png")
    with pytest.raises(InputError) as err:
        load_manifest(path)
    text = str(err.value)
    assert "tile 1003 is not a tile of the base" in text
    assert "tiles of one map have different sizes: 16x16 (tile 1001), 8x8 (tile 1002)" in text


def test_a_composition_error_of_a_tiled_usd_source_is_an_issue(tmp_path, capsys):
    """A reference the tiled USD source cannot resolve is the validator's WP-USD-003, said
    once for every tile, naming the layer; the output is written (exit 1)."""
    path = write_udim_setup(tmp_path / "src", size=16, mask_size=8)
    usd = tmp_path / "src" / "face.usda"
    usd.write_text(usd.read_text() + '\ndef Xform "Extra" (references = @./gone.usda@</X>) {}\n')
    out = tmp_path / "out"
    assert main(["convert", str(path), "-o", str(out), "--no-render"]) == 1
    capsys.readouterr()
    issues = json.loads((out / "report.json").read_text())["validation"]["issues"]
    found = [i for i in issues if i["code"] == "WP-USD-003"]
    assert len(found) == 1 and "gone.usda" in found[0]["message"], issues
    assert found[0]["message"].startswith("every tile: "), found


# ------------------------------------------------------------------------------------------------
# a two-tile face converted


@pytest.fixture(scope="module")
def face(tmp_path_factory):
    root = tmp_path_factory.mktemp("udim_face")
    manifest = write_udim_setup(root / "src", size=32, mask_size=16)
    res = convert(manifest, root / "out", ConvertOptions(render=True))
    return root / "src", root / "out", res


def _png(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path))


def test_convert_exits_0_and_writes_every_tile(face):
    _, out, res = face
    assert res.exit_code == 0, res.report["validation"]["issues"]
    for stem in ("base_normal", "wrinkle_stretch", "wrinkle_compress", "mask_0"):
        for t in (1001, 1002):
            assert (out / "textures" / f"{stem}.{t}.png").is_file()
    for t in (1001, 1002):
        assert (out / "compressed" / f"base_normal.{t}.dds").is_file()
    assert res.report["udim"] == {"tiles": [1001, 1002]}


def test_each_tile_ships_its_own_maps(face):
    """The shipped base of each tile, read by Pillow, is the tile's drawn base within the
    8-bit step (the tiles differ: each has its own bump field)."""
    _, out, _ = face
    for t in (1001, 1002):
        base, _, _ = tile_maps(t, 32)
        got = _png(out / "textures" / f"base_normal.{t}.png").astype(np.float64) / 255.0
        np.testing.assert_allclose(got[..., :3], 0.5 + 0.5 * base, atol=0.6 / 255)


def test_the_usd_names_udim_paths_and_its_tiles(face):
    src, out, _ = face
    stage = Usd.Stage.Open(str(out / "face.usda"))
    mat = stage.GetPrimAtPath("/Face/Looks/Skin")
    assert list(mat.GetAttribute("wrinkle:tiles").Get()) == [1001, 1002]
    base = UsdShade.Shader(mat.GetChild("base_normal")).GetInput("file").Get()
    assert base.path == "./textures/base_normal.<UDIM>.png"
    layer = stage.GetRootLayer()
    tiles = UsdShade.UdimUtils.ResolveUdimTilePaths(base.path, layer)
    assert [int(t) for _, t in tiles] == [1001, 1002]  # USD's own UDIM resolver finds them
    state = UsdShade.Material(mat).GetInput("wrinkle:state:stretch").Get()
    assert state.path == "./textures/wrinkle_stretch.<UDIM>.png"
    mtlx = (out / "face.mtlx").read_text()
    assert (
        "textures/base_normal.&lt;UDIM&gt;.png" in mtlx or "textures/base_normal.<UDIM>.png" in mtlx
    )


def test_usd_validation_finds_only_what_it_cannot_resolve(face):
    """UsdValidation: no error but the normal-map validator's InvalidFile for the base's
    ``<UDIM>`` path (USD resolves UDIM tiles in the renderer, not in an asset path's resolved
    path); the conditions that validator checks hold on every tile, by USD's UDIM resolver."""
    from usd_checks import validation_errors

    _, out, _ = face
    for name in ("face.usda", "face.usdz"):
        stage = Usd.Stage.Open(str(out / name))
        errors = [
            (e.GetIdentifier(), "base_normal.<UDIM>.png" in e.GetMessage())
            for e in validation_errors(stage)
        ]
        assert errors == [("usdShadeValidators:NormalMapTextureValidator.InvalidFile", True)]
        shader = UsdShade.Shader(stage.GetPrimAtPath("/Face/Looks/Skin/base_normal"))
        assert shader.GetInput("sourceColorSpace").Get() == "raw"
        assert tuple(shader.GetInput("scale").Get()) == (2, 2, 2, 1)
        assert tuple(shader.GetInput("bias").Get()) == (-1, -1, -1, 0)
        tiles = UsdShade.UdimUtils.ResolveUdimTilePaths(
            shader.GetInput("file").Get().path, stage.GetRootLayer()
        )
        assert [int(t) for _, t in tiles] == [1001, 1002] and all(p for p, _ in tiles)


def test_the_gltf_is_one_material_per_tile_with_uvs_in_the_tile(face):
    src, out, _ = face
    doc = json.loads((out / "face.gltf").read_text())
    mats = doc["materials"]
    assert [m["extensions"]["WRINKLEPIPE_wrinkle_maps"]["tile"] for m in mats] == [1001, 1002]
    prims = doc["meshes"][0]["primitives"]
    assert [p["material"] for p in prims] == [0, 1]
    images = {i: img["uri"] for i, img in enumerate(doc["images"])}
    for m, t in zip(mats, (1001, 1002)):
        tex = doc["textures"][m["normalTexture"]["index"]]
        assert images[tex["source"]] == f"textures/base_normal.{t}.png"
    pkg = read_package(out / "face.gltf")
    assert pkg.tiles == (1001, 1002)
    # the UDIM layout is back: u in [0, 1] on tile 1001 and [1, 2] on tile 1002
    tiles = udim.triangle_tiles(pkg.mesh.uvs, pkg.mesh.indices)
    assert sorted(set(tiles.tolist())) == [1001, 1002]
    if khronos.available():
        report = khronos.validate_gltf(out / "face.gltf")
        assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]


def test_every_output_reads_back_as_the_same_tiled_package(face):
    src, out, _ = face
    from wrinklepipe.io.confine import allowed_roots

    with allowed_roots([src]):
        pkgs = [read_package(out / n) for n in ("face.gltf", "face.usda", "face.usdz")]
    for p in pkgs:
        assert p.tiles == (1001, 1002)
        assert sorted(t.name for t in p.textures) == sorted(t.name for t in pkgs[0].textures)
        for t in p.textures:
            np.testing.assert_array_equal(t.pixels, pkgs[0].texture(t.name).pixels)
        assert [c.dds for c in p.meta.compressed][:1] == ["compressed/base_normal.<UDIM>.dds"]


def test_validation_is_per_tile_and_over_the_face(face):
    _, out, res = face
    v = res.report["validation"]
    assert v["counts"]["error"] == 0
    rows = v["fidelity"]
    budget = 2.0  # the default p99 budget
    for who in ("1001", "1002", "face"):
        for pose in ("raise", "smile"):
            assert rows[f"{who} {pose}"]["p99_deg"] <= budget
    # the face pools both tiles' texels
    for pose in ("raise", "smile"):
        both = rows[f"1001 {pose}"]["texels"] + rows[f"1002 {pose}"]["texels"]
        assert rows[f"face {pose}"]["texels"] == both
    # no tile says a region painted on the other tile is empty
    assert not any(i["code"] == "WP-MASK-003" for i in v["issues"])
    page = (out / "validation.html").read_text()
    assert "raise.1002" in page and "fidelity_by_tile" in page


def test_validate_asset_reads_the_folder_tile_by_tile(face, capsys):
    _, out, _ = face
    code = main(["validate-asset", str(out / "face.gltf"), "--no-render", "--json"])
    got = json.loads(capsys.readouterr().out)
    assert code == 0
    assert got["input"]["tiles"] == [1001, 1002]
    assert sorted(got["metrics"]["tiles"]) == ["1001", "1002"]


def test_a_tiled_usd_output_over_a_broken_layer_is_an_issue_of_every_tile(tmp_path, capsys):
    """validate-asset on a tiled USD output whose source layer gained a reference that cannot
    be opened: WP-USD-003 once, for every tile (the stage's problems reach each tile's
    input), naming the layer; tile 1002's block-compressed copy cut short: WP-TEX-004 for
    that tile (every tile's listed copies are read)."""
    path = write_udim_setup(tmp_path / "src", size=16, mask_size=8)
    out = tmp_path / "out"
    assert main(["convert", str(path), "-o", str(out), "--no-render"]) == 0
    usd = tmp_path / "src" / "face.usda"
    usd.write_text(usd.read_text() + '\ndef Xform "Extra" (references = @./gone.usda@</X>) {}\n')
    dds = out / "compressed" / "base_normal.1002.dds"
    dds.write_bytes(dds.read_bytes()[:200])  # tile 1002's copy cut short
    capsys.readouterr()
    report = tmp_path / "report.json"
    args = ["validate-asset", str(out / "face.usda"), "--no-render", "--report", str(report)]
    code = main([*args, "--allow-root", str(tmp_path / "src")])
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, err
    found = [i for i in json.loads(report.read_text())["issues"] if i["code"].startswith("WP-USD")]
    assert code == 1 and len(found) == 1, (err, found)
    assert found[0]["code"] == "WP-USD-003" and "gone.usda" in found[0]["message"]
    assert found[0]["message"].startswith("every tile: "), found
    cut = [i for i in json.loads(report.read_text())["issues"] if i["code"] == "WP-TEX-004"]
    assert len(cut) == 1 and cut[0]["message"].startswith("tile 1002: "), cut
    assert "base_normal.1002.dds" in cut[0]["message"], cut


def test_engine_exports_refuse_tiles_by_name(face, tmp_path, capsys):
    _, out, _ = face
    code = main(["export", str(out), "--engine", "godot", "-o", str(tmp_path / "g")])
    assert code == 2
    assert "has UDIM tiles (1001, 1002)" in capsys.readouterr().err
    assert not (tmp_path / "g").exists()
