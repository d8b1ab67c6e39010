"""Normal maps held as the integers of their files, read as float32 unit normals where used.

A conversion holds its source normal maps (the base and every wrinkled state) for the whole run:
the searches, the encoders and the validator read them. As float32 unit normals that is 12 bytes
a texel per map (805 MB per map at 8192²); a 16-bit PNG's texels are 6 bytes (8-bit: 3).
:class:`NormalStack` keeps the files' integer texels and decodes unit normals only where they
are asked for: a map (``stack[k]``), a band (``stack[k, r0:r1]``), texels (``stack[k][rows,
cols]``) or the whole stack (``np.asarray(stack)``, for a stage that needs it at once).

The float values are those the reader gives, bit for bit: :func:`wrinklepipe.normals.read.
decode_texels` of integer texels works texel by texel from ``(2 q - top) / top`` (the values it
is given are re-quantised to ``q`` first), so decoding a band of ``q`` gives that band of the
whole map's normals, and a map read as DirectX is flipped after decoding exactly as the reader
flips it. A map read as float32 (a float file, a repaired map, a wrinkle-only state combined
with the base) stays float32 unit normals: an array, or, when it is large, a :data:`UNIT` map
in a scratch file (:func:`held_floats`), read as it is.

It behaves as the float32 array for what the stages do with normals, as
:class:`wrinklepipe.masks.stack.MaskStack` does for masks: ``shape``, ``ndim``, ``dtype``
(float32), ``len``, indexing, iteration, numpy functions and ufuncs on the float32 values, any
other array attribute of the float32 array made for the call. Nothing changes it in place.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from wrinklepipe.arrayview import FloatView
from wrinklepipe.io.scratch import ScratchArray, hold

_F = np.float32


@dataclass(frozen=True)
class HeldMap:
    """One map's integer texels and how they decode: ``q`` ``[H, W, C]`` uint8 / uint16 (in
    memory, or in a scratch file: :class:`wrinklepipe.io.scratch.ScratchArray`, which reads the
    rows and texels indexed), the layout the reader resolved (``rgb``, ``rg``, ``ag``) and
    whether green is flipped after decoding (a DirectX map). Layout :data:`UNIT`: ``q`` is
    float32 unit normals ``[H, W, 3]`` already (a float file, a repaired map, a state made in
    PD space), held in a scratch file by :func:`held_floats`; they are read as they are."""

    q: np.ndarray | ScratchArray
    layout: str
    flip: bool

    def decode(self, rows: Any = slice(None), cols: Any = slice(None)) -> np.ndarray:
        """Unit normals (float32 ``[..., 3]``) of the texels ``q[rows, cols]``."""
        part = np.asarray(self.q[rows, cols])
        flat = part.reshape(-1, part.shape[-1])
        out = np.empty((flat.shape[0], 3), _F)
        step = max(1, DECODE_TEXELS)
        for t0 in range(0, flat.shape[0], step):  # a chunk's temporaries at a time
            out[t0 : t0 + step] = _unit(flat[t0 : t0 + step], self.layout, self.q.dtype)
        if self.flip:
            out[:, 1] *= -1
        return out.reshape(part.shape[:-1] + (3,))


#: Texels decoded at once (their float32 temporaries: ~10 MB).
DECODE_TEXELS = 1 << 18
#: The layout of a held map whose texels are float32 unit normals already.
UNIT = "unit"


def held_floats(a: np.ndarray) -> np.ndarray | HeldMap:
    """Float32 unit normals ``[H, W, 3]`` as a run holds them: in a scratch file, as a
    :data:`UNIT` map, when :func:`wrinklepipe.io.scratch.hold` takes them there (larger than
    its share of the working set), else the array as it is."""
    a = np.asarray(a, _F)
    kept = hold(a)
    return a if kept is a else HeldMap(kept, UNIT, False)


def _unit(q: np.ndarray, layout: str, dtype: np.dtype) -> np.ndarray:
    """Unit normals ``[n, 3]`` of integer texels ``q`` ``[n, C]``: the operations of
    :func:`wrinklepipe.normals.read.decode_texels` on integer texels, in its order, so the same
    bits (``(2 q - top) / top``, z rebuilt for ``rg`` / ``ag``, divided by the length). An
    integer texel is never zero-length (every component is at least ``1 / top`` from 0), so no
    texel is left undivided and the reader's counts are not needed here."""
    if layout == UNIT:
        return q  # float32 unit normals as they were made
    top = _F(255 if dtype == np.uint8 else 65535)

    def sig(c: np.ndarray) -> np.ndarray:
        x = c.astype(_F)
        x *= _F(2.0)
        x -= top
        x /= top
        return x

    if layout == "rgb":
        n = np.ascontiguousarray(sig(q[:, :3]))
    else:
        x = sig(q[:, 3] if layout == "ag" else q[:, 0])
        y = sig(q[:, 1])
        n = np.empty(x.shape + (3,), dtype=_F)
        n[:, 0] = x
        n[:, 1] = y
        z2 = _F(1.0) - x * x - y * y
        np.maximum(z2, _F(0.0), out=z2)
        np.sqrt(z2, out=n[:, 2])
    l2 = np.einsum("...c,...c->...", n, n)
    length = np.sqrt(l2, out=l2)
    n /= length[..., None]
    return n


