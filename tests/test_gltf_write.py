"""glTF/GLB writer and reader: Khronos validator, JSON Schema, trimesh, hand texels, safety."""

from __future__ import annotations

import base64
import json
import shutil
import struct
from dataclasses import replace
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from wrinklepipe.asset import Mesh, Region, WrinkleAsset
from wrinklepipe.demo.package import demo_package
from wrinklepipe.errors import InputError
from wrinklepipe.gltf.document import read_document
from wrinklepipe.gltf.images import image_pixels, texture_normals
from wrinklepipe.gltf.limits import GltfReadOptions
from wrinklepipe.gltf.package_read import read_wrinkled
from wrinklepipe.gltf.package_write import write_glb, write_gltf
from wrinklepipe.io import khronos
from wrinklepipe.io.images import write_image
from wrinklepipe.io.png import png_bytes, png_pixels
from wrinklepipe.metadata import EXTENSION
from wrinklepipe.paths import SCHEMAS_DIR
from wrinklepipe.pipeline.package import package_from_asset
from wrinklepipe.pipeline.prepare import prepare_mesh

SCHEMA = SCHEMAS_DIR / EXTENSION / "schema" / f"material.{EXTENSION}.schema.json"
#: Information the Khronos validator emits for any vendor extension: it cannot see inside it
#: (UNSUPPORTED_EXTENSION), so textures referenced only from it look unused (UNUSED_OBJECT), and
#: its KHR_animation_pointer support is partial (INCOMPLETE_EXTENSION_SUPPORT).
ALLOWED_INFOS = {"UNSUPPORTED_EXTENSION", "UNUSED_OBJECT", "INCOMPLETE_EXTENSION_SUPPORT"}


@pytest.fixture(scope="module")
def pkg():
    return demo_package(256)


@pytest.fixture(scope="module")
def written(pkg, tmp_path_factory):
    folder = tmp_path_factory.mktemp("gltf")
    write_gltf(pkg, folder, "demo")
    write_glb(pkg, folder / "demo.glb")
    return folder


def _tiny_asset(encoding: str = "pd", scale: float = 1.0) -> WrinkleAsset:
    """A 2x2 map: flat base; state 0 tilted to slopes (0.5, -0.25) everywhere; 1 region."""
    base = np.zeros((2, 2, 3), np.float32)
    base[..., 2] = 1.0
    n = np.array([0.5, -0.25, 1.0], np.float32)
    n /= np.linalg.norm(n)
    state = np.broadcast_to(n, (2, 2, 3)).copy()
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    mesh = Mesh(
        positions=pos,
        indices=np.array([[0, 1, 2]], np.uint32),
        uvs=np.array([[0, 1], [1, 1], [0, 0]], np.float32),
        normals=np.tile(np.array([0, 0, 1], np.float32), (3, 1)),
    )
    return WrinkleAsset(
        name="tiny",
        base=base,
        states=state[None],
        state_names=("s",),
        masks=np.full((1, 2, 2), 0.5, np.float32),
        regions=(Region("r"),),
        encoding=encoding,
        pd_scale=scale,
        mesh=prepare_mesh(mesh),
    )


# ------------------------------------------------------------------------------------------------
# the Khronos validator


@pytest.mark.parametrize("name", ["demo.gltf", "demo.glb"])
def test_khronos_validator_clean(written, name):
    if not khronos.available():
        pytest.skip("Khronos glTF-Validator (node + npm gltf-validator) not installed")
    report = khronos.validate_gltf(written / name)
    issues = report["issues"]
    assert issues["numErrors"] == 0, issues["messages"]
    assert issues["numWarnings"] == 0, issues["messages"]
    codes = {m["code"] for m in issues["messages"]}
    assert codes <= ALLOWED_INFOS, codes
    assert "UNSUPPORTED_EXTENSION" in codes  # the validator did see the vendor extension


def test_extension_block_matches_json_schema(written):
    doc = json.loads((written / "demo.gltf").read_text())
    schema = json.loads(SCHEMA.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    ext = doc["materials"][0]["extensions"][EXTENSION]
    jsonschema.validate(ext, schema, cls=jsonschema.Draft202012Validator)
    # and the schema does reject a malformed block
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**ext, "encoding": "xyz"}, schema)


