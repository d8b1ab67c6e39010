"""Work done once per run: a content-addressed memo for pure, costly array functions.

A conversion computes some things more than once on the very same data: the base resampled to
the states' size (the search, the package, the decoded package for the report, the validator's
source at the shipped size), a PNG the glTF document and the texture folder both hold, a block
encoding the search made and the copy makes again. Inside ``with reuse():`` (``convert`` opens
one per conversion) a function decorated with :func:`reused` computes each distinct input once:
the key is the function, the SHA-256 of every array / bytes argument (with its dtype and shape)
and the ``repr`` of the other arguments, so a hit is the result of exactly those bytes, whoever
asks (a validator reading back a written file gets the result of the bytes in that file).

Arguments may be arrays, bytes, plain values, tuples / lists of them and dataclasses of them.
Only pure, deterministic functions may be decorated. Results are shared, not copied: every array
of a result is handed out as a read-only view of the one stored array (a caller that needs to
change one copies it first; a result's arrays that share memory with an argument are copied
once, when stored), and containers (tuples, lists, dicts, dataclasses) are new for each caller,
so an attribute or item a caller sets stays its own. Outside
``reuse()``, or in a thread that did not enter it (context variables do not follow work into a
thread pool), a decorated function simply runs. The memo is bounded (least recently used entries
are dropped past ``max_bytes``) and ends with the block.
"""

from __future__ import annotations

import contextlib
import contextvars
import copy
import dataclasses
import functools
import hashlib
import os
import threading
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from wrinklepipe.workset import DEFAULT_BYTES, working_set_bytes

#: Default bound of one run's memo (bytes of stored results) when none is given: the
#: default working set (``WRINKLEPIPE_WORKING_SET`` sets another, docs/scale.md).
DEFAULT_MAX_BYTES = DEFAULT_BYTES
#: Calls whose array / bytes arguments total less than this are not worth a key: they just run.
MIN_INPUT_BYTES = 1 << 16
#: Environment variable capping the threads this process's own pools run at once (the block
#: encoders' row chunks, PNGs beside other work): ``wrinklepipe batch --jobs N`` sets it in each
#: worker to its share of the cores, so N workers never start N x cores threads.
THREADS_ENV = "WRINKLEPIPE_THREADS"

F = TypeVar("F", bound=Callable[..., Any])
T = TypeVar("T")
R = TypeVar("R")


@dataclass
class Rows:
    """Results of a row-wise function (each row's result depends on that row's bytes alone):
    ``keys`` [N, K] uint8 rows, their ``hashes`` [N] uint64 (sorted, distinct), ``values``
    [N, V] uint8 the result of each."""

    hashes: np.ndarray
    keys: np.ndarray
    values: np.ndarray

    @property
    def nbytes(self) -> int:
        return int(self.hashes.nbytes + self.keys.nbytes + self.values.nbytes)


@dataclass
class Memo:
    """One run's stored results and what they saved (``hits`` / ``misses`` per function)."""

    max_bytes: int = DEFAULT_MAX_BYTES
    entries: OrderedDict[tuple, Any] = field(default_factory=OrderedDict)
    stored_bytes: int = 0
    hits: dict[str, int] = field(default_factory=dict)
    misses: dict[str, int] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)
    rows: dict[str, Rows] = field(default_factory=dict)  # see known_rows / remember_rows

    def get(self, key: tuple) -> tuple[bool, Any]:
        with self.lock:
            if key not in self.entries:
                return False, None
            self.entries.move_to_end(key)
            return True, self.entries[key]

    def put(self, key: tuple, value: Any) -> None:
        size = _result_bytes(value)
        with self.lock:
            if key in self.entries or size > self.max_bytes:
                return
            self.entries[key] = value
            self.stored_bytes += size
            while self.stored_bytes > self.max_bytes:
                _, old = self.entries.popitem(last=False)
                self.stored_bytes -= _result_bytes(old)

    def count(self, table: dict[str, int], name: str) -> None:
        with self.lock:
            table[name] = table.get(name, 0) + 1


_MEMO: ContextVar[Memo | None] = ContextVar("wrinklepipe_reuse", default=None)


