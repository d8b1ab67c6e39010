"""The shape-from-shading orientation (wrinklepipe.capture.sfs) on analytic creases."""

from __future__ import annotations

import numpy as np
import pytest

from wrinklepipe.capture import grid, heights, slopes
from wrinklepipe.capture import sfs as S
from wrinklepipe.metrics import angle_deg


def _scene(sign: float, tilt: float, n: int = 64):
    """A straight crease (Gaussian, sigma 3 px, steepest slope ~0.3) across a plane turned by
    ``tilt`` (slope along the rows); its exact ratio image and normals."""
    idx = np.arange(n) + 0.5
    yy, xx = np.meshgrid(idx, idx, indexing="ij")
    w = 3.0
    d = yy - n / 2
    c = sign * 0.3 * w * np.sqrt(np.e) * np.exp(-0.5 * (d / w) ** 2)
    c = c * np.exp(-(((xx - n / 2) / (0.35 * n)) ** 6))
    dc_row = np.gradient(c, axis=0)
    dc_col = np.gradient(c, axis=1)
    g0 = np.stack([np.zeros_like(c), np.full_like(c, tilt)], -1)
    p = g0 + np.stack([dc_col, dc_row], -1)
    n0 = slopes.slopes_to_normals(g0)
    n1 = slopes.slopes_to_normals(p)
    ratio = n1[..., 2] / n0[..., 2]
    roi = (((xx - n / 2) / (0.45 * n)) ** 2 + ((yy - n / 2) / (0.45 * n)) ** 2 <= 1).astype(float)
    return ratio, n0, n1, roi


def _angle64(a, b):
    """float64 angle between unit vectors (an identity to 1e-9 needs more than float32)."""
    a, b = np.broadcast_arrays(np.asarray(a, np.float64), np.asarray(b, np.float64))
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), (a * b).sum(-1)))


def test_relative_to_and_back():
    rng = np.random.default_rng(1)
    n0 = slopes.slopes_to_normals(rng.normal(0, 0.5, (50, 2)))
    n1 = slopes.slopes_to_normals(rng.normal(0, 0.5, (50, 2)))
    m = slopes.relative_to(n1, n0)
    assert np.allclose(slopes.relative_to(n0, n0), [0, 0, 1], atol=1e-12)
    assert np.abs(_angle64(m, np.array([0, 0, 1.0])) - _angle64(n1, n0)).max() < 1e-9
    assert np.abs(slopes.expression_normals(m, n0) - n1).max() < 1e-9


@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["ridge", "valley"])
def test_ridge_and_valley_told_apart_on_a_tilted_neutral(sign):
    ratio, n0, n1, roi = _scene(sign, tilt=0.25)
    res = S.solve_crease(ratio, n0, roi)
    est = slopes.slopes_to_normals(res.slopes)
    crease = (angle_deg(n1, n0) > 3.0) & (roi > 0.5)
    lean_t = (n1 - n0)[..., :2]
    lean_e = (est - n0)[..., :2]
    right = np.einsum("...c,...c->...", lean_t, lean_e)[crease] > 0
    assert right.mean() > 0.9
    assert res.residual < 2e-3  # the height explains R (noise-free)


def test_flat_neutral_cannot_tell_concave_from_convex():
    ratio_r, n0, _, roi = _scene(1.0, tilt=0.0)
    ratio_v, *_ = _scene(-1.0, tilt=0.0)
    assert np.allclose(ratio_r, ratio_v)  # the classic ambiguity: only a tilted neutral breaks it
    ratio_t, *_ = _scene(1.0, tilt=0.25)
    ratio_tv, *_ = _scene(-1.0, tilt=0.25)
    assert np.abs(ratio_t - ratio_tv).max() > 0.05  # first order in the neutral's slope


def test_ratio_residual_ranks_the_true_map_first():
    ratio, n0, n1, roi = _scene(1.0, tilt=0.25)
    truth = slopes.relative_to(n1, n0)
    mirrored = truth * [-1.0, -1.0, 1.0]  # every lean the wrong way, tilt kept
    good = S.ratio_residual(truth, n0, ratio, roi)
    bad = S.ratio_residual(mirrored, n0, ratio, roi)
    assert good < 2e-3 < bad


