"""Reading 8/16-bit normal maps as their files' integers (issue 42): the texels read in their
native type, their float32 values made a band at a time, and every answer of the reader (counts,
layout, refusals, notes, convention detection) the same, bit for bit, as reading the whole map
as float32 values and decoding it whole (the reader's steps before, made here from the
float32 read)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from wrinklepipe.errors import InputError
from wrinklepipe.io.images import read_image, texel_values
from wrinklepipe.normals import convention as nc
from wrinklepipe.normals import read as nr
from wrinklepipe.normals.convention import detect_convention, flip_green
from wrinklepipe.normals.held import HeldMap, NormalStack
from wrinklepipe.normals.identify import looks_like


def _write(path: Path, q: np.ndarray) -> Path:
    fmt = oiio.UINT8 if q.dtype == np.uint8 else oiio.UINT16
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(q.shape[1], q.shape[0], q.shape[2], fmt))
    out.write_image(np.ascontiguousarray(q))
    out.close()
    return path


FILES = [(".png", np.uint8), (".png", np.uint16), (".tif", np.uint8), (".tif", np.uint16)]


@pytest.mark.parametrize(("suffix", "dtype"), FILES)
def test_integers_read_natively_are_the_float_read_bit_for_bit(tmp_path, suffix, dtype):
    """Every integer value of the file's type: OpenImageIO's float32 read is texel_values of
    its native read (float32(q) * float32(1 / top)), bit for bit."""
    top = np.iinfo(dtype).max
    q = np.arange(top + 1, dtype=np.int64).reshape(-1, 256) % (top + 1)
    q = np.stack([q, top - q, (q * 7) % (top + 1)], axis=-1).astype(dtype)
    path = _write(tmp_path / f"all{suffix}", q)
    f, info = read_image(path)
    got, info2 = read_image(path, integers=True)
    assert got.dtype == dtype and np.array_equal(got, q) and info2 == info
    assert f.dtype == np.float32
    assert np.array_equal(texel_values(got).view(np.uint32), f.view(np.uint32))
    # and the hand value: 16-bit 1 -> float32(1) * float32(1/65535)
    assert texel_values(np.array([1], dtype))[0] == np.float32(1) * np.float32(1 / top)


def test_a_float_file_reads_as_float_either_way(tmp_path):
    path = tmp_path / "n.exr"
    a = np.random.default_rng(1).random((5, 6, 3)).astype(np.float32)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(6, 5, 3, oiio.FLOAT))
    out.write_image(a)
    out.close()
    f, _ = read_image(path, integers=True)
    assert f.dtype == np.float32 and np.array_equal(f, a)


def _edgy(rng: np.random.Generator, h: int, w: int, c: int, bits: int) -> np.ndarray:
    """Integer texels on the layout tests' edges: red near the top, blue near 0."""
    top = (1 << bits) - 1
    q = rng.integers(0, top + 1, (h, w, c))
    near = rng.integers(0, 3, (h, w))
    q[..., 0] = np.where(rng.random((h, w)) < 0.9, top - near, q[..., 0])
    if c >= 3:
        q[..., 2] = np.where(rng.random((h, w)) < 0.9, near, q[..., 2])
    if rng.random() < 0.5:  # often every texel on the edge's side
        q[..., 0] = top - (near == 0)
        if c >= 3:
            q[..., 2] = near * (rng.random() < 0.5)
    return q.astype(np.uint8 if bits == 8 else np.uint16)


@settings(max_examples=120, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    h=st.integers(1, 9),
    w=st.integers(1, 9),
    c=st.sampled_from([2, 3, 4]),
    bits=st.sampled_from([8, 16]),
)
def test_layout_of_integers_is_the_layout_of_their_values(seed, h, w, c, bits):
    q = _edgy(np.random.default_rng(seed), h, w, c, bits)
    assert nr.guess_layout(q) == nr.guess_layout(texel_values(q))
    for layout in nr.LAYOUTS:
        try:
            want = nr.resolved_layout(texel_values(q), layout)
        except ValueError as exc:
            with pytest.raises(ValueError, match=str(exc).replace("(", r"\(").replace(")", r"\)")):
                nr.resolved_layout(q, layout)
        else:
            assert nr.resolved_layout(q, layout) == want