@contextlib.contextmanager
def reuse(max_bytes: int | None = None) -> Iterator[Memo]:
    """Within the block, :func:`reused` functions compute each distinct input once. Nested
    blocks share the outer memo. ``max_bytes``: the memo's bound (default: the working set,
    :func:`wrinklepipe.workset.working_set_bytes`)."""
    outer = _MEMO.get()
    if outer is not None:
        yield outer
        return
    memo = Memo(max_bytes=working_set_bytes() if max_bytes is None else max_bytes)
    token = _MEMO.set(memo)
    try:
        yield memo
    finally:
        _MEMO.reset(token)


def active() -> Memo | None:
    """The memo of the enclosing :func:`reuse` block (None outside one)."""
    return _MEMO.get()


class _Unkeyable(Exception):
    """An argument the memo cannot key by content: the call just runs."""


def _digest(value: Any, sizes: list[int]) -> Any:
    digest_of = getattr(type(value), "memo_digest", None)  # an array made where it is read
    if digest_of is not None:  # keyed as the array it stands for (the same key)
        sizes.append(int(value.nbytes))
        return ("array", digest_of(value))
    key_of = getattr(type(value), "memo_key", None)  # e.g. masks held as integers: their bytes
    if key_of is not None:
        return (type(value).__name__, _digest(key_of(value), sizes))
    if isinstance(value, np.ndarray):
        a = np.ascontiguousarray(value)
        sizes.append(a.nbytes)
        h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
        h.update(memoryview(a).cast("B") if a.size else b"")
        return ("array", h.digest())
    if isinstance(value, bytes | bytearray | memoryview):
        sizes.append(len(value))
        return ("bytes", hashlib.sha256(value).digest())
    if value is None or isinstance(value, bool | int | float | str):
        return (type(value).__name__, repr(value))
    if isinstance(value, tuple | list):
        return (type(value).__name__, tuple(_digest(v, sizes) for v in value))
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = tuple(
            (f.name, _digest(getattr(value, f.name), sizes)) for f in dataclasses.fields(value)
        )
        return (f"{type(value).__module__}.{type(value).__qualname__}", fields)
    raise _Unkeyable


