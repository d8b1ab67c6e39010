"""The fidelity pictures of the validator's HTML page: the numbers in them computed by hand (a
tiny asset), the PNGs read back by OpenImageIO, and the page of a converted demo."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from wrinklepipe import fidelity as fd
from wrinklepipe import model
from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.io.images import read_image
from wrinklepipe.validate import fidelity_pictures as fp
from wrinklepipe.validate import gl as glw
from wrinklepipe.validate import report as vr
from wrinklepipe.validate.run import Report


def tiny():
    """8x8, flat base, one state of slope 0.3 in x, one region: columns 2..3 (mask 1) and 4
    (mask 0.5); the shipped state lost its wrinkle at texel (row 5, column 3)."""
    base = np.zeros((8, 8, 3), np.float32)
    base[..., 2] = 1
    masks = np.zeros((1, 8, 8), np.float32)
    masks[0, :, 2:4] = 1.0
    masks[0, :, 4] = 0.5
    states = np.zeros((1, 8, 8, 2), np.float32)
    states[0, ..., 0] = 0.3
    poses = [fd.Pose("on", np.ones((1, 1), np.float32))]
    ref = fd.prepare(base, states, masks, poses, ["brow_L"])
    shipped = states.copy()
    shipped[0, 5, 3, 0] = 0.25
    fid = fd.measure(ref, base, shipped, masks, error_maps=True)
    return ref, fid, base, shipped, masks


def test_the_pictures_hold_the_hand_computed_normals_and_errors():
    ref, fid, base, shipped, masks = tiny()
    pics = fp.pose_pictures(ref, fid, base, shipped, masks)
    # active columns 2..4 with a 4-texel margin: the whole 8x8 grid
    err = pics["fidelity_error/on"]
    assert err.shape == (8, 8)
    want = np.degrees(np.arctan(0.3) - np.arctan(0.25))  # both tilts about the same axis
    assert err[5, 3] == pytest.approx(want, abs=1e-4)
    assert err[5, 2] == pytest.approx(0.0, abs=1e-4) and err[0, 0] == 0.0
    src = pics["fidelity_source/on"]
    n = np.array([0.15, 0.0, 1.0]) / np.sqrt(1 + 0.15**2)  # column 4: activation 0.5
    assert np.allclose(src[1, 4], 0.5 + 0.5 * n, atol=1e-5)
    assert np.allclose(src[1, 0], [0.5, 0.5, 1.0])  # inactive: the base
    shp = pics["fidelity_shipped/on"]
    n = np.array([0.25, 0.0, 1.0]) / np.sqrt(1 + 0.25**2)
    assert np.allclose(shp[5, 3], 0.5 + 0.5 * n, atol=1e-5)  # the weakened wrinkle
    assert np.allclose(shp[1, 4], src[1, 4], atol=1e-5)


def test_a_crop_keeps_the_wrinkled_area_and_large_crops_are_strided():
    assert fp.crop_box(np.array([2 * 100 + 40, 30 * 100 + 50]), (100, 100)) == (0, 37, 27, 64)
    flat, h, w = fp._crop_texels((0, 1024, 0, 1024), 2048, 512)
    assert (h, w) == (512, 512) and flat[1] == 2 and flat[512] == 2 * 2048


def test_the_heat_map_png_pixel_is_the_error_and_the_mask_thumbnail_its_value(tmp_path):
    ref, fid, base, shipped, masks = tiny()
    images = {
        **fp.pose_pictures(ref, fid, base, shipped, masks),
        **fp.mask_pictures(masks, ["brow_L"]),
    }
    report = Report(input={"name": "tiny", "regions": ["brow_L"]}, issues=[], images=images)
    pngs = vr.html_images(report)
    for name in ("fidelity_error_on.png", "region_mask_brow_L.png", "fidelity_source_on.png"):
        (tmp_path / name).write_bytes(pngs[name])
    heat, _ = read_image(tmp_path / "fidelity_error_on.png")
    e = np.degrees(np.arctan(0.3) - np.arctan(0.25))
    # the ramp at e / 5 degrees, by hand: between its stops i and i + 1
    t = e / vr.FIDELITY_HEAT_DEG * (len(vr._RAMP) - 1)
    i = int(t)
    want = vr._RAMP[i] * (1 - (t - i)) + vr._RAMP[i + 1] * (t - i)
    assert np.abs(heat[5, 3, :3] - want).max() <= 0.5 / 255 + 1e-6
    assert np.abs(heat[0, 0, :3] - vr._RAMP[0]).max() <= 0.5 / 255 + 1e-6  # 0 degrees
    mask, _ = read_image(tmp_path / "region_mask_brow_L.png")
    assert mask[0, 4, 0] == pytest.approx(128 / 255) and mask[0, 2, 0] == 1.0
    assert mask[0, 0, 0] == 0.0  # visible: grey levels, not a transparent channel
    src, _ = read_image(tmp_path / "fidelity_source_on.png")
    assert src[0, 0, :3] == pytest.approx([128 / 255, 128 / 255, 1.0])


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    d = tmp_path_factory.mktemp("pictures")
    manifest = write_demo_source(d / "demo", 32)
    out = d / "out"
    assert main(["convert", str(manifest), "-o", str(out), "--no-render"]) == 0
    pages = []
    for run in ("a", "b"):
        html = d / run / "page.html"
        code = main(
            [
                "validate-asset",
                str(out),
                "--source",
                str(manifest),
                "--no-render",
                "--html",
                str(html),
            ]
            + ["--report", str(d / run / "report.json")]
        )
        assert code == 0
        pages.append(html)
    return pages, d


def test_the_page_shows_the_measure_the_report_holds(page):
    (html, again), d = page
    text = html.read_text()
    doc = json.loads((d / "a" / "report.json").read_text())
    fid = doc["metrics"]["fidelity"]
    for p in fid["poses"]:
        row = re.search(rf"<tr><th>{p['pose']}</th>((?:<td>[^<]*</td>)+)</tr>", text)
        cells = re.findall(r"<td>([^<]*)</td>", row.group(1))
        assert cells[:4] == [
            str(p["mean_deg"]),
            str(p["p99_deg"]),
            str(p["max_deg"]),
            str(p["texels"]),
        ]
        for r, st in p["regions"].items():
            assert f"<td>{p['pose']}</td><th>{r}</th><td>{st['mean_deg']}</td>" in text
        for kind in ("source", "shipped", "error"):
            assert f"page_files/fidelity_{kind}_{p['pose']}.png" in text
    for r in doc["input"]["regions"]:
        assert f"page_files/region_mask_{r}.png" in text
    assert "linear-gradient" in text and "5 degrees" in text  # the colour bar, with its unit
    files = sorted(p.name for p in (d / "a" / "page_files").iterdir())
    assert [f for f in files if f"page_files/{f}" not in text] == []
    # a rerun writes the same bytes
    assert again.read_bytes() == html.read_bytes()
    for f in files:
        assert (d / "b" / "page_files" / f).read_bytes() == (
            d / "a" / "page_files" / f
        ).read_bytes()


def test_source_pictures_are_the_full_resolution_blend(page):
    (html, _), d = page
    doc = json.loads((d / "a" / "report.json").read_text())
    pose = doc["metrics"]["fidelity"]["poses"][0]["pose"]
    img, _ = read_image(d / "a" / "page_files" / f"fidelity_source_{pose}.png")
    # a normal map's picture: unit vectors 2 v - 1 (to 8-bit rounding)
    n = 2 * img[..., :3].astype(np.float64) - 1
    assert np.abs(np.linalg.norm(n, axis=-1) - 1).max() < 0.02
    assert model.normalize(n.astype(np.float32)).shape == n.shape


def _gl() -> bool:
    try:
        glw.create_context().release()
        return True
    except glw.GLUnavailable:
        return False


@pytest.mark.skipif(not _gl(), reason="no OpenGL 3.3 (EGL) on this machine")
def test_the_source_render_beside_the_shipped_one_shows_the_measured_angle(page, tmp_path):
    """With the render pass: per pose the source's and the shipped render (blended normals per
    pixel); the angle between the two pictures, read back from the PNGs, is the screen-space
    fidelity the report states (to the pictures' 8-bit rounding)."""
    _, d = page
    html = tmp_path / "page.html"
    args = ["validate-asset", str(d / "out"), "--source", str(d / "demo" / "manifest.toml")]
    assert main([*args, "--html", str(html), "--report", str(tmp_path / "r.json")]) == 0
    measured = json.loads((tmp_path / "r.json").read_text())["metrics"]["fidelity_render_deg"]
    text = html.read_text()
    for pose, st in measured.items():
        src, _ = read_image(tmp_path / "page_files" / f"render_source_{pose}.png")
        got, _ = read_image(tmp_path / "page_files" / f"render_shipped_{pose}.png")
        assert f"page_files/render_source_{pose}.png" in text
        covered = ~np.all(src[..., :3] == 1.0, axis=-1)  # white: no face there
        ns = 2 * src[..., :3][covered].astype(np.float64) - 1
        ng = 2 * got[..., :3][covered].astype(np.float64) - 1
        assert np.abs(np.linalg.norm(ns, axis=-1) - 1).max() < 0.01  # unit normals
        cos = (ns * ng).sum(-1) / np.linalg.norm(ns, axis=-1) / np.linalg.norm(ng, axis=-1)
        angle = np.degrees(np.arccos(np.clip(cos, -1, 1)))
        assert abs(angle.max() - st["max"]) < 0.6, (pose, angle.max(), st)


def test_converts_report_shows_each_mask_as_visible_grey_levels(page):
    """convert's report.html shows each region's mask beside the regions table: the validator's
    thumbnail, grey levels equal to the texels of the channel that holds it in the shipped
    mask texture (read by OpenImageIO with alpha unassociated)."""
    _, d = page
    out = d / "out"
    text = (out / "report.html").read_text()
    report = json.loads((out / "report.json").read_text())
    for r in report["asset"]["regions"]:
        thumb = f"validation_files/region_mask_{r['name']}.png"
        assert f"src='{thumb}'" in text
        grey, _ = read_image(out / thumb)
        tex, _ = read_image(out / "textures" / f"mask_{r['mask']['texture']}.png")
        want = tex[..., "rgba".index(r["mask"]["channel"])]
        assert grey.shape[:2] == want.shape and np.abs(grey[..., 0] - want).max() <= 0.5 / 255
        assert grey[..., 0].max() > 0  # the region is there, not black


def test_the_pictures_are_at_the_fastest_zlib_level():
    """The page's pictures are encoded at zlib level 1 (the zlib header says so: FLEVEL 0,
    RFC 1950; level 6 is FLEVEL 2), the same bytes on a rerun."""
    import struct
    import zlib

    ref, fid, base, shipped, masks = tiny()
    images = {**fp.pose_pictures(ref, fid, base, shipped, masks)}
    report = Report(input={"name": "tiny", "regions": ["brow_L"]}, issues=[], images=images)
    pngs = vr.html_images(report)
    assert vr.html_images(report) == pngs
    assert vr.PICTURE_PNG_LEVEL == 1
    for data in pngs.values():
        (n,) = struct.unpack(">I", data[33:37])
        assert data[37:41] == b"IDAT"
        idat = data[41 : 41 + n]
        assert idat[0] == 0x78 and idat[1] >> 6 == 0  # deflate, 32K window, fastest
        assert zlib.decompress(idat)  # one whole stream
