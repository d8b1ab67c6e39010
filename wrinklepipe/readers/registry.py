"""Which reader opens a file: one table keyed by suffix (the shape of trimesh's
``exchange/load.py``).

A :class:`Format` is a name, its suffixes, the reader of its meshes and, for a format
``convert`` writes, the reader of a wrinkle package. Mesh ingest
(:func:`wrinklepipe.readers.meshes.load_meshes`), the written-asset reader
(:func:`wrinklepipe.sources.package.read_package`), ``validate-asset``'s loader, the manifest's
mesh check and the batch folder scan all look a file up here (:func:`reader_for`); a new mesh or
package format is one more entry in :data:`FORMATS`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.gltf.meshes import GltfMeshOptions, read_gltf_meshes
from wrinklepipe.gltf.package_read import read_wrinkled
from wrinklepipe.package import WrinklePackage
from wrinklepipe.readers.obj import read_obj_meshes
from wrinklepipe.suffixes import GLTF_SUFFIXES, OBJ_SUFFIXES, USD_SUFFIXES
from wrinklepipe.usd.meshes import UsdMeshOptions, read_usd_meshes
from wrinklepipe.usd.package_read import read_usd


@dataclass(frozen=True)
class LoadOptions:
    """Options of mesh ingest (:func:`wrinklepipe.readers.meshes.load_mesh` / ``load_meshes``).

    generate_uvs: give meshes without UVs an xatlas layout (default True; noted).
    bake_transforms: glTF/USD: apply node / prim world transforms to non-skinned meshes.
    usd_time: USD time code to read points at (default: the default time).
    """

    generate_uvs: bool = True
    bake_transforms: bool = True
    usd_time: float | None = None


@dataclass(frozen=True)
class Format:
    """A file format wrinklepipe reads: ``meshes(path, options)`` returns every triangulated
    mesh part; ``package(path)`` (None: not a format convert writes) the wrinkle package."""

    name: str
    suffixes: tuple[str, ...]
    meshes: Callable[[Path, LoadOptions], list[Mesh]]
    package: Callable[[Path], WrinklePackage] | None = None


def _gltf_meshes(path: Path, o: LoadOptions) -> list[Mesh]:
    return read_gltf_meshes(path, GltfMeshOptions(bake_transforms=o.bake_transforms))


def _usd_meshes(path: Path, o: LoadOptions) -> list[Mesh]:
    return read_usd_meshes(path, UsdMeshOptions(bake_transforms=o.bake_transforms, time=o.usd_time))


def _obj_meshes(path: Path, o: LoadOptions) -> list[Mesh]:
    return read_obj_meshes(path)


FORMATS: tuple[Format, ...] = (
    Format("gltf", GLTF_SUFFIXES, _gltf_meshes, read_wrinkled),
    Format("usd", USD_SUFFIXES, _usd_meshes, read_usd),
    Format("obj", OBJ_SUFFIXES, _obj_meshes),
)
#: suffix (lower case, with the dot) -> its format
READERS: dict[str, Format] = {s: f for f in FORMATS for s in f.suffixes}
#: every suffix a mesh is read from
MESH_SUFFIXES: tuple[str, ...] = tuple(READERS)
#: every suffix a written wrinkle asset (a package) is read from
PACKAGE_SUFFIXES: tuple[str, ...] = tuple(s for s, f in READERS.items() if f.package)


def format_of(path: str | Path) -> Format | None:
    """The format ``path``'s suffix names (any case), or None."""
    return READERS.get(Path(path).suffix.lower())


def reader_for(path: str | Path, need: str = "mesh") -> Format:
    """The format of ``path`` by its suffix, able to read ``need`` (``"mesh"`` or
    ``"package"``); an :class:`~wrinklepipe.errors.InputError` naming the suffixes that are
    read otherwise."""
    fmt = format_of(path)
    if need == "package":
        if fmt is None or fmt.package is None:
            raise input_error(
                path, f"not a written wrinkle asset: expected one of {', '.join(PACKAGE_SUFFIXES)}"
            )
        return fmt
    if fmt is None:
        raise input_error(
            path,
            f"unknown mesh format {Path(path).suffix!r}; use one of {sorted(MESH_SUFFIXES)}",
        )
    return fmt


def read_meshes(path: str | Path, options: LoadOptions | None = None) -> list[Mesh]:
    """Every mesh part of ``path``, by the reader of its suffix (no UV generation: that is
    :func:`wrinklepipe.readers.meshes.load_meshes`)."""
    p = Path(path)
    fmt = reader_for(p)
    if not p.is_file():
        raise input_error(p, "file not found")
    return fmt.meshes(p, options or LoadOptions())


def read_package_file(path: str | Path) -> WrinklePackage:
    """The wrinkle package of a written .gltf/.glb or USD file."""
    p = Path(path)
    fmt = reader_for(p, "package")
    assert fmt.package is not None  # reader_for(..., "package") guarantees it
    return fmt.package(p)
