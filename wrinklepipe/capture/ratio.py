"""The ratio image and the normal tilt (Dutreve et al. section 3.1, equations 1 and 2).

Under a light at the camera a Lambertian pixel is ``I = C_d C_l N_z`` (with N_z towards the
camera), so the ratio of the registered expression photo to the neutral photo cancels the skin
colour: ``R = I'_d / I = N'_z / N_z``. With the neutral surface's ``N_z`` given (default 1, the
paper's "locally plane, parallel to the camera"), the wrinkled normal's z is ``N'_z = R N_z``.
The map this package writes holds the wrinkle alone, relative to the neutral surface, so its z
is the cosine of the *extra* tilt ``acos(R N_z) - acos(N_z)`` (tilts assumed in one plane); with
``N_z = 1`` that is the paper's ``N'_z = R``.

Guards (all reported, none silent):

- *dark*: neutral pixels below ``dark_threshold`` (linear luminance) are not divided; R = 1.
- *outside*: pixels whose warped position fell outside the expression photo; R = 1.
- *exposure*: the two flashes rarely match, so R is divided by its most common value (see
  :func:`skin_level`) over the skin *around* the ROI (a ring ``exposure_ring`` pixels wide
  outside it: skin the wrinkles leave alone), or over the ROI when that ring is too small (the
  ROI covers the photo); the factor and its reference are reported. Measured on the curved
  sessions: the ring's level is within 0.05 % of the true flash ratio, the ROI's mode 0.5-0.8 %
  low on foreheads lined all over (on a curved neutral R is not stationary at 1 on a crest, so
  the histogram's peaks are the creases' extremes), which reads as 1-2 degrees of tilt.
  Off with ``normalize_exposure=False``.
- *blur*: a normalised Gaussian (invalid pixels do not bleed in) of ``blur_sigma`` pixels.
- *deadband*: ``1 - R`` below ``deadband`` is noise, not a wrinkle (the tilt ``acos(R)`` is
  steepest at R = 1, so tiny noise would read as several degrees); it is subtracted softly.
- *clipped*: after all of this, ``R N_z > 1`` cannot be a cosine; it is clipped to 1 (the
  fraction reported counts only ``R N_z > 1 + deadband``, i.e. beyond the noise floor).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

#: Rec. 709 / sRGB luminance weights of linear RGB.
LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """The sRGB transfer function inverted (IEC 61966-2-1), elementwise on [0, 1]."""
    v = np.asarray(v, np.float32)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4).astype(np.float32)


def luminance(image: np.ndarray) -> np.ndarray:
    """Linear luminance ``[H, W]`` of a linear ``[H, W]``/``[H, W, C]`` image (alpha ignored)."""
    img = np.asarray(image, np.float32)
    if img.ndim == 2:
        return img
    if img.shape[2] >= 3:
        return np.einsum("hwc,c->hw", img[..., :3], LUMA).astype(np.float32)
    return img[..., 0]


@dataclass(frozen=True)
class RatioOptions:
    """Parameters of the ratio step, with the defaults ``wrinklepipe capture`` uses."""

    #: Neutral luminance (linear, 0..1) below which a pixel is not divided.
    dark_threshold: float = 0.02
    #: Divide R by its mode over the valid ROI to cancel a flash/exposure difference.
    normalize_exposure: bool = True
    #: Gaussian blur of R, pixels (the paper's noise filter). 0 disables it.
    blur_sigma: float = 1.0
    #: Soft noise floor on ``1 - R`` (R units); ``None``: ``deadband_sigmas`` times the noise of
    #: the blurred R, measured on the bright side of its mode (wrinkles only darken).
    deadband: float | None = None
    deadband_sigmas: float = 3.0
    #: Width (pixels) of the ring of skin outside the ROI whose ratio level is the exposure
    #: ratio; 0: the ROI's own level. The ring is used when it holds at least
    #: ``EXPOSURE_RING_MIN`` valid pixels.
    exposure_ring: float = 16.0


@dataclass(frozen=True)
class RatioResult:
    """R before and after the guards, ``N'_z``, and what was clipped (fractions of the ROI)."""

    raw: np.ndarray  # I'_d / I where valid, 1 elsewhere (before exposure and blur)
    ratio: np.ndarray  # after exposure normalisation, blur and deadband (unclipped)
    plain: np.ndarray  # after exposure normalisation and blur only (no deadband, unclipped)
    nz: np.ndarray  # z of the wrinkle normal: cos(acos(R N_z) - acos(N_z)); = R when N_z = 1
    valid: np.ndarray  # bool: divided (not dark, inside the expression photo)
    exposure: float  # the factor R was divided by
    frac_dark: float
    frac_outside: float
    frac_clipped_raw: float  # raw R > 1 (before the blur)
    frac_clipped: float  # R N_z > 1 + deadband after the guards (all R N_z > 1 are clipped)
    noise: float  # noise (sigma) of the blurred R, from its bright side
    deadband: float  # the deadband used
    exposure_reference: str = "ROI"  # where the exposure level was measured


