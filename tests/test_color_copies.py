"""The colour maps' block-compressed copies: sRGB BC1 / BC7 in DDS and KTX2, mips made in
linear light (a checkerboard), checked by an independent decoder and CIEDE2000."""

from __future__ import annotations

import os
import struct

import numpy as np
import pytest
import texture2ddecoder

from wrinklepipe.codec import srgb
from wrinklepipe.color import copies as cc
from wrinklepipe.normals.dds import read_dds
from wrinklepipe.normals.ktx2 import read_ktx2

os.environ.setdefault("COLOUR_SCIENCE__FILTER_USAGE_WARNINGS", "True")
colour = pytest.importorskip("colour")
_SRGB = colour.RGB_COLOURSPACES["sRGB"]


def _de(a, b):
    def lab(x):
        xyz = colour.RGB_to_XYZ(np.asarray(x, np.float64), _SRGB, apply_cctf_decoding=False)
        return colour.XYZ_to_Lab(xyz, _SRGB.whitepoint)

    return colour.delta_E(lab(a), lab(b), method="CIE 2000")


def _checker(n: int) -> np.ndarray:
    c = (np.add.outer(np.arange(n), np.arange(n)) % 2 * 255).astype(np.uint8)
    return np.repeat(c[..., None], 3, axis=-1)


def test_a_checkerboards_mips_are_the_linear_average():
    """Black and white texels average to half the light: linear 0.5, sRGB 188 (by
    colour-science's inverse EOTF), not the 128 of averaging the encoded values."""
    want = int(np.rint(colour.models.eotf_inverse_sRGB(0.5) * 255))
    assert want == 188
    levels = cc.linear_mips(_checker(8))
    assert [lv.shape[:2] for lv in levels] == [(4, 4), (2, 2), (1, 1)]
    for lv in levels:
        assert np.all(lv == want)


@pytest.mark.parametrize("fmt", ["bc1", "bc7"])
def test_a_checkerboards_compressed_mips_decode_to_the_linear_average(fmt):
    copy = cc.color_copy("check", _checker(16), fmt)
    assert len(copy.levels) == 5  # 16, 8, 4, 2, 1
    # level 1 (8 x 8) decoded by texture2ddecoder (BGRA): flat 188 within BC1's 5/6-bit steps
    decode = texture2ddecoder.decode_bc1 if fmt == "bc1" else texture2ddecoder.decode_bc7
    bgra = np.frombuffer(decode(copy.levels[1], 8, 8), np.uint8).reshape(8, 8, 4)
    assert np.all(np.abs(bgra[..., :3].astype(int) - 188) <= 4)
    # and level 0 keeps the checkerboard
    assert np.all(np.abs(copy.decoded.astype(int) - _checker(16).astype(int)) <= 4)


def _skin(n: int) -> np.ndarray:
    yy, xx = np.mgrid[0:n, 0:n] / n
    lin = np.stack(
        [0.55 + 0.1 * np.sin(6 * xx), 0.3 + 0.05 * np.cos(5 * yy), 0.22 + 0.04 * xx * yy], -1
    )
    rng = np.random.default_rng(5)
    lin *= 1.0 - 0.2 * rng.random((n, n, 1))  # pores
    return srgb.encode_texels(lin)


@pytest.mark.parametrize("fmt, mean_de", [("bc1", 1.5), ("bc7", 0.75)])
def test_level_zero_is_close_to_the_map_in_ciede2000(fmt, mean_de):
    skin = _skin(64)
    copy = cc.color_copy("skin", skin, fmt, with_mips=False)
    err = _de(srgb.decode_texels(copy.decoded), srgb.decode_texels(skin))
    assert float(err.mean()) < mean_de


@pytest.mark.parametrize("fmt, dxgi, vk", [("bc1", 72, 132), ("bc7", 99, 146)])
def test_containers_record_the_srgb_formats(fmt, dxgi, vk):
    copy = cc.color_copy("skin", _skin(32), fmt)
    files = copy.files()
    dds = files["compressed/skin.dds"]
    assert dds[84:88] == b"DX10"  # the DX10 header: DXT1 has no sRGB FourCC
    assert struct.unpack_from("<I", dds, 128)[0] == dxgi
    img = read_dds(dds)
    assert img.srgb and img.format == fmt and len(img.levels) == 6
    ktx = files["compressed/skin.ktx2"]
    assert struct.unpack_from("<I", ktx, 12)[0] == vk
    k = read_ktx2(ktx)
    assert k.srgb and [bytes(x) for x in k.levels] == [bytes(x) for x in img.levels]
    # the data format descriptor's transfer function: KHR_DF_TRANSFER_SRGB (2)
    word = struct.unpack_from("<I", k.dfd, 4 + 8)[0]
    assert (word >> 16) & 0xFF == 2
    rec = copy.record()
    assert (rec.color_space, rec.layout, rec.levels) == ("srgb", "rgb", 6)


def test_16_bit_colour_maps_have_no_block_copy():
    with pytest.raises(ValueError, match="8-bit"):
        cc.color_copy("deep", np.zeros((8, 8, 3), np.uint16), "bc7")
