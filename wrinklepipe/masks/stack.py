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
from numpy.lib.mixins import NDArrayOperatorsMixin

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


class MaskStack(NDArrayOperatorsMixin):
    """Masks ``[R, H, W]`` held as integers (``q``: uint8 or uint16), seen as float32."""

    __array_priority__ = 20.0

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

    def __getitem__(self, key: Any) -> np.ndarray:
        return to_float(np.asarray(self.q[key]))

    def __iter__(self) -> Any:
        return (self[i] for i in range(len(self)))

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        a = to_float(self.q)
        return a if dtype is None else a.astype(dtype, copy=False)

    def __array_ufunc__(self, ufunc: Any, method: str, *inputs: Any, **kwargs: Any) -> Any:
        def plain(x: Any) -> Any:
            return np.asarray(x) if isinstance(x, MaskStack) else x

        if "out" in kwargs:
            kwargs["out"] = tuple(plain(o) for o in kwargs["out"])
        return getattr(ufunc, method)(*(plain(x) for x in inputs), **kwargs)

    def __array_function__(self, func: Any, types: Any, args: Any, kwargs: Any) -> Any:
        def plain(x: Any) -> Any:
            if isinstance(x, MaskStack):
                return np.asarray(x)
            if isinstance(x, list | tuple):
                return type(x)(plain(v) for v in x)
            return x

        return func(*(plain(a) for a in args), **{k: plain(v) for k, v in kwargs.items()})

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
