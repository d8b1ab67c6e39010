"""A content-addressed cache of convert output folders, safe for concurrent batches.

Layout under the cache folder::

    entries/<k[:2]>/<key>/entry.json    key, files (path, bytes, sha256), total bytes, result
    entries/<k[:2]>/<key>/files/...     the output folder, byte for byte
    tmp/<random>/                       entries being built, and entries being evicted
    times/<h>.json                      how long the last conversion of each asset took (h:
                                        hash of its output path): the longest start first

The protocol is rename-based, so no lock is needed:

* **put**: the entry is built completely in ``tmp/`` and renamed into ``entries/`` in one
  ``rename(2)``. An entry is therefore complete whenever it exists, and never changes. If another
  batch renamed the same key in first, ours is removed (both are the same bytes).
* **get**: read ``entry.json``, copy the files into a staged output folder while hashing them,
  and publish the folder only when every hash matches. A file that is missing (evicted
  meanwhile) or altered makes the get a miss: the asset is converted instead.
* **evict** (size cap, least recently used first; a hit refreshes an entry's use time): the
  victim is first renamed into ``tmp/`` (atomic: concurrent readers see it whole or not at
  all), then deleted.

Only folders this cache made are ever removed: victims, our own unfinished entries, and in
``tmp/`` leftovers of runs killed more than a day ago.

**Faults.** A cache that cannot be written (a full volume, a read-only folder, a quota) never
fails a batch: the first write that fails sets :attr:`Cache.unwritable` (one line saying why),
nothing more is written to it for the rest of the batch, and what it already holds is still
served. An entry that cannot be read back whole (altered, truncated, unreadable, or its
``entry.json`` damaged) is a miss: the asset converts, and its new entry replaces the damaged one.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
import shutil
import time
import uuid
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wrinklepipe.atomic import dumps_json, staged_folder
from wrinklepipe.errors import input_error

ENTRY_SCHEMA = "wrinklepipe/batch-cache-entry@1"
_KEY = re.compile(r"^[0-9a-f]{64}$")
_STALE_TMP_S = 24 * 3600
_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
DEFAULT_MAX_BYTES = 20 << 30


def parse_size(text: str) -> int:
    """``"500M"``, ``"20G"``, ``"1.5T"``, ``"123456"`` -> bytes (binary units)."""
    m = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([KMGT]?)(?:i?B)?\s*", str(text), re.I)
    if not m:
        raise input_error("--cache-size", f"{text!r} is not a size (e.g. 500M, 20G)")
    return int(float(m.group(1)) * _UNITS[m.group(2).upper()])


class CacheMiss(Exception):
    """The entry is absent, incomplete or altered: convert instead."""


@dataclass(frozen=True)
class Entry:
    key: str
    folder: Path
    meta: dict[str, Any]

    @property
    def result(self) -> dict[str, Any]:
        return dict(self.meta.get("result", {}))


def _copy_hashing(src: Path, dst: Path) -> tuple[int, str]:
    h = hashlib.sha256()
    n = 0
    dst.parent.mkdir(parents=True, exist_ok=True)
    with open(src, "rb") as fi, open(dst, "wb") as fo:
        while block := fi.read(1 << 20):
            h.update(block)
            fo.write(block)
            n += len(block)
    return n, h.hexdigest()


class _Unreadable(Exception):
    """Reading a cache entry's file failed (not the output being written)."""


def _restore_file(src: Path, dst: Path) -> tuple[int, str]:
    """:func:`_copy_hashing` from the cache into an output: a read of ``src`` that fails is the
    entry's fault (:class:`_Unreadable`); a write of ``dst`` that fails is the output's."""
    h = hashlib.sha256()
    n = 0
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        fi = open(src, "rb")  # noqa: SIM115 - closed below, errors told apart
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise _Unreadable(f"{src}: {exc.strerror or exc}") from None
    with fi, open(dst, "wb") as fo:
        while True:
            try:
                block = fi.read(1 << 20)
            except OSError as exc:
                raise _Unreadable(f"{src}: {exc.strerror or exc}") from None
            if not block:
                break
            h.update(block)
            fo.write(block)
            n += len(block)
    return n, h.hexdigest()


