"""Masks held as the integers of their files, read as float32 where a stage uses them.

A conversion holds its source masks for the whole run (the searches and the validator measure
against them). As float32 that is 4 bytes a texel per mask (268 MB per mask at 8192²); an 8-bit
file's values are 1 byte (16-bit: 2). :class:`MaskStack` keeps ``[R, H, W]`` in the file's
integers and gives float32 values only where they are asked for: a mask (``stack[i]``), a
band, or the whole stack (``np.asarray(stack, np.float32)``, for a stage that needs it at once).

The float values are those the image reader gives, bit for bit: OpenImageIO converts an integer
texel ``v`` of ``b`` bits to ``float32(v) * float32(1 / (2^b - 1))`` (:func:`to_float`), and
:func:`quantized` keeps a mask in integers only when every texel converts back to the float it
was read as (else the mask stays float32: float files, inverted masks, ...). So every stage sees
the values it saw when the masks were float32, and every output is the same byte for byte.

It behaves as the float32 array for what the stages do with masks: ``shape``, ``ndim``,
``dtype`` (float32), ``len``, indexing and iteration (float32 planes), numpy functions and
ufuncs (``np.asarray``, ``np.clip``, ``>``, ``*`` ...: on the float32 values) and any other
array attribute (``.max()``, ``.T``: of the float32 array, made for the call).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wrinklepipe.arrayview import FloatView

_F = np.float32


def to_float(q: np.ndarray) -> np.ndarray:
    """Integer texels (uint8 / uint16) as the float32 in [0, 1] OpenImageIO reads them as."""
    top = 255 if q.dtype == np.uint8 else 65535
    return q.astype(_F) * _F(1.0 / top)


def quantized(m: np.ndarray, bits: int) -> np.ndarray | None:
    """``m`` (float32 in [0, 1]) as ``bits``-bit integers when :func:`to_float` gives ``m`` back
    bit for bit at every texel, else None."""
    if bits not in (8, 16):
        return None
    a = np.asarray(m, _F)
    top = (1 << bits) - 1
    q = np.rint(np.clip(a, 0.0, 1.0) * _F(top)).astype(np.uint8 if bits == 8 else np.uint16)
    if not np.array_equal(to_float(q).view(np.uint32), a.view(np.uint32)):
        return None
    return q


def float_masks(masks: Any) -> Any:
    """Masks as float32 for a stage that takes them a mask at a time: a :class:`MaskStack` as
    it is (its masks are float32 one by one), anything else ``np.asarray(masks, float32)``."""
    return masks if isinstance(masks, MaskStack) else np.asarray(masks, _F)


class MaskStack(FloatView):
    """Masks ``[R, H, W]`` held as integers (``q``: uint8 or uint16), seen as float32."""

    def __init__(self, q: np.ndarray) -> None:
        if q.dtype not in (np.uint8, np.uint16) or q.ndim != 3:
            raise ValueError(
                f"a mask stack holds [R, H, W] uint8 or uint16, got {q.dtype} {q.shape}"
            )
        self.q = q

    shape = property(lambda self: self.q.shape)
    ndim = property(lambda self: 3)
    size = property(lambda self: self.q.size)
    dtype = property(lambda self: np.dtype(_F))
    #: what the float32 stack would take (the stack itself takes ``q.nbytes``)
    nbytes = property(lambda self: self.q.size * 4)

    def memo_key(self) -> np.ndarray:
        """What the run's memo keys a call on this stack by (:mod:`wrinklepipe.reuse`): its
        integers (the float values are a function of them)."""
        return self.q

    def __len__(self) -> int:
        return int(self.q.shape[0])

    def integers(self, i: int) -> np.ndarray:
        """Mask ``i``'s integers ``[H, W]`` (what :meth:`float_of` turns into its values)."""
        return self.q[i]

    def float_of(self, q: np.ndarray) -> np.ndarray:
        """The float32 values of some of this stack's integers (per texel)."""
        return to_float(q)

    def __getitem__(self, key: Any) -> np.ndarray:
        return to_float(np.asarray(self.q[key]))

    def __iter__(self) -> Any:
        return (self[i] for i in range(len(self)))

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        a = to_float(self.q)
        return a if dtype is None else a.astype(dtype, copy=False)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name == "q":  # copy / pickle protocols, an unset stack
            raise AttributeError(name)
        return getattr(np.asarray(self), name)

    def __copy__(self) -> MaskStack:
        return self  # never changed in place: a copy is the stack itself

    def __deepcopy__(self, memo: dict[int, Any]) -> MaskStack:
        return MaskStack(self.q.copy())

    def __repr__(self) -> str:
        r, h, w = self.q.shape
        return f"MaskStack({r} masks {w}x{h}, {self.q.dtype})"


