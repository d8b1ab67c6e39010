"""The working set: how much memory a run may spend beyond the maps it holds (docs/scale.md).

``WRINKLEPIPE_WORKING_SET`` (bytes, or a number with ``K``, ``M`` or ``G``: ``512M``, ``2G``;
default :data:`DEFAULT_BYTES`) sets two things:

* the run's memo of repeated work (:mod:`wrinklepipe.reuse`) keeps at most that many bytes;
* a stage that works band by band (decoding a normal map, ...) sizes each band's temporaries
  to :data:`BAND_SHARE` of it.

Neither changes a result: a band's texels are computed exactly as the whole image's, and a memo
miss computes what a hit would have returned. A smaller working set trades time (recomputation,
more bands) for memory.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable

import numpy as np

from wrinklepipe.errors import InputError

ENV = "WRINKLEPIPE_WORKING_SET"
#: The working set when the environment does not set one: 1 GiB.
DEFAULT_BYTES = 1 << 30
#: The smallest working set accepted: 16 MiB.
MIN_BYTES = 1 << 24
#: The part of the working set one band's temporaries may take.
BAND_SHARE = 1 / 16

_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30}


def parse_size(text: str) -> int:
    """``"512M"`` -> bytes (``K``, ``M``, ``G`` are powers of 1024; a plain number is bytes)."""
    m = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([KMG]?)i?B?\s*", text, flags=re.IGNORECASE)
    if m is None:
        raise InputError(
            f"{text!r} is not a size; give bytes or a number with K, M or G (e.g. 512M, 2G)",
            ENV,
        )
    size = int(float(m.group(1)) * _UNITS[m.group(2).upper()])
    if size < MIN_BYTES:
        raise InputError(f"{text!r} is below the smallest working set, 16M", ENV)
    return size


def working_set_bytes() -> int:
    """The working set in bytes (``WRINKLEPIPE_WORKING_SET``, else :data:`DEFAULT_BYTES`)."""
    given = os.environ.get(ENV, "").strip()
    return parse_size(given) if given else DEFAULT_BYTES


def band_rows(width: int, bytes_per_texel: int) -> int:
    """Rows of a ``width``-wide image whose temporaries (``bytes_per_texel`` each) fit one
    band's share of the working set (at least one row)."""
    share = int(working_set_bytes() * BAND_SHARE)
    return max(1, share // max(1, width * bytes_per_texel))


def map_rows(
    fn: Callable[[np.ndarray], np.ndarray], x: np.ndarray, bytes_per_texel: int
) -> np.ndarray:
    """``fn(x)`` for a per-texel ``fn`` of an image ``x`` ``[H, W, ...]``, made band by band of
    rows (:func:`band_rows`): the whole image's result, with one band's temporaries."""
    # an image made where it is read (normals held as integers: ``x[r0:r1]`` decodes those
    # rows) is read a band at a time, never made whole
    a = x if getattr(type(x), "reads_rows", False) else np.asarray(x)
    if a.ndim < 2:
        return fn(a)
    h = a.shape[0]
    rows = band_rows(a.shape[1], bytes_per_texel)
    if h <= rows:
        return fn(np.asarray(a))
    out: np.ndarray | None = None
    for r0 in range(0, h, rows):
        band = fn(a[r0 : r0 + rows])
        if out is None:
            out = np.empty((h, *band.shape[1:]), band.dtype)
        out[r0 : r0 + rows] = band
    assert out is not None
    return out