def test_layout_thresholds_by_hand():
    """8-bit: red 255 and blue 0 everywhere is DXT5nm; red 254 is not (254/255 < 254.5/255);
    16-bit: blue 128 of 65535 is still 'zero' (128/65535 <= 0.5/255), 129 is not."""
    a = np.zeros((2, 2, 4), np.uint8)
    a[..., 0] = 255
    assert nr.guess_layout(a) == "ag"
    a[0, 0, 0] = 254
    assert nr.guess_layout(a) == "rg"
    b = np.zeros((2, 2, 3), np.uint16)
    b[..., 2] = 128
    assert nr.guess_layout(b) == "rg"
    b[1, 1, 2] = 129
    assert nr.guess_layout(b) == "rgb"


KINDS = ["normal", "grey", "colour", "flat", "holes", "object", "rg", "rgba"]


def _kinds(rng: np.random.Generator, h: int, w: int, bits: int) -> dict[str, np.ndarray]:
    top = (1 << bits) - 1
    n = rng.normal(0, 0.3, (h, w, 3))
    n[..., 2] = 1.0
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    dt = np.uint8 if bits == 8 else np.uint16
    normal = np.rint((n * 0.5 + 0.5) * top).astype(dt)
    grey = np.repeat(rng.integers(0, top + 1, (h, w, 1)), 3, axis=-1).astype(dt)
    colour = rng.integers(0, top + 1, (h, w, 3)).astype(dt)
    flat = np.full((h, w, 3), (top + 1) // 2, dt)
    holes = normal.copy()
    holes[rng.random((h, w)) < 0.01] = (top + 1) // 2  # a few zero-length texels
    object_space = np.rint((-n * 0.5 + 0.5) * top).astype(dt)
    return {
        "normal": normal,
        "grey": grey,
        "colour": colour,
        "flat": flat,
        "holes": holes,
        "object": object_space,
        "rg": np.ascontiguousarray(normal[..., :2]),
        "rgba": np.concatenate([normal, np.full((h, w, 1), top, dt)], axis=-1),
    }


@pytest.mark.parametrize("bits", [8, 16])
def test_looks_like_of_integers_is_of_their_values(bits):
    """On a map big enough to be judged on a lattice (1100 x 1000 texels: every 2nd) and a
    small one: the same words, numbers and all."""
    rng = np.random.default_rng(bits)
    for h, w in ((1100, 1000), (13, 17)):
        for name, q in _kinds(rng, h, w, bits).items():
            for layout in ("rgb", "rg", "ag"):
                want = looks_like(texel_values(q), layout)
                assert looks_like(q, layout) == want, (name, layout)
                if name == "colour" and layout == "rgb":
                    assert want.startswith("a colour image")


def _whole(q: np.ndarray, layout: str) -> tuple[np.ndarray, nr.NormalStats]:
    """The reader's decode before: the whole map's float32 values, decoded whole."""
    bits = 8 if q.dtype == np.uint8 else 16
    return nr.decode_texels(texel_values(q), layout, False, 0.05, bits)


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    seed=st.integers(0, 2**31 - 1),
    kind=st.sampled_from(KINDS),
    bits=st.sampled_from([8, 16]),
    rows=st.integers(1, 7),
)
def test_banded_counts_and_normals_are_the_whole_maps(monkeypatch, seed, kind, bits, rows):
    rng = np.random.default_rng(seed)
    q = _kinds(rng, int(rng.integers(1, 30)), int(rng.integers(1, 30)), bits)[kind]
    lay = nr.resolved_layout(q, "auto")
    want, ws = _whole(q, "auto")
    monkeypatch.setattr(nr, "band_rows", lambda width, per: rows)
    monkeypatch.setattr(nc, "band_rows", lambda width, per: rows)
    out = np.full((*q.shape[:2], 3), 7.0, np.float32)
    got, gs = nr.decode_integers(q, lay, 0.05, out=out)
    assert got is out and gs == ws
    assert np.array_equal(out.view(np.uint32), want.view(np.uint32))
    none, ns = nr.decode_integers(q, lay, 0.05)
    assert none is None and ns == ws
    rows_of = NormalStack([HeldMap(q, lay, False)], single=True)  # as detection reads it
    r0, r1 = sorted(int(x) for x in rng.integers(0, q.shape[0] + 1, 2))
    assert np.array_equal(rows_of[r0:r1].view(np.uint32), want[r0:r1].view(np.uint32))
    assert detect_convention(rows_of) == detect_convention(want)


