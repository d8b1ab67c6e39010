"""The one measure (wrinklepipe.metrics): the angle against float64 references, weighted
statistics against a brute-force sort, the budget verdict and the choices' margin."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from wrinklepipe.metrics import (
    DECIMALS,
    Budget,
    Stats,
    angle_deg,
    angle_deg_planes,
    weighted_quantile,
    weighted_stats,
    weighted_stats_many,
)


def brute_quantile(v, w, q):
    """Smallest x with W(v <= x) >= q W, by sorting everything."""
    v, w = np.asarray(v, float), np.asarray(w, float)
    keep = w > 0
    v, w = v[keep], w[keep]
    order = np.argsort(v, kind="stable")
    c = np.cumsum(w[order])
    return float(v[order][np.searchsorted(c, q * c[-1] * (1 - 1e-12))])


def test_unit_weights_are_the_nearest_rank_percentile():
    rng = np.random.default_rng(1)
    v = rng.exponential(1.0, 10_001)
    for q in (0.5, 0.9, 0.99):
        want = np.percentile(v, 100 * q, method="inverted_cdf")
        assert weighted_quantile(v, np.ones_like(v), q) == want


def test_a_hand_computed_weighted_quantile():
    # weights 1, 1, 8 on 1, 2, 3: 99 % of the weight is only reached at 3, 10 % already at 1
    assert weighted_quantile([3.0, 1.0, 2.0], [8.0, 1.0, 1.0], 0.99) == 3.0
    assert weighted_quantile([3.0, 1.0, 2.0], [8.0, 1.0, 1.0], 0.1) == 1.0
    assert weighted_quantile([3.0, 1.0, 2.0], [8.0, 1.0, 1.0], 0.15) == 2.0
    # zero weights never count, whatever their value
    assert weighted_quantile([100.0, 1.0], [0.0, 1.0], 0.99) == 1.0
    assert weighted_quantile([], [], 0.5) == 0.0


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(0, 90, allow_nan=False),
            st.floats(0, 4, allow_nan=False, allow_subnormal=False),
        ),
        min_size=1,
        max_size=400,
    ),
    st.sampled_from([0.01, 0.5, 0.9, 0.99, 1.0]),
)
def test_weighted_quantile_matches_a_full_sort(pairs, q):
    v = np.array([p[0] for p in pairs])
    w = np.array([p[1] for p in pairs])
    if not (w > 0).any():
        assert weighted_quantile(v, w, q) == 0.0
        return
    assert weighted_quantile(v, w, q) == brute_quantile(v, w, q)


def test_many_ties_and_a_large_array():
    rng = np.random.default_rng(2)
    v = np.round(rng.normal(2.0, 1.0, 300_000), 1)  # heavy ties
    w = rng.uniform(0.0, 1.0, v.size)
    for q in (0.5, 0.99):
        assert weighted_quantile(v, w, q) == brute_quantile(v, w, q)


def test_weighted_stats_and_budget():
    s = weighted_stats(np.array([1.0, 3.0, 50.0]), np.array([1.0, 3.0, 0.0]))
    assert s.mean == pytest.approx((1 * 1 + 3 * 3) / 4)
    assert s.max == 3.0 and s.texels == 2 and s.weight == 4.0 and s.p99 == 3.0
    assert Budget(mean=3.0, p99=3.0).ok(s) and not Budget(p99=2.9).ok(s)
    assert Budget.from_dict({"max_mean_deg": 0.5, "max_p99_deg": 1.0}) == Budget(0.5, 1.0)
    assert weighted_stats(np.array([]), np.array([])) == Stats(0.0, 0.0, 0.0, 0, 0.0)


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 300), st.integers(1, 5), st.integers(0, 2**31))
def test_many_rows_at_once_equal_one_row_at_a_time(n, g, seed):
    rng = np.random.default_rng(seed)
    err = np.round(rng.exponential(1.0, n), 2).astype(np.float32)  # ties
    w = rng.uniform(0, 1, (g, n)) * (rng.random((g, n)) < 0.7)
    many = weighted_stats_many(err, w)
    for row, got in zip(w, many):
        want = weighted_stats(err, row)
        assert got.p99 == want.p99 and got.max == want.max and got.texels == want.texels
        assert got.mean == pytest.approx(want.mean, rel=1e-9, abs=1e-12)


def test_no_texel_gives_one_empty_row_per_region():
    """A pose with no texel (on one UDIM tile, all its regions painted on another): every
    region's row is empty, not an error."""
    got = weighted_stats_many(np.zeros(0, np.float32), np.zeros((3, 0), np.float32))
    assert [(s.texels, s.weight) for s in got] == [(0, 0.0)] * 3
    assert [s.texels for s in weighted_stats_many(np.zeros(0), np.zeros(0))] == [0]


