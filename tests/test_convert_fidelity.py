"""convert with every choice on auto, judged by fidelity: the fixture end to end (the shipped
files, read back and decoded independently, against the exact truth), what convert prints,
missing sides, a V-flipped base, and the one clipped count."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_document_convert import ROBOT, needs_robot, robot  # noqa: F401 (the fixture)

from wrinklepipe import codec
from wrinklepipe import fidelity as fd
from wrinklepipe.cli import main
from wrinklepipe.demo import face_fixture as ff
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.io.images import read_image, write_image
from wrinklepipe.normals import compress as nc
from wrinklepipe.normals.dds import read_dds
from wrinklepipe.pipeline.ingest import ingest
from wrinklepipe.sources.manifest import load_manifest

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
MESH = DATA / ff.MESH_RELPATH
needs_mesh = pytest.mark.skipif(not MESH.is_file(), reason="../shared/data is absent")


def texels(path: Path) -> np.ndarray:
    """8-bit texels of a written PNG (OpenImageIO, independent of the writer)."""
    v, _ = read_image(path)
    return np.rint(v * 255).astype(np.uint8)


def block_texels(path: Path) -> np.ndarray:
    """The x, y texels of a written DDS, decoded by texture2ddecoder."""
    img = read_dds(path)
    fmt = {"bc5": "bc5", "bc3": "bc3nm", "bc7": "bc7", "bc1": "bc1"}[str(img.format).lower()]
    rgba = nc.decode_bc(bytes(img.levels[0]), img.width, img.height, fmt)
    return nc.unpack_u8(rgba, fmt, 2)


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    src = tmp_path_factory.mktemp("fixture")
    fx = ff.build_fixture(MESH)
    manifest = ff.write_fixture_files(src, fx, MESH)
    out = tmp_path_factory.mktemp("conv") / "out"
    code = main(
        ["convert", str(manifest), "-o", str(out), "--no-render", "--allow-root", str(MESH.parent)]
    )
    return manifest, out, code, fx


@needs_mesh
def test_the_fixture_on_auto_is_within_budget_of_the_truth(converted):
    manifest, out, code, fx = converted
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    assert report["validation"]["counts"]["error"] == 0, report["validation"]["issues"]
    fid = report["fidelity"]
    # the choices the searches have made on this fixture since they were built (the measure's
    # faster path keeps them): full-size states, half-size masks, the scale that clips 63
    # texels of the deepest crease, BC5 copies of states and base
    chosen = [fid[k] for k in ("wrinkle", "mask", "pd_scale", "state_format", "base_format")]
    assert chosen == [1024, 512, 0.875, "bc5", "bc5"]
    a = fx.asset()
    poses = fd.expression_poses(a.region_names, a.region_state_matrix(), a.expressions)
    truth = fd.prepare(fx.base_normal, fx.wrinkle_slopes, fx.masks, poses, a.region_names)
    scale = report["asset"]["scale"]
    ext = json.loads((out / "cesium_face.gltf").read_text())
    meta = next(
        m["extensions"]["WRINKLEPIPE_wrinkle_maps"]
        for m in ext["materials"]
        if "WRINKLEPIPE_wrinkle_maps" in m.get("extensions", {})
    )
    version = int(meta.get("mapping", 1))
    names = [r["name"] for r in meta["regions"]]
    assert names == list(a.region_names)

    def pd(q):
        return codec.decode("pd", q[..., :2], "rg", param=scale, version=version)

    base = codec.decode("full", texels(out / "textures/base_normal.png")[..., :3], "rgb")
    states = np.stack([pd(texels(out / f"textures/wrinkle_{s}.png")) for s in a.state_names])

    # masks through the channel table (rgba layout: texture index + channel)
    def uri(ref):  # a glTF textureInfo -> its image file
        return out / ext["images"][ext["textures"][ref["index"]]["source"]]["uri"]

    mask_tex = [texels(uri(t)) / 255.0 for t in meta["masks"]["textures"]]
    masks = np.stack(
        [mask_tex[e["texture"]][..., "rgba".index(e["channel"])] for e in meta["masks"]["table"]]
    ).astype(np.float32)
    png = fd.measure(truth, base, states, masks)
    assert png.worst_p99() <= 1.0, fd.describe(png)
    assert fid["state_format"] != "png"
    comp = np.stack([pd(block_texels(out / f"compressed/wrinkle_{s}.dds")) for s in a.state_names])
    if fid["base_format"] != "png":
        base = codec.decode("full", block_texels(out / "compressed/base_normal.dds"), "rg")
    bc = fd.measure(truth, base, comp, masks)
    assert bc.worst_p99() <= 2.5, fd.describe(bc)
    # every candidate the searches tried is on record; smaller states were over the budget
    smaller = [t for t in fid["tried"] if t["step"] == "wrinkle" and t["value"] < fid["wrinkle"]]
    assert smaller and not any(t["ok"] for t in smaller)


@needs_mesh
def test_the_clipped_count_is_one_number(converted):
    _, out, _, _ = converted
    report = json.loads((out / "report.json").read_text())
    clipped = report["pd_scale"]["clipped_texels"]
    assert sum(clipped.values()) > 0  # the chosen scale clips a few texels of the deepest crease
    for s, n in clipped.items():
        q = texels(out / f"textures/wrinkle_{s}.png")[..., :2]
        t = codec.mapping(2).decode(q, 8)
        assert n == int(np.any(np.abs(t) >= 1 - 0.5 / 127, axis=-1).sum())  # counted by hand


def small_demo(tmp_path, size=64) -> Path:
    return write_demo_source(tmp_path / "demo", size)


def test_missing_sides_are_inferred_from_names_with_a_warning(tmp_path):
    manifest = small_demo(tmp_path)
    text = "\n".join(
        line for line in manifest.read_text().splitlines() if not line.startswith("side = ")
    )
    manifest.write_text(text + "\n")
    asset, _ = ingest(load_manifest(manifest))
    sides = {r.name: r.side for r in asset.regions}
    assert sides["nose_l"] == "left" and sides["nose_r"] == "right"
    assert sides["glabella"] == "center"
    warnings = asset.provenance["warnings"]
    assert any("'nose_l'" in w and "no side given" in w and "left" in w for w in warnings)
    assert not any("glabella" in w for w in warnings)


def test_a_v_flipped_base_is_reported_and_convert_says_why_it_exits_1(tmp_path, capsys):
    manifest = small_demo(tmp_path)
    base, _ = read_image(manifest.parent / "base_normal.png")
    write_image(manifest.parent / "base_normal.png", base[::-1], bits=16)
    code = main(["convert", str(manifest), "-o", str(tmp_path / "out"), "--no-render"])
    err = capsys.readouterr().err
    assert code == 1
    assert "error WP-FID-006" in err and "flipped vertically" in err
    assert "exit 1: the output was written but validation found errors" in err
    assert "WP-FID-006" in err.splitlines()[-1]


def test_convert_prints_the_fidelity_table(tmp_path, capsys):
    manifest = small_demo(tmp_path)
    assert main(["convert", str(manifest), "-o", str(tmp_path / "out"), "--no-render"]) == 0
    err = capsys.readouterr().err
    assert "fidelity (png, degrees inside each pose's active region" in err
    table = err[err.index("fidelity (png") :].splitlines()
    assert table[1].split() == ["pose", "mean", "p99", "max"]
    poses = {line.split()[0] for line in table[2:9]}
    assert {"joy", "surprise", "anger", "fear", "disgust", "sad"} <= poses


def test_an_offset_base_is_reported_with_its_shift(tmp_path, capsys):
    manifest = small_demo(tmp_path)
    base, _ = read_image(manifest.parent / "base_normal.png")
    write_image(manifest.parent / "base_normal.png", np.roll(base, (5, -3), axis=(0, 1)), bits=16)
    code = main(["convert", str(manifest), "-o", str(tmp_path / "out"), "--no-render"])
    err = capsys.readouterr().err
    assert code == 1
    line = next(x for x in err.splitlines() if "WP-FID-006" in x)
    # rolled by +5 rows (y) and -3 columns (x); moved back, the states fit it again
    assert "offset by (-3, 5) texels" in line and "an offset" in line, line


@needs_robot
def test_the_choices_and_the_rules_judge_the_poses_the_drivers_produce(request, tmp_path):
    """RobotExpressive with a blendshapes driver and no expressions driver: the searches and the
    validator judge the driver's frames, not the expression table."""
    out, report = request.getfixturevalue("robot")  # converted once for the document tests
    poses = {p["pose"]: p for p in report["fidelity"]["png"]["poses"]}
    # the manifest's keys: Angry peaks at t = 1 s (brow_L, brow_R), Surprised at 3 s (mouth)
    assert set(poses) == {"Angry @ 1.0 s", "Surprised @ 3.0 s"}
    # active texels on the 64^2 grid: a mask box of n 16^2 texels, magnified 4x bilinearly, is
    # non-zero on (n + 1) * 4 texels a side (brows 6 x 6 each, mouth 10 x 6)
    assert poses["Angry @ 1.0 s"]["texels"] == 2 * 28 * 28
    assert poses["Surprised @ 3.0 s"]["texels"] == 44 * 28
    v = tmp_path / "v.json"
    args = ["validate-asset", str(out), "--source", str(out.parent / "src" / "manifest.toml")]
    args += ["--no-render", "--report", str(v), "--allow-root", str(ROBOT.parent)]
    assert main(args) == 0
    measured = json.loads(v.read_text())["metrics"]["fidelity"]["poses"]
    assert {p["pose"]: p["texels"] for p in measured} == {k: p["texels"] for k, p in poses.items()}
    by_pose = {p["pose"]: set(p["regions"]) for p in measured}
    assert by_pose == {"Angry @ 1.0 s": {"brow_L", "brow_R"}, "Surprised @ 3.0 s": {"mouth"}}