def _stored(m: HeldMap) -> bool:
    """True when ``m``'s texels are of a kind a stack holds: integers, or float32 unit normals
    of layout :data:`UNIT`."""
    if m.layout == UNIT:
        return m.q.dtype == _F and m.q.shape[-1] == 3
    return m.q.dtype.kind == "u"


def _spatial(key: tuple[Any, ...]) -> bool:
    """True when ``key`` indexes only rows and columns (ints, slices, integer or boolean
    arrays): the integers can be indexed first, the channel axis is the decoded one."""

    def rc(k: Any) -> bool:
        if isinstance(k, np.ndarray):
            return k.dtype.kind in "iub"
        return isinstance(k, int | np.integer | slice)

    return len(key) <= 2 and all(rc(k) for k in key)


class NormalStack(FloatView):
    """Unit normals held as their files' integers: ``[K, H, W, 3]`` (``maps``: K held maps) or,
    with ``single``, one map ``[H, W, 3]``."""

    #: ``stack[r0:r1]`` of a one-map stack decodes those rows (workset.map_rows reads bands)
    reads_rows = True

    def __init__(self, maps: list[HeldMap], single: bool = False) -> None:
        if not maps or (single and len(maps) != 1):
            raise ValueError(f"a normal stack holds 1 map (single) or K >= 1, got {len(maps)}")
        sizes = {m.q.shape[:2] for m in maps}
        if len(sizes) != 1 or any(m.q.ndim != 3 or not _stored(m) for m in maps):
            raise ValueError("a normal stack holds integer or unit maps [H, W, C] of one size")
        self.maps = maps
        self.single = single

    @property
    def shape(self) -> tuple[int, ...]:
        h, w = self.maps[0].q.shape[:2]
        return (h, w, 3) if self.single else (len(self.maps), h, w, 3)

    ndim = property(lambda self: len(self.shape))
    size = property(lambda self: int(np.prod(self.shape)))
    dtype = property(lambda self: np.dtype(_F))
    #: what the float32 array would take (the stack itself takes :attr:`held_bytes`)
    nbytes = property(lambda self: self.size * 4)
    held_bytes = property(lambda self: sum(m.q.nbytes for m in self.maps))

    def memo_key(self) -> tuple[Any, ...]:
        """What the run's memo keys a call on this stack by (:mod:`wrinklepipe.reuse`): the
        integers and how they decode (the float values are a function of them)."""
        return (self.single, *((m.q, m.layout, m.flip) for m in self.maps))

    def __len__(self) -> int:
        return self.shape[0]

    def map(self, k: int) -> NormalStack:
        """State ``k`` as a one-map stack (still integers)."""
        return NormalStack([self.maps[k]], single=True)

    def __getitem__(self, key: Any) -> np.ndarray:
        key = key if isinstance(key, tuple) else (key,)
        if self.single:
            if _spatial(key):
                return self.maps[0].decode(*key)
            return np.asarray(self)[key]
        first, rest = key[0], key[1:]
        if isinstance(first, int | np.integer) and _spatial(rest):
            return self.maps[int(first)].decode(*rest)
        if isinstance(first, slice) and _spatial(rest):
            chosen = self.maps[first]
            if not chosen:
                return np.empty((0, *self.shape[1:]), _F)[rest if rest else ()]
            return np.stack([m.decode(*rest) for m in chosen])
        return np.asarray(self)[key]

    def __iter__(self) -> Any:
        return (self[i] for i in range(len(self)))

    def reshape(self, *shape: Any) -> Any:
        """A one-map stack as ``[H * W, 3]`` texels (``reshape(-1, 3)``): a
        :class:`FlatTexels` that decodes only the texels indexed; any other shape of the
        float32 array made for the call."""
        want = tuple(shape[0]) if len(shape) == 1 and isinstance(shape[0], tuple) else shape
        h, w = self.shape[-3:-1]
        if self.single and want in ((-1, 3), (h * w, 3), (h * w, -1)):
            return FlatTexels(self)
        return np.asarray(self).reshape(*shape)

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        if self.single:
            a = self.maps[0].decode()
        else:
            a = np.empty(self.shape, _F)
            for k, m in enumerate(self.maps):
                a[k] = m.decode()
        return a if dtype is None else a.astype(dtype, copy=False)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name in ("maps", "single"):  # copy / pickle protocols
            raise AttributeError(name)
        return getattr(np.asarray(self), name)

    def __copy__(self) -> NormalStack:
        return self  # never changed in place: a copy is the stack itself

    def __deepcopy__(self, memo: dict[int, Any]) -> NormalStack:
        return NormalStack([HeldMap(m.q.copy(), m.layout, m.flip) for m in self.maps], self.single)

    def __repr__(self) -> str:
        h, w = self.shape[-3:-1]
        kind = "1 map" if self.single else f"{len(self.maps)} maps"
        return f"NormalStack({kind} {w}x{h}, {self.maps[0].q.dtype})"


