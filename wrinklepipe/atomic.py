"""Safe, atomic, deterministic output: nothing of the user's is ever lost.

The rules every writing command follows (the README's "Safety" section says the same):

* **Never over an input.** Callers pass the paths they read; a target that is one of them, or an
  output folder that equals or contains an input folder, is refused.
* **One writer per output.** :func:`output_lock` takes ``.NAME.wrinklepipe-lock`` beside the
  output (an ``flock`` held for the whole run, with pid, host, start time and command inside).
  A second run gets an error naming the lock and its holder. The kernel drops the lock when the
  process dies (even by ``kill -9``), so a lock left behind is stale by construction; the next
  run takes it over and removes the file when done.
* **Built aside, published by one rename.** Everything is written into a staging folder beside
  the output, ``.NAME.<random>.wrinklepipe-partial/``, which carries a marker file
  (``.wrinklepipe-staging``: pid, host, process start, flock held while the run lives). The
  staging folder itself appears by a rename: it is made as ``...wrinklepipe-partial-new/``, its
  marker written inside, then renamed, so a staging folder never exists without its complete
  marker (a kill in between leaves a ``-new`` folder the run's lock lists). The result is
  renamed into place only when complete. ``rename(2)`` of a folder onto a non-empty
  folder fails (``ENOTEMPTY``), so files added to the output meanwhile are never replaced.
* **Remove only what this run created**, or what a dead run of this tool provably left: a staging
  folder is removed by a later run only when its marker names a process on this host that is
  gone (and its flock is free). Nothing is removed because of its name alone.
* ``--force`` replaces an existing output *folder as it was when the run started*: the old one is
  moved into this run's staging folder, the new one renamed in, and only then the old one
  removed. If anything in it changed during the run, nothing is replaced.
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
import tempfile
import threading
import time
from collections.abc import Iterable, Iterator, Mapping
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
# inputs are never written


def check_not_input(target: str | Path, inputs: Iterable[str | Path] = ()) -> None:
    """Refuse a target that is one of the inputs or (for folders) contains one; a new file
    inside an input folder is allowed."""
    t = Path(target).resolve()
    for raw in inputs:
        p = Path(raw).resolve()
        if t == p:
            raise input_error(target, f"refusing to write over the input {raw}")
        if p.is_dir() and (t == p or p in t.parents):
            continue  # writing a new file inside an input folder is allowed
        if t.is_dir() and t in p.parents and Path(target).exists():
            raise input_error(target, f"output folder contains the input {raw}; choose another")


def _check_folder_not_input(target: Path, inputs: Iterable[str | Path]) -> None:
    t_res = target.resolve()
    for raw in inputs:
        p = Path(raw).resolve()
        base = p if p.is_dir() else p.parent
        if t_res == p or t_res == base or t_res in p.parents:
            raise input_error(target, f"output folder would overwrite or contain the input {raw}")


def default_mode() -> int:
    """Permissions of a new file under the current umask (mkstemp would give 0600)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


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


def _remove_staging(folder: Path, fd: int) -> None:
    """Remove a staging folder: its contents first, the marker last (a kill part-way through
    leaves a folder still marked as a dead run's, which the next run removes)."""
    try:
        for child in folder.iterdir():
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
    the ``-new`` staging folders its record lists: the record is the only proof that one killed
    before its marker was written is that run's, so it goes with the lock. (A ``-new`` folder
    holds a marker at most, so the flock is held a moment only; renamed staging folders carry
    their marker and are removed as any dead run's, by :func:`remove_dead_leftovers`.)"""
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
                    if str(name).endswith(STAGING_NEW_SUFFIX):
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


# ------------------------------------------------------------------------------------------------
# single files


def _make_parents(folder: Path) -> list[Path]:
    """Create ``folder`` and missing parents; return the ones created (deepest first)."""
    created = []
    p = folder
    while not p.exists():
        created.append(p)
        if p.parent == p:
            break
        p = p.parent
    try:
        for q in reversed(created):
            q.mkdir(exist_ok=True)
    except FileExistsError:
        raise input_error(folder, "a file is in the way of this folder") from None
    except NotADirectoryError:
        raise input_error(folder, "a file is in the way of this folder") from None
    return created


def _remove_created(created: list[Path]) -> None:
    for q in created:
        with contextlib.suppress(OSError):
            q.rmdir()  # only if still empty


