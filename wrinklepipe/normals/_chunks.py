"""Row-chunked, threaded execution of numpy kernels (numpy releases the GIL in its loops).

Chunks are multiples of 4 rows (whole BC block rows) of about ``CHUNK_TEXELS`` texels, small
enough that a kernel's temporaries stay in the CPU cache.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from wrinklepipe.reuse import thread_budget

#: Texels per chunk (512 KB per float32 plane; measured best on a 2-core EPYC).
CHUNK_TEXELS = 1 << 17

_POOL: ThreadPoolExecutor | None = None
_PREFIX = "wp-normals"


def threads() -> int:
    """Worker threads used (the process's thread budget, :func:`wrinklepipe.reuse.thread_budget`:
    the CPU count unless a batch worker set its share; at most 4)."""
    return max(1, min(4, thread_budget()))


def pool() -> ThreadPoolExecutor:
    """The shared worker pool (created on first use)."""
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=threads(), thread_name_prefix=_PREFIX)
    return _POOL


def on_pool() -> bool:
    """Whether the calling thread is one of the pool's workers (work it would hand to the pool
    runs in place instead: a worker waiting on its own pool can wait forever)."""
    return threading.current_thread().name.startswith(_PREFIX)


def row_chunks(height: int, width: int, texels: int | None = None) -> list[slice]:
    """Row slices covering ``height`` rows with about ``texels`` texels each (multiples of 4)."""
    texels = CHUNK_TEXELS if texels is None else texels
    rows = max(4, (texels // max(width, 1)) // 4 * 4)
    return [slice(r, min(r + rows, height)) for r in range(0, height, rows)]


def map_rows(fn: Callable[[slice], Any], height: int, width: int) -> list[Any]:
    """Run ``fn(rows)`` over row chunks on the pool; results in chunk order."""
    chunks = row_chunks(height, width)
    if len(chunks) == 1 or threads() == 1:
        return [fn(c) for c in chunks]
    return list(pool().map(fn, chunks))