#: Fewest valid pixels in the ring around the ROI for its level to be the exposure ratio.
EXPOSURE_RING_MIN = 500


def skin_level(values: np.ndarray, bins: int = 1024) -> float:
    """The most common ratio (the mode of a smoothed histogram): the level of unwrinkled skin.

    Wrinkles only darken, so the median is biased low by the creased share of the ROI; the mode
    is not.
    """
    v = np.asarray(values, np.float64).ravel()
    lo, hi = np.percentile(v, [1.0, 99.9])
    if not hi > lo:
        return float(np.median(v))
    hist, edges = np.histogram(v, bins=bins, range=(lo, hi))
    hist = ndimage.gaussian_filter1d(hist.astype(np.float64), 3.0, mode="constant")
    k = int(np.argmax(hist))
    return float(0.5 * (edges[k] + edges[k + 1]))


def upper_noise(values: np.ndarray) -> float:
    """Noise sigma of a ratio around 1 from the bright side only (1.4826 x median |R - 1|)."""
    v = np.asarray(values, np.float64).ravel()
    up = v[v > 1.0] - 1.0
    return float(1.4826 * np.median(up)) if len(up) else 0.0


def pixel_noise(raw: np.ndarray, valid: np.ndarray) -> float:
    """Noise sigma of the unblurred ratio per pixel from its mixed second difference
    ``(r00 - r01 - r10 + r11) / 2`` (1.4826 x median absolute value over 2x2 blocks of valid
    pixels): smooth content (creases a few pixels wide, the neutral's shading) cancels, so
    unlike :func:`upper_noise` it is not raised by creases; interpolation of the warped photo
    correlates neighbours, so it reads somewhat low (measured 0.70x the noise of crease-free
    skin after the blur, converted by :func:`blurred_noise`)."""
    r = np.asarray(raw, np.float64)
    v = np.asarray(valid, bool)
    if r.shape[0] < 2 or r.shape[1] < 2:
        return 0.0
    d = 0.5 * (r[:-1, :-1] - r[:-1, 1:] - r[1:, :-1] + r[1:, 1:])
    ok = v[:-1, :-1] & v[:-1, 1:] & v[1:, :-1] & v[1:, 1:]
    return float(1.4826 * np.median(np.abs(d[ok]))) if ok.any() else 0.0


def blurred_noise(sigma_pixel: float, blur: float) -> float:
    """White noise of sigma ``sigma_pixel`` after a Gaussian blur of ``blur`` pixels (the
    kernel's L2 norm, ``1 / (2 sqrt(pi) blur)``, at most 1)."""
    return float(sigma_pixel * min(1.0, 1.0 / (2.0 * np.sqrt(np.pi) * max(blur, 1e-9))))


def masked_blur(values: np.ndarray, weight: np.ndarray, sigma: float) -> np.ndarray:
    """A normalised Gaussian blur: pixels of weight 0 do not bleed in (1 where none is near)."""
    if sigma <= 0:
        return values
    num = ndimage.gaussian_filter(values * weight, sigma, mode="nearest")
    den = ndimage.gaussian_filter(weight, sigma, mode="nearest")
    return np.where(den > 1e-6, num / np.maximum(den, 1e-6), 1.0)


