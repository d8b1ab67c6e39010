"""Baking a driver, the pure parts: :func:`changed_frames` (which frames need a new map),
:func:`weights_csv`, :func:`blend_frames` (the maps through :func:`wrinklepipe.model.blend`),
:func:`encode_states` (full wrinkled normals -> what the encoding stores). Reading the manifest
and writing the folder is the job :func:`wrinklepipe.jobs.bake.bake_manifest`.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from wrinklepipe.drivers.base import DriverResult
from wrinklepipe.model import blend, normal_to_diff, normal_to_pd, pd_to_normal


def changed_frames(weights: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
    """Index of the rendered frame each frame uses ``[F]``: a frame is rendered when its weights
    differ from the last rendered frame's by more than ``tolerance`` (max abs)."""
    w = np.asarray(weights, np.float64).reshape(weights.shape[0], -1)
    use = np.zeros(w.shape[0], np.int64)
    last = 0
    for f in range(1, w.shape[0]):  # frames, not texels: a short loop
        if np.max(np.abs(w[f] - w[last]), initial=0.0) > tolerance:
            last = f
        use[f] = last
    return use


def weights_csv(res: DriverResult) -> str:
    """``time,<region>:<state>,...`` then one row per frame (6 decimals, deterministic)."""
    labels = (
        res.regions if not res.per_vertex else tuple(str(i) for i in range(res.weights.shape[1]))
    )
    cols = [f"{r}:{s}" for r in labels for s in res.states]
    lines = [",".join(["time", *cols])]
    flat = np.round(res.weights.reshape(res.weights.shape[0], -1).astype(np.float64), 6) + 0.0
    for t, row in zip(res.times, flat):
        lines.append(",".join([f"{t:.6f}", *(f"{v:.6f}" for v in row)]))
    return "\n".join(lines) + "\n"


def encode_states(
    base: np.ndarray, states: np.ndarray, encoding: str, include_base: bool = True
) -> np.ndarray:
    """Unit normals of the wrinkled face (``include_base``) or of the wrinkles alone -> what
    :func:`wrinklepipe.model.combine` takes for ``encoding``."""
    b = np.asarray(base, np.float32)
    w = np.asarray(states, np.float32)
    if not include_base:  # wrinkle-only normals: add their slopes to the base's
        w = pd_to_normal(normal_to_pd(b)[None] + normal_to_pd(w))
    if encoding == "pd":
        return (normal_to_pd(w) - normal_to_pd(b)[None]).astype(np.float32)
    if encoding == "diff":
        return normal_to_diff(w, b[None])
    if encoding == "full":
        return w
    if encoding == "composite":
        return pd_to_normal(normal_to_pd(w) - normal_to_pd(b)[None])
    raise ValueError(f"unknown encoding {encoding!r}")


def blend_frames(
    base: np.ndarray,
    states: np.ndarray,
    masks: np.ndarray,
    weights: np.ndarray,
    use: np.ndarray,
    encoding: str = "pd",
    policy: str = "clamp01",
) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(frame, normals [H, W, 3])`` for every frame that is rendered (``use[f] == f``)."""
    for f in np.flatnonzero(use == np.arange(len(use))):
        w = weights[f][:, 0] if policy == "signed" else weights[f]
        yield int(f), blend(base, states, masks, w, encoding, policy)
