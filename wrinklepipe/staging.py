"""Output locks and staging folders: who holds an output, and what a dead run left behind.

The machinery under :mod:`wrinklepipe.atomic` (whose docstring states the rules):

* :func:`output_lock` takes ``.NAME.wrinklepipe-lock`` beside an output: an ``flock`` held for
  the whole run, with pid, host, process start and command inside. A second run gets an error
  naming the lock and its holder; the kernel drops the lock when the process dies, so the next
  run takes a stale one over.
* :class:`_Staging` is ``.NAME.<random>.wrinklepipe-partial/`` beside the output, made as
  ``...-new/``, its marker (``.wrinklepipe-staging``: pid, host, process start, flock held
  while the run lives) written inside, then renamed: a staging folder never exists without its
  complete marker.
* :func:`remove_dead_leftovers` removes only what a dead run of this tool provably left: a
  staging folder whose marker names a process on this host that is gone (its flock free), and
  the ``-new`` folders a dead run's lock lists. Nothing is removed because of its name alone.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import secrets
import shutil
import socket
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wrinklepipe.errors import input_error

#: Suffix of a staging folder beside an output; marker file inside it; suffix of a lock file.
STAGING_SUFFIX = ".wrinklepipe-partial"


#: Suffix of a staging folder while its marker is being written (renamed to STAGING_SUFFIX).
STAGING_NEW_SUFFIX = STAGING_SUFFIX + "-new"


STAGING_MARKER = ".wrinklepipe-staging"


LOCK_SUFFIX = ".wrinklepipe-lock"


_TOOL = "wrinklepipe"


# ------------------------------------------------------------------------------------------------
# who we are: enough to tell later whether the process that wrote a marker is gone


def _process_start(pid: int) -> str:
    """The process's start time in clock ticks since boot (``/proc/PID/stat`` field 22), or ""."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return ""
    return stat.rsplit(")", 1)[-1].split()[19]


def _owner() -> dict[str, Any]:
    pid = os.getpid()
    return {
        "tool": _TOOL,
        "pid": pid,
        "host": socket.gethostname(),
        "start": _process_start(pid),
        "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "command": " ".join(["wrinklepipe", *sys.argv[1:]])[:300],
    }


def _process_gone(owner: dict[str, Any]) -> bool:
    """True only when the owner is provably dead: same host, and its pid is gone or reused."""
    if owner.get("tool") != _TOOL or owner.get("host") != socket.gethostname():
        return False
    pid = owner.get("pid")
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        pass  # alive, another user's
    start = _process_start(pid)
    return bool(start and owner.get("start") and start != owner.get("start"))


