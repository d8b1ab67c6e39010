"""DDS and KTX2 containers, footprint, resampling, and the encode-normals command end to end."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from wrinklepipe.cli import main
from wrinklepipe.demo import character
from wrinklepipe.io.images import write_image
from wrinklepipe.metrics import Budget
from wrinklepipe.normals import compress as cmp
from wrinklepipe.normals import dds, footprint, ktx2, resample
from wrinklepipe.normals import encode as enc


def _blocks(fmt: str, w: int, h: int, seed: int = 0) -> bytes:
    rng = np.random.default_rng(seed)
    q = (rng.random((h, w, 2)) * 255).astype(np.uint8)
    qp, _ = cmp.pad_to_blocks(q)
    return cmp.encode_bc(cmp.pack_rgba(qp, fmt), fmt)


# --- DDS ------------------------------------------------------------------------------------


def test_dds_header_fields_by_hand():
    data = _blocks("bc5", 8, 8)
    raw = dds.dds_bytes("bc5", 8, 8, [data])  # DX10 by default for BC5
    assert raw[:4] == b"DDS "
    size, flags, height, width, linear = struct.unpack_from("<5I", raw, 4)
    assert (size, height, width, linear) == (124, 8, 8, 64)  # 2 x 2 blocks x 16 bytes
    assert raw[4 + 80 : 4 + 84] == b"DX10"
    dxgi, dim, _, array_size, _ = struct.unpack_from("<5I", raw, 128)
    assert (dxgi, dim, array_size) == (83, 3, 1)  # DXGI_FORMAT_BC5_UNORM, TEXTURE2D
    assert len(raw) == 128 + 20 + 64
    legacy = dds.dds_bytes("bc5", 8, 8, [data], dx10=False)
    assert legacy[4 + 80 : 4 + 84] == b"ATI2" and len(legacy) == 128 + 64
    assert dds.dds_bytes("bc1", 8, 8, [_blocks("bc1", 8, 8)])[84:88] == b"DXT1"
    assert dds.dds_bytes("bc3nm", 8, 8, [_blocks("bc3nm", 8, 8)])[84:88] == b"DXT5"
    with pytest.raises(ValueError, match="no legacy FourCC"):
        dds.dds_bytes("bc7", 8, 8, [bytes(64)], dx10=False)


@pytest.mark.parametrize("fmt", ["bc1", "bc3nm", "bc5", "bc7"])
def test_dds_roundtrip_with_mips(fmt):
    dims = dds.mip_dims(16, 8, 5)
    assert dims == [(16, 8), (8, 4), (4, 2), (2, 1), (1, 1)]
    levels = [_blocks(fmt, w, h, i) for i, (w, h) in enumerate(dims)]
    img = dds.read_dds(dds.dds_bytes(fmt, 16, 8, levels))
    assert img.format == dds.container_format(fmt)
    assert (img.width, img.height) == (16, 8)
    assert img.levels == levels


def test_dds_level_size_checked():
    with pytest.raises(ValueError, match="must hold 64 bytes"):
        dds.dds_bytes("bc5", 8, 8, [bytes(10)])


# --- KTX2 -----------------------------------------------------------------------------------


def test_ktx2_layout_by_hand():
    dims = dds.mip_dims(8, 8, 4)
    levels = [_blocks("bc5", w, h, i) for i, (w, h) in enumerate(dims)]
    raw = ktx2.ktx2_bytes("bc5", 8, 8, levels)
    assert raw[:12] == bytes.fromhex("AB4B5458203230BB0D0A1A0A")
    vk, type_size, w, h, depth, layers, faces, count, scheme = struct.unpack_from("<9I", raw, 12)
    assert (vk, type_size, w, h, depth, layers, faces, count, scheme) == (
        141,
        1,
        8,
        8,
        0,
        0,
        1,
        4,
        0,
    )
    dfd_off, dfd_len, kvd_off, kvd_len = struct.unpack_from("<4I", raw, 48)
    assert dfd_off == 80 + 24 * 4
    # DFD: total size, then the basic descriptor: BC5 model 132, BT.709, linear, 4x4 blocks
    words = struct.unpack_from(f"<{dfd_len // 4}I", raw, dfd_off)
    assert words[0] == dfd_len == 4 + 24 + 2 * 16
    assert words[1] == 0 and words[2] == 2 | (56 << 16)  # Khronos basic, v2, 24 + 2 samples
    assert words[3] == 132 | (1 << 8) | (1 << 16)  # BC5 model, BT.709, linear transfer
    assert words[4] == 0x0303 and words[5] == 16 and words[6] == 0  # 4x4 blocks, 16 bytes
    assert words[7] == 0x003F0000 and words[10] == 0xFFFFFFFF  # red: bits 0..63
    assert words[11] == 0x013F0040  # green: bits 64..127, channel 1
    # levels: smallest first in the file, 16-byte aligned, sizes as the format says
    offs = [struct.unpack_from("<3Q", raw, 80 + 24 * i) for i in range(4)]
    assert [o[1] for o in offs] == [64, 16, 16, 16]
    assert all(o[0] % 16 == 0 for o in offs)
    assert offs[3][0] < offs[2][0] < offs[1][0] < offs[0][0]
    assert offs[0][0] + 64 == len(raw)
    img = ktx2.read_ktx2(raw)
    assert img.levels == levels and img.format == "bc5"
    assert img.key_values["KTXorientation"] == b"rd"


@pytest.mark.parametrize("fmt,vk", [("bc1", 131), ("bc3nm", 137), ("bc7", 145)])
def test_ktx2_formats(fmt, vk):
    data = _blocks(fmt, 8, 8)
    raw = ktx2.ktx2_bytes(fmt, 8, 8, [data])
    assert struct.unpack_from("<I", raw, 12)[0] == vk
    assert ktx2.read_ktx2(raw).levels == [data]


# --- footprint ------------------------------------------------------------------------------


def test_paper_footprint_is_96_kb():
    assert footprint.texture_bytes("bc5", 256, 256) == 65536
    assert footprint.texture_bytes("rgba8", 64, 64) == 16384
    assert footprint.paper_total() == 96 * 1024
    # a full mip chain adds about a third: 256 + 64 + 16 + 4 + 1 + 1 + 1 + 1 + 1 blocks rows
    assert footprint.texture_bytes("bc5", 256, 256, mips=True) == 16 * (
        4096 + 1024 + 256 + 64 + 16 + 4 + 1 + 1 + 1
    )
    fp = footprint.footprint([("w", "bc5", 256, 256, False), ("m", "rgba8", 64, 64, False)])
    assert fp.total == 65536 + 16384
    assert fp.to_json()["paper_total_kb"] == 96.0


# --- resampling -----------------------------------------------------------------------------


def test_resize_pd_space_keeps_a_linear_slope_field():
    # slopes linear in x: PD space filtering keeps them linear (away from the border)
    x = np.linspace(-0.5, 0.5, 64)[None, :].repeat(64, 0)
    slopes = np.stack([x, 0.2 * np.ones_like(x)], -1).astype(np.float32)
    small = resample.resize_slopes(slopes, 16)
    xs = (np.arange(16) + 0.5) / 16 - 0.5  # texel centres of the 16-wide map
    expect = xs * (1.0 / (1 - 1 / 64))  # the 64 samples span [-0.5, 0.5] edge to edge
    np.testing.assert_allclose(small[8, 3:13, 0], expect[3:13], atol=2e-3)
    np.testing.assert_allclose(small[..., 1], 0.2, atol=1e-5)


def test_mip_chain_sizes_and_normal_mips_are_unit():
    n = character.generate(64).base_normal
    chain = resample.normal_mips(n)
    assert [c.shape[0] for c in chain] == [64, 32, 16, 8, 4, 2, 1]
    for c in chain:
        np.testing.assert_allclose(np.linalg.norm(c, axis=-1), 1.0, atol=1e-5)


def test_resize_masks_clipped():
    m = np.zeros((2, 32, 32), np.float32)
    m[0, 8:24, 8:24] = 1
    small = resample.resize_masks(m, 8)
    assert small.shape == (2, 8, 8) and small.min() >= 0 and small.max() <= 1
    assert small[0, 4, 4] == pytest.approx(1.0, abs=1e-3)


def test_reduction_error_grows_as_size_shrinks():
    d = character.generate(128)
    base = d.base_normal
    states = np.stack([enc.normal_slopes(d.wrinkle_only_normal(k)) for k in range(2)])
    w = np.zeros((8, 2), np.float32)
    w[:, 1] = 1.0
    e64 = resample.reduction_error(base, states, d.masks, [w], 64)
    e16 = resample.reduction_error(base, states, d.masks, [w], 16)
    assert e16.mean > e64.mean > 0
    size, tried = resample.auto_size(base, states, d.masks, [w], Budget(p99=1e9))
    assert size == 16 and 16 in tried


# --- the command end to end ------------------------------------------------------------------


@pytest.fixture(scope="module")
def demo_files(tmp_path_factory):
    d = character.generate(128)
    folder = tmp_path_factory.mktemp("demo")
    write_image(folder / "base.png", d.base_normal * 0.5 + 0.5, bits=16)
    write_image(folder / "compress.png", d.wrinkled_normal(1) * 0.5 + 0.5, bits=16)
    return folder, d


def _cli(*argv):
    return main(["encode-normals", *map(str, argv)])


def test_encode_normals_bc5_dds_report(tmp_path, demo_files, capsys):
    folder, d = demo_files
    out, rep = tmp_path / "c.dds", tmp_path / "r.json"
    code = _cli(folder / "compress.png", "--base", folder / "base.png", "-o", out, "--report", rep)
    assert code == 0
    r = json.loads(rep.read_text())
    assert r["format"]["name"] == "bc5" and r["format"]["levels"] == 8  # 128 .. 1
    assert r["encoding"]["name"] == "pd" and r["encoding"]["scale"] in (0.5, 1.0, 2.0, 4.0)
    chk = r["checks"][0]
    assert chk["error"]["p99_deg"] <= 2.0 and set(chk["blended"]) == {"0.5", "1"}
    img = dds.read_dds(out)
    assert img.format == "bc5" and len(img.levels) == 8
    assert img.levels[0] == cmp.encode_bc(
        cmp.pack_rgba(
            enc.encode_pd(
                __import__("wrinklepipe.model", fromlist=["pd_to_normal"]).pd_to_normal(
                    enc.normal_slopes(_read(folder / "compress.png"))
                    - enc.normal_slopes(_read(folder / "base.png"))
                ),
                r["encoding"]["scale"],
            ).texels,
            "bc5",
        ),
        "bc5",
    )
    assert r["encoding"]["mapping"] == 2 and r["format"]["layout"] == "rg"
    # rerun: byte-identical outputs
    out2, rep2 = tmp_path / "c2.dds", tmp_path / "r2.json"
    _cli(folder / "compress.png", "--base", folder / "base.png", "-o", out2, "--report", rep2)
    assert out2.read_bytes() == out.read_bytes()
    assert rep2.read_text().replace("c2.dds", "c.dds") == rep.read_text()


def _read(p: Path) -> np.ndarray:
    from wrinklepipe.normals.read import ReadOptions, read_normal_map

    return read_normal_map(p, ReadOptions(convention="opengl")).normals


def test_encode_normals_auto_format_ktx2_and_plain(tmp_path, demo_files, capsys):
    folder, _ = demo_files
    out = tmp_path / "a.ktx2"
    argv = [folder / "compress.png", "-o", out, "--format", "auto", "--json", "--max-p99", "45"]
    assert _cli(*argv) == 0
    r = json.loads(capsys.readouterr().out)
    assert {c["format"] for c in r["checks"]} == {"bc5", "bc1", "bc3nm", "bc7"}
    assert r["format"]["name"] in ("bc5", "bc1", "bc3nm", "bc7")
    assert ktx2.read_ktx2(out).format == dds.container_format(r["format"]["name"])
    png = tmp_path / "p.png"
    assert _cli(folder / "compress.png", "-o", png, "--format", "png16", "--size", "64") == 0
    from wrinklepipe.io.images import read_header

    h = read_header(png)
    assert (h.width, h.height, h.channels) == (64, 64, 3)
    diff = tmp_path / "d.dds"
    assert _cli(
        folder / "compress.png",
        "--base",
        folder / "base.png",
        "-o",
        diff,
        "--encoding",
        "diff",
        "--format",
        "bc1",
    ) in (0, 1)
    assert dds.read_dds(diff).format == "bc1"


def test_bench_normals_quick_smoke():
    from wrinklepipe.bench.normals import bench_normals

    r = bench_normals(True)
    steps = {row.step for row in r.rows}
    assert "bare BC5 encoder (normals.bc4.encode_bc5)" in steps
    assert "whole (fused, no read)" in steps
    assert all(row.mpix_per_s and row.mpix_per_s > 0 for row in r.rows)
    assert 0 < r.extra["error"]["mean_deg"] < 10.0
    demo = r.extra["bc5"]["demo base"]
    assert set(demo) >= {"ours", "exhaustive", "etcpak", "quicktex", "ispc_texcomp"}
    assert demo["ours"]["mean_deg"] <= 1.03 * demo["exhaustive"]["mean_deg"]
    assert demo["ours"]["mean_deg"] < demo["etcpak"]["mean_deg"]
    assert set(r.extra["formats"]) == {"bc1", "bc3", "bc7"}
    # the coarse-to-fine hard-block search against the encoder before it, in the same run
    assert "ours (before: whole hard window)" in demo and r.extra["bc5_before_over_now"] > 0


def test_bench_record_keeps_the_benchmarks_it_did_not_run(tmp_path):
    from wrinklepipe.commands.bench import _merged

    f = tmp_path / "results.json"
    f.write_text(json.dumps({"quick": False, "results": [{"name": "a"}, {"name": "normals"}]}))
    run = {"quick": False, "results": [{"name": "normals", "new": 1}]}
    assert _merged(str(f), run)["results"] == [{"name": "a"}, {"name": "normals", "new": 1}]
    assert _merged(str(f), {"quick": True, "results": []}) == {"quick": True, "results": []}
    f.write_text("{not json")
    assert _merged(str(f), run) == run
    assert _merged(str(tmp_path / "absent.json"), run) == run


def test_uastc_ktx2_when_basis_universal_is_installed(tmp_path, demo_files):
    pytest.importorskip("alktx2")
    folder, _ = demo_files
    out, rep = tmp_path / "u.ktx2", tmp_path / "u.json"
    argv = ["--base", folder / "base.png", "-o", out, "--format", "uastc", "--report", rep]
    assert _cli(folder / "compress.png", *argv, "--max-p99", "5") == 0
    raw = out.read_bytes()
    assert raw[:12] == bytes.fromhex("AB4B5458203230BB0D0A1A0A")
    r = json.loads(rep.read_text())
    chk = r["checks"][0]
    assert chk["format"] == "uastc" and chk["error"]["p99_deg"] <= 5.0
    # the same order as BC5 on the same map (both keep 8-bit-ish precision per channel);
    # BC5 from the near-exhaustive BC4 encoder is about twice as accurate as basisu's UASTC
    bc5 = tmp_path / "b.dds"
    rep5 = tmp_path / "b.json"
    _cli(folder / "compress.png", "--base", folder / "base.png", "-o", bc5, "--report", rep5)
    e5 = json.loads(rep5.read_text())["checks"][0]["error"]["mean_deg"]
    assert e5 < chk["error"]["mean_deg"] < 3 * e5


def test_uastc_refused_for_dds(tmp_path, demo_files, capsys):
    folder, _ = demo_files
    out = tmp_path / "u.dds"
    assert _cli(folder / "compress.png", "-o", out, "--format", "uastc") == 2
    assert not out.exists()
    assert "KTX2" in capsys.readouterr().err