def dense_stats_many(err, weights):
    """Per row, by the whole sorted row: one stable sort of err, the float64 running sum of
    the row's weights over every texel in that order (zeros included), the first texel
    reaching 99 %, the mean as the dot over every texel."""
    e = np.asarray(err).ravel()
    order = np.argsort(e, kind="stable")
    es = e[order].astype(np.float64)
    out = []
    for row in np.asarray(weights, np.float64):
        ws = row[order]
        pos = np.flatnonzero(ws > 0)
        if pos.size == 0:
            out.append(Stats(0.0, 0.0, 0.0, 0, 0.0))
            continue
        cw = np.cumsum(ws)
        j = min(int(np.searchsorted(cw, 0.99 * cw[-1] * (1 - 1e-12))), int(pos[-1]))
        mean = float(np.dot(es, ws) / cw[-1])
        out.append(Stats(mean, float(es[j]), float(es[pos[-1]]), int(pos.size), float(cw[-1])))
    return out


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 400), st.integers(1, 6), st.floats(0.0, 1.0), st.integers(0, 2**31))
def test_many_rows_read_on_their_own_texels_equal_the_whole_sorted_rows(n, g, density, seed):
    # each row is read on its texels of positive weight only: the same running sums as over
    # the whole sorted row (the others add 0), so p99, max, texels and weight are exactly the
    # dense computation's, the mean to rounding; a row without positive weight is empty
    rng = np.random.default_rng(seed)
    err = np.round(rng.exponential(1.0, n), 2).astype(np.float32)  # ties
    w = (rng.uniform(0, 1, (g, n)) * (rng.random((g, n)) < density)).astype(np.float32)
    w[0] = 0.0  # always one empty row
    for got, want in zip(weighted_stats_many(err, w), dense_stats_many(err, w)):
        assert (got.p99, got.max, got.texels, got.weight) == (
            want.p99,
            want.max,
            want.texels,
            want.weight,
        )
        assert got.mean == pytest.approx(want.mean, rel=1e-12, abs=1e-12)
    assert weighted_stats_many(err, w)[0] == Stats(0.0, 0.0, 0.0, 0, 0.0)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0.0, 90.0, width=32), min_size=1, max_size=400),
    st.booleans(),
)
@example([0.0, 4.792440747990874e-43], False)  # a range of denormals: the bin scale overflowed
def test_unit_weights_are_the_nearest_rank_stats(values, overwrite):
    # every weight 1: the p99 is the ceil(0.99 n)-th smallest value (a brute-force sort), the
    # mean the plain mean; and weighted_stats with unit weights says the same
    e = np.asarray(values, np.float32)
    got = weighted_stats(e.copy(), overwrite=overwrite)
    want_p99 = brute_quantile(e, np.ones(e.size), 0.99)
    assert got.p99 == want_p99
    assert got.max == float(e.max())
    assert (got.texels, got.weight) == (e.size, float(e.size))
    assert got.mean == pytest.approx(float(np.mean(e.astype(np.float64))), rel=1e-12, abs=1e-12)
    ws = weighted_stats(e, np.ones(e.size, np.float32))
    assert (ws.p99, ws.max, ws.texels, ws.weight) == (got.p99, got.max, got.texels, got.weight)
    assert ws.mean == pytest.approx(got.mean, rel=1e-12, abs=1e-12)
    assert weighted_stats(np.zeros(0, np.float32)).texels == 0


# ------------------------------------------------------------------------------------------------
# the angle


def reference_angle(a, b):
    """float64 angle between directions: acos of the normalised dot, by the half-angle form
    ``2 atan2(|a' - b'|, |a' + b'|)`` of unit vectors (independent of the code's formula)."""
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(
        2 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1))
    )


