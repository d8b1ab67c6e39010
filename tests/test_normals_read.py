"""Reading normal maps: conventions, layouts, texel problems, bad files through the CLI."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from wrinklepipe.cli import main
from wrinklepipe.demo import character
from wrinklepipe.io.images import write_image
from wrinklepipe.normals import compress as cmp
from wrinklepipe.normals import dds
from wrinklepipe.normals.convention import detect_convention, flip_green
from wrinklepipe.normals.read import ReadOptions, decode_texels, read_normal_map

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
SAMPLES = DATA / "gltf-samples"


@pytest.fixture(scope="module")
def demo():
    return character.generate(128)


def _write16(path: Path, n: np.ndarray) -> Path:
    write_image(path, n * 0.5 + 0.5, bits=16)
    return path


def _write_u16(path: Path, q: np.ndarray) -> Path:
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(q.shape[1], q.shape[0], q.shape[2], oiio.UINT16))
    out.write_image(np.ascontiguousarray(q))
    out.close()
    return path


def test_directx_map_read_as_directx_equals_opengl_map(tmp_path, demo):
    n = demo.wrinkled_normal(1)
    q = np.rint((n * 0.5 + 0.5) * 65535).astype(np.uint16)
    gl = _write_u16(tmp_path / "gl.png", q)
    qd = q.copy()
    qd[..., 1] = 65535 - qd[..., 1]  # the DirectX map: green inverted
    dx = _write_u16(tmp_path / "dx.png", qd)
    a = read_normal_map(gl, ReadOptions(convention="opengl")).normals
    b = read_normal_map(dx, ReadOptions(convention="directx")).normals
    np.testing.assert_array_equal(a, b)  # texel for texel, bit for bit
    # and auto-detection gets there too
    c = read_normal_map(dx)
    assert c.convention == "directx"
    np.testing.assert_array_equal(c.normals, a)
    # 8-bit too
    q8 = np.rint((n * 0.5 + 0.5) * 255).astype(np.uint8)
    q8d = q8.copy()
    q8d[..., 1] = 255 - q8d[..., 1]
    write_image(tmp_path / "gl8.png", q8 / 255.0, bits=8)
    write_image(tmp_path / "dx8.png", q8d / 255.0, bits=8)
    a8 = read_normal_map(tmp_path / "gl8.png", ReadOptions(convention="opengl")).normals
    b8 = read_normal_map(tmp_path / "dx8.png", ReadOptions(convention="directx")).normals
    np.testing.assert_array_equal(a8, b8)


@pytest.mark.parametrize("k", [None, 0, 1])
def test_detection_on_demo_maps(demo, k):
    n = demo.base_normal if k is None else demo.wrinkled_normal(k)
    q = np.rint((n * 0.5 + 0.5) * 255) / 255 * 2 - 1  # as an 8-bit file holds it
    assert detect_convention(q).convention == "opengl"
    r = detect_convention(flip_green(q))
    assert r.convention == "directx" and r.confidence > 0.9


def test_detection_flat_map_is_undetermined():
    n = np.zeros((16, 16, 3), np.float32)
    n[..., 2] = 1
    assert detect_convention(n).convention == "undetermined"


def _glb_normal_png(glb: Path, tmp_path: Path) -> Path:
    pygltflib = pytest.importorskip("pygltflib")
    g = pygltflib.GLTF2().load(str(glb))
    blob = g.binary_blob()
    mat = next(m for m in g.materials if m.normalTexture is not None)
    img = g.images[g.textures[mat.normalTexture.index].source]
    bv = g.bufferViews[img.bufferView]
    start = bv.byteOffset or 0
    out = tmp_path / f"{glb.stem}_normal.png"
    out.write_bytes(blob[start : start + bv.byteLength])
    return out


@pytest.mark.shared
@pytest.mark.parametrize("name", ["NormalTangentTest", "NormalTangentMirrorTest", "DamagedHelmet"])
def test_detection_on_gltf_samples(tmp_path, name):
    glb = SAMPLES / name / "glTF-Binary" / f"{name}.glb"
    if not glb.exists():
        pytest.skip(f"{glb} not present")
    png = _glb_normal_png(glb, tmp_path)
    nm = read_normal_map(png)  # glTF normal maps are OpenGL (+Y)
    flipped = detect_convention(flip_green(nm.normals)).convention
    if name == "DamagedHelmet":
        # a hard-surface bake with mixed evidence: never guessed as DirectX, falls back to the
        # glTF convention and says so
        assert nm.detection.convention == "undetermined"
        assert nm.convention == "opengl"
        assert any("undetermined" in note for note in nm.notes)
    else:
        assert nm.detection.convention == "opengl" and nm.detection.confidence > 0.5
        assert flipped == "directx"


def test_two_channel_and_dxt5nm_rebuild_z():
    n = np.array([[[0.6, 0.0, 0.8], [0.0, -0.28, 0.96]]], np.float32)
    rg = (n[..., :2] + 1) / 2
    got, st = decode_texels(rg, "auto")
    np.testing.assert_allclose(got, n, atol=1e-6)
    assert st.non_unit == 0
    ag = np.stack([np.ones(2), rg[0, :, 1], np.zeros(2), rg[0, :, 0]], -1)[None]
    got, _ = decode_texels(ag, "auto")
    np.testing.assert_allclose(got, n, atol=1e-6)


def test_texel_problem_counts_and_repair(tmp_path):
    v = np.zeros((2, 3, 3), np.float32)
    v[..., 2] = 1
    v[0, 0] = np.nan
    v[0, 1] = 0.0
    v[1, 0] = (0.0, 0.0, -1.0)
    v[1, 1] = (0.0, 0.0, 0.5)  # non-unit
    n, st = decode_texels(v, "rgb", signed=True)
    assert (st.nan, st.zero, st.z_negative, st.non_unit) == (1, 1, 1, 1)
    assert st.first_nan == (0, 0) and st.first_zero == (0, 1)
    p = tmp_path / "bad.exr"
    write_image(p, v, bits=32)
    opts = ReadOptions(convention="opengl", repair=True)
    nm = read_normal_map(p, opts)
    assert nm.stats.repaired
    np.testing.assert_allclose(nm.normals[0, 0], [0, 0, 1])
    np.testing.assert_allclose(nm.normals[1, 0], [0, 0, 1])


def test_dds_bc5_ingest(tmp_path, demo):
    n = demo.wrinkled_normal(0)
    q = np.rint((n[..., :2] * 0.5 + 0.5) * 255).astype(np.uint8)
    data = cmp.encode_bc(cmp.pack_rgba(q, "bc5"), "bc5")
    p = tmp_path / "n.dds"
    p.write_bytes(dds.dds_bytes("bc5", 128, 128, [data]))
    nm = read_normal_map(p, ReadOptions(convention="opengl"))
    assert nm.source_format == "dds:bc5" and nm.layout == "rg"
    # by hand: x = 2 R / 255 - 1, y = 2 G / 255 - 1, z = sqrt(1 - x^2 - y^2)
    rgba = cmp.decode_bc(data, 128, 128, "bc5").astype(np.float64)
    x, y = rgba[..., 0] / 127.5 - 1, rgba[..., 1] / 127.5 - 1
    z = np.sqrt(np.maximum(0, 1 - x * x - y * y))
    hand = np.stack([x, y, z], -1)
    hand /= np.linalg.norm(hand, axis=-1, keepdims=True)
    np.testing.assert_allclose(nm.normals, hand, atol=2e-6)


def test_dds_dxt5nm_ingest(tmp_path):
    x = np.linspace(-0.5, 0.5, 8)[None, :].repeat(8, 0)
    y = np.linspace(0.4, -0.4, 8)[:, None].repeat(8, 1)
    q = np.rint((np.stack([x, y], -1) * 0.5 + 0.5) * 255).astype(np.uint8)
    data = cmp.encode_bc(cmp.pack_rgba(q, "bc3nm"), "bc3nm")
    p = tmp_path / "nm.dds"
    p.write_bytes(dds.dds_bytes("bc3nm", 8, 8, [data]))
    nm = read_normal_map(p, ReadOptions(convention="opengl"))
    assert nm.source_format == "dds:bc3" and nm.layout == "ag"
    np.testing.assert_allclose(nm.normals[..., 0], x, atol=0.04)  # BC3 alpha: 8 steps per block
    np.testing.assert_allclose(nm.normals[..., 1], y, atol=0.04)


# ------------------------------------------------------------------------------------------
# bad inputs through the CLI: one clear message, exit code 2, nothing written


def _run(capsys, *argv):
    code = main(["encode-normals", *map(str, argv)])
    captured = capsys.readouterr()
    return code, captured.err


def _assert_refused(capsys, out: Path, argv, *needles):
    code, err = _run(capsys, *argv)
    assert code == 2, err
    assert not out.exists()
    assert not any(out.parent.glob(f".{out.name}*"))  # no temp leftovers
    lines = [line for line in err.splitlines() if line.strip().startswith("error:")]
    assert len(lines) == 1, err
    for needle in needles:
        assert needle in " ".join(err.split()), err
    assert "Traceback" not in err


def test_bad_wrong_channel_count(tmp_path, capsys):
    p = tmp_path / "gray.png"
    write_image(p, np.full((8, 8), 0.5, np.float32), bits=8)
    out = tmp_path / "o.dds"
    _assert_refused(capsys, out, [p, "-o", out], "1 channel", "needs 2 (RG), 3 (RGB) or 4")


def test_bad_size_not_multiple_of_four_refused_with_no_pad(tmp_path, capsys):
    n = np.zeros((6, 10, 3), np.float32)
    n[..., 2] = 1
    p = _write16(tmp_path / "odd.png", n)
    out = tmp_path / "o.dds"
    _assert_refused(capsys, out, [p, "-o", out, "--no-pad"], "10 x 6 is not a multiple of 4")
    # default: padded, said clearly, written
    code, err = _run(capsys, p, "-o", out)
    assert code == 0 and out.exists()
    assert "padded to multiples of 4" in " ".join(err.split())
    img = dds.read_dds(out)
    assert (img.width, img.height) == (10, 6)


def test_bad_empty_file(tmp_path, capsys):
    p = tmp_path / "empty.png"
    p.write_bytes(b"")
    out = tmp_path / "o.dds"
    _assert_refused(capsys, out, [p, "-o", out], "empty")


def test_bad_truncated_png(tmp_path, capsys, demo):
    full = _write16(tmp_path / "full.png", demo.base_normal)
    p = tmp_path / "trunc.png"
    p.write_bytes(full.read_bytes()[:300])
    out = tmp_path / "o.dds"
    _assert_refused(capsys, out, [p, "-o", out], "trunc.png")


def test_bad_truncated_dds(tmp_path, capsys):
    data = cmp.encode_bc(np.zeros((8, 8, 4), np.uint8), "bc5")
    p = tmp_path / "t.dds"
    p.write_bytes(dds.dds_bytes("bc5", 8, 8, [data])[:-10])
    out = tmp_path / "o.dds"
    _assert_refused(capsys, out, [p, "-o", out], "truncated")


def test_bad_huge_header_refused_before_allocating(tmp_path, capsys):
    # a DDS header claiming 100000 x 100000 BC5 (10 GB of blocks) followed by nothing
    raw = bytearray(dds.dds_bytes("bc5", 4, 4, [bytes(16)]))
    struct.pack_into("<II", raw, 4 + 8, 100000, 100000)
    p = tmp_path / "huge.dds"
    p.write_bytes(bytes(raw))
    out = tmp_path / "o.dds"
    _assert_refused(capsys, out, [p, "-o", out], "100000 x 100000", "over the cap")
    # PNGs whose (valid, CRC-correct) header claims a huge size: only the header is read
    tiny = tmp_path / "tiny.png"
    write_image(tiny, np.zeros((1, 1, 3), np.float32), bits=8)
    for side, needle in ((100000, "100000"), (10000, "over the cap")):
        b = bytearray(tiny.read_bytes())
        struct.pack_into(">II", b, 16, side, side)  # IHDR width, height
        struct.pack_into(">I", b, 29, zlib.crc32(bytes(b[12:29])) & 0xFFFFFFFF)
        png = tmp_path / f"huge{side}.png"
        png.write_bytes(bytes(b))
        _assert_refused(capsys, out, [png, "-o", out], needle)
    # a configurable cap
    ok = _write16(tmp_path / "ok.png", np.dstack([np.zeros((8, 8, 2)), np.ones((8, 8))]))
    _assert_refused(capsys, out, [ok, "-o", out, "--max-pixels", "32"], "over the cap of 32")


def test_bad_nan_texels(tmp_path, capsys):
    v = np.zeros((8, 8, 3), np.float32)
    v[..., 2] = 1
    v[2, 5] = np.nan
    p = tmp_path / "nan.exr"
    write_image(p, v, bits=32)
    out = tmp_path / "o.dds"
    _assert_refused(capsys, out, [p, "-o", out], "1 NaN texel, first at row 2, col 5", "--repair")
    code, _ = _run(capsys, p, "-o", out, "--repair")
    assert code == 0 and out.exists()


def test_bad_diff_without_base_and_two_channel_format(tmp_path, capsys, demo):
    p = _write16(tmp_path / "w.png", demo.wrinkled_normal(0))
    out = tmp_path / "o.dds"
    _assert_refused(capsys, out, [p, "-o", out, "--encoding", "diff"], "needs --base")
    _assert_refused(
        capsys, out, [p, "-o", out, "--encoding", "diff", "--base", p], "three channels"
    )
