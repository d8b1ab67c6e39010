"""A written asset -> :class:`WrinklePackage`: a convert folder, a .gltf/.glb or a USD file."""

from __future__ import annotations

from pathlib import Path

from wrinklepipe.errors import input_error
from wrinklepipe.package import WrinklePackage
from wrinklepipe.readers.registry import READERS, read_package_file

#: The order a folder's written asset is looked for in (convert writes all three beside).
FOLDER_ORDER = (".gltf", ".glb", ".usda", ".usdc", ".usdz", ".usd")


def asset_file(folder: Path, suffixes: tuple[str, ...] = FOLDER_ORDER) -> Path | None:
    """The written asset a folder holds: its first .gltf, else .glb, else USD file (sorted
    by name within a suffix; only ``suffixes``, in their order), or None. The one place a
    convert folder is recognised."""
    for suffix in suffixes:
        found = sorted(q for q in folder.iterdir() if q.suffix.lower() == suffix and q.is_file())
        if found:
            return found[0]
    return None


def written_file(path: str | Path) -> Path:
    """The file a written asset is read from: a convert folder's asset file
    (:func:`asset_file`), or ``path`` itself."""
    path = Path(path)
    if path.is_dir():
        found = asset_file(path)
        if found is None:
            raise input_error(
                path, "no .gltf, .glb or USD file in this folder (is it a convert output?)"
            )
        path = found
    return path


def read_package(path: str | Path) -> WrinklePackage:
    """A written asset: a convert folder, a .gltf/.glb or a .usda/.usdc/.usdz file (the
    package reader of its suffix in :data:`wrinklepipe.readers.registry.READERS`)."""
    path = written_file(path)
    fmt = READERS.get(path.suffix.lower())
    if fmt is None or fmt.package is None:
        raise input_error(path, "expected a convert folder, .gltf/.glb or .usda/.usdc/.usdz")
    return read_package_file(path)
