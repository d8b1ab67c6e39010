"""Which files an input may make the tool read: its own folder, and the roots you allow.

A manifest's paths, a glTF's URIs and a USD layer's sublayers, references and payloads are
resolved (symbolic links followed) and must land inside the folder of the file that names them,
or inside a folder allowed with ``--allow-root DIR`` (repeatable; :func:`allowed_roots`).
Anything else is refused before it is opened, with a message naming the file that referenced
the outside path and the key where it did.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterable, Iterator
from contextvars import ContextVar
from pathlib import Path

from wrinklepipe.errors import input_error

_ROOTS: ContextVar[tuple[Path, ...]] = ContextVar("wrinklepipe_allowed_roots", default=())


@contextlib.contextmanager
def allowed_roots(roots: Iterable[str | Path]) -> Iterator[tuple[Path, ...]]:
    """Allow reading under these folders too (``--allow-root``) for the block."""
    resolved = tuple(Path(os.path.expanduser(r)).resolve() for r in roots)
    token = _ROOTS.set(_ROOTS.get() + resolved)
    try:
        yield resolved
    finally:
        _ROOTS.reset(token)


def is_inside(path: Path, root: Path) -> bool:
    return path == root or root in path.parents


def confine(
    folder: str | Path, ref: str | Path, file: str | Path, key: str = "", what: str = "path"
) -> Path:
    """``ref`` (relative to ``folder``, or absolute) resolved; refused unless it lies inside
    ``folder`` or an allowed root. ``file`` is the input that named it (for the message)."""
    folder = Path(folder).resolve()
    path = (folder / Path(ref)).resolve()
    if is_inside(path, folder) or any(is_inside(path, r) for r in _ROOTS.get()):
        return path
    raise input_error(
        file,
        f"{what} {str(ref)!r} is outside {folder} ({path}); only files inside the folder of the "
        "file that names them are read (allow another folder with --allow-root DIR)",
        key,
    )


def confine_usd(path: str | Path) -> None:
    """Check every sublayer, reference and payload reachable from a USD file before the stage
    is opened: each must lie inside the root layer's folder or an allowed root."""
    from pxr import Sdf, Tf  # deferred: usd-core, USD only

    root = Path(path).resolve()
    folder = root.parent
    seen = {str(root)}
    stack = [str(root)]
    while stack:
        layer_path = stack.pop()
        try:
            layer = Sdf.Layer.FindOrOpen(layer_path)
        except Tf.ErrorException:
            layer = None
        if layer is None:
            continue  # opening the stage reports it
        for dep in sorted(layer.GetCompositionAssetDependencies()):
            if not dep:
                continue
            absolute = layer.ComputeAbsolutePath(dep)
            if "[" in absolute and absolute.endswith("]"):
                package = absolute[: absolute.index("[")]  # a layer inside a .usdz package
                confine(folder, package, layer_path, dep, "USD layer")
            else:
                absolute = str(confine(folder, absolute, layer_path, dep, "USD layer"))
            if absolute not in seen:
                seen.add(absolute)
                stack.append(absolute)
