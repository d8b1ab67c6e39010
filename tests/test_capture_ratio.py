"""The ratio image: hand-computed values, guards and their reported fractions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from wrinklepipe.capture.ratio import (
    RatioOptions,
    luminance,
    ratio_image,
    skin_level,
    srgb_to_linear,
)

PLAIN = RatioOptions(normalize_exposure=False, blur_sigma=0.0, deadband=0.0)


def test_ratio_is_the_cosine_ratio():
    i0 = np.full((8, 8), 0.5)
    i1 = np.full((8, 8), 0.4)
    r = ratio_image(i0, i1, options=PLAIN)
    assert np.allclose(r.ratio, 0.8) and np.allclose(r.nz, 0.8)
    # With the neutral surface tilted (N_z = 0.9) the expression's z is R N_z = 0.72 (equation
    # 2); the wrinkle alone is the extra tilt acos(0.72) - acos(0.9) = 43.946 - 25.842 degrees.
    r = ratio_image(i0, i1, nz_neutral=0.9, options=PLAIN)
    assert np.allclose(r.nz, np.cos(np.radians(43.9455 - 25.8419)), atol=1e-5)
    # No change between the photos: no wrinkle, whatever the neutral tilt.
    assert np.allclose(ratio_image(i0, i0, nz_neutral=0.8, options=PLAIN).nz, 1.0)


def test_dark_pixels_are_not_divided_and_counted():
    i0 = np.full((10, 10), 0.5)
    i0[:2] = 0.01  # 20 dark pixels under the default 0.02 threshold
    i1 = np.full((10, 10), 0.45)
    r = ratio_image(i0, i1, options=PLAIN)
    assert r.frac_dark == pytest.approx(0.2)
    assert np.all(r.ratio[:2] == 1.0) and not r.valid[:2].any()
    assert np.allclose(r.ratio[2:], 0.9)


def test_outside_pixels_are_counted():
    i0 = np.full((10, 10), 0.5)
    inside = np.ones((10, 10), bool)
    inside[:, :3] = False
    r = ratio_image(i0, i0 * 0.9, inside=inside, options=PLAIN)
    assert r.frac_outside == pytest.approx(0.3)
    assert np.all(r.nz[:, :3] == 1.0)


def test_brighter_expression_is_clipped_and_reported():
    i0 = np.full((10, 10), 0.5)
    i1 = np.full((10, 10), 0.5)
    i1[:5] = 0.6  # R = 1.2 on half the image: not a cosine
    r = ratio_image(i0, i1, options=PLAIN)
    assert r.frac_clipped_raw == pytest.approx(0.5)
    assert r.frac_clipped == pytest.approx(0.5)
    assert np.all(r.nz <= 1.0) and np.allclose(r.nz[:5], 1.0)


def test_exposure_difference_is_cancelled_by_the_skin_level():
    rng = np.random.default_rng(0)
    shading = np.ones((40, 40))
    shading[:18] = 0.8  # 45 % of the ROI creased: the median would be biased, the mode is not
    i0 = rng.uniform(0.3, 0.7, (40, 40))
    i1 = 1.1 * i0 * shading
    assert skin_level((i1 / i0).ravel()) == pytest.approx(1.1, abs=2e-3)
    r = ratio_image(i0, i1, options=RatioOptions(blur_sigma=0.0, deadband=0.0))
    assert r.exposure == pytest.approx(1.1, abs=2e-3)
    assert np.allclose(r.nz[:18], 0.8, atol=2e-3) and np.allclose(r.nz[18:], 1.0, atol=2e-3)


def test_roi_weights_the_statistics():
    i0 = np.full((10, 10), 0.5)
    i0[:, :5] = 0.0  # dark, but outside the ROI
    roi = np.zeros((10, 10))
    roi[:, 5:] = 1.0
    r = ratio_image(i0, np.full((10, 10), 0.4), roi=roi, options=PLAIN)
    assert r.frac_dark == 0.0


def test_colour_helpers_hand_values():
    assert float(srgb_to_linear(np.float32(0.5))) == pytest.approx(0.214041, abs=1e-5)
    assert float(srgb_to_linear(np.float32(0.04))) == pytest.approx(0.04 / 12.92, abs=1e-7)
    rgb = np.zeros((1, 1, 3), np.float32)
    rgb[..., 0] = 1.0
    assert float(luminance(rgb)[0, 0]) == pytest.approx(0.2126, abs=1e-6)


@settings(max_examples=30, deadline=None)
@given(
    st.floats(0.5, 2.0),
    st.floats(0.3, 0.99),
    st.integers(0, 10_000),
)
def test_ratio_law_cancels_albedo_and_exposure(exposure, shade, seed):
    # Any skin colour and any flash difference: N'_z comes back as the shading alone, as long as
    # most of the ROI is unwrinkled (the skin level is then the exposure).
    rng = np.random.default_rng(seed)
    albedo = rng.uniform(0.1, 1.0, (24, 24))
    shading = np.ones((24, 24))
    shading[:8] = shade  # a third of the image "wrinkled"
    r = ratio_image(
        albedo, exposure * albedo * shading, options=RatioOptions(blur_sigma=0.0, deadband=0.0)
    )
    assert r.exposure == pytest.approx(exposure, rel=2e-3)
    assert np.allclose(r.nz[:8], shade, atol=3e-3) and np.allclose(r.nz[8:], 1.0, atol=3e-3)


def test_exposure_is_measured_on_the_skin_around_the_roi():
    # A ROI lined all over (cosine creases on a tilted neutral: R swings above and below 1 and
    # its histogram peaks at the swings' extremes, not at 1) inside unwrinkled skin: the flash
    # ratio 1.035 is read from the ring of skin around the ROI.
    n = 96
    idx = np.arange(n) + 0.5
    yy, xx = np.meshgrid(idx, idx, indexing="ij")
    roi = ((xx - 48) ** 2 + (yy - 48) ** 2 <= 30**2).astype(float)
    g0 = 0.15  # the neutral's slope along the rows
    q = 0.36 * np.sin(2 * np.pi * yy / 9.0) * roi  # the creases' slope
    nz0 = 1 / np.sqrt(1 + g0**2)
    nz1 = 1 / np.sqrt(1 + (g0 + q) ** 2)
    i0 = np.full((n, n), 0.4)
    i1 = 0.4 * 1.035 * nz1 / nz0
    opts = RatioOptions(blur_sigma=0.0, deadband=0.0)
    r = ratio_image(i0, i1, roi=roi, options=opts)
    assert r.exposure == pytest.approx(1.035, abs=2e-4)
    assert r.exposure_reference == "skin around the ROI"
    inside = ratio_image(i0, i1, roi=roi, options=RatioOptions(blur_sigma=0.0, exposure_ring=0))
    assert inside.exposure_reference == "ROI"
    assert abs(inside.exposure - 1.035) > 1e-3  # its mode sits on a crease extreme (-0.18 %)
    # a ROI covering the photo leaves no ring: its own level, said so
    whole = ratio_image(i0, i1, options=opts)
    assert whole.exposure_reference == "ROI"
    assert ratio_image(i0, i1, roi=roi, options=PLAIN).exposure_reference == "none"


def test_pixel_noise_ignores_smooth_creases_and_flat_skin_is_found():
    from wrinklepipe.capture.pipeline import flat_skin
    from wrinklepipe.capture.ratio import blurred_noise, pixel_noise

    rng = np.random.default_rng(5)
    n = 128
    yy, xx = np.mgrid[0:n, 0:n].astype(float)
    crease = 0.06 * np.exp(-0.5 * ((yy - 40) / 3.0) ** 2)  # a dark line 3 px wide
    raw = 1.0 - crease + rng.normal(0.0, 0.004, (n, n))
    valid = np.ones((n, n), bool)
    # the mixed second difference of white noise has the noise's sigma; the crease cancels
    assert pixel_noise(raw, valid) == pytest.approx(0.004, rel=0.05)
    assert pixel_noise(1.0 - crease, valid) < 2e-4
    # a Gaussian blur of sigma s keeps 1 / (2 sqrt(pi) s) of white noise
    blurred = ndimage.gaussian_filter(rng.normal(0.0, 1.0, (400, 400)), 1.5)
    assert blurred_noise(1.0, 1.5) == pytest.approx(blurred.std(), rel=0.03)
    r = ndimage.gaussian_filter(raw, 1.2)
    noise = blurred_noise(pixel_noise(raw, valid), 1.2)
    flat = flat_skin(r, valid, np.ones((n, n)), noise, 3.0, 3.0)
    assert flat[90:110, 20:100].mean() > 0.9  # skin far from the line
    assert flat[37:44, 20:100].max() < 0.05  # on the line
