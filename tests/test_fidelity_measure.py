"""The fidelity measure on tiny hand-built assets (expected numbers computed by hand)."""

from __future__ import annotations

import numpy as np
import pytest

from wrinklepipe import fidelity as fd
from wrinklepipe import model
from wrinklepipe.metrics import Budget


def flat(h, w):
    n = np.zeros((h, w, 3), np.float32)
    n[..., 2] = 1.0
    return n


def tilt_deg(slope):
    return float(np.degrees(np.arctan(slope)))


def one_region(h=8, w=8):
    """One state, one region covering columns 2..3 (mask 1) and column 4 (mask 0.5)."""
    masks = np.zeros((1, h, w), np.float32)
    masks[0, :, 2:4] = 1.0
    masks[0, :, 4] = 0.5
    states = np.zeros((1, h, w, 2), np.float32)
    states[0, :, :, 0] = 0.3  # a constant wrinkle slope everywhere (masked to the region)
    poses = [fd.Pose("on", np.ones((1, 1), np.float32))]
    ref = fd.prepare(flat(h, w), states, masks, poses, ["r"])
    return ref, states, masks


def test_sampling_matches_a_hand_computed_bilinear_texel():
    img = np.array([[[0.0], [1.0]], [[2.0], [3.0]]], np.float32)  # 2x2
    # 4x4 grid: texel (row 1, col 2) has centre (2.5 / 4, 1.5 / 4) -> source x = 0.75, y = 0.25
    got = fd.sample_at(img, (4, 4), np.array([1 * 4 + 2]))
    want = (1 - 0.25) * ((1 - 0.75) * 0 + 0.75 * 1) + 0.25 * ((1 - 0.75) * 2 + 0.75 * 3)
    assert got[0, 0] == pytest.approx(want)
    # clamp to edge: the corner texel is the corner value
    assert fd.sample_at(img, (4, 4), np.array([0]))[0, 0] == 0.0


def test_identical_shipped_data_is_exact_and_only_active_texels_count():
    ref, states, masks = one_region()
    assert ref.union.size == 8 * 3  # columns 2, 3, 4
    f = fd.measure(ref, flat(8, 8), states, masks)
    assert f.worst_p99() == 0.0 and f.poses[0].overall.texels == 24
    assert f.poses[0].overall.weight == pytest.approx(8 * (1 + 1 + 0.5))


def test_a_wrong_state_texel_costs_its_angle_weighted_by_activation():
    ref, states, masks = one_region()
    bad = states.copy()
    bad[0, :, 4, 0] = 0.0  # the half-active column lost its wrinkle
    f = fd.measure(ref, flat(8, 8), bad, masks)
    o = f.poses[0].overall
    want = tilt_deg(0.5 * 0.3)  # activation 0.5 there: truth slope 0.15, shipped 0
    assert o.max == pytest.approx(want, abs=1e-4)
    # weighted mean: 8 texels of weight 0.5 at `want`, 16 texels of weight 1 at 0
    assert o.mean == pytest.approx(want * 4 / 20, abs=1e-4)
    # p99: 80 % of the weight is exact, so the 99th percentile is the wrong column
    assert o.p99 == pytest.approx(want, abs=1e-4)
    # a texel outside every region does not count, however wrong
    worse = bad.copy()
    worse[0, :, 0] = 5.0
    assert fd.measure(ref, flat(8, 8), worse, masks).poses[0].overall.max == pytest.approx(o.max)


def test_a_leaking_mask_is_an_error_outside_the_source_region():
    ref, states, masks = one_region()
    leak = masks.copy()
    leak[0, :, 6] = 1.0  # shipped mask active where the source has nothing
    f = fd.measure(ref, flat(8, 8), states, leak)
    p = f.poses[0]
    assert p.leak_texels == 8
    assert p.overall.max == pytest.approx(tilt_deg(0.3), abs=1e-4)


@pytest.mark.parametrize("mask_size", [16, 8, 64])
def test_leak_texels_are_every_texel_a_smaller_shipped_mask_activates_outside_the_source(
    mask_size,
):
    """Every grid texel where the shipped masks (magnified bilinearly) give an activation the
    source does not, counted by brute force over the whole 64 x 64 grid."""
    rng = np.random.default_rng(mask_size)
    masks = np.zeros((2, 64, 64), np.float32)
    masks[0, 10:30, 12:40] = 1.0
    masks[1, 40:50, 5:60] = 0.5
    states = rng.normal(0, 0.2, (1, 64, 64, 2)).astype(np.float32)
    poses = [fd.Pose("a", np.array([[1.0], [0.0]], np.float32)), fd.Pose("b", np.ones((2, 1)))]
    ref = fd.prepare(flat(64, 64), states, masks, poses, ["r0", "r1"])
    shipped = np.clip(rng.random((2, mask_size, mask_size)) - 0.7, 0, 1).astype(np.float32)
    s = fd.sample(ref, masks=shipped)
    every = np.arange(64 * 64)
    for p, leak in zip(poses, s.leaks):
        shipped_act = model.activations(fd.sample_masks_at(shipped, (64, 64), every), p.weights)
        source_act = model.activations(masks.reshape(2, -1), p.weights)
        want = np.flatnonzero((np.abs(shipped_act).sum(0) > 0) & (np.abs(source_act).sum(0) == 0))
        got = np.zeros(0, np.int64) if leak is None else leak[0]
        assert np.array_equal(np.sort(got), want), p.name
        assert want.size > 0