def test_auto_picks_what_was_measured_best():
    from wrinklepipe.capture.pipeline import resolve_method

    assert resolve_method("auto", None) == "integrable"  # no neutral normals
    assert resolve_method("auto", np.full(1000, 0.995)) == "integrable"  # nearly flat
    assert resolve_method("auto", np.linspace(0.8, 1.0, 1000)) == "sfs"  # turned away
    assert resolve_method("gradient", np.full(10, 0.8)) == "gradient"
    with pytest.raises(ValueError, match="unknown orientation"):
        resolve_method("shading", None)


def test_eikonal_height_is_the_distance_cone():
    # |grad u| = 1 on a disc with u = 0 on its border: the largest solution is the distance to
    # the border (a cone, maximum at the centre), the smallest its negative.
    n = 61
    idx = np.arange(n) - 30.0
    yy, xx = np.meshgrid(idx, idx, indexing="ij")
    r = np.hypot(xx, yy)
    mask = r <= 25.0
    ring = mask & ~(np.hypot(xx, yy) <= 24.0)
    up = heights.eikonal_height(np.ones((n, n)), mask, np.zeros((n, n)), upward=True)
    down = heights.eikonal_height(np.ones((n, n)), mask, np.zeros((n, n)), upward=False)
    dist = 25.0 - r  # analytic, from the disc's edge; the ring pixels are the border
    inner = mask & ~ring
    assert np.abs(up - dist)[inner].mean() < 1.0  # upwind first order: within a pixel
    assert up[30, 30] == pytest.approx(25.0, abs=1.5)
    assert np.allclose(down, -up)
    # a slope twice as steep: twice as high
    up2 = heights.eikonal_height(np.full((n, n), 2.0), mask, np.zeros((n, n)))
    assert np.allclose(up2[inner], 2.0 * up[inner], rtol=1e-6)


def test_neutral_height_from_slopes():
    # a tilted paraboloid's analytic slopes, given only inside an irregular mask
    n = 48
    idx = np.arange(n) + 0.5
    yy, xx = np.meshgrid(idx, idx, indexing="ij")
    h = 0.01 * (xx - 20) ** 2 - 0.004 * (yy - 30) ** 2 + 0.3 * xx
    # central slopes of the pixel grid: the midpoint rule on a quadratic is exact
    g = np.stack([0.02 * (xx - 20) + 0.3, -0.008 * (yy - 30)], -1)
    mask = ((xx - 24) ** 2 + (yy - 24) ** 2 < 400) & ~((xx > 30) & (yy < 20))
    g = np.where(mask[..., None], g, 99.0)  # outside the mask: ignored
    est = heights.neutral_height(mask, g)
    ref = h - h[mask].mean()
    assert np.abs(est - ref)[mask].max() < 5e-3  # of a 15 px range (a tiny shrink term)


def test_ratio_residual_on_a_downsampled_grid():
    # Photos wider than max_side are judged on a coarser grid: slopes are the same there (a
    # height in coarse pixels over a coarse pixel), so the true map still explains R.
    ratio, n0, n1, roi = _scene(1.0, tilt=0.25, n=96)
    truth = slopes.relative_to(n1, n0)
    full = S.ratio_residual(truth, n0, ratio, roi)
    half = S.ratio_residual(truth, n0, ratio, roi, max_side=48)
    assert full < 2e-3 and half < 4e-3
    assert S.ratio_residual(truth * [-1.0, -1.0, 1.0], n0, ratio, roi, max_side=48) > 5 * half


def test_sign_ambiguity_is_reported_where_the_photos_do_not_fix_it():
    # c and -c give the same R on a neutral facing the camera (checked above): the two starts
    # end equally good and lean opposite ways on every crease pixel. On a tilted neutral the
    # wrong sign cannot explain R, so nothing is ambiguous.
    for tilt, lo, hi in ((0.0, 0.9, 1.0), (0.25, 0.0, 0.05)):
        ratio, n0, n1, roi = _scene(1.0, tilt=tilt)
        q = (slopes.neutral_slopes(n1) - slopes.neutral_slopes(n0)) * (roi > 0.5)[..., None]
        res = S.solve_crease(ratio, n0, roi, starts={"truth": q, "mirror": -q})
        assert lo <= res.ambiguous_fraction <= hi, tilt
        crease = (
            np.hypot(*np.moveaxis(res.slopes - slopes.neutral_slopes(n0), -1, 0)) > S.CREASE_SLOPE
        )
        assert res.ambiguous.shape == ratio.shape
        assert not (res.ambiguous & ~crease).any()  # only crease pixels are flagged


