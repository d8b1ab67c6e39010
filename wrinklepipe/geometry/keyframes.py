"""glTF 2.0 keyframe sampling (the spec's Appendix C): STEP, LINEAR (slerp for rotations) and
CUBICSPLINE (Hermite with tangents scaled by the key interval), clamped outside the keys.

The one sampler of glTF animation channels: node TRS poses (:mod:`wrinklepipe.gltf.meshes`),
morph-weight tracks (:func:`wrinklepipe.drivers.curves.sample_morph_tracks`) and the USD
writer's time samples (:mod:`wrinklepipe.usd.animation`) all call it.
"""

from __future__ import annotations

import numpy as np


def sample_channel(t: np.ndarray, v: np.ndarray, time: float, interp: str, path: str) -> np.ndarray:
    """Sample a glTF animation channel at ``time`` (:func:`sample_channel_at` at one time)."""
    return sample_channel_at(t, v, np.array([time], np.float64), interp, path)[0]


def _slerp_rows(q0: np.ndarray, q1: np.ndarray, a: np.ndarray) -> np.ndarray:
    """:func:`slerp` of quaternion rows ``[F, 4]`` by ``a`` ``[F]``."""
    d = np.sum(q0 * q1, axis=1)
    q1 = np.where(d[:, None] < 0, -q1, q1)
    d = np.abs(d)
    near = d > 0.9995
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    sin = np.where(near, 1.0, np.sin(theta))
    w0 = np.where(near, 1 - a, np.sin((1 - a) * theta) / sin)
    w1 = np.where(near, a, np.sin(a * theta) / sin)
    q = w0[:, None] * q0 + w1[:, None] * q1
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def sample_channel_at(
    t: np.ndarray, v: np.ndarray, times: np.ndarray, interp: str, path: str
) -> np.ndarray:
    """Sample a glTF animation channel at ``times`` -> ``[F, C]``, per the glTF 2.0 spec
    (Appendix C).

    ``v`` is ``[N, C]`` for STEP / LINEAR and ``[N, 3, C]`` (in-tangent, value, out-tangent)
    for CUBICSPLINE. LINEAR rotations slerp; cubic rotations are normalised. Times outside the
    keys clamp to the first / last value.
    """
    vals = v[:, 1] if interp == "CUBICSPLINE" else v
    times = np.asarray(times, np.float64)
    if len(t) == 1:
        return np.repeat(vals[:1], len(times), axis=0).astype(np.float64)
    k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)
    td = t[k + 1] - t[k]
    a = np.clip((times - t[k]) / np.where(td > 0, td, 1.0), 0.0, 1.0)
    if interp == "STEP":
        out = vals[k].astype(np.float64)
    elif interp == "CUBICSPLINE":
        a2, a3 = a * a, a * a * a
        out = (
            (2 * a3 - 3 * a2 + 1)[:, None] * v[k, 1]
            + (td * (a3 - 2 * a2 + a))[:, None] * v[k, 2]
            + (-2 * a3 + 3 * a2)[:, None] * v[k + 1, 1]
            + (td * (a3 - a2))[:, None] * v[k + 1, 0]
        )
        if path == "rotation":
            out /= np.linalg.norm(out, axis=1, keepdims=True)
    elif path == "rotation":
        out = _slerp_rows(vals[k].astype(np.float64), vals[k + 1].astype(np.float64), a)
    else:
        out = (1 - a)[:, None] * vals[k] + a[:, None] * vals[k + 1]
    out[times <= t[0]] = vals[0]
    out[times >= t[-1]] = vals[-1]
    return out