def test_the_base_is_measured_alone_over_the_footprint():
    ref, states, masks = one_region()
    base = flat(8, 8)
    base[:, 7] = model.pd_to_normal(np.array([0.1, 0.0], np.float32))  # outside the region
    f = fd.measure(ref, base, states, masks)
    assert f.worst_p99() == 0.0  # no pose sees column 7
    assert f.base.max == pytest.approx(tilt_deg(0.1), abs=1e-4)
    fp = np.zeros((8, 8), bool)
    fp[:, :4] = True  # a footprint that leaves column 7 out
    ref.footprint = fp
    assert fd.base_fidelity(ref, base).max == 0.0


def test_smaller_shipped_maps_are_magnified_and_per_region_stats_split():
    h = w = 8
    masks = np.zeros((2, h, w), np.float32)
    masks[0, :, :4] = 1.0
    masks[1, :, 4:] = 1.0
    states = np.zeros((1, h, w, 2), np.float32)
    states[0, :, :4, 1] = 0.2
    states[0, :, 4:, 1] = -0.2
    poses = [fd.Pose("both", np.ones((2, 1), np.float32))]
    ref = fd.prepare(flat(h, w), states, masks, poses, ["left", "right"])
    small = states[:, ::2, ::2]  # 4x4: each texel the same value as its 2x2 block
    f = fd.measure(ref, flat(h, w), small, masks)
    p = f.poses[0]
    # bilinear magnification blends the two halves only in columns 3 and 4
    assert p.regions["left"].texels == 32 and p.regions["right"].texels == 32
    # column 3 samples 3/4 of +0.2 and 1/4 of -0.2 = 0.1 instead of 0.2
    err3 = abs(np.degrees(np.arctan(0.2)) - np.degrees(np.arctan(0.1)))
    assert p.regions["left"].max == pytest.approx(err3, abs=1e-3)
    assert p.overall.max == pytest.approx(err3, abs=1e-3)


def test_describe_lists_every_pose_worst_first():
    ref, states, masks = one_region()
    f = fd.measure(ref, flat(8, 8), states, masks)
    lines = fd.describe(f, Budget(p99=1.0))
    assert lines[1].startswith("on") and "over budget" not in lines[1]
    assert lines[-1].startswith("base (face)")


def test_the_footprint_wraps_whole_triangles_across_the_texture_edge():
    # A quad over u 0.9..1.1, v 0.2..0.4 on a 20x20 grid: texel centres (i + 0.5) / 20 inside
    # it are columns 18, 19 and (wrapped) 0, 1, rows 4..7 -> 16 texels, nothing in between.
    uv = np.array([[0.9, 0.2], [1.1, 0.2], [1.1, 0.4], [0.9, 0.4]])
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    fp = fd.footprint(uv, quad, (20, 20))
    expected = np.zeros((20, 20), bool)
    expected[4:8, [0, 1, 18, 19]] = True
    np.testing.assert_array_equal(fp, expected)
    # A triangle with two vertices on u = 1 stays at the right edge (wrapping u = 1 to 0 per
    # vertex stretched it over the whole row): (0.9, 0.1), (1, 0.1), (1, 0.3) holds the
    # centres with u >= 0.9 + (v - 0.1) / 2: row 2 columns 18-19, rows 3 and 4 column 19.
    tri = np.array([[0.9, 0.1], [1.0, 0.1], [1.0, 0.3]])
    fp = fd.footprint(tri, quad[:1], (20, 20))
    expected = np.zeros((20, 20), bool)
    expected[2, [18, 19]] = True
    expected[3:5, 19] = True
    np.testing.assert_array_equal(fp, expected)
    # A triangle in the next tile (u 1.2..1.4) covers what its copy in [0, 1) covers.
    np.testing.assert_array_equal(
        fd.footprint(tri + [[-0.5, 0.0]], quad[:1], (20, 20)),
        fd.footprint(tri + [[0.5, 0.0]], quad[:1], (20, 20)),
    )