@contextlib.contextmanager
def temp_path(path: str | Path, inputs: Iterable[str | Path] = ()) -> Iterator[Path]:
    """Yield a temporary path with ``path``'s name (so writers pick the same format) in a marked
    staging folder beside it; on success it gets umask permissions and is renamed over
    ``path``, on failure it is removed and ``path`` is untouched.

    Inside a staging folder this process has open (a :func:`staged_folder` being built) the
    temporary file is a hidden sibling with the same suffix instead: the whole folder is
    published by one rename or removed, so a marked folder of its own per file (a ``mkdir``,
    an flock'd marker, a ``rmdir``: most of the cost of writing a small file) adds nothing."""
    path = Path(path)
    check_not_input(path, inputs)
    if path.is_dir() and not path.is_symlink():
        raise input_error(path, "is a folder; expected a file name to write")
    if _in_open_staging(path):
        yield from _sibling_temp(path)
        return
    created = _make_parents(path.parent)
    done = False
    try:
        staging = _Staging(path.parent, path.name)
        try:
            tmp = staging.dir / path.name
            yield tmp
            os.chmod(tmp, default_mode())
            os.replace(tmp, path)
            done = True
        finally:
            staging.remove()
    finally:
        if not done:
            _remove_created(created)


def _sibling_temp(path: Path) -> Iterator[Path]:
    """:func:`temp_path` inside an open staging folder: ``.<random>.NAME`` beside ``path``
    (same suffix, so writers pick the same format), renamed over it on success, removed on
    failure."""
    created = _make_parents(path.parent)
    tmp = path.with_name(f".{secrets.token_hex(6)}.{path.name}")
    try:
        yield tmp
        os.chmod(tmp, default_mode())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        _remove_created(created)
        raise


def write_bytes(path: str | Path, data: bytes, inputs: Iterable[str | Path] = ()) -> Path:
    """Write ``data`` to ``path`` atomically (staged beside it, then ``os.replace``)."""
    with temp_path(path, inputs) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def dumps_json(obj: Any) -> str:
    """Deterministic JSON: sorted keys, fixed separators, trailing newline."""
    return json.dumps(obj, sort_keys=True, indent=2, ensure_ascii=False, allow_nan=False) + "\n"


def write_json(path: str | Path, obj: Any, inputs: Iterable[str | Path] = ()) -> Path:
    """Write deterministic JSON atomically."""
    return write_bytes(path, dumps_json(obj).encode("utf-8"), inputs)


@contextlib.contextmanager
def output_files(*paths: str | Path | None) -> Iterator[None]:
    """Lock the named output files (``None`` ignored) for a command's whole run; folders that
    had to be created for them are removed again if the block fails and they stayed empty."""
    targets = sorted({Path(os.path.abspath(p)) for p in paths if p is not None})
    created: list[Path] = []
    with contextlib.ExitStack() as stack:
        try:
            for t in targets:
                if t.is_dir() and not t.is_symlink():
                    raise input_error(t, "is a folder; expected a file name to write")
                created += _make_parents(t.parent)
                stack.enter_context(output_lock(t))
            yield
        except BaseException:
            stack.close()
            _remove_created(created)
            raise


def write_output(path: str | Path, data: bytes, inputs: Iterable[str | Path] = ()) -> Path:
    """Write one file a command was asked for: locked, atomic, never over an input."""
    with output_files(path):
        return write_bytes(path, data, inputs)


# ------------------------------------------------------------------------------------------------
# output folders


@dataclass(frozen=True)
class _Entry:
    kind: str
    size: int
    mtime_ns: int


def _snapshot(folder: Path) -> dict[str, _Entry]:
    """What a folder holds (relative path -> kind, size, mtime), without following links."""
    out: dict[str, _Entry] = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            p = Path(root) / name
            try:
                st = p.lstat()
            except FileNotFoundError:
                continue
            kind = "link" if p.is_symlink() else "dir" if name in dirs else "file"
            size = 0 if kind == "dir" else st.st_size
            mtime = 0 if kind == "dir" else st.st_mtime_ns
            out[p.relative_to(folder).as_posix()] = _Entry(kind, size, mtime)
    return out


def _diff(before: dict[str, _Entry], after: dict[str, _Entry]) -> list[str]:
    return sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))


def _refuse_unsafe_force(target: Path) -> None:
    """``--force`` never replaces the current folder, one of its parents or the home folder."""
    t = target.resolve()
    cwd = Path.cwd().resolve()
    if t == cwd or t in cwd.parents:
        raise input_error(target, "refusing to replace the current folder or one of its parents")
    with contextlib.suppress(RuntimeError, KeyError):
        home = Path.home().resolve()
        if t == home or t in home.parents:
            raise input_error(target, "refusing to replace the home folder or one of its parents")


