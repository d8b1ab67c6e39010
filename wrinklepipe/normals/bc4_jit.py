"""Compiling the BC4 encoder's kernels with numba on first use, and their shared constants.

The kernels (:mod:`wrinklepipe.normals.bc4_block`, :mod:`wrinklepipe.normals.bc4_search`) are
plain Python until :func:`compile_kernels` is first called: it imports numba (about half a
second, which every command that never encodes a BC4 block is spared), compiles each function
marked ``@kernel`` and puts the compiled function in its place in its module, so that the
kernels call each other compiled (across modules through the module: ``bc4_block.nearest``).
numba caches the machine code beside the modules (``cache=True``): a later process loads it
instead of compiling (about 12 s of CPU).

Arithmetic is float32 throughout, operation by operation as the numpy encoder the kernels
replaced did it (no fused multiply-adds: numba does not contract without fastmath); constants
are module-level float32 values, which numba types as float32 (a Python float literal would
turn an expression into float64). Sums over a block's texels run in texel order.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np

#: The kernels: (their module's namespace, name, numba options), in definition order.
_KERNELS: list[tuple[dict[str, Any], str, dict[str, Any]]] = []
_JIT = {"cache": True, "nogil": True, "error_model": "numpy", "boundscheck": False}
_COMPILED = False
_LOCK = threading.Lock()


def kernel(**options: Any) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Mark a function to be compiled by :func:`compile_kernels` (with numba ``options``)."""

    def mark(fn: Callable[..., Any]) -> Callable[..., Any]:
        _KERNELS.append((fn.__globals__, fn.__name__, {**_JIT, **options}))
        return fn

    return mark


def compile_kernels() -> None:
    """Replace every marked function by its numba-compiled version (once; thread-safe)."""
    global _COMPILED
    with _LOCK:
        if not _COMPILED:
            import numba  # deferred: ~0.5 s to import, needed only when BC4 blocks are encoded

            for namespace, name, options in _KERNELS:
                namespace[name] = numba.njit(**options)(namespace[name])
            _COMPILED = True


_F = np.float32
#: Mean truncation of the 8-value palette's interpolants (floor of j r / 7), in levels.
_TRUNC = _F(0.43)
#: Step 4: a block is hard when a texel misses by 2 levels or more (squared error 4); its
#: pairs are then scored with every texel's excess over that times ``HARD_PENALTY``; levels
#: searched outside / inside its range: every ``HARD_STEP``-th pair of that window, then the
#: pairs one level around the best; the blocks still missing by 3 levels or more (squared error
#: ``HARD_TAIL``: the tail the p99 is made of) get every pair of the window.
HARD_TEXEL_ERROR = 4.0
HARD_PENALTY = 1.0
HARD_OUTSIDE = 16
HARD_INSIDE = 8.0
HARD_STEP = 4
HARD_TAIL = 9.0
# float32 constants: numba types a module-level numpy float32 as float32, so arithmetic with
# them stays in float32 (a Python float literal would promote an expression to float64)
_0, _1, _2, _5, _7 = _F(0), _F(1), _F(2), _F(5), _F(7)
_255 = _F(255)
_SEVENTH = _F(1.0 / 7.0)
_DET_MIN = _F(1e-3)
_RANGE_MIN = _F(1e-6)
_INF = _F(np.inf)
_TAU = _F(HARD_TEXEL_ERROR)
_LAM = _F(HARD_PENALTY)
_INSIDE = _F(HARD_INSIDE)
_TAIL = _F(HARD_TAIL)
#: Step 2: (palette position of the block's minimum, of its maximum) for the extended fits.
_EXTENDED = np.array([(0, 6), (1, 7), (1, 6), (0, 5), (2, 7), (2, 6), (1, 5)], np.int64)
#: A palette entry ``floor(j r / n)`` (j <= n, r <= 255 integers; n = 7 or 5) is exactly
#: ``floor(j * fl(r * fl(1 / n)))`` (fl(1/7) and fl(1/5) round up; a test checks every j, r):
#: a multiply per texel instead of a multiply and a divide, and the same value.
_RECIP7 = _1 / _7
_RECIP5 = _1 / _5
#: Blocks searched side by side, one per SIMD lane (16 float32: one AVX-512 register).
LANES = 16
#: The window's widest reach inside a block's range (``ceil(HARD_INSIDE)``).
_TOP = int(np.ceil(HARD_INSIDE))
