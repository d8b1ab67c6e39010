"""Issue 42: the searches' full-size PD slopes made where they are read (fidelity.level.PdLevel)
are the whole level's bit for bit: bands, gathers, the pyramid's first halving, the clipping
counts, the reference, the judge's samples, the memo's key and the search's choice."""

from __future__ import annotations

import numpy as np
import pytest

from wrinklepipe import model, reuse
from wrinklepipe.fidelity import level as flv
from wrinklepipe.fidelity import pyramid, scales, ship
from wrinklepipe.fidelity import reference as fre
from wrinklepipe.fidelity import sampling as fsa


def _source(size: int, k: int = 2, seed: int = 5) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    base = model.normalize(rng.normal(0, 0.3, (size, size, 3)) + [0, 0, 1]).astype(np.float32)
    states = model.normalize(rng.normal(0, 0.5, (k, size, size, 3)) + [0, 0, 1])
    states = states.astype(np.float32)
    states[0, 1, 2] = [1.0, 0.0, 0.0]  # on the horizon: a slope of 1e12
    states[1, size - 1, 0] = [0.6, 0.0, 0.8]  # a slope of 0.75 exactly
    return base, states


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.uint32)


@pytest.mark.parametrize("rows", [1, 3, 7, 1000])
def test_level_bands_gathers_and_halving_are_the_whole_levels(monkeypatch, rows):
    base, states = _source(40)
    whole = fre.source_states(base, states, "pd")
    monkeypatch.setattr(flv, "band_rows", lambda width, per: rows)
    lv = flv.PdLevel(base, states)
    assert lv.shape == whole.shape and len(lv) == 2
    assert np.array_equal(_bits(np.asarray(lv)), _bits(whole))
    assert np.array_equal(_bits(np.concatenate([b for _, b in flv.row_bands(lv)], 1)), _bits(whole))
    flat = np.random.default_rng(1).choice(40 * 40, 300)
    assert np.array_equal(_bits(lv.at(flat)), _bits(whole.reshape(2, -1, 2)[:, flat]))
    for k, x in enumerate(lv):
        assert np.array_equal(_bits(x.at(flat)), _bits(whole[k].reshape(-1, 2)[flat]))
        assert np.array_equal(_bits(x[5:23]), _bits(whole[k, 5:23]))
        assert np.array_equal(_bits(np.asarray(x)), _bits(whole[k]))
    # the pyramid: every level the whole array's, the full size kept as the level itself
    want, got = pyramid.levels(whole, 4), pyramid.levels(lv, 4)
    assert sorted(want) == sorted(got) == [5, 10, 20, 40] and got[40] is lv
    for s in (5, 10, 20):
        assert np.array_equal(_bits(got[s]), _bits(want[s]))
    # a hand-made halving at one output texel: 12 x 12 Lanczos taps, edges clamped
    w = pyramid.WEIGHTS.astype(np.float64)
    idx = np.clip(np.arange(12) - 5, 0, 39)  # output row / column 0 reads inputs -5 .. 6
    by_hand = np.einsum("i,j,ijc->c", w, w, whole[0][np.ix_(idx, idx)].astype(np.float64))
    assert np.allclose(got[20][0, 0, 0], by_hand, rtol=1e-5, atol=1e-6)


def test_level_scales_and_samples_are_the_whole_levels(monkeypatch):
    base, states = _source(32)
    whole = fre.source_states(base, states, "pd")
    monkeypatch.setattr(flv, "band_rows", lambda width, per: 5)
    monkeypatch.setattr(fsa, "CHUNK_TEXELS", 64)
    lv = flv.PdLevel(base, states)
    assert (
        scales.largest_held(lv)
        == scales.largest_held(whole)
        == pytest.approx(float(np.abs(whole[np.abs(whole) <= 1e6]).max()))
    )
    for t_lv, t_whole in zip(scales.tails(lv, 0.5), scales.tails(whole, 0.5)):
        assert np.array_equal(_bits(t_lv), _bits(t_whole))
    assert scales.clipped_texels(lv, 0.75) == scales.clipped_texels(whole, 0.75)
    flat = np.arange(0, 32 * 32, 7)
    for reader in (None, ship.pd_reader(0.75)):
        for x_lv, x in zip(lv, whole):
            a = fsa.sample_at(x_lv, (32, 32), flat, reader)
            b = fsa.sample_at(x, (32, 32), flat, reader)
            assert a.shape == b.shape and a.strides == b.strides
            assert np.array_equal(_bits(a), _bits(b))


def test_level_reference_is_the_arrays_and_its_memo_key_the_same():
    base, states = _source(64)
    whole = fre.source_states(base, states, "pd")
    lv = flv.PdLevel(base, states)
    masks = np.zeros((1, 64, 64), np.float32)
    masks[0, 8:40, 12:50] = 0.7
    poses = [fre.Pose("on", np.ones((1, 2), np.float32))]
    assert reuse._key("f", (lv,), {}) == reuse._key("f", (whole,), {})
    with reuse.reuse() as memo:
        a = fre.prepare(base, lv, masks, poses, ["r"])
        b = fre.prepare(base, whole, masks, poses, ["r"])
    assert memo.hits == {"wrinklepipe.fidelity.reference._prepare": 1}
    c = fre.prepare(base, whole, masks, poses, ["r"])  # no memo: made from the array
    assert np.array_equal(_bits(a.poses[0].normal), _bits(c.poses[0].normal))
    assert np.array_equal(a.union, c.union) and b.union.size == 32 * 38


@pytest.mark.parametrize("width", [16.0, 2.0])  # smooth: a small size; fine: the full size
def test_search_on_a_level_chooses_what_it_chooses_on_the_array(monkeypatch, width):
    from wrinklepipe.fidelity import search as fs
    from wrinklepipe.metrics import Budget

    monkeypatch.setattr(flv, "band_rows", lambda w, per: 9)
    size = 64
    rng = np.random.default_rng(4)
    base = model.pd_to_normal(rng.normal(0, 0.02, (size, size, 2)).astype(np.float32))
    x = np.arange(size, dtype=np.float32)
    slopes = np.zeros((2, size, size, 2), np.float32)
    slopes[0, :, :, 0] = 0.3 * np.sin(2 * np.pi * x / (2 * width))[None, :]
    slopes[1, :, :, 1] = 0.2 * np.sin(2 * np.pi * x / (2 * width))[:, None]
    states = model.pd_to_normal(model.normal_to_pd(base)[None] + slopes).astype(np.float32)
    masks = np.zeros((2, size, size), np.float32)
    masks[0, 8:56, 8:32] = 1.0
    masks[1, 8:56, 32:56] = 1.0
    poses = [fre.Pose(f"r{r}", np.diag(np.eye(2, dtype=np.float32)[r])) for r in range(2)]

    def run(level):
        src = fs.Source(base, level, masks, poses, ["a", "b"])
        return fs.search(src, Budget(mean=0.5, p99=1.0))

    a = run(flv.PdLevel(base, states))
    b = run(fre.source_states(base, states, "pd"))
    assert a.to_json() == b.to_json()
    assert np.array_equal(_bits(a.states), _bits(b.states))
    assert (a.wrinkle_size < size) == (width > 8)