def _before(path: Path, o: nr.ReadOptions) -> dict[str, object]:
    """What the reader answered before (issue 42): the map read whole as float32 values,
    decoded whole, judged whole; its normals, or its refusal."""
    try:
        values, info = read_image(path, o.max_pixels)
        bits = {"uint8": 8, "uint16": 16}[info.format]
        try:
            normals, stats = nr.decode_texels(values, o.layout, False, o.unit_tolerance, bits)
        except ValueError as exc:
            return {"refused": f"{path}: {exc}"}
        layout = o.layout if o.layout != "auto" else nr.guess_layout(values)
        what = looks_like(values, layout)
    except InputError as exc:
        return {"refused": str(exc)}
    det = detect_convention(normals)
    return {
        "stats": stats,
        "layout": layout,
        "what": what,
        "detection": det,
        "normals": normals,
    }


@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("convention", ["auto", "opengl", "directx"])
def test_the_reader_answers_as_before(tmp_path, monkeypatch, bits, kind, convention):
    """Read held (integers, nothing made whole), read with normals, and the whole-map
    computation of before: the same counts, layout, detection, notes and refusals."""
    rng = np.random.default_rng(bits * 100 + len(kind))
    q = _kinds(rng, 37, 29, bits)[kind]
    path = _write(tmp_path / f"{kind}.png", q)
    monkeypatch.setattr(nr, "band_rows", lambda width, per: 4)
    monkeypatch.setattr(nc, "band_rows", lambda width, per: 3)
    o = nr.ReadOptions(convention=convention)
    before = _before(path, o)
    answers = []
    for held in (True, False):
        try:
            answers.append(nr.read_normal_map(path, o, held=held))
        except InputError as exc:
            answers.append(str(exc))
    if isinstance(answers[0], str):
        assert answers[0] == answers[1]
        assert kind in ("grey", "colour", "flat", "holes", "object")
        if "refused" in before:
            assert answers[0] == before["refused"]
            return
        st_ = before["stats"]
        if before["what"] and st_.short != st_.texels:
            assert f"it looks like {before['what']}" in answers[0]
        else:
            assert st_.zero or st_.short  # refused for its texels
            assert f"{st_.short} of {st_.texels} texels too short" in answers[0] or (
                f"{st_.zero} zero-length texel" in answers[0]
            )
        return
    held, plain = answers
    assert held.normals is None  # (a two-channel PNG is grey + alpha: the file's own texels)
    assert np.array_equal(held.integers, read_image(path, integers=True)[0])
    assert held.to_json() == plain.to_json() and held.notes == plain.notes
    assert held.stats == before["stats"] and held.layout == before["layout"]
    assert before["what"] == "" and held.detection == before["detection"]
    want = before["normals"]
    want = flip_green(want) if plain.convention == "directx" else want
    assert np.array_equal(plain.normals.view(np.uint32), want.view(np.uint32))
    one = NormalStack([HeldMap(held.integers, held.layout, held.convention == "directx")], True)
    assert np.array_equal(np.asarray(one).view(np.uint32), plain.normals.view(np.uint32))


