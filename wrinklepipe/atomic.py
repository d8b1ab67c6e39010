"""Atomic, deterministic output: write under a temporary name, rename into place when complete.

Never writes over an input: callers pass the input paths they read, and a target that resolves to
one of them (or an output folder that contains or equals an input folder) is refused.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from wrinklepipe.errors import input_error


def check_not_input(target: str | Path, inputs: Iterable[str | Path] = ()) -> None:
    """Refuse a target that is, or (for folders) contains or lies inside of, one of the inputs."""
    t = Path(target).resolve()
    for raw in inputs:
        p = Path(raw).resolve()
        if t == p:
            raise input_error(target, f"refusing to write over the input {raw}")
        if p.is_dir() and (t == p or p in t.parents):
            continue  # writing a new file inside an input folder is allowed
        if t.is_dir() and t in p.parents and Path(target).exists():
            raise input_error(target, f"output folder contains the input {raw}; choose another")


def default_mode() -> int:
    """Permissions of a new file under the current umask (mkstemp would give 0600)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def temp_path(path: str | Path, inputs: Iterable[str | Path] = ()) -> Iterator[Path]:
    """Yield a temporary sibling of ``path`` (same suffix, so writers pick the same format) to
    write to; on success it gets umask permissions and is renamed over ``path``, on failure it
    is removed and ``path`` is untouched."""
    path = Path(path)
    check_not_input(path, inputs)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.chmod(tmp, default_mode())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_bytes(path: str | Path, data: bytes, inputs: Iterable[str | Path] = ()) -> Path:
    """Write ``data`` to ``path`` atomically (temp file in the same folder + ``os.replace``)."""
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
def staged_folder(
    target: str | Path, *, force: bool = False, inputs: Iterable[str | Path] = ()
) -> Iterator[Path]:
    """Build an output folder under a temporary sibling name; move it into place on success.

    On any exception the temporary folder is removed and a previous output stays intact.
    An existing non-empty target is refused unless ``force``.
    """
    target = Path(target)
    t_res = target.resolve()
    for raw in inputs:
        p = Path(raw).resolve()
        base = p if p.is_dir() else p.parent
        if t_res == p or t_res == base or t_res in p.parents:
            raise input_error(target, f"output folder would overwrite or contain the input {raw}")
    if target.exists() and not target.is_dir():
        raise input_error(target, "output exists and is not a folder")
    if target.exists() and any(target.iterdir()) and not force:
        raise input_error(target, "output folder exists and is not empty (use --force to replace)")
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".partial", dir=target.parent))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    if target.exists():
        old = target.with_name(f".{target.name}.old")
        shutil.rmtree(old, ignore_errors=True)
        os.replace(target, old)
    os.replace(tmp, target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
