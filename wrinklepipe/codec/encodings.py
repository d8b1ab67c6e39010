"""Encoding declarations: what a stored wrinkle map holds, how it is scaled to [-1, 1], how it
decodes back to a normal (DESIGN.md sections 1 and 9).

========== ============ ========================================= ============ ===========
encoding   components   quantity ``x`` (signed ``t = x * k``)       parameter    mapping
========== ============ ========================================= ============ ===========
``pd``     2            slopes ``d = pd(W) - pd(B)``, ``t = d / s``  scale ``s``  versioned
``diff``   3            delta ``W - B``, ``t = g (W - B)``           gain ``g``   versioned
``full``   3 (2)        the wrinkled face's normal ``W``, ``t = W``  none         glTF (v1)
``composite`` 3 (2)     the wrinkle-only normal ``pd^-1(d)``         none         glTF (v1)
========== ============ ========================================= ============ ===========

``pd(n) = (x / z, y / z)`` with no minus sign (Jimenez et al.); convention OpenGL (+Y). Normal
encodings may be stored with two components (z rebuilt). The base map itself is a ``full``
normal map of the neutral face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wrinklepipe.codec import vectors as vec
from wrinklepipe.codec.mappings import CURRENT_VERSION, MAPPINGS, Mapping, mapping

_F = np.float32

#: Green convention of every stored map (DESIGN.md section 4); DirectX maps are flipped at
#: ingest and export only.
CONVENTION = "opengl"


@dataclass(frozen=True)
class Encoding:
    """One encoding: its stored quantity, scaling parameter and mapping rule."""

    name: str
    components: int  # components a full store holds (normal encodings may drop z)
    quantity: str  # "slopes" | "delta" | "normal"
    parameter: str | None  # "scale" (pd), "gain" (diff) or None
    versioned: bool  # the value mapping follows the asset's version (pd, diff)
    summary: str

    @property
    def is_normal(self) -> bool:
        return self.quantity == "normal"

    def mapping(self, version: int | None = CURRENT_VERSION) -> Mapping:
        """The value mapping texels of this encoding use at ``version`` (normal maps: glTF)."""
        return mapping(version) if self.versioned else MAPPINGS[1]

    # ------------------------------------------------------------------ quantity <-> signed
    def to_signed(self, x: np.ndarray, param: float = 1.0) -> tuple[np.ndarray, int]:
        """The quantity scaled to [-1, 1] (float32, clipped) and the texels that were clipped
        (pd: a slope beyond ``[-s, s]``; diff: a delta component beyond ``1 / g``)."""
        x = np.asarray(x, _F)
        p = self._param(param)
        if self.parameter == "scale":
            t = x / _F(p)
        elif self.parameter == "gain":
            t = x * _F(p)
        else:
            t = x.astype(_F, copy=True)
        clipped = 0
        if not self.is_normal:
            out = np.any(np.abs(t) > _F(1.0), axis=-1)
            clipped = int(np.count_nonzero(out))
        np.clip(t, _F(-1.0), _F(1.0), out=t)
        return t, clipped

    def from_signed(self, t: np.ndarray, param: float = 1.0) -> np.ndarray:
        """Signed values -> the quantity (normal encodings: unit normals, z rebuilt from two)."""
        t = np.asarray(t, _F)
        if self.is_normal:
            return vec.rebuild_z(t[..., :2]) if t.shape[-1] == 2 else vec.normalize(t[..., :3])
        p = _F(self._param(param))
        t = t[..., : self.components]
        return (t * p if self.parameter == "scale" else t / p).astype(_F)

    def _param(self, param: float) -> float:
        p = float(param)
        if self.parameter is None:
            return 1.0
        if not p > 0 or not np.isfinite(p):
            raise ValueError(f"{self.name} {self.parameter} must be a positive number, got {param}")
        return p

    # ------------------------------------------------------------------ normals <-> quantity
    def from_normals(self, state: np.ndarray, base: np.ndarray | None = None) -> np.ndarray:
        """The quantity a state normal map ``W`` stores (pd, diff, composite need the base)."""
        w = np.asarray(state, _F)
        if self.name == "full":
            return vec.normalize(w)
        if base is None:
            if self.name == "diff":
                raise ValueError("a diff map is relative to the base: give the base normals")
            d = vec.normal_to_pd(w)  # no base: the map itself is the wrinkle-only normal
        else:
            b = np.asarray(base, _F)
            if self.name == "diff":
                return (vec.normalize(w) - vec.normalize(b)).astype(_F)
            d = vec.normal_to_pd(w) - vec.normal_to_pd(b)
        return vec.pd_to_normal(d) if self.name == "composite" else d

    def to_normal(self, x: np.ndarray, base: np.ndarray | None = None) -> np.ndarray:
        """Unit normals from the quantity: the wrinkled face over ``base`` (full activation),
        or, without a base, the wrinkle-only normal (pd, composite) / the map (full)."""
        x = np.asarray(x, _F)
        if self.name == "full":
            return vec.normalize(x)
        if self.name == "diff":
            if base is None:
                raise ValueError("a diff map is relative to the base: give the base normals")
            return vec.normalize(np.asarray(base, _F) + x)
        d = x if self.name == "pd" else vec.normal_to_pd(x)
        if base is not None:
            d = vec.normal_to_pd(base) + d
        return vec.pd_to_normal(d)

    def combine_input(self, x: np.ndarray) -> np.ndarray:
        """The quantity in the form :func:`wrinklepipe.model.combine` takes (diff: the biased
        ``D = 0.5 + 0.5 (W - B)``; the others as they are)."""
        x = np.asarray(x, _F)
        return (_F(0.5) + _F(0.5) * x).astype(_F) if self.name == "diff" else x


PD = Encoding("pd", 2, "slopes", "scale", True, "PD slopes of the wrinkle-only normal")
DIFF = Encoding("diff", 3, "delta", "gain", True, "difference W - B to the base")
FULL = Encoding("full", 3, "normal", None, False, "absolute normal of the wrinkled face")
COMPOSITE = Encoding("composite", 3, "normal", None, False, "wrinkle-only normal (Oat)")
#: The base map: a ``full`` normal map of the neutral face.
BASE = FULL

ENCODINGS: dict[str, Encoding] = {e.name: e for e in (PD, DIFF, FULL, COMPOSITE)}


def encoding(name: str) -> Encoding:
    """The declaration of encoding ``name``."""
    if name not in ENCODINGS:
        raise ValueError(f"unknown encoding {name!r}; expected one of {', '.join(ENCODINGS)}")
    return ENCODINGS[name]