def _detect_whole(n: np.ndarray, mask: np.ndarray | None) -> tuple[float, float, float, int]:
    """The curl test's numbers as first written, on the whole map at once (every difference,
    jump and kept term gathered whole): (curl_opengl, curl_directx, signal, used)."""
    a, b, valid, jump = nc._curl_terms(n, mask)
    jumps = jump[valid]
    if jumps.size == 0:
        return 0.0, 0.0, 0.0, 0
    keep = jumps <= max(float(np.percentile(jumps, 99.0)) * 4.0, 1e-6)
    av, bv = a[valid][keep], b[valid][keep]
    if av.size == 0:
        return 0.0, 0.0, 0.0, 0
    return (
        float(np.mean(np.abs(av + bv), dtype=np.float64)),
        float(np.mean(np.abs(av - bv), dtype=np.float64)),
        float(np.mean(np.abs(av) + np.abs(bv), dtype=np.float64)) * 0.5,
        int(av.size),
    )


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    h=st.integers(3, 60),
    w=st.integers(3, 60),
    rows=st.integers(1, 9),
    kind=st.sampled_from(["opengl", "directx", "seams", "masked", "hostile", "noise", "flat"]),
)
def test_convention_numbers_are_the_whole_maps(seed, h, w, rows, kind):
    """Banded, with the jumps made for the percentile alone and the kept terms gathered band by
    band: the same seam limit, texels and means, to the last bit, as gathering all at once."""
    rng = np.random.default_rng(seed)
    f = rng.normal(0.0, 1.0, (h + 2, w + 2)).cumsum(0).cumsum(1) * 0.01
    px, py = np.diff(f, axis=1)[1:-1, :-1], np.diff(f, axis=0)[:-1, 1:-1]
    if kind != "directx":
        py = -py
    n = np.stack([-px, -py, np.ones_like(px)], -1)
    if kind == "noise":
        n = rng.normal(0.0, 0.3, (h, w, 3)) + [0, 0, 1]
    if kind == "flat":
        n = np.zeros((h, w, 3)) + [0, 0, 1]
    n = (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)
    mask = rng.random((h, w)) > 0.2 if kind == "masked" else None
    if kind == "seams":
        n[:, w // 2 :] = n[:, w // 2 :, [1, 0, 2]]
    if kind == "hostile":
        n[rng.random((h, w)) < 0.05] = np.nan
        n[rng.random((h, w)) < 0.2, 2] = 0.1
    gl, dx, signal, used = _detect_whole(n, mask)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(nc, "band_rows", lambda width, per: rows)
        got = detect_convention(n, mask)
    assert got.texels_used == used
    assert (got.curl_opengl, got.curl_directx) == (gl, dx)
    if used:
        hi, lo = max(gl, dx), min(gl, dx)
        assert got.confidence == (0.0 if hi <= 0 else 1.0 - lo / hi)
        flat = got.reason == "map is flat: no evidence"
        assert flat == (signal < nc.MIN_SIGNAL)


@settings(max_examples=300, deadline=None)
@given(
    a=st.floats(-8, 8, width=32, allow_subnormal=True),
    b=st.floats(-8, 8, width=32, allow_subnormal=True),
)
def test_abs_sum_is_the_larger_of_sum_and_difference(a, b):
    """The detection's signal |a| + |b| made as max(|a + b|, |a - b|) in float32: the same
    bits (round to nearest is symmetric in sign, and monotonic)."""
    x, y = np.float32(a), np.float32(b)
    want = np.abs(x) + np.abs(y)
    got = np.maximum(np.abs(x + y), np.abs(x - y))
    assert want.view(np.uint32) == got.view(np.uint32) or (want == 0 and got == 0)


def test_abs_sum_identity_on_many_slopes():
    rng = np.random.default_rng(0)
    a = (rng.standard_normal(1 << 20) * 10.0 ** rng.integers(-8, 1, 1 << 20)).astype(np.float32)
    b = (rng.standard_normal(1 << 20) * 10.0 ** rng.integers(-8, 1, 1 << 20)).astype(np.float32)
    want = np.abs(a) + np.abs(b)
    got = np.maximum(np.abs(a + b), np.abs(a - b))
    assert np.array_equal(want.view(np.uint32), got.view(np.uint32))