def _result_bytes(value: Any) -> int:
    if isinstance(value, np.ndarray):
        return int(value.nbytes)
    if isinstance(value, bytes):
        return len(value)
    if isinstance(value, tuple | list):
        return sum(_result_bytes(v) for v in value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return sum(_result_bytes(getattr(value, f.name)) for f in dataclasses.fields(value))
    return 64


def _arrays(value: Any, out: list[np.ndarray]) -> list[np.ndarray]:
    """The arrays ``value`` holds (arguments of a call: arrays, sequences, dicts, dataclasses
    and objects keyed by ``memo_key``, e.g. a MaskStack)."""
    if isinstance(value, np.ndarray):
        out.append(value)
    elif isinstance(value, tuple | list):
        for v in value:
            _arrays(v, out)
    elif isinstance(value, dict):
        for v in value.values():
            _arrays(v, out)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            _arrays(getattr(value, f.name), out)
    elif getattr(type(value), "memo_key", None) is not None:
        _arrays(type(value).memo_key(value), out)
        _arrays(list(getattr(value, "__dict__", {}).values()), out)
    return out


def _shared(value: Any, inputs: Sequence[np.ndarray] = ()) -> Any:
    """``value`` as the memo stores and hands it out: every array a read-only view of the one
    stored result (shared, never copied: a caller cannot change what a later call gets), an
    array that shares memory with an argument (``inputs``) copied first (the caller's own array
    may change); tuples, lists, dicts and dataclasses of them as new containers around those
    views (a caller's attribute or item set stays its own); bytes and scalars as they are."""
    if isinstance(value, np.ndarray):
        if any(np.may_share_memory(value, a) for a in inputs):
            value = value.copy()
        view = value.view()
        view.flags.writeable = False
        return view
    if value is None or isinstance(value, bytes | str | int | float | bool | np.generic):
        return value
    if isinstance(value, tuple):
        return tuple(_shared(v, inputs) for v in value)
    if isinstance(value, list):
        return [_shared(v, inputs) for v in value]
    if isinstance(value, dict):
        return {k: _shared(v, inputs) for k, v in value.items()}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out = copy.copy(value)
        for f in dataclasses.fields(value):
            object.__setattr__(out, f.name, _shared(getattr(value, f.name), inputs))
        return out
    return copy.deepcopy(value)  # any other result: a private copy


def _key(name: str, args: tuple, kwargs: dict[str, Any]) -> tuple[tuple, int]:
    """The memo key of a call and the bytes of its array / bytes arguments."""
    sizes: list[int] = []
    key = (
        name,
        tuple(_digest(a, sizes) for a in args),
        tuple(sorted((k, _digest(v, sizes)) for k, v in kwargs.items())),
    )
    return key, sum(sizes)


def remember(fn: Callable[..., Any], result: Any, *args: Any, **kwargs: Any) -> None:
    """Store ``result`` as what the :func:`reused` function ``fn`` gives for these arguments
    (a caller that computed it another way, e.g. several maps' blocks in one encoder pass, so
    that the call made later is a hit). Only for results equal to what ``fn`` computes; nothing
    happens outside a :func:`reuse` block."""
    memo = _MEMO.get()
    if memo is None:
        return
    try:
        key, size = _key(f"{fn.__module__}.{fn.__qualname__}", args, kwargs)
    except _Unkeyable:
        return
    if size >= MIN_INPUT_BYTES:
        memo.put(key, _shared(result, _arrays(args, _arrays(kwargs, []))))


def known_rows(
    name: str, hashes: np.ndarray, keys: np.ndarray
) -> tuple[np.ndarray, np.ndarray | None]:
    """Which of the rows ``keys`` [M, K] uint8 (with their ``hashes`` [M] uint64) this run's
    memo holds a result of under ``name`` (:func:`remember_rows`), and those results [M, V]
    (zeros where not held); ``(all False, None)`` outside :func:`reuse` or when it holds none.
    A row is found only when its bytes equal the stored row's (hashes only narrow the search)."""
    found = np.zeros(len(hashes), bool)
    memo = _MEMO.get()
    store = None if memo is None else memo.rows.get(name)
    if store is None or not len(hashes):
        return found, None
    pos = np.minimum(np.searchsorted(store.hashes, hashes), len(store.hashes) - 1)
    found = store.hashes[pos] == hashes
    idx = np.flatnonzero(found)
    found[idx] = np.all(store.keys[pos[idx]] == keys[idx], axis=1)
    values = np.zeros((len(hashes), store.values.shape[1]), store.values.dtype)
    values[found] = store.values[pos[found]]
    return found, values


def rows_room(name: str, nbytes: int) -> bool:
    """Whether :func:`remember_rows` would store ``nbytes`` more under ``name`` (the stores stop
    growing past a quarter of the memo's bound); False outside :func:`reuse`."""
    memo = _MEMO.get()
    if memo is None:
        return False
    old = memo.rows.get(name)
    return (0 if old is None else old.nbytes) + int(nbytes) <= memo.max_bytes // 4


def remember_rows(name: str, hashes: np.ndarray, keys: np.ndarray, values: np.ndarray) -> None:
    """Store the results ``values`` [M, V] of rows ``keys`` [M, K] (``hashes`` [M] uint64) under
    ``name`` in this run's memo, for :func:`known_rows`. Only for a function whose result for a
    row depends on that row's bytes alone; nothing happens outside :func:`reuse`. Of rows with
    one hash only the first is kept (another with the same hash is simply not found); stores
    stop growing past a quarter of the memo's bound."""
    memo = _MEMO.get()
    if memo is None or not len(hashes):
        return
    with memo.lock:
        old = memo.rows.get(name)
        h, k, v = np.asarray(hashes, np.uint64), np.asarray(keys), np.asarray(values)
        held = 0 if old is None else old.nbytes
        if held + h.nbytes + k.nbytes + v.nbytes > memo.max_bytes // 4:
            return
        order = np.argsort(h, kind="stable")  # of the new rows, the first among equal hashes
        h = h[order]
        first = np.ones(len(h), bool)
        first[1:] = h[1:] != h[:-1]
        if old is not None:  # the stored rows first: a new row of a stored hash is dropped
            pos = np.minimum(np.searchsorted(old.hashes, h), len(old.hashes) - 1)
            first &= old.hashes[pos] != h
        pick = order[first]
        h, k, v = h[first], k[pick], v[pick]
        if old is not None:  # merged in hash order, one copy of the store (not a sort of it)
            at = np.searchsorted(old.hashes, h)
            h = np.insert(old.hashes, at, h)
            k = np.insert(old.keys, at, k, axis=0)
            v = np.insert(old.values, at, v, axis=0)
        memo.rows[name] = Rows(h, np.ascontiguousarray(k), np.ascontiguousarray(v))


def forget_rows() -> None:
    """Drop this run's row stores (:func:`remember_rows`): for a run past the last step that
    asks them (``convert``'s block encodes, before its validation reads the folder back: up to
    a quarter of the memo per store). Nothing changes a result: a row not found is computed."""
    memo = _MEMO.get()
    if memo is not None:
        with memo.lock:
            memo.rows.clear()


def reused(fn: F) -> F:
    """Decorate a pure function of arrays / bytes / plain values (see the module doc)."""
    name = f"{fn.__module__}.{fn.__qualname__}"

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        memo = _MEMO.get()
        if memo is None:
            return fn(*args, **kwargs)
        try:
            key, size = _key(name, args, kwargs)
        except _Unkeyable:
            return fn(*args, **kwargs)
        if size < MIN_INPUT_BYTES:
            return fn(*args, **kwargs)
        found, value = memo.get(key)
        if found:
            memo.count(memo.hits, name)
            return _shared(value)
        memo.count(memo.misses, name)
        out = _shared(fn(*args, **kwargs), _arrays(args, _arrays(kwargs, [])))
        memo.put(key, out)
        return _shared(out)

    return wrapper  # type: ignore[return-value]


def thread_budget() -> int:
    """Threads this process's work may run on at once: ``WRINKLEPIPE_THREADS`` when it is a
    positive integer (a batch worker's share of the cores), else the CPU count. Results never
    depend on it (work is split the same way whatever runs it), only the time does."""
    text = os.environ.get(THREADS_ENV, "").strip()
    n = int(text) if text.isdigit() else 0
    return n if n > 0 else max(1, os.cpu_count() or 1)


def _workers(workers: int | None) -> int:
    return max(1, workers if workers is not None else min(2, thread_budget()))


def map_threads(fn: Callable[[T], R], items: Iterable[T], workers: int | None = None) -> list[R]:
    """``[fn(x) for x in items]`` on ``workers`` threads (default: 2, or 1 when
    :func:`thread_budget` is 1), each
    call in a copy of the caller's context, so this run's memo applies as it does in the
    caller. For work that releases the GIL (zlib, the block
    encoders); results in order; the first exception is raised."""
    todo = list(items)
    n = _workers(workers)
    if n == 1 or len(todo) < 2:
        return [fn(x) for x in todo]
    with ThreadPoolExecutor(max_workers=n, thread_name_prefix="wp-reuse") as ex:
        futures = [ex.submit(contextvars.copy_context().run, fn, x) for x in todo]
        return [f.result() for f in futures]


def warm(calls: Sequence[Callable[[], object]], workers: int = 1) -> Callable[[], None]:
    """Start ``calls`` (calls of :func:`reused` functions) on background threads in this run's
    memo, so that the same calls made later are hits while the caller does other work; returns
    ``wait()``, to call before those later calls. Without an active memo nothing starts (the
    results would have nowhere to go). A call that fails here is simply not stored: the later
    call computes it again and raises where it is made. With a budget of one thread
    (:func:`thread_budget`) nothing starts either: the later calls compute where they are made
    rather than beside the caller's work."""
    if _MEMO.get() is None or not calls or thread_budget() < 2:
        return lambda: None
    ex = ThreadPoolExecutor(max_workers=_workers(workers), thread_name_prefix="wp-warm")
    futures = [ex.submit(contextvars.copy_context().run, c) for c in calls]
    ex.shutdown(wait=False)

    def wait() -> None:
        for f in futures:
            f.exception()  # waits; an error is raised again by the real call

    return wait
