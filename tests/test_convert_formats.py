"""Every block format forced for the base and the states converts and validates with 0 errors.

The validator reads the compressed copies (``compressed/*.dds``) with the layouts the extension
records (x, y, z in R, G, B for BC1 / BC7; x, y for BC5; x in A and y in G for DXT5nm) and
renders them on the GPU against the numpy model; ``demo --size 2048`` used to fail exactly
here (BC7 written with B = 0, read with z from B).
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import alktx2
import numpy as np
import OpenImageIO as oiio
import pytest
import texture2ddecoder as t2d

from wrinklepipe import codec
from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.io.images import write_image
from wrinklepipe.normals import dds
from wrinklepipe.sources.validation import LoadOptions, load_input
from wrinklepipe.validate import ValidateOptions, validate
from wrinklepipe.validate.context import Context


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return write_demo_source(tmp_path_factory.mktemp("src") / "demo", size=64)


def _with_formats(manifest: Path, base: str, wrinkle: str, tmp: Path) -> Path:
    # a budget every format meets at 64^2 (BC1: ~3.3 degrees mean on the base): the test is
    # about reading the copies right; a wrong layout is tens of degrees off (176 at the 2048
    # demo's BC7 base)
    text = manifest.read_text().replace("max_mean_deg = 0.5", "max_mean_deg = 5.0")
    text = text.replace("max_p99_deg = 2.0", "max_p99_deg = 12.0")
    text += f'\n[formats]\nbase = "{base}"\nwrinkle = "{wrinkle}"\n'
    out = manifest.parent / f"manifest_{base}_{wrinkle}.toml"
    out.write_text(text)
    return out


@pytest.mark.parametrize("fmt", ["bc5", "bc7", "bc1", "bc3nm"])
def test_forced_format_converts_and_validates_clean(source, tmp_path, fmt):
    m = _with_formats(source, fmt, fmt, tmp_path)
    out = tmp_path / "out"
    code = main(["convert", str(m), "-o", str(out)])
    report = json.loads((out / "report.json").read_text())
    comp = report["compression"]
    assert comp["base"]["chosen"] == fmt and comp["wrinkle"]["chosen"] == fmt
    container = {"bc3nm": "bc3"}.get(fmt, fmt)
    for name in ("base_normal", "wrinkle_stretch", "wrinkle_compress"):
        img = dds.read_dds(out / "compressed" / f"{name}.dds")
        # a full chain, down to 1 x 1 (the states are stored at the size "auto" chose)
        assert (
            img.format == container and len(img.levels) == max(img.width, img.height).bit_length()
        )
    doc = json.loads((out / "demo_head.gltf").read_text())
    ext = doc["materials"][0]["extensions"]["WRINKLEPIPE_wrinkle_maps"]
    layouts = {
        doc["textures"][c["texture"]["index"]]["name"]: c["layout"] for c in ext["compressed"]
    }
    want = {"bc5": "rg", "bc7": "rgb", "bc1": "rgb", "bc3nm": "ag"}[fmt]
    assert layouts["base_normal"] == want
    assert layouts["wrinkle_stretch"] == ("ag" if fmt == "bc3nm" else "rg")  # pd slopes
    v = report["validation"]
    assert v["status"] == "ran" and v["counts"].get("error", 0) == 0, v["issues"]
    assert code in (0, 1)  # warnings may remain (a budget over BC1's error is one)
    # the validator's decode of the written copies equals the codec's decode of the texels
    # texture2ddecoder reads from the files, texel for texel; and a hand reading of them
    ctx = Context(load_input(out))
    rgba = {n: _t2d(out / "compressed" / f"{n}.dds") for n in ("base_normal", "wrinkle_stretch")}
    base = codec.decode("full", rgba["base_normal"], want)
    assert np.array_equal(ctx.shipped_base, base)
    v = rgba["base_normal"].astype(np.float64) / 255 * 2 - 1
    hand = {"rgb": v[..., :3], "rg": v[..., :2], "ag": v[..., [3, 1]]}[want]
    if hand.shape[-1] == 2:
        hand = np.dstack([hand, np.sqrt(np.maximum(0, 1 - (hand**2).sum(-1)))])
    hand /= np.linalg.norm(hand, axis=-1, keepdims=True)
    assert np.max(np.abs(ctx.shipped_base - hand)) < 2e-6
    k = [t.name for t in ctx.inp.state_textures()].index("wrinkle_stretch")
    scale = ctx.asset.pd_scale
    xy = rgba["wrinkle_stretch"][..., [3, 1] if fmt == "bc3nm" else [0, 1]]
    hand_pd = (np.maximum(xy.astype(np.float64), 1) - 128) / 127 * scale  # mapping v2
    assert np.max(np.abs(ctx.shipped_states[k] - hand_pd)) < 1e-6
    lay = "ag" if fmt == "bc3nm" else "rg"
    pd = codec.decode("pd", rgba["wrinkle_stretch"], lay, param=scale)
    assert np.array_equal(ctx.shipped_states[k], pd)


def _t2d(path: Path) -> np.ndarray:
    """Level 0 of a DDS as RGBA8, decoded by texture2ddecoder (BGRA order)."""
    img = dds.read_dds(path)
    fn = getattr(t2d, f"decode_{img.format}")
    px = np.frombuffer(fn(bytes(img.levels[0]), img.width, img.height), np.uint8)
    return px.reshape(img.height, img.width, 4)[..., [2, 1, 0, 3]]


@pytest.fixture(scope="module")
def steep_source(tmp_path_factory) -> Path:
    """The safety engineer's steep-wrinkle demo (tests/test_safety_answers.py): wrinkle_stretch
    tilted 60 degrees on 16 x 16 of the 32 x 32 map, so the PD scale goes above 1."""
    src = write_demo_source(tmp_path_factory.mktemp("steep") / "demo", size=32)
    n = np.zeros((32, 32, 3), np.float32)
    n[..., 2] = 1.0
    tilt = np.radians(60.0)
    n[8:24, 8:24] = (np.sin(tilt), 0.0, np.cos(tilt))
    write_image(src.parent / "wrinkle_stretch.png", n * 0.5 + 0.5, bits=16)
    return src


@pytest.mark.parametrize("fmt", ["auto", "bc7", "bc7xy"])
def test_steep_wrinkles_with_compressed_copies_validate_clean(steep_source, tmp_path, fmt):
    """The automatic choice (and BC7 either way) on the steep demo: the validator reads the
    base copy in the layout the writer used. bc7xy keeps x, y only (the extension records
    'rg'); the validator read it as x, y, z in R, G, B: z = -1 on every texel (WP-MAP-002),
    ~180 degrees from the source (WP-TEX-005)."""
    m = _with_formats(steep_source, fmt, "auto" if fmt == "auto" else fmt, tmp_path)
    out = tmp_path / "out"
    code = main(["convert", str(m), "-o", str(out), "--no-render"])
    report = json.loads((out / "report.json").read_text())
    base = report["compression"]["base"]
    if fmt != "auto":
        assert base["chosen"] == fmt
    doc = json.loads((out / "demo_head.gltf").read_text())
    ext = doc["materials"][0]["extensions"]["WRINKLEPIPE_wrinkle_maps"]
    rec = {doc["textures"][c["texture"]["index"]]["name"]: c for c in ext["compressed"]}
    want = {"bc5": "rg", "bc1": "rgb", "bc3nm": "ag", "bc7": "rgb", "bc7xy": "rg"}
    assert rec["base_normal"]["layout"] == base["layout"] == want[base["chosen"]]
    v = report["validation"]
    assert v["status"] == "ran" and v["counts"].get("error", 0) == 0, v["issues"]
    # what the validator measured on the copy is BC7's error, not 180 degrees
    check = base["checks"][base["chosen"]]["base_normal"]["error"]
    assert check["mean_deg"] < 1.0
    assert code == 0


def test_uastc_copies_when_asked(source, tmp_path):
    """formats = uastc: a Basis Universal KTX2 per map (basisu's UASTC LDR 4x4, the mip chain
    made here), no DDS; the validator reads it transcoded, with 0 errors."""
    m = _with_formats(source, "uastc", "uastc", tmp_path)
    out = tmp_path / "out"
    code = main(["convert", str(m), "-o", str(out), "--no-render"])
    report = json.loads((out / "report.json").read_text())
    v = report["validation"]
    assert v["status"] == "ran" and v["counts"].get("error", 0) == 0, v["issues"]
    assert code in (0, 1)
    comp = report["compression"]
    assert comp["base"]["chosen"] == comp["wrinkle"]["chosen"] == "uastc"
    doc = json.loads((out / "demo_head.gltf").read_text())
    ext = doc["materials"][0]["extensions"]["WRINKLEPIPE_wrinkle_maps"]
    rec = {doc["textures"][c["texture"]["index"]]["name"]: c for c in ext["compressed"]}
    assert rec["base_normal"]["layout"] == "rgb" and rec["wrinkle_stretch"]["layout"] == "rg"
    assert rec["base_normal"]["uris"] == ["compressed/base_normal.ktx2"]
    # no DDS of a normal map (the demo's colour maps choose their formats separately: BC7)
    normal_dds = [p.name for p in (out / "compressed").glob("*.dds") if "color" not in p.name]
    assert not normal_dds, normal_dds
    for name in ("base_normal", "wrinkle_stretch"):
        ktx = (out / "compressed" / f"{name}.ktx2").read_bytes()
        info = alktx2.inspect_ktx2(ktx)
        png = _oiio_png(out / "textures" / f"{name}.png")
        h, w = png.shape[:2]
        assert ktx[:12] == b"\xabKTX 20\xbb\r\n\x1a\n"
        assert rec[name]["levels"] == max(w, h).bit_length() == struct.unpack("<I", ktx[40:44])[0]
        assert info, info
        # transcoded by alktx2 (independent of the writer's check) = the PNG within UASTC's error
        got, _ = alktx2.decode_ktx2_to_bytes(ktx, format="png")
        p = tmp_path / f"{name}.png"
        p.write_bytes(got)
        dec = _oiio_png(p)
        c = [0, 1, 2] if name == "base_normal" else [0, 1]
        diff = np.abs(dec[..., c].astype(int) - png[..., c].astype(int))
        assert diff.mean() < 2.0 and diff.max() <= 40, (name, diff.mean(), diff.max())
        # the error the convert check reported is the one this reading measures (written out:
        # glTF 2 v / 255 - 1 normalised; pd v2 (v - 128) / 127 s, n = normalize(-d, 1))
        group = "base" if name == "base_normal" else "wrinkle"
        reported = comp[group]["checks"]["uastc"][name]["compression_error"]["mean_deg"]
        assert _mean_angle(dec, png, name, report["pd_scale"]["value"]) == pytest.approx(
            reported, abs=2e-3
        )


def _mean_angle(a: np.ndarray, b: np.ndarray, name: str, scale: float) -> float:
    def normals(v: np.ndarray) -> np.ndarray:
        v = v.astype(np.float64)
        if name == "base_normal":
            n = v[..., :3] / 255 * 2 - 1
        else:
            d = (np.maximum(v[..., :2], 1) - 128) / 127 * scale
            n = np.dstack([-d, np.ones(d.shape[:2])])
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    cos = np.clip((normals(a) * normals(b)).sum(-1), -1, 1)
    return float(np.degrees(np.arccos(cos)).mean())


def _oiio_png(path: Path) -> np.ndarray:
    buf = oiio.ImageBuf(str(path))
    return np.asarray(buf.get_pixels(oiio.UINT8))


def test_copies_judged_by_the_compressed_budget_everywhere(source, tmp_path):
    """A manifest whose ``compressed_max_*`` keys are looser than the maps' budget, BC1 forced:
    the copies the validator reads are inside the compressed budget, so neither the fidelity
    rules nor the shipping error (WP-TEX-005) call them over. WP-TEX-005 judged them by the
    maps' budget, which BC1 on the base is over at 64^2 (mean ~3 degrees against 0.5)."""
    text = source.read_text()
    maps = "[budget]\nmax_mean_deg = 0.5\nmax_p99_deg = 2.0\n"
    assert maps in text
    text = text.replace(
        maps, maps + "compressed_max_mean_deg = 8.0\ncompressed_max_p99_deg = 20.0\n"
    )
    m = source.parent / "manifest_loose_copies.toml"
    m.write_text(text + '\n[formats]\nbase = "bc1"\nwrinkle = "bc1"\n')
    out = tmp_path / "out"
    main(["convert", str(m), "-o", str(out), "--no-render"])
    report = json.loads((out / "report.json").read_text())
    assert report["compression"]["base"]["chosen"] == "bc1"
    codes = [i["code"] for i in report["validation"]["issues"]]
    assert "WP-TEX-005" not in codes and "WP-FID-001" not in codes, report["validation"]
    # the shipping error is over the maps' budget: judged by it, WP-TEX-005 would fire
    inp = load_input(out, LoadOptions(source=str(m)))
    assert any(t.is_block for t in inp.textures if t.role == "base")
    r = validate(inp, ValidateOptions(render=False))
    worst = max(s["mean"] for s in r.metrics["shipping_error_deg"].values())
    assert 0.5 < worst <= 8.0
