"""A written asset -> :class:`WrinklePackage`: a convert folder, a .gltf/.glb or a USD file."""

from __future__ import annotations

from pathlib import Path

from wrinklepipe.document.package import read_wrinkled
from wrinklepipe.errors import input_error
from wrinklepipe.io.package import WrinklePackage
from wrinklepipe.io.usd_read import read_usd


def written_file(path: str | Path) -> Path:
    """The file a written asset is read from: a convert folder's .gltf (else its .glb), or
    ``path`` itself."""
    path = Path(path)
    if path.is_dir():
        found = sorted(path.glob("*.gltf")) or sorted(path.glob("*.glb"))
        if not found:
            raise input_error(path, "no .gltf or .glb in this folder (is it a convert output?)")
        path = found[0]
    return path


def read_package(path: str | Path) -> WrinklePackage:
    """A written asset: a convert folder (its glTF), a .gltf/.glb or a .usda/.usdc/.usdz file."""
    path = written_file(path)
    suffix = path.suffix.lower()
    if suffix in (".gltf", ".glb"):
        return read_wrinkled(path)
    if suffix in (".usda", ".usdc", ".usd", ".usdz"):
        return read_usd(path)
    raise input_error(path, "expected a convert folder, .gltf/.glb or .usda/.usdc/.usdz")