def test_document_structure(written, pkg):
    doc = json.loads((written / "demo.gltf").read_text())
    assert EXTENSION in doc["extensionsUsed"]
    assert "extensionsRequired" not in doc  # plain viewers still render the base
    prim = doc["meshes"][0]["primitives"][0]
    assert {"POSITION", "NORMAL", "TANGENT", "TEXCOORD_0", "_WRINKLE_VERTEX_ID"} <= set(
        prim["attributes"]
    )
    vid = doc["accessors"][prim["attributes"]["_WRINKLE_VERTEX_ID"]]
    assert vid["componentType"] == 5126 and vid["type"] == "SCALAR"
    assert doc["meshes"][0]["extras"]["targetNames"][:2] == ["brow_raise", "brow_furrow"]
    assert len(prim["targets"]) == 8
    # region weight curve through KHR_animation_pointer on the extension's weights
    ch = doc["animations"][0]["channels"][0]["target"]
    assert ch["path"] == "pointer"
    assert ch["extensions"]["KHR_animation_pointer"]["pointer"] == (
        f"/materials/0/extensions/{EXTENSION}/weights"
    )
    ext = doc["materials"][0]["extensions"][EXTENSION]
    assert ext["masks"]["table"][6] == {"region": "glabella", "texture": 1, "channel": "b"}
    # Jimenez Table 1.1, anger row (Red..Gray): -0.6 -0.6 -0.8 -0.8 0.8 0.8 1.0 0.0
    anger = next(e for e in ext["expressions"] if e["name"] == "anger")
    assert anger["weights"] == [-0.6, -0.6, -0.8, -0.8, 0.8, 0.8, 1.0, 0.0]


def test_trimesh_keeps_vertex_ids(written, pkg):
    trimesh = pytest.importorskip("trimesh")
    scene = trimesh.load(written / "demo.gltf", process=False)
    geom = next(iter(scene.geometry.values()))
    ids = np.asarray(geom.vertex_attributes["_WRINKLE_VERTEX_ID"]).reshape(-1)
    assert np.array_equal(ids, pkg.mesh.vertex_ids.astype(np.float32))
    # seam twins (same position, different UV) share an ID
    assert len(np.unique(ids)) < len(ids)


@pytest.mark.parametrize("name", ["demo.gltf", "demo.glb"])
def test_reader_round_trip(written, pkg, name):
    back = read_wrinkled(written / name)
    assert back.meta == pkg.meta
    assert [t.name for t in back.textures] == [t.name for t in pkg.textures]
    for t in back.textures:
        assert np.array_equal(t.pixels, pkg.texture(t.name).pixels), t.name
    for f in ("positions", "indices", "uvs", "normals", "tangents", "vertex_ids", "morph_deltas"):
        assert np.array_equal(getattr(back.mesh, f), getattr(pkg.mesh, f)), f
    assert back.mesh.morph_names == pkg.mesh.morph_names
    assert np.array_equal(back.curves[0].values, pkg.curves[0].values)
    assert back.name == "demo"  # the file's stem (the rule of the one glTF package reader)
    assert np.array_equal(back.curves[0].times, pkg.curves[0].times)


def test_package_is_named_by_the_file_stem(written):
    """A renamed file, or one whose scene and nodes are named otherwise, is read by its stem."""
    path = _rewrite(
        written, lambda d: (d["scenes"][0].update(name="Scene"), d["nodes"][0].update(name="Body"))
    )
    assert json.loads(path.read_text())["scenes"][0]["name"] == "Scene"
    assert read_wrinkled(path).name == "edited"


def test_writer_is_deterministic(pkg, tmp_path):
    write_gltf(pkg, tmp_path / "a", "x")
    write_gltf(pkg, tmp_path / "b", "x")
    write_glb(pkg, tmp_path / "a.glb")
    write_glb(pkg, tmp_path / "b.glb")
    for rel in ("x.gltf", "x.bin", "textures/base_normal.png", "textures/mask_1.png"):
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes()
    assert (tmp_path / "a.glb").read_bytes() == (tmp_path / "b.glb").read_bytes()


# ------------------------------------------------------------------------------------------------
# stored texels against hand-computed values


