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

The lock and the staging folders (markers, leftovers of dead runs) are
:mod:`wrinklepipe.staging`; this module is what writers call.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import secrets
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wrinklepipe.errors import input_error
from wrinklepipe.staging import STAGING_MARKER, _in_open_staging, _Staging, output_lock

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
        # the file's lock (taken here when the caller holds none; waiting, not refusing, for
        # another writer of the same file) records the staging folder before it exists
        with output_lock(path, wait=True):
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