def test_a_blurred_ratio_is_fitted_with_the_blur_in_the_model():
    # R blurred by 1.5 px: fitted with an unblurred model the narrow crease comes out too
    # shallow; with the blur in the model (the polish) its slopes are recovered much closer.
    from scipy import ndimage

    ratio, n0, n1, roi = _scene(-1.0, tilt=0.25)
    blurred = ndimage.gaussian_filter(ratio, 1.5, mode="nearest")
    crease = (angle_deg(n1, n0) > 3.0) & (roi > 0.5)
    err = {}
    for b in (0.0, 1.5):
        res = S.solve_crease(blurred, n0, roi, blur=b)
        err[b] = angle_deg(slopes.slopes_to_normals(res.slopes), n1)[crease].mean()
    assert err[1.5] < 0.6 * err[0.0], err
    # the blur operator is symmetric (its own adjoint, as the Gauss-Newton steps assume)
    mask = roi > 0.5
    op = grid._Blur(mask.shape, np.flatnonzero(mask.ravel()), 1.3)
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, mask.sum()))
    assert a @ op(b) == pytest.approx(b @ op(a), rel=1e-12)


@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["ridge", "valley"])
def test_a_side_lit_photo_tells_ridge_from_valley_on_a_flat_neutral(sign):
    # On a neutral facing the camera R cannot tell c from -c (above). A second photo lit from
    # the unit direction l gives S = n1 . l / N1_z = l_z - l_x p_col + l_y p_row: first order
    # in the slopes, so the sign is in every crease pixel.
    ratio, n0, n1, roi = _scene(sign, tilt=0.0)
    light = np.array([0.3, 0.4, 0.0])
    light[2] = np.sqrt(1.0 - light @ light)
    side = (n1 @ light) / n1[..., 2]  # the Lambertian side-lit photo over the flash-lit one
    crease = (angle_deg(n1, n0) > 3.0) & (roi > 0.5)
    lean_t = (n1 - n0)[..., :2]
    for starts in ({}, None):  # no prior, and the default starts (zero, the eikonal ones)
        res = S.solve_crease(ratio, n0, roi, starts=starts, side=(side, light))
        lean_e = (slopes.slopes_to_normals(res.slopes) - n0)[..., :2]
        right = np.einsum("...c,...c->...", lean_t, lean_e)[crease] > 0
        assert right.mean() > 0.95, (sign, right.mean())
        assert res.ambiguous_fraction < 0.05
    # the mirrored crease cannot explain the side-lit photo
    q = slopes.neutral_slopes(n1)
    mirror = S.solve_crease(
        ratio,
        n0,
        roi,
        starts={"mirror": -q},
        side=(side, light),
        options=S.SfsOptions(iterations=0, coarse=0, eikonal=False, detrend=0, polish=False),
    )
    truth = S.solve_crease(
        ratio,
        n0,
        roi,
        starts={"truth": q},
        side=(side, light),
        options=S.SfsOptions(iterations=0, coarse=0, eikonal=False, detrend=0, polish=False),
    )
    assert truth.starts["truth"] < 0.2 * mirror.starts["mirror"]


def test_a_free_border_lets_a_crease_run_through_the_roi_edge():
    # A straight valley across the whole photo on a tilted plane, the ROI a disc that cuts it:
    # with c = 0 forced at the ROI border the solve must bend the crease to zero there; a free
    # border does not, and its slopes stay closer to the truth near the edge.
    n = 64
    idx = np.arange(n) + 0.5
    yy, xx = np.meshgrid(idx, idx, indexing="ij")
    w = 3.0
    c = -0.3 * w * np.sqrt(np.e) * np.exp(-0.5 * ((yy - n / 2) / w) ** 2)
    g0 = np.stack([np.zeros_like(c), np.full_like(c, 0.25)], -1)
    n0 = slopes.slopes_to_normals(g0)
    q = np.stack([np.gradient(c, axis=1), np.gradient(c, axis=0)], -1)
    n1 = slopes.slopes_to_normals(g0 + q)
    ratio = n1[..., 2] / n0[..., 2]
    r = np.hypot(xx - n / 2, yy - n / 2)
    roi = (r <= 0.4 * n).astype(float)
    edge = (roi > 0.5) & (r > 0.3 * n) & (np.abs(yy - n / 2) < 2 * w)
    err = {}
    for border in ("zero", "free"):
        res = S.solve_crease(ratio, n0, roi, options=S.SfsOptions(border=border))
        err[border] = np.hypot(*np.moveaxis(res.slopes - (g0 + q), -1, 0))[edge].mean()
    assert err["free"] < 0.5 * err["zero"], err