def test_pd_texel_hand_computed(tmp_path):
    # slopes (x/z, y/z) = (0.5, -0.25); scale 1, mapping v2: q = 128 + 127 d / s
    # -> 191.5 -> 192 (round half up), 96.25 -> 96; B = 0
    write_gltf(package_from_asset(_tiny_asset("pd", 1.0)), tmp_path, "t")
    px = png_pixels((tmp_path / "textures/wrinkle_s.png").read_bytes())
    assert px[0, 0].tolist() == [192, 96, 0]
    # scale 2: 128 + 63.5 * (0.5, -0.25) -> 159.75 -> 160, 112.125 -> 112
    write_gltf(package_from_asset(_tiny_asset("pd", 2.0)), tmp_path / "s2", "t")
    px = png_pixels((tmp_path / "s2/textures/wrinkle_s.png").read_bytes())
    assert px[0, 0].tolist()[:2] == [160, 112]
    doc = json.loads((tmp_path / "t.gltf").read_text())
    assert doc["materials"][0]["extensions"][EXTENSION]["mapping"] == 2
    # mask 0.5 -> 127.5 -> 128 in channel r of mask_0; base (0,0,1) -> (128, 128, 255)
    assert png_pixels((tmp_path / "textures/mask_0.png").read_bytes())[1, 1, 0] == 128
    assert png_pixels((tmp_path / "textures/base_normal.png").read_bytes())[0, 0].tolist() == [
        128,
        128,
        255,
    ]


def test_diff_texel_hand_computed(tmp_path):
    # W = (0.5, -0.25, 1)/|.| = (0.43644, -0.21822, 0.87287); t = W - (0,0,1); q = 128 + 127 t
    write_gltf(package_from_asset(_tiny_asset("diff", 1.0)), tmp_path, "t")
    px = png_pixels((tmp_path / "textures/wrinkle_s.png").read_bytes())[0, 0]
    w = np.array([0.5, -0.25, 1.0]) / np.sqrt(1.3125)
    expect = np.rint(128 + 127 * (w - [0, 0, 1]))
    assert px.tolist() == expect.astype(int).tolist() == [183, 100, 112]


def test_png_has_no_colour_chunks():
    data = png_bytes(np.zeros((3, 5, 4), np.uint8))
    chunks, off = [], 8
    while off < len(data):
        (n,) = struct.unpack(">I", data[off : off + 4])
        chunks.append(data[off + 4 : off + 8])
        off += 12 + n
    assert chunks == [b"IHDR", b"IDAT", b"IEND"]


# ------------------------------------------------------------------------------------------------
# reader safety


def _rewrite(folder: Path, edit) -> Path:
    doc = json.loads((folder / "demo.gltf").read_text())
    edit(doc)
    out = folder / "edited.gltf"
    out.write_text(json.dumps(doc))
    return out


@pytest.mark.parametrize(
    "uri, words",
    [
        ("../outside.bin", "'..'"),
        ("textures/../../x.png", "'..'"),
        ("/etc/passwd", "absolute"),
        ("C:/data/x.bin", "absolute"),
        ("file:///etc/passwd", "scheme"),
        ("https://example.com/x.bin", "scheme"),
    ],
)
def test_reader_refuses_unsafe_uris(written, uri, words):
    path = _rewrite(written, lambda d: d["buffers"][0].update(uri=uri))
    with pytest.raises(InputError) as exc:
        read_wrinkled(path)
    msg = str(exc.value)
    assert words in msg and "edited.gltf" in msg and "/buffers/0/uri" in msg


def test_reader_caps_data_uris(written):
    blob = base64.b64encode(b"\0" * 4096).decode()
    path = _rewrite(
        written,
        lambda d: d["images"][1].update(uri="data:image/png;base64," + blob),
    )
    with pytest.raises(InputError, match="over the cap of 1024"):
        read_wrinkled(path, GltfReadOptions(max_data_uri_bytes=1024))


def test_reader_caps_pixels(written):
    with pytest.raises(InputError, match="over the cap"):
        read_wrinkled(written / "demo.gltf", GltfReadOptions(max_pixels=100))


@pytest.mark.parametrize("suffix", [".png", ".jpg"])
def test_document_images_honour_the_pixel_cap(written, tmp_path, suffix):
    """Every image read from a document is held to its ``max_pixels`` before decoding: the
    demo's maps are 256 x 256 (``demo_package(256)``); a JPEG base goes through OpenImageIO's
    header check."""
    path = written / "demo.gltf"
    if suffix == ".jpg":
        shutil.copytree(written, tmp_path / "c")
        write_image(tmp_path / "c" / "base.jpg", np.full((256, 256, 3), 0.5, np.float32), 8)
        path = _rewrite(tmp_path / "c", lambda d: d["images"][0].update(uri="base.jpg"))
    doc = read_document(path, GltfReadOptions(max_pixels=256 * 256 - 1))
    with pytest.raises(InputError) as exc:
        image_pixels(doc, 0)
    msg = str(exc.value)
    assert "256 x 256" in msg and "over the cap" in msg and "/images/0" in msg, msg
    with pytest.raises(InputError, match="over the cap"):
        texture_normals(doc, 0, "/materials/0/normalTexture")
    fits = read_document(path, GltfReadOptions(max_pixels=256 * 256))
    assert image_pixels(fits, 0).shape[:2] == (256, 256)


