"""Arrays held in a scratch file instead of memory, read where they are indexed.

A conversion holds its source maps for the whole run: the searches, the encoders and the
validator read them again and again. At 8192² a 16-bit RGB map's integers are 403 MB; the base
and two states, 1.2 GB, a third of the run's peak. :func:`hold` keeps an array larger than
:data:`SPILL_SHARE` of the working set (:mod:`wrinklepipe.workset`) in a scratch file and gives
back a :class:`ScratchArray`, which reads what is indexed: a band of rows (``a[r0:r1]``), a row,
the texels at integer or boolean indices (gathered band by band), or the whole array
(``np.asarray``). The values are the array's, bit for bit; nothing changes them.

The file has no name (``O_TMPFILE``, or unlinked as soon as it is made where the filesystem
cannot do that): it is gone when the array is, and when the process ends however it ends, so a
run leaves nothing behind. The operating system may keep the file's pages in its cache, but
they are not the process's memory and it can take them back at any time.

Where: ``WRINKLEPIPE_SCRATCH`` names the directory; ``off`` keeps every array in memory. Unset,
``/var/tmp`` (on disk by convention, where ``/tmp`` may be RAM: a ``tmpfs`` ``/tmp``, Debian
13's default, would hold a spilled map in the memory it was meant to free), else the system's
temporary directory.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import threading
from pathlib import Path
from typing import IO, Any

import numpy as np

from wrinklepipe.errors import InputError
from wrinklepipe.workset import band_rows, working_set_bytes

ENV = "WRINKLEPIPE_SCRATCH"
#: An array larger than this share of the working set is held in a scratch file (128 MiB of
#: the default 1 GiB: a 4096² 16-bit RGB map, 96 MiB, stays in memory; an 8192² one goes).
SPILL_SHARE = 1 / 8
#: Bytes written to the scratch file at a time.
_WRITE_BYTES = 1 << 24
#: Positional reads (Linux, BSD, macOS): rows are read without the file's shared position.
_PREADV = hasattr(os, "preadv")


def scratch_dir() -> Path | None:
    """The directory scratch files go in; None when ``WRINKLEPIPE_SCRATCH`` is ``off``."""
    given = os.environ.get(ENV, "").strip()
    if given.lower() == "off":
        return None
    if given:
        return Path(given)
    var_tmp = Path("/var/tmp")
    if var_tmp.is_dir() and os.access(var_tmp, os.W_OK | os.X_OK):
        return var_tmp
    return Path(tempfile.gettempdir())


def hold(a: np.ndarray) -> np.ndarray | ScratchArray:
    """``a`` as a run holds it: in a scratch file (:class:`ScratchArray`) when it is larger
    than :data:`SPILL_SHARE` of the working set and scratch files are on, else ``a`` itself."""
    where = scratch_dir()
    if where is None or a.nbytes <= working_set_bytes() * SPILL_SHARE:
        return a
    return ScratchArray(a, where)


class ScratchArray:
    """A read-only array ``[H, ...]`` kept in an unnamed scratch file under ``directory``;
    indexing reads the rows it needs (``os.preadv``, or a locked seek and read where the system
    has no ``preadv``; safe from several threads at once)."""

    def __init__(self, a: np.ndarray, directory: Path) -> None:
        a = np.ascontiguousarray(a)
        if a.ndim < 1 or a.dtype.hasobject:
            raise ValueError(f"a scratch array holds plain arrays of rank >= 1, got {a.dtype}")
        self.shape: tuple[int, ...] = a.shape
        self.dtype = a.dtype
        self._digest: bytes | None = None
        self._lock = threading.Lock()
        try:
            self._file: IO[bytes] = tempfile.TemporaryFile(dir=directory, buffering=0)
            flat = memoryview(a.reshape(-1).view(np.uint8))
            for b0 in range(0, len(flat), _WRITE_BYTES):
                chunk = flat[b0 : b0 + _WRITE_BYTES]
                done = 0
                while done < len(chunk):
                    done += self._file.write(chunk[done:])
        except OSError as exc:
            raise InputError(
                f"cannot hold a {a.nbytes / 2**20:.0f} MiB source map in a scratch file there: "
                f"{exc.strerror or exc}; set {ENV} to a directory with room, or to off to "
                "hold it in memory",
                directory,
            ) from None

    ndim = property(lambda self: len(self.shape))
    size = property(lambda self: int(np.prod(self.shape)))
    itemsize = property(lambda self: self.dtype.itemsize)
    nbytes = property(lambda self: self.size * self.itemsize)

    def __len__(self) -> int:
        return self.shape[0]

    def _row_bytes(self) -> int:
        return int(np.prod(self.shape[1:], dtype=np.int64)) * self.itemsize

    def rows(self, r0: int, r1: int) -> np.ndarray:
        """Rows ``r0:r1`` (clipped to the array), read from the file."""
        r0, r1 = max(0, r0), min(self.shape[0], max(r0, r1))
        out = np.empty((r1 - r0, *self.shape[1:]), self.dtype)
        view = memoryview(out.reshape(-1).view(np.uint8))
        offset, done = r0 * self._row_bytes(), 0
        while done < len(view):
            got = self._read_into(view[done:], offset + done)
            if got <= 0:
                raise OSError(f"the scratch file ended {len(view) - done} bytes early")
            done += got
        return out

    def _read_into(self, view: memoryview, offset: int) -> int:
        """Bytes of the file from ``offset`` into ``view``; how many were read."""
        if _PREADV:  # no shared file position: threads read at once
            return os.preadv(self._file.fileno(), [view], offset)
        with self._lock:  # a system without preadv: one seek and read at a time
            self._file.seek(offset)
            return self._file.readinto(view) or 0

    def _band(self) -> int:
        """Rows read at a time when gathering (a band of the working set)."""
        return band_rows(int(np.prod(self.shape[1:], dtype=np.int64)), self.itemsize)

    def __getitem__(self, key: Any) -> np.ndarray:
        key = key if isinstance(key, tuple) else (key,)
        if not key:
            return np.asarray(self)
        first, rest = key[0], key[1:]
        if isinstance(first, list):
            first = np.asarray(first)
        if isinstance(first, int | np.integer):
            r = int(first) + (self.shape[0] if first < 0 else 0)
            if not 0 <= r < self.shape[0]:
                raise IndexError(f"row {first} out of range for {self.shape[0]} rows")
            return self.rows(r, r + 1)[(0, *rest)]
        if isinstance(first, slice):
            r0, r1, step = first.indices(self.shape[0])
            if step == 1:
                return self.rows(r0, r1)[(slice(None), *rest)]
            return self._gather_rows(np.arange(r0, r1, step))[(slice(None), *rest)]
        if isinstance(first, np.ndarray) and first.dtype == bool and self.ndim >= 2:
            if first.ndim == 1:
                return self[(np.flatnonzero(first), *rest)]
            if first.ndim == 2 and first.shape == self.shape[:2]:
                r, c = np.nonzero(first)
                return self[(r, c, *rest)]
        if isinstance(first, np.ndarray) and first.dtype.kind in "iu" and self.ndim >= 2:
            second = rest[0] if rest else None
            second = np.asarray(second) if isinstance(second, list) else second
            if isinstance(second, np.ndarray) and second.dtype.kind in "iu":
                return self._gather_texels(first, second)[(Ellipsis, *rest[1:])]
            if not rest or isinstance(second, slice | int | np.integer):
                return self._gather_rows(first)[(*(slice(None),) * first.ndim, *rest)]
        return np.asarray(self)[key]

    def _runs(self, rows: np.ndarray) -> Any:
        """Bands ``(b0, b1, i0, i1)`` covering sorted ``rows``: rows ``b0:b1`` read hold
        ``rows[i0:i1]``."""
        band = self._band()
        i0, n = 0, len(rows)
        while i0 < n:
            b0 = int(rows[i0])
            i1 = int(np.searchsorted(rows, b0 + band, side="left"))
            yield b0, int(rows[i1 - 1]) + 1, i0, i1
            i0 = i1

    def _gather_rows(self, rows: np.ndarray) -> np.ndarray:
        """Whole rows ``rows`` (any shape and order, repeats allowed) -> ``[*rows.shape, ...]``."""
        shape = np.shape(rows)
        rows = np.asarray(rows, np.int64).reshape(-1)
        rows = np.where(rows < 0, rows + self.shape[0], rows)
        if rows.size and (rows.min() < 0 or rows.max() >= self.shape[0]):
            raise IndexError(f"a row index is out of range for {self.shape[0]} rows")
        order = np.argsort(rows, kind="stable")
        ordered = rows[order]
        out = np.empty((len(rows), *self.shape[1:]), self.dtype)
        for b0, b1, i0, i1 in self._runs(ordered):
            out[order[i0:i1]] = self.rows(b0, b1)[ordered[i0:i1] - b0]
        return out.reshape(*shape, *self.shape[1:])

    def _gather_texels(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Texels at broadcast ``rows``, ``cols`` -> ``[*shape, ...]`` (numpy's fancy
        indexing of the first two axes)."""
        r, c = np.broadcast_arrays(np.asarray(rows, np.int64), np.asarray(cols, np.int64))
        h, w = self.shape[:2]
        fr = np.where(r < 0, r + h, r).reshape(-1)
        fc = np.where(c < 0, c + w, c).reshape(-1)
        if fr.size and (fr.min() < 0 or fr.max() >= h or fc.min() < 0 or fc.max() >= w):
            raise IndexError(f"a texel index is out of range for {w}x{h}")
        order = np.argsort(fr, kind="stable")
        ordered = fr[order]
        out = np.empty((fr.size, *self.shape[2:]), self.dtype)
        for b0, b1, i0, i1 in self._runs(ordered):
            take = order[i0:i1]
            out[take] = self.rows(b0, b1)[ordered[i0:i1] - b0, fc[take]]
        return out.reshape(*r.shape, *self.shape[2:])

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        a = self.rows(0, self.shape[0])
        return a if dtype is None else a.astype(dtype, copy=False)

    def copy(self) -> ScratchArray:
        """The array itself: it is never changed, so a copy can share its file."""
        return self

    def memo_digest(self) -> bytes:
        """What the run's memo keys this array by (:mod:`wrinklepipe.reuse`): the digest it
        gives the array in memory (its dtype, shape and bytes), computed once."""
        if self._digest is None:
            h = hashlib.sha256(f"{self.dtype.str}{self.shape}".encode())
            band = self._band()
            for r0 in range(0, self.shape[0], band):
                h.update(memoryview(self.rows(r0, r0 + band).reshape(-1).view(np.uint8)))
            self._digest = h.digest()
        return self._digest

    def __reduce__(self) -> Any:
        return (np.asarray, (np.asarray(self),))  # sent to another process as the array

    def __repr__(self) -> str:
        return f"ScratchArray({self.shape}, {self.dtype})"
