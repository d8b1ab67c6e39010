"""Height fields with exact gradients: a tiny forward-mode algebra on numpy arrays.

A :class:`Field` holds a value and its two partial derivatives (``du``, ``dv``) on a grid, so a
height built from sums, products and smooth functions of the UV coordinates carries its exact
slopes with it (no finite differences). The fidelity fixture builds its wrinkles this way, so the
true normal of any blend of them is known to float precision.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Field:
    """Value ``f`` and partial derivatives ``du`` (along u, columns) and ``dv`` (along v, rows)."""

    f: np.ndarray
    du: np.ndarray
    dv: np.ndarray

    # ---------------------------------------------------------------- arithmetic
    def __add__(self, o: Field | float) -> Field:
        if isinstance(o, Field):
            return Field(self.f + o.f, self.du + o.du, self.dv + o.dv)
        return Field(self.f + o, self.du, self.dv)

    __radd__ = __add__

    def __neg__(self) -> Field:
        return Field(-self.f, -self.du, -self.dv)

    def __sub__(self, o: Field | float) -> Field:
        return self + (-o)

    def __rsub__(self, o: float) -> Field:
        return (-self) + o

    def __mul__(self, o: Field | float) -> Field:
        if isinstance(o, Field):
            return Field(self.f * o.f, self.du * o.f + self.f * o.du, self.dv * o.f + self.f * o.dv)
        return Field(self.f * o, self.du * o, self.dv * o)

    __rmul__ = __mul__

    def __truediv__(self, o: float) -> Field:
        return self * (1.0 / o)

    def chain(self, g: np.ndarray, dg: np.ndarray) -> Field:
        """``g(self)`` given ``g`` and ``g'`` evaluated at ``self.f``."""
        return Field(g, dg * self.du, dg * self.dv)

    def pow(self, n: int) -> Field:
        return self.chain(self.f**n, n * self.f ** (n - 1))

    @property
    def slopes(self) -> np.ndarray:
        """PD slopes ``(-dh/du, +dh/dv)`` ``[H, W, 2]`` float32: x along u, +Y up while v (rows)
        runs down, so ``normalize(px, py, 1)`` is the tangent-space normal (as
        :func:`wrinklepipe.model.height_slopes`)."""
        return np.stack([-self.du, self.dv], axis=-1).astype(np.float32)


def coords(
    size: int, rows: tuple[int, int] | None = None, cols: tuple[int, int] | None = None
) -> tuple[Field, Field]:
    """The UV coordinates of the texel centres of a ``size`` x ``size`` map as fields (or of
    the window ``rows`` x ``cols``, half-open texel ranges)."""
    r0, r1 = rows or (0, size)
    c0, c1 = cols or (0, size)
    cu = (np.arange(c0, c1, dtype=np.float64) + 0.5) / size
    cv = (np.arange(r0, r1, dtype=np.float64) + 0.5) / size
    u, v = np.meshgrid(cu, cv, indexing="xy")
    one, zero = np.ones_like(u), np.zeros_like(u)
    return Field(u, one, zero), Field(v, zero, one)


def const(like: Field, value: float) -> Field:
    z = np.zeros_like(like.f)
    return Field(z + value, z, z)


def exp(x: Field) -> Field:
    e = np.exp(x.f)
    return x.chain(e, e)


def cos(x: Field) -> Field:
    return x.chain(np.cos(x.f), -np.sin(x.f))


def sin(x: Field) -> Field:
    return x.chain(np.sin(x.f), np.cos(x.f))


def smoothstep(e0: float, e1: float, x: Field) -> Field:
    """Hermite ``3t^2 - 2t^3`` of ``t = clip((x - e0) / (e1 - e0), 0, 1)`` (C1)."""
    t = np.clip((x.f - e0) / (e1 - e0), 0.0, 1.0)
    inside = (x.f > e0) & (x.f < e1) if e1 > e0 else (x.f < e0) & (x.f > e1)
    dt = np.where(inside, 1.0 / (e1 - e0), 0.0)
    return x.chain(t * t * (3.0 - 2.0 * t), 6.0 * t * (1.0 - t) * dt)


def box(x: Field, lo: float, hi: float, soft: float) -> Field:
    """1 between ``lo`` and ``hi``, smooth ramps of half-width ``soft``, 0 outside."""
    return smoothstep(lo - soft, lo + soft, x) * (1.0 - smoothstep(hi - soft, hi + soft, x))


def gaussian(d: Field, sigma: float) -> Field:
    """``exp(-d^2 / (2 sigma^2))``: a crease profile across a line at signed distance ``d``."""
    return exp(d * d * (-0.5 / sigma**2))


def hypot(x: Field, y: Field) -> Field:
    r = np.hypot(x.f, y.f)
    inv = 1.0 / np.maximum(r, 1e-300)
    return Field(r, (x.f * x.du + y.f * y.du) * inv, (x.f * x.dv + y.f * y.dv) * inv)


def atan2(y: Field, x: Field) -> Field:
    r2 = np.maximum(x.f * x.f + y.f * y.f, 1e-300)
    return Field(
        np.arctan2(y.f, x.f), (x.f * y.du - y.f * x.du) / r2, (x.f * y.dv - y.f * x.dv) / r2
    )
