"""The shape-from-shading orientation (wrinklepipe.capture.sfs) on analytic creases."""

from __future__ import annotations

import numpy as np
import pytest

from wrinklepipe.capture import sfs as S
from wrinklepipe.model import angular_error_deg


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
    n0 = S.slopes_to_normals(g0)
    n1 = S.slopes_to_normals(p)
    ratio = n1[..., 2] / n0[..., 2]
    roi = (((xx - n / 2) / (0.45 * n)) ** 2 + ((yy - n / 2) / (0.45 * n)) ** 2 <= 1).astype(float)
    return ratio, n0, n1, roi


def test_relative_to_and_back():
    rng = np.random.default_rng(1)
    n0 = S.slopes_to_normals(rng.normal(0, 0.5, (50, 2)))
    n1 = S.slopes_to_normals(rng.normal(0, 0.5, (50, 2)))
    m = S.relative_to(n1, n0)
    assert np.allclose(S.relative_to(n0, n0), [0, 0, 1], atol=1e-12)
    assert (
        np.abs(angular_error_deg(m, np.array([0, 0, 1.0])) - angular_error_deg(n1, n0)).max() < 1e-9
    )
    assert np.abs(S.expression_normals(m, n0) - n1).max() < 1e-9


@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["ridge", "valley"])
def test_ridge_and_valley_told_apart_on_a_tilted_neutral(sign):
    ratio, n0, n1, roi = _scene(sign, tilt=0.25)
    res = S.solve_crease(ratio, n0, roi)
    est = S.slopes_to_normals(res.slopes)
    crease = (angular_error_deg(n1, n0) > 3.0) & (roi > 0.5)
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
    truth = S.relative_to(n1, n0)
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