class Cache:
    """The cache at ``root`` with a size cap of ``max_bytes`` (None: no cap)."""

    def __init__(self, root: str | Path, max_bytes: int | None = DEFAULT_MAX_BYTES) -> None:
        self.root = Path(os.path.abspath(root))
        self.max_bytes = max_bytes
        self.entries = self.root / "entries"
        self.tmp = self.root / "tmp"
        #: Why the cache cannot be written (set by the first write that failed), else None.
        self.unwritable: str | None = None

    def _cannot_write(self, exc: OSError) -> None:
        if self.unwritable is None:
            self.unwritable = (
                f"the cache {self.root} cannot be written ({exc.strerror or exc}); this batch "
                "stores nothing more in it (entries already there are still used)"
            )

    def _folder(self, key: str) -> Path:
        if not _KEY.match(key):
            raise ValueError(f"not a cache key: {key!r}")
        return self.entries / key[:2] / key

    def _new_tmp(self) -> Path:
        self.tmp.mkdir(parents=True, exist_ok=True)
        d = self.tmp / f"{uuid.uuid4().hex}.{os.getpid()}"
        d.mkdir()
        return d

    # -- get ------------------------------------------------------------------------------------

    def lookup(self, key: str) -> Entry | None:
        """The entry for ``key`` if there is a complete one."""
        folder = self._folder(key)
        try:
            meta = json.loads((folder / "entry.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        if not isinstance(meta, dict) or not isinstance(meta.get("files"), list):
            return None
        if meta.get("schema") != ENTRY_SCHEMA or meta.get("key") != key:
            return None
        return Entry(key, folder, meta)

    def restore(self, entry: Entry, output: Path, *, force: bool, inputs: Iterable[Path]) -> None:
        """Write the entry's files as the output folder (staged, published when all hashes
        match); refresh its use time. Raises :class:`CacheMiss` when it cannot be restored."""
        files = entry.meta.get("files", [])
        try:
            with staged_folder(output, force=force, inputs=list(inputs)) as tmp:
                for f in files:
                    rel = Path(f["path"])
                    if rel.is_absolute() or ".." in rel.parts:
                        raise CacheMiss(f"bad path in cache entry: {f['path']}")
                    n, digest = _restore_file(entry.folder / "files" / rel, tmp / rel)
                    if n != f["bytes"] or digest != f["sha256"]:
                        raise CacheMiss(f"cache entry {entry.key[:12]} altered: {rel}")
        except FileNotFoundError as exc:
            raise CacheMiss(f"cache entry {entry.key[:12]} went away: {exc.filename}") from None
        except _Unreadable as exc:
            raise CacheMiss(f"cache entry {entry.key[:12]} cannot be read: {exc}") from None
        except (KeyError, TypeError, ValueError) as exc:
            raise CacheMiss(f"cache entry {entry.key[:12]} damaged: {exc}") from None
        with contextlib.suppress(OSError):
            os.utime(entry.folder / "entry.json")

    # -- put ------------------------------------------------------------------------------------

    def put(self, key: str, output: Path, result: dict[str, Any]) -> Entry | None:
        """Store the output folder under ``key`` (a no-op when the key is already there);
        the entry under ``key`` afterwards, if any."""
        self.store(key, output, result)
        return self.lookup(key)

    def store(self, key: str, output: Path, result: dict[str, Any], replace: bool = False) -> bool:
        """Store the output folder under ``key``; True when this call stored it. A complete
        entry already there is kept (another batch stored the same bytes), unless ``replace``
        (it could not be restored); a damaged one (no readable ``entry.json``) is replaced.
        A write that fails makes the cache :attr:`unwritable` (no exception)."""
        if self.unwritable is not None:
            return False
        folder = self._folder(key)
        if folder.exists() and self.lookup(key) is not None and not replace:
            return False
        tmp = None
        try:
            if folder.exists():
                self._discard(folder)
            tmp = self._new_tmp()
            rows = []
            for p in sorted(output.rglob("*")):
                if p.is_file():
                    rel = p.relative_to(output).as_posix()
                    n, digest = _copy_hashing(p, tmp / "files" / rel)
                    rows.append({"path": rel, "bytes": n, "sha256": digest})
            meta = {
                "schema": ENTRY_SCHEMA,
                "key": key,
                "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                "bytes": sum(r["bytes"] for r in rows),
                "files": rows,
                "result": result,
            }
            (tmp / "entry.json").write_text(dumps_json(meta), encoding="utf-8")
            folder.parent.mkdir(parents=True, exist_ok=True)
            try:
                os.rename(tmp, folder)
            except OSError as exc:
                if exc.errno not in (errno.EEXIST, errno.ENOTEMPTY):
                    raise
                shutil.rmtree(tmp, ignore_errors=True)  # another batch stored it first
                return False
            return True
        except OSError as exc:
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
            self._cannot_write(exc)
            return False
        except BaseException:
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
            raise

    def _discard(self, folder: Path) -> bool:
        """Move an entry out of ``entries/`` (one rename: readers see it whole or not at all),
        then delete it; False when another batch removed it first."""
        self.tmp.mkdir(parents=True, exist_ok=True)
        victim = self.tmp / f"evict.{uuid.uuid4().hex}"
        try:
            os.rename(folder, victim)
        except FileNotFoundError:
            return False
        shutil.rmtree(victim, ignore_errors=True)
        return True

    # -- how long each asset took ---------------------------------------------------------------

    def _times_file(self, job_id: str) -> Path:
        return (
            self.root / "times" / f"{hashlib.sha256(job_id.encode('utf-8')).hexdigest()[:32]}.json"
        )

    def remember_seconds(self, job_id: str, seconds: float) -> None:
        """Record how long converting the asset ``job_id`` took (written whole by a rename;
        the last batch to finish one wins). A hint for scheduling, never part of a result."""
        if self.unwritable is not None:
            return
        f = self._times_file(job_id)
        tmp = f.with_name(f".{uuid.uuid4().hex}.tmp")
        try:
            f.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(json.dumps({"id": job_id, "seconds": round(float(seconds), 3)}))
            os.replace(tmp, f)
        except OSError as exc:
            with contextlib.suppress(OSError):
                tmp.unlink()
            self._cannot_write(exc)

    def last_seconds(self, job_id: str) -> float | None:
        """How long the last conversion of ``job_id`` took, if this cache saw one."""
        try:
            got = json.loads(self._times_file(job_id).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        if not isinstance(got, dict) or got.get("id") != job_id:
            return None
        sec = got.get("seconds")
        return float(sec) if isinstance(sec, int | float) and sec >= 0 else None

    # -- size -----------------------------------------------------------------------------------

    def _all(self) -> list[tuple[float, int, Path]]:
        out = []
        try:
            shards = [s for s in self.entries.iterdir() if s.is_dir()]
        except OSError:
            return out
        for shard in shards:
            try:
                folders = list(shard.iterdir())
            except OSError:
                continue
            for folder in folders:
                meta = folder / "entry.json"
                try:
                    st = meta.stat()
                    size = int(json.loads(meta.read_text(encoding="utf-8")).get("bytes", 0))
                except (OSError, ValueError, AttributeError, TypeError):
                    continue  # being evicted, damaged, or not ours
                out.append((st.st_mtime, size, folder))
        return out

    def size(self) -> int:
        """Bytes held by complete entries."""
        return sum(s for _, s, _ in self._all())

    def evict(self, keep: Iterable[str] = ()) -> list[str]:
        """Remove least recently used entries until the cache fits its cap; ``keep``: keys not
        to remove unless nothing else is left. Returns the removed keys. Nothing is removed
        from a cache that cannot be written."""
        if self.unwritable is not None:
            return []
        try:
            self._clean_tmp()
        except OSError as exc:
            self._cannot_write(exc)
            return []
        if self.max_bytes is None:
            return []
        entries = self._all()
        total = sum(s for _, s, _ in entries)
        keep = set(keep)
        entries.sort(key=lambda e: (e[2].name in keep, e[0]))
        removed = []
        for _, size, folder in entries:
            if total <= self.max_bytes:
                break
            try:
                gone = self._discard(folder)
            except OSError as exc:
                self._cannot_write(exc)
                break
            total -= size
            if gone:
                removed.append(folder.name)
        return removed

    def _clean_tmp(self) -> None:
        if not self.tmp.is_dir():
            return
        now = time.time()
        for d in self.tmp.iterdir():
            with contextlib.suppress(OSError):
                if now - d.stat().st_mtime > _STALE_TMP_S:
                    shutil.rmtree(d, ignore_errors=True)