def _try_flock(fd: int) -> bool:
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def _read_owner(fd: int) -> dict[str, Any]:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        data = json.loads(os.read(fd, 4096).decode("utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _write_owner(fd: int, record: dict[str, Any] | None = None) -> None:
    data = (json.dumps(record or _owner(), sort_keys=True) + "\n").encode("utf-8")
    os.pwrite(fd, data, 0)  # records only grow: a kill mid-update never loses what was there
    os.ftruncate(fd, len(data))


def _same_process(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return all(a.get(k) == b.get(k) for k in ("tool", "pid", "host", "start"))


# ------------------------------------------------------------------------------------------------
# the output lock


def lock_path(target: str | Path) -> Path:
    """The lock file of an output: ``.NAME.wrinklepipe-lock`` beside it."""
    target = Path(target)
    return target.parent / f".{target.name}{LOCK_SUFFIX}"


@dataclass
class _Held:
    """A lock this process holds: its fd, nesting depth and the record written into it (the
    owner and every staging folder created for the output, so that the next holder can remove
    what this run left if it dies, even a folder whose marker was not yet written)."""

    fd: int
    depth: int
    record: dict[str, Any]

    def register(self, *staging_names: str) -> None:
        self.record.setdefault("staging", []).extend(staging_names)
        _write_owner(self.fd, self.record)


_HELD: dict[Path, _Held] = {}  # lock files this process holds


def _describe(owner: dict[str, Any]) -> str:
    if not owner:
        return "another wrinklepipe run"
    cmd = f" `{owner['command']}`" if owner.get("command") else ""
    return f"pid {owner.get('pid')} on {owner.get('host')} since {owner.get('time')}{cmd}"


def _acquire(lock: Path, target: Path, wait: bool = False) -> int:
    """Open and flock ``lock`` (``wait``: block until it is free, for shared caches); the file
    we hold must still be the one at the path."""
    owner: dict[str, Any] = {}
    for _ in range(50):
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o644)
        except OSError as exc:
            raise input_error(
                target, f"cannot create the lock file {lock}: {exc.strerror or exc}"
            ) from None
        if wait:
            fcntl.flock(fd, fcntl.LOCK_EX)
        if wait or _try_flock(fd):
            try:
                same = os.fstat(fd).st_ino == os.stat(lock, follow_symlinks=False).st_ino
            except FileNotFoundError:
                same = False
            if same:
                return fd
            os.close(fd)  # the file was removed by its previous holder: take the new one
            continue
        owner = _read_owner(fd)
        os.close(fd)
        if owner and not _process_gone(owner):
            break
        time.sleep(0.02)  # a dead run's lock being cleaned up: it frees in a moment
    raise input_error(
        target,
        f"is being written by {_describe(owner)}; lock file {lock}. Wait for that run to finish "
        "(the lock frees itself when its process ends)",
    )


@contextlib.contextmanager
def output_lock(target: str | Path, wait: bool = False) -> Iterator[Path]:
    """Hold the output's lock for the block; nested use for the same output is free. ``wait``
    blocks until another holder is done (for a shared cache) instead of refusing.

    The folder holding the output must exist. Taking the lock also removes what dead runs of
    this tool left in that folder (:func:`remove_dead_leftovers`)."""
    target = Path(os.path.abspath(target))
    lock = lock_path(target)
    if lock in _HELD:
        _HELD[lock].depth += 1
        try:
            yield lock
        finally:
            _HELD[lock].depth -= 1
        return
    fd = _acquire(lock, target, wait)
    try:
        previous = _read_owner(fd)
        held = _HELD[lock] = _Held(fd, 1, _owner())
        dead = list(previous.get("staging", [])) if _process_gone(previous) else []
        if dead:  # ours to remove now: recorded first, so a kill below loses none of them
            held.record["staging"] = dead
        _write_owner(fd, held.record)
        for name in dead:
            _remove_recorded(target.parent, name, previous)
        remove_dead_leftovers(target.parent)
        yield lock
    finally:
        _HELD.pop(lock, None)
        with contextlib.suppress(OSError):
            os.unlink(lock)  # unlink while still holding: a waiter retries on the new file
        os.close(fd)


# ------------------------------------------------------------------------------------------------
# staging folders and leftovers of dead runs


class _Staging:
    """``.NAME.<random>.wrinklepipe-partial/`` with our marker (flock held while we live).

    Made under the name ``...-partial-new``, the marker created, locked and written inside, then
    renamed: the staging folder appears with its complete marker at once. Both names are in the
    output lock's record before anything exists, so the next holder of the lock removes what a
    run killed at any moment left (a ``-new`` folder that is empty or holds only our marker)."""

    def __init__(self, parent: Path, name: str) -> None:
        held = _HELD.get(parent / f".{name}{LOCK_SUFFIX}")
        for _ in range(100):
            stem = f".{name}.{secrets.token_hex(6)}"
            new, folder = parent / f"{stem}{STAGING_NEW_SUFFIX}", parent / f"{stem}{STAGING_SUFFIX}"
            if folder.exists() or folder.is_symlink():
                continue
            if held is not None:
                held.register(new.name, folder.name)  # before they exist: no moment unaccounted
            try:
                new.mkdir(mode=0o700)
                break
            except FileExistsError:
                continue
        else:
            raise FileExistsError(errno.EEXIST, "no free staging folder name", str(parent))
        try:
            marker = new / STAGING_MARKER
            self.fd = os.open(marker, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o644)
        except BaseException:
            os.rmdir(new)
            raise
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX)
            _write_owner(self.fd, held.record if held is not None else None)
            os.rename(new, folder)  # `folder` was checked free (and its name is random)
        except BaseException:
            _remove_staging(new, self.fd)
            raise
        self.dir = folder
        with _OPEN_STAGING_LOCK:
            _OPEN_STAGING.add(os.path.abspath(folder) + os.sep)

    def remove(self) -> None:
        with _OPEN_STAGING_LOCK:
            _OPEN_STAGING.discard(os.path.abspath(self.dir) + os.sep)
        _remove_staging(self.dir, self.fd)


#: The staging folders this process has open (absolute, with a trailing separator). A file
#: written inside one needs no staging folder of its own: the folder is published, or removed,
#: as a whole (see :func:`temp_path`).
_OPEN_STAGING: set[str] = set()


_OPEN_STAGING_LOCK = threading.Lock()


def _in_open_staging(path: Path) -> bool:
    p = os.path.abspath(path)
    with _OPEN_STAGING_LOCK:
        return any(p.startswith(d) for d in _OPEN_STAGING)


def _put_back_previous(folder: Path) -> None:
    """``--force`` moves the output it replaces into its staging folder as ``NAME.previous``,
    then renames the new output in: a run stopped between the two (``kill -9``, a signal) left
    no output but the previous one in here. Rename it back, if the output's place is still
    free, before the staging folder goes; once the new output is in place it is removed."""
    stem = folder.name[1:].removesuffix(STAGING_SUFFIX).removesuffix(STAGING_NEW_SUFFIX)
    name = stem.rpartition(".")[0]  # ".NAME.<random>.wrinklepipe-partial" -> NAME
    previous = folder / f"{name}.previous"
    if not name or previous.is_symlink() or not previous.is_dir():
        return
    with contextlib.suppress(OSError):  # (taken meanwhile: it goes with the staging folder)
        if not os.path.lexists(folder.parent / name):
            os.rename(previous, folder.parent / name)


def _remove_staging(folder: Path, fd: int) -> None:
    """Remove a staging folder: its contents first, the marker last (a kill part-way through
    leaves a folder still marked as a dead run's, which the next run removes); a previous
    output that ``--force`` had moved into it and not yet replaced is put back first."""
    try:
        _put_back_previous(folder)
        try:
            children = list(folder.iterdir())
        except FileNotFoundError:  # another run removing the same dead run's folder was first
            children = []
        for child in children:
            if child.name == STAGING_MARKER:
                continue
            if child.is_dir() and not child.is_symlink():
                shutil.rmtree(child, ignore_errors=True)
            else:
                with contextlib.suppress(FileNotFoundError):
                    child.unlink()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(folder / STAGING_MARKER)
    finally:
        os.close(fd)
    with contextlib.suppress(OSError):
        os.rmdir(folder)


def _staging_name(name: str) -> bool:
    ends = name.endswith(STAGING_SUFFIX) or name.endswith(STAGING_NEW_SUFFIX)
    return name.startswith(".") and ends and "/" not in name


def _remove_recorded(parent: Path, name: str, holder: dict[str, Any]) -> None:
    """Remove a staging folder that the lock of a dead run lists: when its marker names that run,
    or when it holds nothing but an empty marker or nothing at all (killed while creating it)."""
    folder = parent / str(name)
    if not _staging_name(str(name)) or folder.is_symlink() or not folder.is_dir():
        return
    try:
        fd = os.open(folder / STAGING_MARKER, os.O_RDWR | os.O_CLOEXEC | os.O_NOFOLLOW)
    except FileNotFoundError:
        with contextlib.suppress(OSError):
            os.rmdir(folder)  # only if empty
        return
    except OSError:
        return
    if _try_flock(fd):
        owner = _read_owner(fd)
        only_marker = [p.name for p in folder.iterdir()] == [STAGING_MARKER]
        if _same_process(owner, holder) or (not owner and only_marker):
            _remove_staging(folder, fd)
            return
    os.close(fd)


def _dead_staging_fd(entry: Path) -> int | None:
    """An flock'd fd on the marker of a staging folder that a dead run left, else None."""
    if not _staging_name(entry.name) or entry.is_symlink():
        return None
    try:
        fd = os.open(entry / STAGING_MARKER, os.O_RDWR | os.O_CLOEXEC | os.O_NOFOLLOW)
    except OSError:
        return None  # no marker: not provably ours, never touched
    if _try_flock(fd) and _process_gone(_read_owner(fd)):
        return fd
    os.close(fd)
    return None


def _dead_lock(entry: Path) -> None:
    """Remove a lock file whose holder is gone (its flock is free and its pid is dead), after
    every staging folder its record lists: the record is the only proof that a folder without
    its marker is that run's (one killed before its marker was written, or while removing it:
    after the marker, before the empty folder), so they go before the lock does. A listed folder
    is removed only when its marker names that run, or when it is empty or holds nothing but an
    empty marker (:func:`_remove_recorded`)."""
    if not entry.name.startswith(".") or not entry.name.endswith(LOCK_SUFFIX) or entry in _HELD:
        return
    try:
        fd = os.open(entry, os.O_RDWR | os.O_CLOEXEC | os.O_NOFOLLOW)
    except OSError:
        return
    try:
        owner = _read_owner(fd) if _try_flock(fd) else {}
        if owner and _process_gone(owner):
            if os.fstat(fd).st_ino == os.stat(entry, follow_symlinks=False).st_ino:
                for name in owner.get("staging", []):
                    _remove_recorded(entry.parent, name, owner)
                os.unlink(entry)
    except OSError:
        pass
    finally:
        os.close(fd)


def remove_dead_leftovers(folder: str | Path) -> list[Path]:
    """Remove staging folders and lock files in ``folder`` that dead runs of this tool left.

    Only entries carrying our marker (JSON naming the tool, pid, host and process start) whose
    process on this host is gone and whose flock is free; anything else is left alone."""
    removed = []
    try:
        entries = list(Path(folder).iterdir())
    except OSError:
        return removed
    for entry in entries:
        if entry.name.endswith(LOCK_SUFFIX):
            _dead_lock(entry)
            continue
        fd = _dead_staging_fd(entry)
        if fd is not None:
            _remove_staging(entry, fd)
            removed.append(entry)
    return removed