def test_hand_computed_angles():
    z = np.array([0.0, 0.0, 1.0])
    got = angle_deg(
        np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, -2.0], [0.0, 0.0, 5.0]]), z
    )
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, [90.0, 45.0, 180.0, 0.0], atol=1e-5)
    # a length is not a direction: a vector 1 % long is at 0 degrees
    assert angle_deg(np.array([0.0, 0.0, 1.01]), z) == 0.0
    tiny = np.radians(1e-3)  # a thousandth of a degree is resolved
    v = np.array([np.sin(tiny), 0.0, np.cos(tiny)])
    assert abs(float(angle_deg(v, z)) - 1e-3) < 2e-5


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 200), st.floats(1e-6, 3.0), st.integers(0, 2**31))
def test_angles_match_a_float64_reference(n, spread, seed):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, 3))
    b = a + spread * rng.normal(size=(n, 3))
    a /= np.linalg.norm(a, axis=-1, keepdims=True)
    b /= np.linalg.norm(b, axis=-1, keepdims=True)
    a32, b32 = a.astype(np.float32), b.astype(np.float32)
    want = reference_angle(a32, b32)
    got = angle_deg(a32, b32)
    np.testing.assert_allclose(got, want, atol=2e-5)
    # the planes layout is the same float32 operations
    planes = angle_deg_planes(np.moveaxis(a32, -1, 0), np.moveaxis(b32, -1, 0))
    np.testing.assert_array_equal(planes, got)


def test_nan_errors_count_as_180_degrees():
    e = np.array([1.0, np.nan, 1.0, 1.0], np.float32)
    s = weighted_stats(e)
    assert s.max == 180.0 and s.mean == pytest.approx((3 + 180) / 4)
    assert weighted_stats(e, np.ones(4)).max == 180.0
    assert weighted_stats_many(e, np.ones((1, 4)))[0].max == 180.0


def test_a_large_unit_array_finds_its_p99_among_the_sampled_tail():
    # above 65 536 errors the p99 is selected among those at or above a sampled threshold:
    # the same order statistic as a full sort, including for a tail the sample misses
    rng = np.random.default_rng(5)
    for e in (
        rng.exponential(1.0, 300_001).astype(np.float32),
        np.concatenate([np.zeros(297_000), rng.uniform(5, 6, 3_001)]).astype(np.float32),
    ):
        k = int(np.ceil(0.99 * e.size))
        assert weighted_stats(e).p99 == float(np.sort(e)[k - 1])
        assert weighted_stats(e).p99 == float(np.percentile(e, 99, method="inverted_cdf"))


# ------------------------------------------------------------------------------------------------
# the verdict and the choices' margin


def test_the_verdict_compares_at_the_printed_decimals():
    b = Budget(mean=0.5, p99=2.0)
    at = Stats(0.50004, 2.0, 9.0, 10, 10.0)  # prints as 0.5000: within
    assert b.ok(at) and not b.inside(at)
    over = Stats(0.50005, 1.0, 9.0, 10, 10.0)  # prints as 0.5001 (half up): over
    assert not b.ok(over) and b.over(over) == ["mean"]
    assert Budget().ok(Stats(99.0, 99.0, 99.0, 1, 1.0)) and Budget().empty
    assert b.to_json() == {"max_mean_deg": 0.5, "max_p99_deg": 2.0}
    assert b.describe() == "mean 0.5, p99 2"


@settings(max_examples=200, deadline=None)
@given(
    st.floats(0.0, 10.0),
    st.floats(0.0, 10.0),
    st.floats(-4.9e-5, 4.9e-5),
)
def test_inside_is_ok_with_a_margin_the_rounding_cannot_cross(limit, value, noise):
    # what the choices accept (unrounded) the verdict accepts, even after the value moves by
    # less than half a printed unit (another read of the same bytes, another order of sums)
    b = Budget(p99=round(limit, DECIMALS))
    s = Stats(0.0, value, value, 1, 1.0)
    if b.inside(s):
        assert b.ok(s)
        assert b.ok(Stats(0.0, max(value + noise, 0.0), value, 1, 1.0))