def ratio_image(
    neutral: np.ndarray,
    expression_warped: np.ndarray,
    inside: np.ndarray | None = None,
    roi: np.ndarray | None = None,
    nz_neutral: np.ndarray | float = 1.0,
    options: RatioOptions | None = None,
) -> RatioResult:
    """Compute ``R = I'_d / I`` and the wrinkle normal's z from luminance images ``[H, W]``.

    ``inside`` marks pixels that the warp sampled inside the expression photo; ``roi`` (0..1)
    weights the statistics (exposure median, clipped fractions); ``nz_neutral`` is a scalar or a
    ``[H, W]`` map of the neutral surface's N_z.
    """
    o = options or RatioOptions()
    i0 = np.asarray(neutral, np.float64)
    i1 = np.asarray(expression_warped, np.float64)
    h, w = i0.shape
    inside_b = np.ones((h, w), bool) if inside is None else np.asarray(inside, bool)
    roi_w = np.ones((h, w)) if roi is None else np.clip(np.asarray(roi, np.float64), 0, 1)
    in_roi = roi_w > 0.5
    n_roi = max(int(in_roi.sum()), 1)

    dark = i0 < o.dark_threshold
    valid = inside_b & ~dark
    raw = np.where(valid, i1 / np.where(valid, i0, 1.0), 1.0)

    exposure = 1.0
    sel = valid & in_roi
    reference = "ROI"
    if o.normalize_exposure and sel.any():
        # On the blurred ratio: quantised photos give a spiky histogram of raw ratios.
        smooth = masked_blur(raw, valid.astype(np.float64), max(o.blur_sigma, 1.0))
        ref = sel
        if o.exposure_ring > 0 and not in_roi.all():
            ring = valid & (ndimage.distance_transform_edt(~in_roi) <= o.exposure_ring) & ~in_roi
            if int(ring.sum()) >= EXPOSURE_RING_MIN:
                ref, reference = ring, "skin around the ROI"
        level = skin_level(smooth[ref])
        if level > 1e-6:
            exposure = level
    r = np.where(valid, raw / exposure, 1.0)
    r = masked_blur(r, valid.astype(np.float64), o.blur_sigma)
    plain = r.copy()
    noise = upper_noise(r[sel]) if sel.any() else 0.0
    deadband = o.deadband if o.deadband is not None else o.deadband_sigmas * noise
    if deadband > 0:
        r = 1.0 - np.maximum((1.0 - r) - deadband, 0.0) + np.maximum(r - 1.0, 0.0)
    nzn = np.broadcast_to(np.asarray(nz_neutral, np.float64), (h, w))
    nz_raw = r * nzn  # the paper's N'_z: the expression's z towards the camera
    # The map holds the wrinkle alone, in the neutral surface's frame: the extra tilt beyond the
    # neutral's own (assuming the two tilts lie in one plane; N_z = 1 gives the paper's N'_z).
    extra = np.arccos(np.clip(nz_raw, 0.0, 1.0)) - np.arccos(np.clip(nzn, 0.0, 1.0))
    nz = np.cos(np.clip(extra, 0.0, np.pi / 2))
    return RatioResult(
        raw=raw.astype(np.float32),
        ratio=r.astype(np.float32),
        plain=plain.astype(np.float32),
        nz=nz.astype(np.float32),
        valid=valid,
        exposure=float(exposure),
        frac_dark=float((dark & in_roi).sum() / n_roi),
        frac_outside=float((~inside_b & in_roi).sum() / n_roi),
        frac_clipped_raw=float((valid & in_roi & (raw / exposure > 1.0)).sum() / n_roi),
        frac_clipped=float((in_roi & (nz_raw > 1.0 + deadband)).sum() / n_roi),
        noise=float(noise),
        deadband=float(deadband),
        exposure_reference=reference if exposure != 1.0 else "none",
    )
