"""Masks proposed from baked wrinkle states: where a state's normal differs from the base's.

Per state ``k`` and texel: the angle between the state's and the base's normal; a smoothstep
from ``low`` to ``high`` degrees (0 below ``low``: noise and the sculpt's own jitter; 1 above
``high``); grown by a maximum filter of radius ``2 sigma`` and blurred by a Gaussian of
``sigma`` texels over the covered texels (so a mask covers the wrinkled area around the
creases, not only the creases) and padded beyond the UV islands like the maps. A proposal to
paint over, not a finished mask: each mask says where that pose's sculpt differs from the
neutral one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from wrinklepipe.geometry.uv_samples import blur_covered, pad_islands


@dataclass(frozen=True)
class ProposalOptions:
    """Options of :func:`propose_masks`: the smoothstep's ``low`` and ``high`` (degrees), the
    blur ``sigma`` (texels; None: ``size / 256``, at least 1) and ``padding`` (texels)."""

    low: float = 0.5
    high: float = 4.0
    sigma: float | None = None
    padding: int = 8


def propose_masks(
    base: np.ndarray,
    states: np.ndarray,
    covered: np.ndarray,
    options: ProposalOptions | None = None,
) -> np.ndarray:
    """Masks ``[K, H, W]`` float32 in [0, 1] from the base ``[H, W, 3]`` and states
    ``[K, H, W, 3]`` (unit normals) over the ``covered`` texels ``[H, W]`` (see the module
    doc)."""
    o = options or ProposalOptions()
    b = np.asarray(base, np.float64)
    cov = np.asarray(covered, bool)
    sigma = o.sigma if o.sigma is not None else max(1.0, b.shape[0] / 256.0)
    out = np.zeros((len(states), *b.shape[:2]), np.float32)
    for k, s in enumerate(np.asarray(states, np.float64)):
        cos = np.clip(np.einsum("hwc,hwc->hw", b, s), -1.0, 1.0)
        ang = np.degrees(np.arccos(cos))
        t = np.clip((ang - o.low) / max(o.high - o.low, 1e-9), 0.0, 1.0)
        m = np.where(cov, t * t * (3.0 - 2.0 * t), 0.0)
        r = max(1, int(round(2.0 * sigma)))
        m = ndimage.maximum_filter(m, size=2 * r + 1, mode="constant")
        m = blur_covered(m[..., None], cov.astype(np.float64), sigma)
        out[k] = np.clip(pad_islands(m, cov, o.padding)[..., 0], 0.0, 1.0)
    return out
