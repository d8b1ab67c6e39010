"""The wrinkle model: the numpy reference every shader and engine export must agree with.

Per texel (or per vertex; any spatial shape works) of a face::

    s_k     = sum_r M_r * w_{r,k}                 region activations (one matmul)
    a_k     = policy(s_k)                         how overlapping regions meet
    N       = combine(B, {W_k, a_k}, encoding)    the wrinkled normal
    C       = C_B + sum_k a_k (C_k - C_B)         the wrinkled colour (linear light, optional)

Conventions (DESIGN.md section 4): float32, unit tangent-space normals in the last axis
(``[..., 3]``), OpenGL green (+Y). Masks are channels-first ``[R, *S]`` so the activation is a
single ``weights.T @ masks`` product; weights are ``[R, K]`` (region x state), except under the
``signed`` policy where they are ``[R]`` (or ``[R, 1]``): Oat's single weight in [-1, 1] whose
negative part drives state 0 (stretch) and positive part state 1 (compress).

Encodings (what a stored wrinkle state holds and how it is combined with the base B):

``pd``
    Partial-derivative slopes ``d = (x/z, y/z)`` of the *wrinkle-only* normal (Jimenez et al.,
    no minus sign). ``N = normalize(B_d + sum_k a_k W_d,k, 1)``. PD is linear in the height
    field, so this is exactly the normal of ``h_base + sum_k a_k h_k``.
``diff``
    Biased difference to the base ``D = 0.5 + 0.5 (W - B)`` (Jimenez et al. 1.2.1), with W the
    full normal of the face in the wrinkled pose. ``N = normalize(B + sum_k a_k (2 D_k - 1))``.
``full``
    Absolute normal maps of the wrinkled face (MetaHuman style). ``N = normalize(B + sum_k a_k
    (W_k - B))``: a lerp when one state is active, additive deltas when several are.
``composite``
    Oat's / Dutreve et al.'s detail-preserving composite of the base with wrinkle-only normals:
    x and y add, z multiplies. With activations: ``xy = B_xy + sum_k a_k W_k,xy`` and
    ``z = B_z * prod_k (1 + a_k (W_k,z - 1))``, so ``a = 1`` gives ``(B_xy + W_xy, B_z W_z)``.

Colour (appearance states, DESIGN.md section 1): a state may carry a colour map ``C_k`` beside
(or instead of) its normal map: the face's albedo in that pose, as an artist paints it (sRGB).
:func:`combine_color` blends in *linear light* (decode with :func:`srgb_to_linear` first) with
the same activations as the normals, ``C = clip(C_B + sum_k a_k (C_k - C_B), 0, 1)``, the base
colour bit for bit where no state is active. The same sum serves any other linear per-state map
(roughness, cavity): it is a per-channel lerp-and-add, whatever the channels hold.

Policies (how the summed region activation becomes a state activation):

``clamp01``      Jimenez et al.: ``a = clip(s, 0, 1)``; negative weights cancel positive ones.
``signed``       Oat: ``s = clip(sum_r M_r w_r, -1, 1)``; state 0 gets ``max(-s, 0)``, state 1
                 gets ``max(s, 0)``. Needs exactly two states.
``additive``     MetaHuman reference shader: ``a = s``, no clamp.
``renormalize``  Unity Digital Human: where masks overlap (``sum_r M_r > 1``) they are divided by
                 their sum, so overlapping regions average instead of add; then ``a = clip(s,0,1)``.
``lerp``         Reis et al.: each activation is clamped to [0, 1] and the set is made convex
                 (divided by ``sum_k a_k`` where that exceeds 1), so the result is a lerp between
                 the unwrinkled and the wrinkled surface.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from wrinklepipe.codec.srgb import linear_to_srgb, srgb_to_linear
from wrinklepipe.codec.vectors import composite as composite_detail
from wrinklepipe.codec.vectors import normal_to_pd, normalize, pd_to_normal

__all__ = [
    "ENCODINGS",
    "POLICIES",
    "POLICY_WEIGHT_RANGE",
    "activations",
    "blend",
    "blend_color",
    "combine",
    "combine_color",
    "composite_detail",
    "diff_to_delta",
    "height_slopes",
    "height_to_normal",
    "linear_to_srgb",
    "normal_to_diff",
    "normal_to_pd",
    "normalize",
    "pd_to_normal",
    "region_sum",
    "srgb_to_linear",
]

Encoding = Literal["pd", "diff", "full", "composite"]
Policy = Literal["clamp01", "signed", "additive", "renormalize", "lerp"]

#: The encodings of :mod:`wrinklepipe.codec.encodings` (their storage is declared there; this
#: module combines their float quantities).
ENCODINGS: tuple[str, ...] = ("pd", "diff", "full", "composite")
POLICIES: tuple[str, ...] = ("clamp01", "signed", "additive", "renormalize", "lerp")

#: Largest supported counts (the model itself has no hard limit; these are what is tested).
MAX_STATES = 16
MAX_REGIONS = 256

_EPS = np.float32(1e-12)


@dataclass(frozen=True)
class WeightRange:
    """The range a policy accepts for each region weight (used by validators)."""

    low: float
    high: float


#: Weight range per policy: values outside are reported by ``validate-asset``.
POLICY_WEIGHT_RANGE: dict[str, WeightRange] = {
    "clamp01": WeightRange(-1.0, 1.0),
    "signed": WeightRange(-1.0, 1.0),
    "additive": WeightRange(-4.0, 4.0),
    "renormalize": WeightRange(0.0, 1.0),
    "lerp": WeightRange(0.0, 1.0),
}


def height_to_normal(height: np.ndarray, texel_size: float = 1.0) -> np.ndarray:
    """Analytic tangent-space normal of a height field sampled on a grid, ``[H, W] -> [H, W, 3]``.

    ``N = normalize(-dh/dx, -dh/dy, 1)`` with x along columns (u) and y along rows. Rows run
    top to bottom (glTF UV origin) while +Y (OpenGL green) points up, so ``dh/dy`` is the
    negative of the row derivative. Central differences inside, one-sided at the border.
    """
    hx, hy = height_slopes(height, texel_size)
    return pd_to_normal(np.stack([hx, hy], axis=-1))


def height_slopes(height: np.ndarray, texel_size: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """PD slopes ``(-dh/dx, -dh/dy)`` of a height field, so that ``N = normalize(px, py, 1)``."""
    h = np.asarray(height, dtype=np.float64)
    d_row, d_col = np.gradient(h, texel_size)
    # x grows with the column; y grows upwards, i.e. against the row index.
    px = -d_col
    py = d_row
    return px.astype(np.float32), py.astype(np.float32)


def normal_to_diff(wrinkled: np.ndarray, base: np.ndarray) -> np.ndarray:
    """Difference map ``0.5 + 0.5 (W - B)`` in [0, 1] (Jimenez et al. 1.2.1)."""
    return (0.5 + 0.5 * (np.asarray(wrinkled, np.float32) - np.asarray(base, np.float32))).astype(
        np.float32
    )


def diff_to_delta(d: np.ndarray) -> np.ndarray:
    """The signed delta ``2 D - 1`` a difference map stores."""
    return (2.0 * np.asarray(d, np.float32) - 1.0).astype(np.float32)


def _as_weight_matrix(weights: np.ndarray, policy: str, n_regions: int) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float32)
    if policy == "signed":
        if w.ndim == 2 and w.shape[1] == 1:
            w = w[:, 0]
        if w.ndim != 1:
            raise ValueError(f"policy 'signed' takes one weight per region, got shape {w.shape}")
        w = w[:, None]
    if w.ndim != 2 or w.shape[0] != n_regions:
        raise ValueError(f"weights must be [regions={n_regions}, states], got shape {w.shape}")
    return w


def region_sum(masks: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``s_k = sum_r M_r w_{r,k}`` as one matmul: ``[R, *S]`` x ``[R, K]`` -> ``[K, *S]``."""
    m = np.asarray(masks, dtype=np.float32)
    w = np.asarray(weights, dtype=np.float32)
    spatial = m.shape[1:]
    flat = m.reshape(m.shape[0], -1)
    return (w.T @ flat).reshape((w.shape[1],) + spatial)