class FlatTexels:
    """A one-map :class:`NormalStack` seen as ``[H * W, 3]`` texels: indexing with flat
    texel indices (an integer or boolean array, a slice) decodes those texels only."""

    def __init__(self, stack: NormalStack) -> None:
        self.stack = stack
        h, w = stack.shape[:2]
        self.shape = (h * w, 3)

    ndim = 2
    dtype = np.dtype(_F)

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, key: Any) -> np.ndarray:
        if isinstance(key, slice):
            return texels_at(self.stack, np.arange(*key.indices(self.shape[0])))
        if isinstance(key, np.ndarray) and key.dtype == bool and key.ndim == 1:
            return texels_at(self.stack, np.flatnonzero(key))
        if isinstance(key, np.ndarray) and key.dtype.kind in "iu":
            return texels_at(self.stack, key.reshape(-1)).reshape(*key.shape, 3)
        return np.asarray(self)[key]

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        a = np.asarray(self.stack).reshape(self.shape)
        return a if dtype is None else a.astype(dtype, copy=False)


def rows_of(a: Any) -> Any:
    """Normals to be read a band of rows (or some texels) at a time: a :class:`NormalStack`
    as it is (its rows decode where read), anything else as a float32 array."""
    return a if isinstance(a, NormalStack | FlatTexels) else np.asarray(a, _F)


def texels_at(a: Any, flat: np.ndarray) -> np.ndarray:
    """The texels at flat indices ``flat`` of a map ``[H, W, C]`` (-> ``[n, C]``) or of every
    map of a stack ``[K, H, W, C]`` (-> ``[K, n, C]``): an array's gathered, a
    :class:`NormalStack`'s decoded at those texels only."""
    if not isinstance(a, NormalStack):
        a = np.asarray(a)
        h, w = a.shape[-3:-1]
        return a.reshape(*a.shape[:-3], h * w, a.shape[-1])[..., flat, :]
    w = a.shape[-2]
    rows, cols = np.divmod(np.asarray(flat, np.int64), w)
    got = [m.decode(rows, cols) for m in a.maps]
    return got[0] if a.single else np.stack(got)


def one_map(a: Any, k: int) -> Any:
    """Map ``k`` of a stack ``[K, H, W, C]``: a :class:`NormalStack`'s still held as integers
    (:meth:`NormalStack.map`), an array's as a view."""
    return a.map(k) if isinstance(a, NormalStack) else a[k]