def _check_target(target: Path, force: bool) -> None:
    if target.is_symlink():
        raise input_error(target, "output is a symbolic link; give the folder it points to")
    if target.exists() and not target.is_dir():
        raise input_error(target, "output exists and is not a folder")
    if target.is_dir():
        if os.path.ismount(target):
            raise input_error(
                target, "output is a mount point (it cannot be replaced); give a folder inside it"
            )
        if any(target.iterdir()):
            if not force:
                raise input_error(
                    target, "output folder exists and is not empty (use --force to replace it)"
                )
            _refuse_unsafe_force(target)


def _changed_message(target: Path, changed: list[str]) -> str:
    shown = ", ".join(changed[:5]) + (f" and {len(changed) - 5} more" if len(changed) > 5 else "")
    return (
        f"files in the output folder changed while this run was writing it ({shown}); nothing was "
        "replaced and the new output was discarded"
    )


def _publish(staging: _Staging, new: Path, target: Path, snapshot: dict[str, _Entry] | None):
    """Rename ``new`` to ``target``; with ``--force`` (``snapshot`` given) move the old folder
    aside first and remove it only after the new one is in place."""
    try:
        os.rename(new, target)  # target absent or empty: atomic; non-empty: ENOTEMPTY
        return
    except OSError as exc:
        if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST):
            if exc.errno == errno.ENOTDIR:
                raise input_error(
                    target, "a file appeared at the output path during the run; nothing changed"
                ) from None
            raise
        if snapshot is None:
            now = _snapshot(target)
            raise input_error(target, _changed_message(target, sorted(now))) from None
    aside = staging.dir / f"{target.name}.previous"
    os.rename(target, aside)
    changed = _diff(snapshot, _snapshot(aside))
    if changed:
        _put_back(aside, target)
        raise input_error(target, _changed_message(target, changed))
    try:
        os.rename(new, target)
    except OSError:
        _put_back(aside, target)
        raise


def _put_back(aside: Path, target: Path) -> None:
    """Return a moved-aside folder to its place; if the place was taken meanwhile, keep it under
    a new visible name (never removed by this tool) and say so."""
    try:
        os.rename(aside, target)
    except OSError:
        keep = Path(tempfile.mkdtemp(prefix=f"{target.name}.previous-", dir=target.parent))
        os.rename(aside, keep / target.name)
        raise input_error(
            target,
            f"the output path was taken during the run; the previous output is kept at {keep}",
        ) from None


@contextlib.contextmanager
def staged_folder(
    target: str | Path, *, force: bool = False, inputs: Iterable[str | Path] = ()
) -> Iterator[Path]:
    """Build an output folder in a staging folder beside it; publish it by rename on success.

    Holds the output's lock throughout. On any exception (or signal turned into one) the staging
    folder is removed and the previous output stays intact. An existing non-empty target is
    refused unless ``force``; see the module docstring for what ``force`` replaces."""
    target = Path(os.path.abspath(target))
    _check_folder_not_input(target, inputs)
    _check_target(target, force)
    if target.name == STAGING_MARKER:
        raise input_error(target, "this name is reserved by wrinklepipe; choose another")
    created = _make_parents(target.parent)
    published = False
    try:
        with output_lock(target):
            _check_target(target, force)  # another run may have finished meanwhile
            snapshot = _snapshot(target) if force and target.is_dir() else None
            staging = _Staging(target.parent, target.name)
            try:
                new = staging.dir / target.name
                new.mkdir()
                yield new
                _publish(staging, new, target, snapshot)
                published = True
            finally:
                staging.remove()
    finally:
        if not published:
            _remove_created(created)


def write_files(
    target: str | Path,
    files: Mapping[str, bytes],
    *,
    force: bool = False,
    inputs: Iterable[str | Path] = (),
    what: str = "the output",
) -> Path:
    """Write ``files`` (``{relative path: bytes}``, in sorted order) as the folder ``target``
    through :func:`staged_folder`: all of them or none, never over an input, ``force`` as
    there. An ``OSError`` while writing (disk full, permissions) becomes one
    :class:`~wrinklepipe.errors.InputError` naming ``target``: "could not write ``what``
    (reason); nothing was changed". The one helper for a job that has its files as bytes."""
    try:
        with staged_folder(target, force=force, inputs=inputs) as tmp:
            for rel, data in sorted(files.items()):
                write_bytes(tmp / rel, data)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise input_error(
            target, f"could not write {what} ({reason}); nothing was changed"
        ) from None
    return Path(target)
