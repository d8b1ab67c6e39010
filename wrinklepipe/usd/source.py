"""A USD source read for conversion: which meshes get wrinkled, and their render mesh.

The manifest's ``material`` (a Material prim's name or path, or a list) selects the wrinkled
meshes: those bound to it, or to one of them (``material:binding`` as
``UsdShade.MaterialBindingAPI.ComputeBoundMaterial`` resolves it). Without ``material``: the
stage's only bound material, or, when no mesh has one, every mesh (convert then adds a
material). ``meshes`` restricts the selection to Mesh prims named by name or path (without
``material``: those meshes, with the materials they are bound to); a material also bound to
meshes outside the selection is then cloned in the output layer (an internal reference), as
the glTF path clones a shared material. Bad selections are one
:class:`~wrinklepipe.errors.InputError` each, listing what the stage has.

The render mesh is the wrinkled meshes as :func:`wrinklepipe.usd.meshes.read_usd_meshes`
reads them (world space, skins at their bind pose), merged in prim order; each
:class:`~wrinklepipe.asset.MeshPart` keeps the prim path, its corner-to-vertex map and the
transform the reader applied, so the output layer can write the wrinkle data back onto the
prim's own topology (:mod:`wrinklepipe.usd.layer`). A mesh without texture coordinates
gets front-projected UVs (as a glTF primitive does): they split no vertex, and the layer adds
them as ``primvars:st``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.asset import Mesh, MeshPart
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.merge import merge_meshes
from wrinklepipe.gltf.wrinkled import front_projection_uvs
from wrinklepipe.names import did_you_mean, noun
from wrinklepipe.usd.composition import UsdProblem
from wrinklepipe.usd.meshes import open_stage_checked, read_usd_meshes, uv_primvar


@dataclass
class UsdSource:
    """The wrinkled part of a USD source.

    ``materials``: the source Material prims the wrinkle data goes on (none: the layer defines
    one and binds the meshes to it); ``cloned``: those also bound to meshes that are not
    wrinkled, so the layer wrinkles a copy of each; ``added_uvs``: prims given front-projected
    UVs; ``uv_names``: each prim's UV primvar (the wrinkle textures' reader of its material
    reads it; added UVs take the name most of the other meshes use, else ``st``)."""

    path: Path
    mesh: Mesh
    prims: tuple[str, ...]
    materials: tuple[str, ...]
    cloned: tuple[str, ...] = ()
    added_uvs: tuple[str, ...] = ()
    notes: list[str] = field(default_factory=list)
    uv_names: dict[str, str] = field(default_factory=dict)
    problems: tuple[UsdProblem, ...] = ()  # composition errors USD reported opening it


def _bindings(stage: Any, prims: list[str]) -> tuple[dict[str, str | None], dict[str, list[str]]]:
    """Each mesh's bound material (None: unbound), and every Material prim of the stage with the
    meshes bound to it (GeomSubset bindings listed under the material with ``'PATH (faces)'``)."""
    from pxr import Usd, UsdShade  # deferred: usd-core, USD only

    bound: dict[str, str | None] = {}
    materials: dict[str, list[str]] = {
        str(p.GetPath()): []
        for p in stage.Traverse(Usd.TraverseInstanceProxies())
        if p.IsA(UsdShade.Material)
    }
    for path in prims:
        prim = stage.GetPrimAtPath(path)
        api = UsdShade.MaterialBindingAPI(prim)
        mat, _ = api.ComputeBoundMaterial()
        bound[path] = str(mat.GetPath()) if mat else None
        if mat:
            materials.setdefault(str(mat.GetPath()), []).append(path)
        for subset in api.GetMaterialBindSubsets():
            smat, _ = UsdShade.MaterialBindingAPI(subset.GetPrim()).ComputeBoundMaterial()
            if smat:
                materials.setdefault(str(smat.GetPath()), []).append(f"{path} (faces)")
    return bound, materials


def _listing(materials: dict[str, list[str]]) -> str:
    return "; ".join(
        f"{Path(m).name!r} ({m}: {', '.join(meshes) or 'no mesh'})"
        for m, meshes in sorted(materials.items())
    )


def _find_material(
    name: str, materials: dict[str, list[str]], file: str, key: str, stage_name: str
) -> str:
    hits = [m for m in materials if m == name or m.rsplit("/", 1)[-1] == name]
    if len(hits) == 1:
        return hits[0]
    if not hits:
        what = f"no material {name!r} in {stage_name}" + did_you_mean(
            name, [m.rsplit("/", 1)[-1] for m in materials]
        )
    else:
        what = f"material name {name!r} is ambiguous in {stage_name} (name it by path)"
    raise input_error(file, f"{what}; its materials: {_listing(materials) or 'none'}", key)


def _named(
    prims: list[str], names: tuple[str, ...] | list[str], among: list[str], where: str, file: str
) -> list[str]:
    """The prims of ``among`` (in ``prims`` order) named by ``names`` (prim name or path)."""
    keep: set[str] = set()
    for k, name in enumerate(names):
        hits = {p for p in among if p == name or p.rsplit("/", 1)[-1] == name}
        if not hits:
            raise input_error(
                file,
                f"no Mesh prim {name!r} {where} (meshes {where}: {', '.join(among) or 'none'})",
                f"meshes[{k}]",
            )
        keep |= hits
    return [p for p in prims if p in keep]


def select_meshes(
    stage: Any,
    prims: list[str],
    material: str | list[str] | None,
    meshes: tuple[str, ...] | list[str],
    file: str,
    stage_name: str,
) -> tuple[list[str], list[str], list[str]]:
    """The wrinkled Mesh prims (in ``prims`` order), the materials they are bound to (none: no
    material bound) and those of them also bound to meshes not wrinkled, which the layer
    clones (see the module doc)."""
    bound, materials = _bindings(stage, prims)
    used = {m: ms for m, ms in materials.items() if ms}
    if material is None and meshes:  # the named meshes, bound to whatever they are bound to
        picked = _named(prims, meshes, prims, "in the stage", file)
        mats = {bound[p] for p in picked}
        if None in mats and len(mats) > 1:
            listing = ", ".join(f"{p}: {bound[p] or 'none'}" for p in picked)
            raise input_error(
                file,
                "some of the named meshes are bound to a material and some to none "
                f"({listing}): bind them, or wrinkle them separately",
                "meshes",
            )
        chosen = sorted(m for m in mats if m is not None)
        return picked, chosen, [m for m in chosen if any(p not in picked for p in used[m])]
    if material is None:
        if not used:
            chosen: list[str] = []
        elif len(used) == 1:
            chosen = list(used)
        else:
            raise input_error(
                file,
                f"{stage_name} has {len(used)} materials bound to meshes: name the wrinkled one "
                f'(material = "NAME" or a list); its materials: {_listing(materials)}',
                "material",
            )
    else:
        names = [material] if isinstance(material, str) else list(material)
        chosen = []
        for i, n in enumerate(names):
            key = "material" if isinstance(material, str) else f"material[{i}]"
            m = _find_material(str(n), materials, file, key, stage_name)
            if not used.get(m):
                raise input_error(file, f"material {m} is bound to no mesh in {stage_name}", key)
            if not [p for p in used[m] if not p.endswith(" (faces)")]:
                raise input_error(
                    file,
                    f"material {m} is bound only to GeomSubset faces ({', '.join(used[m])}); "
                    "wrinkling part of a mesh is not supported: bind it to whole meshes",
                    key,
                )
            chosen.append(m)
    picked = [p for p in prims if bound[p] in chosen] if chosen else list(prims)
    if meshes:
        picked = _named(prims, meshes, picked, f"bound to {', '.join(chosen)}", file)
    cloned = [m for m in chosen if any(p not in picked for p in used[m])]
    return picked, chosen, cloned


def read_usd_source(manifest: Any) -> UsdSource:
    """The manifest's USD mesh: the selected meshes read and merged (see the module doc)."""
    path = Path(manifest.mesh).resolve()
    file = str(manifest.path)
    parts = read_usd_meshes(path)
    stage, problems = open_stage_checked(path)
    prims, mats, cloned = select_meshes(
        stage, [m.name for m in parts], manifest.material, manifest.meshes, file, path.name
    )
    by_name = {m.name: m for m in parts}
    chosen = [by_name[p] for p in prims]
    notes: list[str] = []
    uv_names = {
        p: str(pv.GetPrimvarName()) for p in prims if (pv := uv_primvar(stage.GetPrimAtPath(p)))
    }
    found = sorted(uv_names.values())
    uv_name = max(found, key=found.count) if found else "st"  # what added UVs are called
    bare = [m.name for m in chosen if m.normals is None]
    if bare:
        notes.append(
            f"no normals on {', '.join(bare)}: the tangents are made against area-weighted "
            "vertex normals (the layer adds no normals; a renderer's own smooth normals agree "
            "up to the weighting)"
        )
    added: list[str] = []
    if any(m.uvs is None for m in chosen):
        uv = np.split(
            front_projection_uvs(np.concatenate([m.positions for m in chosen])),
            np.cumsum([m.vertex_count for m in chosen])[:-1],
        )
        for i, m in enumerate(chosen):
            if m.uvs is None:
                chosen[i] = replace(m, uvs=uv[i])
                added.append(m.name)
                uv_names[m.name] = uv_name
        notes.append(
            f"no texture coordinates on {', '.join(added)}: front-projected UVs (u along +X, v "
            f"down -Y over the wrinkled meshes' bounds), added to the output layer as "
            f"primvars:{uv_name}"
        )
    mesh = merge_parts(chosen)
    what = ", ".join(
        f"{m} (cloned: also bound to meshes not wrinkled)" if m in cloned else m for m in mats
    )
    notes.append(
        "wrinkled "
        f"{noun(len(mats), 'material') + ' ' + what if mats else 'meshes (no material bound)'}: "
        + ", ".join(f"{p.name} ({p.count} vertices)" for p in mesh.parts)
    )
    return UsdSource(
        path,
        mesh,
        tuple(prims),
        tuple(mats),
        tuple(cloned),
        tuple(added),
        notes,
        uv_names,
        tuple(problems),
    )


def merge_parts(meshes: list[Mesh], keep_ids: bool = False) -> Mesh:
    """The meshes as one, each run of vertices a :class:`MeshPart` (prim path, corners,
    transform). ``keep_ids``: keep the parts' vertex IDs (a written layer's, read back); else
    they are dropped on a merge and computed over the whole (IDs shared across the parts)."""
    if len(meshes) == 1:
        merged = replace(meshes[0], notes=list(meshes[0].notes))
    else:
        merged = merge_meshes(meshes)
        merged.name = "+".join(Path(m.name).name for m in meshes)
        if keep_ids and all(m.vertex_ids is not None for m in meshes):
            merged.vertex_ids = np.concatenate([m.vertex_ids for m in meshes])
    starts = np.concatenate([[0], np.cumsum([m.vertex_count for m in meshes])[:-1]])
    merged.parts = tuple(
        MeshPart(m.name, m.name, int(s), m.vertex_count, corners=p.corners, transform=p.transform)
        for m, s in zip(meshes, starts)
        for p in m.parts[:1]
    )
    return merged
