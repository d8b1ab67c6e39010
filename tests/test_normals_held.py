"""Normal maps held as their files' integers (wrinklepipe.normals.held): every way a stage reads
them gives the reader's float32 unit normals bit for bit, from 8- and 16-bit files of every
layout, read as OpenGL or DirectX."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_normals_read_lean import _write  # the 8/16-bit file writer

from wrinklepipe.normals import held
from wrinklepipe.normals.held import HeldMap, NormalStack
from wrinklepipe.normals.read import ReadOptions, read_normal_map


def _texels(rng: np.random.Generator, h: int, w: int, bits: int, layout: str) -> np.ndarray:
    """Integer texels of tilted unit normals in the file layout ``layout``."""
    n = rng.normal(0, 0.3, (h, w, 3))
    n[..., 2] = 1.0
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    top = (1 << bits) - 1
    q = np.rint((n * 0.5 + 0.5) * top).astype(np.uint8 if bits == 8 else np.uint16)
    if layout == "rg":
        return q[..., :2]
    if layout == "ag":
        a = np.full((h, w, 4), 0, q.dtype)
        a[..., 0] = top
        a[..., 1] = q[..., 1]
        a[..., 3] = q[..., 0]
        return a
    return q


def _read(tmp: Path, q: np.ndarray, convention: str):
    path = _write(tmp / f"n{q.shape[2]}_{q.dtype}.png", q)
    return read_normal_map(path, ReadOptions(convention=convention, detect=False))


@settings(
    max_examples=24, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    seed=st.integers(0, 2**31 - 1),
    h=st.integers(1, 40),
    w=st.integers(1, 40),
    bits=st.sampled_from([8, 16]),
    layout=st.sampled_from(["rgb", "rg", "ag"]),
    convention=st.sampled_from(["opengl", "directx"]),
)
def test_every_read_gives_the_readers_normals_bit_for_bit(
    tmp_path, seed, h, w, bits, layout, convention
):
    rng = np.random.default_rng(seed)
    nm = _read(tmp_path, _texels(rng, h, w, bits, layout), convention)
    assert nm.integers is not None and nm.layout == layout
    want = nm.normals.view(np.uint32)
    held = HeldMap(nm.integers, nm.layout, convention == "directx")
    one = NormalStack([held], single=True)
    assert one.shape == (h, w, 3) and one.dtype == np.float32
    assert np.array_equal(np.asarray(one).view(np.uint32), want)
    r0, r1 = sorted(rng.integers(0, h + 1, 2))
    assert np.array_equal(one[r0:r1].view(np.uint32), want[r0:r1])
    r = int(rng.integers(0, h))
    assert np.array_equal(one[r].view(np.uint32), want[r])
    rows, cols = rng.integers(0, h, 17), rng.integers(0, w, 17)
    assert np.array_equal(one[rows, cols].view(np.uint32), want[rows, cols])
    pick = rng.random((h, w)) < 0.3
    assert np.array_equal(one[pick].view(np.uint32), want[pick])
    assert np.array_equal(one[..., 1].view(np.uint32), want[..., 1])  # any other key: whole
    stack = NormalStack([held, held])
    assert stack.shape == (2, h, w, 3) and len(stack) == 2
    assert np.array_equal(stack[1, r0:r1].view(np.uint32), want[r0:r1])
    assert np.array_equal(stack[:, r0:r1].view(np.uint32), np.stack([want[r0:r1]] * 2))
    assert np.array_equal(np.asarray(stack[0]).view(np.uint32), want)


def test_a_directx_map_is_the_opengl_one_with_y_negated(tmp_path):
    q = _texels(np.random.default_rng(3), 9, 11, 16, "rgb")
    gl = NormalStack([HeldMap(q, "rgb", False)], single=True)
    dx = NormalStack([HeldMap(q, "rgb", True)], single=True)
    a, b = np.asarray(gl), np.asarray(dx)
    assert np.array_equal(b[..., 1], -a[..., 1]) and np.array_equal(b[..., ::2], a[..., ::2])
    # a hand-computed texel: 16-bit (65535, 32768, 32768) -> (1, 1/65535, 1/65535), normalised
    one = NormalStack([HeldMap(np.array([[[65535, 32768, 32768]]], np.uint16), "rgb", False)], True)
    e = np.float32(1 / 65535)
    want = np.array([1, e, e], np.float32) / np.sqrt(np.float32(1) + 2 * e * e)
    np.testing.assert_allclose(np.asarray(one)[0, 0], want, rtol=2e-7)


def test_it_behaves_as_the_float_array(tmp_path):
    q = _texels(np.random.default_rng(5), 6, 7, 8, "rgb")
    s = NormalStack([HeldMap(q, "rgb", False)] * 3)
    f = np.asarray(s)
    assert f.shape == (3, 6, 7, 3) and s.ndim == 4 and s.nbytes == f.nbytes
    assert s.held_bytes == q.nbytes * 3
    assert np.array_equal(s * 2, f * 2) and np.array_equal(np.clip(s, 0, 0.5), np.clip(f, 0, 0.5))
    assert np.array_equal(s.sum(axis=0), f.sum(axis=0))
    assert [x.shape for x in s] == [(6, 7, 3)] * 3
    assert copy.copy(s) is s and np.array_equal(np.asarray(copy.deepcopy(s)), f)
    assert s.map(2).shape == (6, 7, 3)
    with pytest.raises(TypeError):
        s[0] = 0  # nothing changes it in place
    with pytest.raises(ValueError, match="one size"):
        NormalStack([HeldMap(q, "rgb", False), HeldMap(q[:3], "rgb", False)])


def test_float_and_repaired_maps_keep_no_integers(tmp_path):
    q = _texels(np.random.default_rng(7), 5, 5, 16, "rgb")
    path = _write(tmp_path / "n.png", q)
    assert read_normal_map(path, ReadOptions(repair=True)).integers is None
    exr = tmp_path / "n.exr"
    out = oiio.ImageOutput.create(str(exr))
    out.open(str(exr), oiio.ImageSpec(5, 5, 3, oiio.FLOAT))
    out.write_image(np.ascontiguousarray(q.astype(np.float32) / 65535))
    out.close()
    assert read_normal_map(exr).integers is None


@pytest.mark.parametrize("layout", ["rgb", "rg"])
def test_a_map_larger_than_a_decode_chunk_is_the_readers(tmp_path, layout):
    """More texels than one chunk of the decode (held.DECODE_TEXELS): the same bits."""
    q = _texels(np.random.default_rng(9), 600, 520, 16, layout)
    nm = _read(tmp_path, q, "directx")
    one = NormalStack([HeldMap(nm.integers, nm.layout, True)], single=True)
    assert 600 * 520 > held.DECODE_TEXELS
    assert np.array_equal(np.asarray(one).view(np.uint32), nm.normals.view(np.uint32))
    assert np.array_equal(one[100:590].view(np.uint32), nm.normals[100:590].view(np.uint32))
