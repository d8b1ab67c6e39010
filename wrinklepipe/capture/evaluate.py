"""Error statistics of a captured normal map against known truth (synthetic sessions).

``tilt`` is the angle from +Z (what the ratio image measures); ``angular`` is the full angle
between the normals (tilt and orientation). ``orientation_correct`` is the share of texels whose
true tilt exceeds ``min_tilt_deg`` where the captured in-plane direction is within 90 degrees of
the true one (among texels the capture tilts by more than 0.5 degrees; the share of such
texels is ``orientation_coverage``). A flat map ``(0, 0, 1)`` is the baseline: its tilt and
angular errors are both the true tilt.
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.metrics import angle_deg, weighted_quantile, weighted_stats


def _tilt_deg(n: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.asarray(n, np.float64)[..., 2], -1.0, 1.0)))


def _stats(values: np.ndarray) -> dict[str, float]:
    if values.size == 0:
        return {"mean": 0.0, "median": 0.0, "p95": 0.0, "max": 0.0}
    s = weighted_stats(values)  # the one measure's mean and max; quantiles by nearest rank
    ones = np.ones(values.size, np.float32)
    return {
        "mean": s.mean,
        "median": weighted_quantile(values, ones, 0.5),
        "p95": weighted_quantile(values, ones, 0.95),
        "max": s.max,
    }


def errors(
    captured: np.ndarray, truth: np.ndarray, mask: np.ndarray, min_tilt_deg: float = 3.0
) -> dict:
    """Tilt and angular error statistics (degrees) inside ``mask`` (> 0.5).

    Also the flat baseline and the orientation-correct rate; the ``crease_*`` entries restrict to
    texels whose true tilt exceeds ``min_tilt_deg``.
    """
    sel = np.asarray(mask) > 0.5
    c = np.asarray(captured, np.float64)[sel]
    t = np.asarray(truth, np.float64)[sel]
    true_tilt = _tilt_deg(t)
    tilt_err = np.abs(_tilt_deg(c) - true_tilt)
    ang = angle_deg(c, t)
    crease = true_tilt > min_tilt_deg
    oriented = crease & (_tilt_deg(c) > 0.5)  # where the capture leans at all
    dots = np.einsum("ic,ic->i", c[oriented, :2], t[oriented, :2])
    return {
        "texels": int(sel.sum()),
        "crease_texels": int(crease.sum()),
        "tilt": _stats(tilt_err),
        "angular": _stats(ang),
        "flat": _stats(true_tilt),
        "crease_angular": _stats(ang[crease]),
        "crease_flat": _stats(true_tilt[crease]),
        "orientation_correct": float((dots > 0).mean()) if oriented.any() else 1.0,
        "orientation_coverage": float(oriented.sum() / max(int(crease.sum()), 1)),
    }
