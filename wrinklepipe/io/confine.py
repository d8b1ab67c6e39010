"""Which files an input may make the tool read: its own folder, and the roots you allow.

A manifest's paths, a glTF's URIs and a USD layer's sublayers, references and payloads are
resolved (symbolic links followed) and must land inside the folder of the file that names them,
or inside a folder allowed with ``--allow-root DIR`` (repeatable; :func:`allowed_roots`).
Anything else is refused before it is opened, with a message naming the file that referenced
the outside path and the key where it did.
"""

from __future__ import annotations

import contextlib
import functools
import os
from collections.abc import Iterable, Iterator
from contextvars import ContextVar
from pathlib import Path
from typing import Any

from wrinklepipe.errors import input_error
from wrinklepipe.io.usd_diagnostics import captured_diagnostics

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


def current_roots() -> tuple[Path, ...]:
    """The folders allowed now (resolved): a batch job carries them to its worker process."""
    return _ROOTS.get()


def is_inside(path: Path, root: Path) -> bool:
    return path == root or root in path.parents


def allowed(path: Path, folder: Path) -> bool:
    """``path`` (resolved) lies inside ``folder`` (resolved) or an allowed root."""
    return is_inside(path, folder) or any(is_inside(path, r) for r in _ROOTS.get())


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


def _package_file(path: str) -> str:
    """The file of a package-relative path (``/a/b.usdz[x/y.png]`` -> ``/a/b.usdz``)."""
    return path[: path.index("[")] if "[" in path and path.endswith("]") else path


def _is_layer_file(path: str) -> bool:
    """A path USD opens as a layer (usda, usdc, usd, usdz, inside a package too)."""
    from pxr import Sdf  # deferred: usd-core, USD only

    inner = path[path.rindex("[") + 1 : -1] if path.endswith("]") and "[" in path else path
    ext = inner.rsplit(".", 1)[-1].lower() if "." in inner.rsplit("/", 1)[-1] else ""
    return bool(ext) and Sdf.FileFormat.FindByExtension(ext) is not None


def _contains(value: Any, raw: str) -> bool:
    """``value`` (any field of a USD spec) holds the asset path ``raw``."""
    if isinstance(value, str):
        return value == raw
    if hasattr(value, "assetPath"):  # Sdf.Reference, Sdf.Payload
        return value.assetPath == raw
    if hasattr(value, "resolvedPath") and hasattr(value, "path"):  # Sdf.AssetPath
        return value.path == raw
    if isinstance(value, dict):
        return any(_contains(v, raw) for v in value.values())
    if hasattr(value, "prependedItems"):  # a list op (references, payloads)
        items = ("explicitItems", "addedItems", "prependedItems", "appendedItems", "orderedItems")
        return any(_contains(list(getattr(value, k)), raw) for k in items)
    if isinstance(value, (list, tuple)) or type(value).__name__.endswith("Array"):
        return any(_contains(v, raw) for v in value)
    return False


def _where(layer: Any, raw: str) -> str:
    """Where in ``layer`` the asset path ``raw`` is authored (``</Prim>.info:doc``,
    ``</Prim> references``, ``subLayers``): for the message; found by a walk over the layer's
    specs, done only when a path is refused."""
    from pxr import Sdf  # deferred: usd-core, USD only

    if raw in list(layer.subLayerPaths):
        return "subLayers"
    found: list[str] = []

    def visit(path: Any) -> None:
        if found:
            return
        spec = layer.GetObjectAtPath(path)
        if spec is None:
            return
        for key in spec.ListInfoKeys():
            if _contains(spec.GetInfo(key), raw):
                if path.IsPropertyPath():
                    field = "" if key in ("default", "timeSamples") else f" {key}"
                    found.append(f"<{path.GetPrimPath()}>.{path.name}{field}")
                else:
                    found.append(f"<{path}> {key}")
                return

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    return found[0] if found else ""


def _record(into: list[str], asset: str) -> str:
    into.append(asset)
    return asset


def confine_usd(path: str | Path) -> list[Path]:
    """Check every path a USD file can name before the stage is opened: sublayers, references,
    payloads, value clips (``clips.assetPaths``, ``manifestAssetPath``, templates), textures
    (``inputs:file``), ``info:*`` and any other asset-valued attribute or metadata, in every
    layer reachable from the file. Each must resolve (through USD's resolver, symbolic links
    followed) inside the root layer's folder or an allowed root; the first that does not is
    refused with the layer and the spec that name it. Returns the files found (layers and
    assets that exist), sorted: what opening and packing the stage may read."""
    from pxr import Ar, Sdf, Tf, UsdUtils  # deferred: usd-core, USD only

    root = Path(path).resolve()
    folder = root.parent
    resolver = Ar.GetResolver()
    seen = {str(root)}
    files = {root}
    stack = [str(root)]
    with (
        captured_diagnostics(),
        Ar.ResolverContextBinder(resolver.CreateDefaultContextForAsset(str(root))),
    ):
        while stack:
            layer_path = stack.pop()
            try:
                layer = Sdf.Layer.FindOrOpen(layer_path)
            except Tf.ErrorException:
                layer = None
            if layer is None:
                continue  # opening the stage reports it (WP-USD-001/003)
            authored: list[str] = []
            # every asset path of the layer, metadata, time samples and clips included; the
            # function returns each unchanged, so the layer stays clean
            UsdUtils.ModifyAssetPaths(layer, functools.partial(_record, authored))
            here = os.path.dirname(_package_file(layer.realPath or layer_path))
            for raw in sorted(set(authored)):
                if not raw:
                    continue
                anchored = layer.ComputeAbsolutePath(raw)
                resolved = str(resolver.Resolve(anchored)) if "#" not in raw else ""
                target = resolved or (anchored if os.path.isabs(_package_file(anchored)) else "")
                target = target or os.path.join(here, raw)
                real = Path(_package_file(target)).resolve()
                if not allowed(real, folder):
                    where = _where(layer, raw)
                    shown = "" if str(real) == raw else f" ({real})"
                    raise input_error(
                        layer_path,
                        f"USD asset path @{raw}@ is outside {folder}{shown}; only files inside "
                        "the folder of the file that names them are read (allow another folder "
                        "with --allow-root DIR)",
                        where or raw,
                    )
                if real.is_file():
                    files.add(real)
                if resolved and _is_layer_file(resolved) and resolved not in seen:
                    seen.add(resolved)
                    stack.append(resolved)
    return sorted(files)