def activations(masks: np.ndarray, weights: np.ndarray, policy: str = "clamp01") -> np.ndarray:
    """State activations ``a_k(uv)`` ``[K, *S]`` from masks ``[R, *S]`` and weights."""
    if policy not in POLICIES:
        raise ValueError(f"unknown policy {policy!r}; expected one of {', '.join(POLICIES)}")
    m = np.asarray(masks, dtype=np.float32)
    w = _as_weight_matrix(weights, policy, m.shape[0])
    if policy == "renormalize":
        total = m.sum(axis=0)
        m = m / np.maximum(total, np.float32(1.0))[None]
    s = region_sum(m, w)
    if policy == "clamp01" or policy == "renormalize":
        return np.clip(s, 0.0, 1.0, out=s)
    if policy == "additive":
        return s
    if policy == "signed":
        sig = np.clip(s[0], -1.0, 1.0)
        return np.stack([np.maximum(-sig, 0.0), np.maximum(sig, 0.0)]).astype(np.float32)
    # lerp: clamp each, then make the set convex with the base.
    a = np.clip(s, 0.0, 1.0, out=s)
    total = a.sum(axis=0)
    return (a / np.maximum(total, np.float32(1.0))[None]).astype(np.float32)


def combine(
    base: np.ndarray, states: np.ndarray, act: np.ndarray, encoding: str = "pd"
) -> np.ndarray:
    """Combine the base with K encoded states under activations.

    base:   ``[*S, 3]`` unit normals.
    states: ``[K, *S, 2]`` PD slopes (``pd``), ``[K, *S, 3]`` difference maps in [0, 1] (``diff``),
            or ``[K, *S, 3]`` unit normals (``full``: wrinkled face; ``composite``: wrinkle only).
    act:    ``[K, *S]`` activations.
    Returns ``[*S, 3]`` unit normals (float32).
    """
    b = np.asarray(base, dtype=np.float32)
    st = np.asarray(states, dtype=np.float32)
    a = np.asarray(act, dtype=np.float32)
    if st.shape[0] != a.shape[0]:
        raise ValueError(f"{st.shape[0]} states but {a.shape[0]} activations")
    out = _combine(b, st, a, encoding)
    # Where no state is active the base comes back bit for bit (the neutral face is untouched).
    idle = ~np.any(a != 0, axis=0)
    np.copyto(out, b, where=idle[..., None])
    return out