class CroppedMasks(MaskStack):
    """A :class:`MaskStack` that holds each mask's integers only inside the box of its non-zero
    texels (a region's mask is zero over most of the face: 8 region masks at 8192² are 512 MiB
    as 8-bit stacks, their boxes a fraction of it). The values are the stack's, bit for bit:
    zero outside a box, the file's integers inside."""

    def __init__(self, q: np.ndarray) -> None:  # noqa: D107 - built from the dense stack
        super().__init__(q)
        crops: list[tuple[np.ndarray, int, int]] = []
        for m in q:
            rows = np.flatnonzero(m.any(axis=1))
            cols = np.flatnonzero(m.any(axis=0))
            if rows.size == 0:
                crops.append((np.zeros((0, 0), q.dtype), 0, 0))
                continue
            r0, r1, c0, c1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
            crops.append((np.ascontiguousarray(m[r0:r1, c0:c1]), r0, c0))
        self.crops = crops
        self._shape = q.shape
        self._dtype_q = q.dtype
        del self.q  # the dense stack is not kept

    shape = property(lambda self: self._shape)
    size = property(lambda self: int(np.prod(self._shape)))
    nbytes = property(lambda self: self.size * 4)
    #: what the held boxes take
    held_bytes = property(lambda self: sum(c.nbytes for c, _, _ in self.crops))

    @staticmethod
    def saves(q: np.ndarray) -> bool:
        """True when boxing ``q``'s masks holds less than 3/4 of it."""
        held = 0
        for m in q:
            rows = np.flatnonzero(m.any(axis=1))
            cols = np.flatnonzero(m.any(axis=0))
            if rows.size:
                held += (rows[-1] + 1 - rows[0]) * (cols[-1] + 1 - cols[0]) * q.itemsize
        return held < 0.75 * q.nbytes

    def memo_key(self) -> Any:
        """The boxes and their integers (the float values are a function of them)."""
        return (self._shape, tuple((c, r0, c0) for c, r0, c0 in self.crops))

    def __len__(self) -> int:
        return int(self._shape[0])

    def integers(self, i: int) -> np.ndarray:
        return self.dense(i)

    def dense(self, i: int, rows: Any = slice(None)) -> np.ndarray:
        """Mask ``i``'s integers at ``rows`` (an int or a slice) ``[r, W]`` (``[W]``)."""
        h, w = self._shape[1:]
        rr = np.arange(h)[rows]
        one = rr.ndim == 0
        rr = np.atleast_1d(rr)
        out = np.zeros((rr.size, w), self._dtype_q)
        crop, r0, c0 = self.crops[i]
        inside = (rr >= r0) & (rr < r0 + crop.shape[0])
        if crop.size and inside.any():
            out[inside, c0 : c0 + crop.shape[1]] = crop[rr[inside] - r0]
        return out[0] if one else out

    def __getitem__(self, key: Any) -> np.ndarray:
        k = key if isinstance(key, tuple) else (key,)
        simple = all(isinstance(x, int | np.integer | slice) for x in k[1:3]) and len(k) <= 3
        if isinstance(k[0], int | np.integer) and simple:
            rows = k[1] if len(k) > 1 else slice(None)
            d = self.dense(int(k[0]) % len(self), rows)
            if len(k) == 3:
                d = d[..., k[2]]
            return to_float(d)
        return to_float(self._dense_all()[key])

    def _dense_all(self) -> np.ndarray:
        return np.stack([self.dense(i) for i in range(len(self))])

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        a = to_float(self._dense_all())
        return a if dtype is None else a.astype(dtype, copy=False)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name in ("q", "crops", "_shape", "_dtype_q"):
            raise AttributeError(name)
        return getattr(np.asarray(self), name)

    def __deepcopy__(self, memo: dict[int, Any]) -> CroppedMasks:
        return CroppedMasks(self._dense_all())

    def __repr__(self) -> str:
        r, h, w = self._shape
        return f"CroppedMasks({r} masks {w}x{h}, {self._dtype_q}, {self.held_bytes} bytes held)"
