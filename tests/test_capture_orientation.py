"""Orientation of the wrinkle normals on analytic creases, and the Poisson integration."""

from __future__ import annotations

import numpy as np
import pytest

from wrinklepipe.capture.orientation import (
    OrientationOptions,
    integrability_residual,
    integrate_poisson,
    orient,
)
from wrinklepipe.model import height_to_normal

W = 4.0  # crease width (Gaussian sigma), pixels


def _profile(x: np.ndarray, shoulder: float = 0.0) -> np.ndarray:
    h = -W * np.exp(-0.5 * (x / W) ** 2)
    return h + shoulder * W * np.exp(-0.5 * ((np.abs(x) - 2.2 * W) / W) ** 2)


def _straight_crease(shoulder: float = 0.0, sign: float = 1.0):
    """A straight vertical crease across a 48 x 96 image: truth normals and R = N_z."""
    x = np.arange(96) + 0.5 - 48.0
    h = np.tile(sign * _profile(x, shoulder), (48, 1))
    n = height_to_normal(h)
    return x, n, n[..., 2].astype(np.float64)


def _correct(est: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return np.einsum("...c,...c->...", est[..., :2], truth[..., :2]) > 0


def test_ratio_cannot_tell_a_furrow_from_a_ridge():
    _, nf, rf = _straight_crease(sign=1.0)
    _, nr, rr = _straight_crease(sign=-1.0)
    assert np.allclose(rf, rr)  # the classic concave/convex ambiguity
    assert np.allclose(nf[..., 0], -nr[..., 0])


def test_paper_gradient_is_right_on_the_inner_half_only():
    x, n, r = _straight_crease()
    est = orient(r, r, OrientationOptions(method="gradient"))
    ok = _correct(est, n)[24]
    inner = (np.abs(x) > 0.3 * W) & (np.abs(x) < 0.8 * W)
    outer = (np.abs(x) > 1.25 * W) & (np.abs(x) < 3.0 * W)
    assert ok[inner].all()  # R decreases away from the centre: grad R points inwards
    assert not ok[outer].any()  # beyond the steepest line grad R points outwards: wrong


@pytest.mark.parametrize("method", ["furrow", "integrable"])
def test_priors_orient_a_simple_furrow(method):
    x, n, r = _straight_crease()
    est = orient(r, r, OrientationOptions(method=method, furrow_sigma=W))
    tilt = np.degrees(np.arccos(n[..., 2]))
    sel = tilt > 3.0
    assert _correct(est, n)[sel].mean() > 0.95
    # The tilt itself comes straight from R: exact.
    assert np.allclose(est[..., 2], r, atol=1e-6)


def test_integrable_resolves_shoulders_where_the_furrow_rule_fails():
    x, n, r = _straight_crease(shoulder=0.35)
    tilt = np.degrees(np.arccos(n[..., 2]))
    sel = tilt > 3.0
    shoulder_out = sel & (np.abs(x) > 2.3 * W)[None, :]  # outer flank of the shoulders
    furrow = orient(r, r, OrientationOptions(method="furrow", furrow_sigma=W))
    integ = orient(r, r, OrientationOptions(method="integrable", furrow_sigma=W))
    assert _correct(integ, n)[sel].mean() > 0.95
    assert _correct(integ, n)[shoulder_out].mean() > 0.95
    assert _correct(furrow, n)[shoulder_out].mean() < 0.5


def test_poisson_integration_recovers_a_height_field():
    yy, xx = np.mgrid[0:40, 0:56].astype(np.float64)
    h = np.sin(xx / 6.0) * np.cos(yy / 9.0) + 0.01 * xx * yy
    gx = np.zeros_like(h)
    gy = np.zeros_like(h)
    gx[:, :-1] = h[:, 1:] - h[:, :-1]
    gy[:-1, :] = h[1:, :] - h[:-1, :]
    rec = integrate_poisson(gx, gy)
    assert np.abs((rec - rec.mean()) - (h - h.mean())).max() < 1e-9


def test_integrability_residual_separates_gradients_from_curl():
    yy, xx = np.mgrid[0:48, 0:48].astype(np.float64)
    h = 3.0 * np.exp(-((xx - 24) ** 2 + (yy - 24) ** 2) / 80.0)
    assert integrability_residual(height_to_normal(h)) < 0.05
    # A rotational slope field (pure curl) is as far from a gradient as can be.
    px, py = (yy - 24) / 60.0, (xx - 24) / 60.0  # rows run down, +Y up: this one circulates
    n = np.stack([px, py, np.ones_like(px)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    assert integrability_residual(n) > 0.8
