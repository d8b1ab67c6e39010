"""pack-masks end to end: files in, files out, read back; bad inputs give one message and exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wrinklepipe.cli import main
from wrinklepipe.io.images import quantize, read_image, write_image
from wrinklepipe.masks import check_masks, read_packed, resample_masks, unpack


def _write_masks(folder, names, masks, bits=8, ext="png"):
    paths = []
    for n, m in zip(names, masks):
        p = folder / f"{n}.{ext}"
        write_image(p, m, bits)
        paths.append(str(p))
    return paths


@pytest.mark.parametrize("layout", ["rgba", "array", "jimenez8", "lr-split"])
@pytest.mark.parametrize("bits", [8, 16])
def test_pack_masks_files_round_trip(tmp_path, layout, bits):
    rng = np.random.default_rng(7)
    names = ["forehead_outer_l", "forehead_outer_r", "glabella", "chin", "nose_l", "nose_r"]
    top = (1 << bits) - 1
    masks = (rng.integers(0, top + 1, (6, 5, 7)) / top).astype(np.float32)
    if layout == "lr-split":
        left = np.zeros((5, 7), bool)
        left[:, 4:] = True
        masks[[0, 4]] *= left
        masks[[1, 5]] *= ~left
    src = tmp_path / "src"
    paths = _write_masks(src, names, masks, bits)
    out = tmp_path / "out"
    assert main(["pack-masks", *paths, "--layout", layout, "-o", str(out)]) == 0
    p = read_packed(out)
    got_names, got = unpack(p.textures, p.table)
    assert list(got_names) == names
    np.testing.assert_array_equal(quantize(got, bits), quantize(masks, bits))
    doc = json.loads((out / "channels.json").read_text())
    assert doc["bits"] == bits and doc["layout"] == ("rgba" if layout == "jimenez8" else layout)
    # byte-identical rerun
    out2 = tmp_path / "out2"
    assert main(["pack-masks", *paths, "--layout", layout, "-o", str(out2)]) == 0
    for f in sorted(out.iterdir()):
        assert (out2 / f.name).read_bytes() == f.read_bytes()


def test_pack_masks_invert_reads_reis_convention(tmp_path):
    painted = np.array([[1.0, 0.0], [0.5, 0.25]], np.float32)  # white = none, black = full
    p = _write_masks(tmp_path, ["a"], [painted], 16)
    assert main(["pack-masks", *p, "--layout", "array", "--invert", "-o", str(tmp_path / "o")]) == 0
    _, got = unpack(read_packed(tmp_path / "o").textures, read_packed(tmp_path / "o").table)
    np.testing.assert_allclose(got[0], [[0.0, 1.0], [0.5, 0.75]], atol=1 / 65535)
    assert json.loads((tmp_path / "o" / "channels.json").read_text())["invert"] is True


def test_pack_masks_resamples_to_size(tmp_path):
    m = np.zeros((8, 8), np.float32)
    m[:4, :4] = 1.0
    m[4:, 4:] = 0.5
    p = _write_masks(tmp_path, ["a"], [m], 16)
    assert main(["pack-masks", *p, "--size", "2", "-o", str(tmp_path / "o")]) == 0
    tex, _ = read_image(tmp_path / "o" / "masks_0.png")
    np.testing.assert_allclose(tex[..., 0], [[1.0, 0.0], [0.0, 0.5]], atol=1 / 65535)


def test_pack_masks_fail_on_warning_fails_a_region_that_covers_nothing(tmp_path, capsys):
    brow = np.zeros((4, 4), np.float32)
    brow[:2] = 1.0
    paths = _write_masks(tmp_path, ["brow", "chin"], [brow, np.zeros((4, 4), np.float32)])
    args = ["pack-masks", *paths, "-o"]
    assert main([*args, str(tmp_path / "a")]) == 0  # a warning, written, exit 0 by default
    assert "region 'chin' covers nothing" in capsys.readouterr().err
    assert main([*args, str(tmp_path / "b"), "--fail-on", "warning", "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert (tmp_path / "b" / "channels.json").is_file() and out["report"]["empty"] == ["chin"]
    both = _write_masks(tmp_path / "ok", ["brow", "chin"], [brow, 1.0 - brow])
    assert main(["pack-masks", *both, "-o", str(tmp_path / "c"), "--fail-on", "warning"]) == 0


def test_resample_box_and_bilinear():
    m = np.zeros((1, 4, 4), np.float32)
    m[0, :2, :2] = 1.0
    np.testing.assert_allclose(resample_masks(m, 2)[0], [[1, 0], [0, 0]])
    np.testing.assert_allclose(resample_masks(m, 1)[0], [[0.25]])
    up = resample_masks(np.ones((1, 3, 3), np.float32) * 0.3, 5)
    np.testing.assert_allclose(up, 0.3, atol=1e-6)


def test_check_masks_reports_overlap_coverage_and_empty():
    m = np.zeros((3, 2, 4), np.float32)
    m[0, :, :2] = 1.0  # covers half
    m[1, 0, 1:3] = 0.5  # overlaps region 0 at (x=1, y=0): sum 1.5
    rep = check_masks(m, ["a", "b", "c"])
    assert rep.empty == ["c"]
    assert rep.regions[0].coverage == pytest.approx(0.5)
    assert rep.regions[1].coverage == pytest.approx(2 / 8)
    assert rep.overlap_texels == 1 and rep.overlap_max == pytest.approx(1.5)
    assert rep.overlap_worst == (1, 0)
    assert rep.uncovered_fraction == pytest.approx(3 / 8)
    assert any("covers nothing" in w for w in rep.warnings)


# ---- bad inputs: one clear message each, exit code 2 -------------------------------------------


def _run_bad(capsys, argv):
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, err
    return " ".join(err.split())


def test_bad_masks_of_different_sizes(tmp_path, capsys):
    a = _write_masks(tmp_path, ["a"], [np.zeros((4, 4), np.float32)])
    b = _write_masks(tmp_path, ["b"], [np.zeros((4, 8), np.float32)])
    msg = _run_bad(capsys, ["pack-masks", *a, *b, "-o", str(tmp_path / "o")])
    assert "b.png" in msg and "different sizes" in msg and "8 x 4" in msg
    assert not (tmp_path / "o").exists()


def test_bad_rgb_mask_whose_channels_differ(tmp_path, capsys):
    rgb = np.zeros((4, 4, 3), np.float32)
    rgb[2, 1] = (0.5, 0.2, 0.5)
    write_image(tmp_path / "rgb.png", rgb, 8)
    msg = _run_bad(capsys, ["pack-masks", str(tmp_path / "rgb.png"), "-o", str(tmp_path / "o")])
    assert "rgb.png" in msg and "channels differ" in msg and "(x=1, y=2)" in msg


def test_grey_rgb_mask_is_accepted(tmp_path):
    g = np.linspace(0, 1, 16, dtype=np.float32).reshape(4, 4)
    write_image(tmp_path / "g.png", np.stack([g, g, g], -1), 8)
    assert main(["pack-masks", str(tmp_path / "g.png"), "-o", str(tmp_path / "o")]) == 0


def test_bad_negative_values_in_float_tiff(tmp_path, capsys):
    m = np.full((4, 4), 0.5, np.float32)
    m[3, 2] = -0.25
    write_image(tmp_path / "neg.tif", m, 32)
    msg = _run_bad(capsys, ["pack-masks", str(tmp_path / "neg.tif"), "-o", str(tmp_path / "o")])
    assert "neg.tif" in msg and "negative" in msg and "-0.25" in msg and "(x=2, y=3)" in msg


def test_bad_duplicate_region_names(tmp_path, capsys):
    p = _write_masks(tmp_path, ["a", "b"], [np.zeros((2, 2), np.float32)] * 2)
    msg = _run_bad(capsys, ["pack-masks", *p, "--names", "brow,brow", "-o", str(tmp_path / "o")])
    assert "duplicate region name 'brow'" in msg and "b.png" in msg


def test_bad_more_regions_than_the_layout_holds(tmp_path, capsys):
    names = [f"z{i}" for i in range(9)]
    p = _write_masks(tmp_path, names, [np.zeros((2, 2), np.float32)] * 9)
    msg = _run_bad(capsys, ["pack-masks", *p, "--layout", "jimenez8", "-o", str(tmp_path / "o")])
    assert "'jimenez8' holds at most 8 regions, got 9" in msg


def test_bad_unknown_metahuman_region(tmp_path, capsys):
    p = _write_masks(tmp_path, ["brow"], [np.zeros((2, 2), np.float32)])
    msg = _run_bad(capsys, ["pack-masks", *p, "--layout", "metahuman", "-o", str(tmp_path / "o")])
    assert "'brow' is not a MetaHuman region" in msg


def test_pack_masks_metahuman_files_and_json(tmp_path, capsys):
    from wrinklepipe.presets import metahuman

    names = ["head_wm2_browsDown_L", "head_wm13_lips_UR", "head_wm1_jawOpen"]
    rng = np.random.default_rng(3)
    masks = (rng.integers(0, 256, (3, 4, 6)) / 255).astype(np.float32)
    paths = _write_masks(tmp_path / "src", names, masks)
    out = tmp_path / "mh"
    assert main(["pack-masks", *paths, "--layout", "metahuman", "-o", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["table"][1] == {"region": "head_wm13_lips_UR", "texture": 9, "channel": "a"}
    assert doc["table"][0] == {"region": "head_wm2_browsDown_L", "texture": 4, "channel": "r"}
    assert [r["name"] for r in doc["report"]["regions"]] == names
    files = sorted(p.name for p in out.iterdir())
    assert files == sorted(
        ["channels.json", "masks_array.png"] + [f"masks_{t}.png" for t in range(10)]
    )
    p = read_packed(out)
    assert p.textures.shape == (10, 4, 6, 4) and p.array is not None
    for packed in (p, p.array):
        got_names, got = unpack(packed.textures, packed.table)
        assert list(got_names) == names
        np.testing.assert_array_equal(quantize(got, 8), quantize(masks, 8))
    assert metahuman.side_of("head_wm13_lips_UR") == "right"
    assert (
        metahuman.shader_parameter("head_wm1_jawOpen", "wm1") == "head_wm1_normal_head_wm1_jawOpen"
    )
