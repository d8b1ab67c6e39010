"""Channel layouts: which RGBA channels of a stored texture hold x, y and z.

``rgb``  x in R, y in G, z in B (stored), A = 1. What every consumer reads from a three- or
         four-channel normal map (BC1, BC7, PNG, EXR, UASTC): glTF ``normalTexture``,
         ``UsdPreviewSurface``, engines, viewers. Difference maps use it for their three deltas.
``rg``   x in R, y in G, B = 0, A = 1; z is not stored (a normal map rebuilds it:
         ``z = sqrt(1 - x^2 - y^2)``; PD slopes have no z). BC5 / 3Dc by convention.
``ag``   x in A, y in G, R = 1, B = 0; z rebuilt. DXT5nm / BC3nm (Unity and Unreal).

Channel indices are RGBA (R = 0 ... A = 3). :func:`pack` and :func:`unpack` move component
arrays in and out of RGBA texels; the fill values are in units of the texel's top value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Layout:
    """Where the components live: ``x``, ``y`` and ``z`` (None: not stored) channel indices,
    and the constant (0 or 1, times the top texel value) of every other RGBA channel."""

    name: str
    x: int
    y: int
    z: int | None
    fill: tuple[float, float, float, float]
    summary: str

    @property
    def components(self) -> tuple[int, ...]:
        """Channel index of each stored component, x first."""
        return (self.x, self.y) if self.z is None else (self.x, self.y, self.z)

    @property
    def stores_z(self) -> bool:
        return self.z is not None

    @property
    def swizzle(self) -> str:
        """The KTX2 ``KTXswizzle`` value: for each of R, G, B, A of the logical texture, the
        stored channel (``r g b a``) or constant (``0 1``) it is read from."""
        src = "rgba"
        out = [src[self.x], src[self.y], src[self.z] if self.z is not None else "0", "1"]
        return "".join(out)

    def glsl_swizzle(self) -> str:
        """The swizzle that reads the stored components from an RGBA texel (``rg``, ``ag``)."""
        return "".join("rgba"[c] for c in self.components)


RGB = Layout("rgb", 0, 1, 2, (0.0, 0.0, 0.0, 1.0), "x in R, y in G, z in B")
RG = Layout("rg", 0, 1, None, (0.0, 0.0, 0.0, 1.0), "x in R, y in G, z rebuilt")
AG = Layout("ag", 3, 1, None, (1.0, 0.0, 0.0, 0.0), "x in A, y in G, z rebuilt (DXT5nm)")

LAYOUTS: dict[str, Layout] = {lay.name: lay for lay in (RGB, RG, AG)}
#: Integer ids the generated shader functions use (``WP_LAYOUT_RGB`` ...), stable.
LAYOUT_IDS: dict[str, int] = {"rgb": 0, "rg": 1, "ag": 2}


def layout(name: str) -> Layout:
    """The layout called ``name`` (``rgb``, ``rg``, ``ag``)."""
    if name not in LAYOUTS:
        raise ValueError(f"unknown channel layout {name!r}; expected one of {', '.join(LAYOUTS)}")
    return LAYOUTS[name]


def pack(components: np.ndarray, lay: Layout, channels: int = 4) -> np.ndarray:
    """Component texels ``[..., 2 or 3]`` (x, y[, z]; uint8/uint16/float) -> ``[..., channels]``
    texels in the layout, the other channels filled with the layout's constants.

    Three components into a layout without z drop z (it is rebuilt on decode)."""
    c = np.asarray(components)
    n = c.shape[-1]
    if n not in (2, 3):
        raise ValueError(f"expected 2 or 3 components, got {n}")
    if n == 2 and lay.stores_z:
        raise ValueError(f"layout {lay.name} stores z: give three components")
    top = _top(c.dtype)
    out = np.empty(c.shape[:-1] + (channels,), dtype=c.dtype)
    for ch in range(channels):
        out[..., ch] = lay.fill[ch] * top if ch < 4 else 0
    for i, ch in enumerate(lay.components):
        if ch >= channels:
            raise ValueError(f"layout {lay.name} needs channel {'rgba'[ch]}; {channels} given")
        out[..., ch] = c[..., i]
    return out


def unpack(texels: np.ndarray, lay: Layout) -> np.ndarray:
    """The stored components ``[..., 2 or 3]`` (x, y[, z]) of RGBA-ordered texels."""
    t = np.asarray(texels)
    need = max(lay.components) + 1
    if t.shape[-1] < need:
        raise ValueError(
            f"layout {lay.name} reads channel {'rgba'[need - 1]}; the texels have "
            f"{t.shape[-1]} channel{'' if t.shape[-1] == 1 else 's'}"
        )
    return t[..., list(lay.components)]


def _top(dtype: np.dtype) -> float:
    if dtype == np.uint8:
        return 255.0
    if dtype == np.uint16:
        return 65535.0
    return 1.0
