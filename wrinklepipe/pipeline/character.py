"""The character's render mesh exactly as ``convert`` reads it, from a mesh file alone.

The authoring commands (``regions``, ``bake-states``) write maps into the UV layout and tangent
frame that ``convert`` will ship, so they read the mesh the way ``convert`` does for a manifest
naming it with ``material`` (and ``meshes``):

- glTF / GLB: the document (repaired), the wrinkled primitives of the material
  (:func:`~wrinklepipe.gltf.wrinkled.select_wrinkled`), given what convert gives them
  (:func:`~wrinklepipe.gltf.wrinkled.add_wrinkle_attributes`: MikkTSpace ``TANGENT`` where
  missing or invalid, front-projected UVs where there are none, vertex IDs), read as one render
  mesh (:func:`~wrinklepipe.gltf.render_mesh.wrinkled_mesh`);
- USD: the meshes bound to the material (:func:`~wrinklepipe.usd.source.read_usd_source`);
- OBJ: the whole file (:func:`~wrinklepipe.readers.meshes.load_mesh`).

Then :func:`~wrinklepipe.pipeline.prepare.prepare_mesh` (normals, tangents and vertex IDs
where still missing), as convert's mesh stage does.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.gltf.document import Document, read_document
from wrinklepipe.gltf.render_mesh import wrinkled_mesh
from wrinklepipe.gltf.repair import repair
from wrinklepipe.gltf.wrinkled import Selection, add_wrinkle_attributes, select_wrinkled
from wrinklepipe.pipeline.prepare import prepare_mesh
from wrinklepipe.readers.meshes import load_mesh
from wrinklepipe.readers.registry import MESH_SUFFIXES, format_of
from wrinklepipe.usd.source import read_usd_source


@dataclass(frozen=True)
class CharacterSource:
    """What selects the wrinkled part of a mesh file, as a manifest's keys do (``mesh``,
    ``material``, ``meshes``); ``path`` is the file named in messages, ``name`` the asset's."""

    mesh: Path
    material: str | list[str] | None = None
    meshes: tuple[str, ...] = ()
    path: Path | None = None
    name: str = ""

    def __post_init__(self) -> None:
        if self.path is None:
            object.__setattr__(self, "path", self.mesh)
        if not self.name:
            object.__setattr__(self, "name", Path(self.mesh).stem)


def open_wrinkled_document(src: CharacterSource) -> tuple[Document, Selection, list[str]]:
    """A glTF source's document (repaired) and its wrinkled selection, with the notes of both."""
    doc = read_document(src.mesh)
    notes = list(doc.notes) + repair(doc)
    sel = select_wrinkled(doc, src.material, src.meshes, src.path, src.name)
    return doc, sel, notes + sel.notes


def read_character(src: CharacterSource) -> tuple[Mesh, list[str]]:
    """The render mesh of ``src``'s wrinkled part as convert sees it, and notes (see the module
    doc). Raises :class:`~wrinklepipe.errors.InputError` for a missing or unreadable file, an
    unknown format, or a material/mesh selection that does not fit."""
    path = Path(src.mesh)
    if not path.is_file():
        raise input_error(path, "file not found" if not path.exists() else "is not a file")
    fmt = format_of(path)
    if fmt is None:
        raise input_error(
            path, f"unsupported mesh format {path.suffix!r} ({', '.join(MESH_SUFFIXES)})"
        )
    if fmt.name == "gltf":
        doc, sel, notes = open_wrinkled_document(src)
        for part in add_wrinkle_attributes(doc, sel.refs):
            where = f"{doc.mesh_name(part.ref.mesh)}/{part.ref.primitive}"
            notes += [f"{where}: {n}" for n in part.notes]
        mesh = wrinkled_mesh(doc, sel.refs)
    elif fmt.name == "usd":
        usd = read_usd_source(src)
        mesh, notes = usd.mesh, list(usd.notes)
    else:
        if src.material or src.meshes:
            raise input_error(path, "--material and --meshes select parts of a glTF or USD file")
        mesh = load_mesh(path)
        notes = list(mesh.notes)
    mesh = prepare_mesh(mesh)
    return mesh, notes + [n for n in mesh.notes if n not in notes]
