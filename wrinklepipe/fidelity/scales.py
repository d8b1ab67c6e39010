"""PD scales: the candidates the search tries and the texels each one clips.

A PD map stores slopes ``d / s`` in 8 bits; a slope beyond the scale ``s`` sits at the end of
the range (clipped, what the validator's WP-MAP-004 counts). A texel on the horizon (z = 0, a
two-channel texel with x^2 + y^2 >= 1) has a slope of 1e12: no scale holds it, it clips at every
one, and it must never drive the choice (:func:`largest_held`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from wrinklepipe.fidelity import sampling as fsa
from wrinklepipe.fidelity import ship
from wrinklepipe.fidelity.level import PdLevel, row_bands
from wrinklepipe.normals.encode import MAX_PD_SCALE


def scale_candidates(max_slope: float, factors: Sequence[float]) -> list[float]:
    """PD scales to try: ``max_slope`` times each factor, rounded up to a multiple of 1/64
    (exact in float32 and in every shader), distinct, largest first. ``max_slope`` is taken as
    at most :data:`~wrinklepipe.normals.encode.MAX_PD_SCALE` (a texel on the horizon, z = 0,
    has a slope of 1e12: no scale holds it, and it clips at every one)."""
    top = min(max(float(max_slope), 1.0 / 64.0), MAX_PD_SCALE)
    out = sorted({float(np.ceil(top * f * 64.0) / 64.0) for f in factors}, reverse=True)
    return [s for s in out if s > 0]


def clipped_texels(level: np.ndarray, scale: float) -> list[int]:
    """Per state: texels stored at the end of the range at ``scale`` (:func:`ship.edge_texels`,
    the one clipped count)."""
    return [ship.edge_texels(ship.pd_texels(np.asarray(x), scale)[0]) for x in level]


def largest_held(x: np.ndarray | PdLevel) -> float:
    """The largest |component| of slopes ``x`` that some PD scale holds (at most
    :data:`~wrinklepipe.normals.encode.MAX_PD_SCALE`); 0 when none. Without temporaries when
    every texel is held (at full size a map is 4M texels); horizon texels (slopes up to 1e12)
    are left out. A :class:`~wrinklepipe.fidelity.level.PdLevel` band by band (the largest of
    the bands' is the whole map's)."""
    if isinstance(x, PdLevel):
        return max((largest_held(b) for _, b in row_bands(x)), default=0.0)
    big = max(float(np.max(x, initial=0.0)), -float(np.min(x, initial=0.0)))
    if big <= MAX_PD_SCALE:
        return big
    a = np.abs(x)
    return float(a[a <= MAX_PD_SCALE].max(initial=0.0))


def tails(level: np.ndarray | PdLevel, smallest: float) -> list[np.ndarray]:
    """Per state of ``level`` ``[K, s, s, 2]``: its texels ``[n, 1, 2]`` (in map order) whose
    larger |component| is at least 0.99 of scale ``smallest`` (the only ones that can clip at
    a scale of at least that). In chunks of rows (:func:`~wrinklepipe.fidelity.sampling.chunks`:
    the same texels, small temporaries) and two planes per chunk (a reduction over a last axis
    of 2 is ten times slower than one elementwise maximum; the same values)."""
    out = []
    for x in level:
        parts = []
        for sl in fsa.chunks(x.shape[0], max(1, fsa.CHUNK_TEXELS // max(x.shape[1], 1))):
            c = x[sl]
            amax = np.maximum(np.abs(c[..., 0]), np.abs(c[..., 1]))
            parts.append(c[amax >= 0.99 * smallest])
        out.append(np.concatenate(parts)[:, None, :])
    return out