def _combine(b: np.ndarray, st: np.ndarray, a: np.ndarray, encoding: str) -> np.ndarray:
    if encoding == "pd":
        acc = normal_to_pd(b) + np.einsum("k...,k...c->...c", a, st)
        return pd_to_normal(acc)
    if encoding == "diff":
        return normalize(b + np.einsum("k...,k...c->...c", a, diff_to_delta(st)))
    if encoding == "full":
        return normalize(b + np.einsum("k...,k...c->...c", a, st - b[None]))
    if encoding == "composite":
        xy = b[..., :2] + np.einsum("k...,k...c->...c", a, st[..., :2])
        z = b[..., 2] * np.prod(1.0 + a * (st[..., 2] - 1.0), axis=0)
        return normalize(np.concatenate([xy, z[..., None]], axis=-1))
    raise ValueError(f"unknown encoding {encoding!r}; expected one of {', '.join(ENCODINGS)}")


def blend(
    base: np.ndarray,
    states: np.ndarray,
    masks: np.ndarray,
    weights: np.ndarray,
    encoding: str = "pd",
    policy: str = "clamp01",
) -> np.ndarray:
    """The whole model: ``combine(B, W, policy(sum_r M_r w_r), encoding)`` -> ``[*S, 3]``."""
    return combine(base, states, activations(masks, weights, policy), encoding)


def combine_color(base: np.ndarray, states: np.ndarray, act: np.ndarray) -> np.ndarray:
    """The colour model: ``C = clip(C_B + sum_k a_k (C_k - C_B), 0, 1)``, per channel.

    base:   ``[*S, C]`` the base colour in linear light (or any linear map in [0, 1]).
    states: ``[K, *S, C]`` the states' colours, linear.
    act:    ``[K, *S]`` the activations of those K states (the same ``a_k`` the normals use).
    Returns ``[*S, C]`` float32. The sum is clipped to [0, 1] (an albedo outside that is no
    colour; the shaders clamp the same way); where no state is active the base comes back bit
    for bit.
    """
    b = np.asarray(base, dtype=np.float32)
    st = np.asarray(states, dtype=np.float32)
    a = np.asarray(act, dtype=np.float32)
    if st.shape[0] != a.shape[0]:
        raise ValueError(f"{st.shape[0]} colour states but {a.shape[0]} activations")
    if st.shape[1:] != b.shape:
        raise ValueError(f"colour states {st.shape[1:]} and base colour {b.shape} differ")
    out = b + np.einsum("k...,k...c->...c", a, st - b[None])
    np.clip(out, 0.0, 1.0, out=out)
    idle = ~np.any(a != 0, axis=0)
    np.copyto(out, b, where=idle[..., None])
    return out.astype(np.float32, copy=False)


def blend_color(
    base: np.ndarray,
    states: np.ndarray,
    masks: np.ndarray,
    weights: np.ndarray,
    policy: str = "clamp01",
    color_states: tuple[int, ...] | None = None,
) -> np.ndarray:
    """The colour model whole: :func:`combine_color` under ``policy(sum_r M_r w_r)``.

    ``weights`` are the asset's ``[R, K]`` (all K states: the activations are the normals');
    ``color_states`` the indices of the states that carry a colour, in the order of ``states``
    (None: every state does). Colours in linear light.
    """
    act = activations(masks, weights, policy)
    if color_states is not None:
        act = act[list(color_states)]
    return combine_color(base, states, act)