def test_reader_requires_the_extension(written):
    def drop(d):
        del d["materials"][0]["extensions"]

    with pytest.raises(InputError, match="not a wrinklepipe asset"):
        read_wrinkled(_rewrite(written, drop))


def test_reader_truncated_buffer(written, tmp_path):
    import shutil

    shutil.copytree(written, tmp_path / "c")
    bin_path = tmp_path / "c" / "demo.bin"
    bin_path.write_bytes(bin_path.read_bytes()[:100])
    with pytest.raises(InputError, match="byteLength"):
        read_wrinkled(tmp_path / "c" / "demo.gltf")


def test_vertex_ids_beyond_float_precision_refused(pkg, tmp_path):
    big = replace(pkg, mesh=replace(pkg.mesh, vertex_ids=pkg.mesh.vertex_ids + (1 << 24)))
    with pytest.raises(InputError, match="exact as FLOAT"):
        write_gltf(big, tmp_path, "x")


def test_names_from_inputs_never_leave_the_folder(tmp_path):
    from wrinklepipe.outputs.curves import curve_files
    from wrinklepipe.package import WeightCurves, safe_name

    asset = _tiny_asset()
    asset = replace(asset, state_names=("../../evil",))
    pkg = package_from_asset(asset)
    write_gltf(pkg, tmp_path / "out", "t")
    files = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file())
    assert all(f.startswith("out/") for f in files), files
    assert "out/textures/wrinkle_.._.._evil.png" in files
    assert pkg.meta.states[0].name == "../../evil"  # the name itself is kept
    c = WeightCurves("../up/../x", np.zeros(1, np.float32), np.zeros((1, 1), np.float32))
    assert sorted(curve_files(c, ["r"])) == ["curves/_up_.._x.csv", "curves/_up_.._x.json"]
    assert safe_name("a/b", {"a_b"}) == "a_b_2"
    bad = replace(pkg, textures=[replace(t, name="../x") for t in pkg.textures])
    with pytest.raises(InputError, match="not a safe file name"):
        write_gltf(bad, tmp_path / "o2", "t")


@pytest.mark.parametrize("layout", ["rgba", "array", "lr-split", "jimenez8"])
def test_every_mask_layout_matches_the_schema_and_round_trips(layout, tmp_path):
    from wrinklepipe.pipeline.package import PackOptions, asset_from_package

    names = [
        "forehead_outer_l",
        "forehead_outer_r",
        "forehead_inner_l",
        "forehead_inner_r",
        "nose_l",
        "nose_r",
        "glabella",
        "chin",
    ]
    # sided masks never overlap their twin (left half / right half), values multiple of 1/255
    rng = np.random.default_rng(5)
    masks = (rng.integers(0, 256, (8, 4, 4)) / 255).astype(np.float32)
    masks[0::2, :, :2] = 0  # left regions only on the right half of the image ...
    masks[1:6:2, :, 2:] = 0  # ... right regions only on the left half
    asset = replace(
        _tiny_asset(),
        masks=masks,
        regions=tuple(
            Region(n, "left" if n.endswith("_l") else "right" if n.endswith("_r") else "center")
            for n in names
        ),
    )
    pkg = package_from_asset(asset, PackOptions(mask_layout=layout))
    write_gltf(pkg, tmp_path, "t")
    doc = json.loads((tmp_path / "t.gltf").read_text())
    ext = doc["materials"][0]["extensions"][EXTENSION]
    jsonschema.validate(ext, json.loads(SCHEMA.read_text()), cls=jsonschema.Draft202012Validator)
    assert ext["masks"]["layout"] == layout
    back = asset_from_package(read_wrinkled(tmp_path / "t.gltf"))
    assert np.allclose(back.masks, masks, atol=0.5 / 255 + 1e-6)
