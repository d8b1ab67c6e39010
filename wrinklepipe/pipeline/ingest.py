"""Ingest: a loaded manifest and the files it names -> a :class:`WrinkleAsset`.

Maps come back as float32 unit normals (+Y), wrinkle states as the whole wrinkled face, masks as
``[R, H, W]`` in [0, 1].

The mesh: a glTF source is read as a whole document (:mod:`wrinklepipe.gltf`): the
manifest's ``material`` (and ``meshes``) select the wrinkled primitives, which get their
tangents and vertex IDs in the document, and the render mesh is those primitives only
(:func:`wrinklepipe.gltf.render_mesh.wrinkled_mesh`); convert then writes the document back
with the wrinkle data added. Without ``base`` the wrinkled material's own ``normalTexture`` is
the base map. A USD source likewise: the manifest's ``material``/``meshes`` select the wrinkled
Mesh prims (:func:`wrinklepipe.usd.source.read_usd_source`), the render mesh is those
meshes, and convert writes a layer over the source. OBJ comes through
:func:`wrinklepipe.readers.meshes.load_mesh`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import masks as wm
from wrinklepipe import model
from wrinklepipe.asset import Mesh, Region, WrinkleAsset
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.rasterise import triangle_ids
from wrinklepipe.gltf.document import Document
from wrinklepipe.gltf.images import texture_normals
from wrinklepipe.gltf.render_mesh import wrinkled_mesh
from wrinklepipe.gltf.wrinkle_maps import WrinkleTarget
from wrinklepipe.gltf.wrinkled import (
    add_wrinkle_attributes,
    material_normal_texture,
)
from wrinklepipe.io.images import read_image
from wrinklepipe.io.scratch import hold
from wrinklepipe.names import noun
from wrinklepipe.normals import alignment as al
from wrinklepipe.normals.convention import BEYOND_DOUBT, CONVENTIONS
from wrinklepipe.normals.held import HeldMap, NormalStack, held_floats
from wrinklepipe.normals.read import NormalMap, ReadOptions, read_normal_map
from wrinklepipe.pipeline.character import open_wrinkled_document
from wrinklepipe.pipeline.ingest_color import MaterialColor, material_color, read_colors
from wrinklepipe.readers.meshes import load_mesh
from wrinklepipe.readers.registry import format_of
from wrinklepipe.usd.source import UsdSource, read_usd_source


def _flipped(nm: NormalMap, convention: str) -> bool:
    """True when the map's curl test says, beyond doubt, the other convention than declared."""
    d = nm.detection
    return (
        convention in CONVENTIONS
        and d is not None
        and d.convention not in ("undetermined", convention)
        and d.confidence >= BEYOND_DOUBT
    )


def check_conventions(
    maps: dict[Path, NormalMap], convention: str, base: Path | None, include_base: bool
) -> None:
    """Refuse, before anything is written, a manifest whose declared green convention is
    wrong beyond doubt (the validator's flip rule, WP-MAP-003): every map's curl test says the
    other convention (the manifest's ``convention`` is wrong), or one map's does while the
    others agree with the declaration and its detail matches theirs only with its green
    channel flipped (a map mirrored vertically also fails the curl test, but does not match
    with green flipped: that is left to the validator, which names the mirror)."""
    flipped = [p for p, nm in maps.items() if _flipped(nm, convention)]
    if not flipped:
        return
    other = "directx" if convention == "opengl" else "opengl"
    up = "+Y up" if convention == "opengl" else "-Y up"
    if len(flipped) == len(maps):
        raise input_error(
            flipped[0],
            f"declared {convention} ({up}) in the manifest, but every normal map's slopes are "
            f"integrable only as {other} (curl test, {len(maps)} maps): green is flipped "
            f'(WP-MAP-003); set convention = "{other}"',
        )
    if base is None or not include_base or base not in maps:
        return
    b = maps[base].normals
    rows, cols = al.lattice(np.ones(b.shape[:2], bool))
    green = al.TRANSFORMS["the base's green channel flipped"]
    for p in flipped:
        pairs = [(maps[p].normals, maps[q].normals) for q in maps if q != p and q not in flipped]
        if not pairs:
            continue
        ok = [
            x.shape == y.shape
            and not _kept(al.kept(y, x, rows, cols))
            and _kept(al.kept(y, x, rows, cols, green))
            for x, y in pairs
        ]
        if all(ok):
            raise input_error(
                p,
                f"declared {convention} ({up}) but its slopes are integrable only as {other} "
                f"(curl test confidence {maps[p].detection.confidence:.2f}) and its detail "  # type: ignore[union-attr]
                f"matches the other maps' only with green flipped: green is flipped "
                f"(WP-MAP-003); flip its green channel",
            )


def _kept(k: float | None) -> bool:
    return k is not None and k >= al.KEPT


def _read_normals(
    path: Path,
    convention: str,
    stats: dict[str, Any] | None = None,
    role: str = "",
    read: dict[Path, NormalMap] | None = None,
) -> tuple[np.ndarray | HeldMap, list[str]]:
    """A normal map file -> unit normals ``[H, W, 3]`` (+Y) and notes (wrinklepipe.normals.read):
    the file's integers with how they decode (:class:`HeldMap`) when it has them, else float32.
    The reader's counts of problem texels go into ``stats[role]``; ``read[path]``: the map as
    read, its normals held as the returned value."""
    hint = "a state's colour map goes in color = FILE" if role.startswith("state") else ""
    o = ReadOptions(convention=convention, refusal_hint=hint)
    nm = read_normal_map(path, o, held=True)  # integers: never made whole as float32
    notes = [f"{path.name}: {nm.source_format}, convention {nm.convention}"]
    notes += [f"{path.name}: {n}" for n in nm.notes if "convention" not in n]
    if stats is not None:
        stats[role] = {
            "file": path.name,
            "stats": nm.stats.to_json(),
            "tolerance": o.unit_tolerance,
        }
    got: np.ndarray | HeldMap
    if nm.integers is not None:  # held as the file's integers (6 bytes a texel, not 12)
        got = HeldMap(hold(nm.integers), nm.layout, nm.convention == "directx")
        nm = replace(nm, normals=NormalStack([got], single=True), integers=None)
    else:  # float32 normals: in a scratch file when they are large (held_floats)
        got = held_floats(nm.normals)
        if isinstance(got, HeldMap):
            nm = replace(nm, normals=NormalStack([got], single=True))
    if read is not None:
        read[path] = nm
    return got, notes


def _held_stack(parts: list[np.ndarray | HeldMap], shape: tuple[int, ...]) -> Any:
    """The states ``[K, H, W, 3]``: a :class:`NormalStack` when every state is a held map
    (integers, or float32 in a scratch file), else float32 (the held ones decoded into their
    place)."""
    if parts and all(isinstance(p, HeldMap) for p in parts):
        return NormalStack(parts)  # type: ignore[arg-type]
    states = np.empty((len(parts), *shape), np.float32)
    for k, p in enumerate(parts):
        states[k] = p.decode() if isinstance(p, HeldMap) else p
        parts[k] = states[k]  # the part's float copy freed as soon as it is in place
    return states


def _as_normals(m: np.ndarray | HeldMap) -> Any:
    """A map as read, seen as unit normals ``[H, W, 3]`` (a held map: a one-map stack)."""
    return NormalStack([m], single=True) if isinstance(m, HeldMap) else m


def _load_mesh(path: Path) -> Mesh:
    """The render mesh (:func:`wrinklepipe.readers.meshes.load_mesh`: glTF, USD, OBJ)."""
    return load_mesh(path)


def read_maps(
    manifest: Any, base: np.ndarray | HeldMap | None = None, stats: dict[str, Any] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """The manifest's maps as read: base ``[H, W, 3]``, wrinkled-face states ``[K, H, W, 3]``
    (unit normals, +Y; wrinkle-only maps get the base added in PD space), masks ``[R, h, w]``,
    and notes on what was read. ``base``: the base map when it does not come from the
    manifest's ``base`` file (a glTF material's own normalTexture). ``stats``: the reader's
    problem-texel counts per map file."""
    notes: list[str] = []
    read: dict[Path, NormalMap] = {}
    base_part: np.ndarray | HeldMap | None = None
    if base is not None:  # the material's normalTexture: held as its integers when it has them
        base_part = base if isinstance(base, HeldMap) else held_floats(base)
    if base is None:
        base_part, n = _read_normals(manifest.base, manifest.convention, stats, "base", read)
        notes += n
    base = _as_normals(base_part)
    if not manifest.states:
        np.stack([])  # no states: the error np.stack of them always raised
    # every state held as its file's integers when it can be (normals/held.py), one float map
    # beside it while it is read
    parts: list[np.ndarray | HeldMap] = []
    for s in manifest.states:
        if s.map is None:  # a colour-only state: its normal is the base (it adds nothing)
            parts.append(base_part)
            continue
        st, n = _read_normals(s.map, manifest.convention, stats, f"state {s.name}", read)
        notes += n
        shape = st.q.shape[:2] if isinstance(st, HeldMap) else st.shape[:2]
        if shape != base.shape[:2]:
            raise input_error(
                s.map,
                f"size {shape[1]}x{shape[0]} differs from the base map "
                f"{base.shape[1]}x{base.shape[0]}"
                + ("" if manifest.base is not None else " (the wrinkled material's normalTexture)"),
            )
        if not manifest.states_include_base:  # wrinkle-only normals: add the base in PD space
            wrinkle = np.asarray(_as_normals(st))
            st = held_floats(
                model.pd_to_normal(
                    model.normal_to_pd(np.asarray(base)) + model.normal_to_pd(wrinkle)
                )
            )
            del wrinkle
        parts.append(st)
        del st
    states = _held_stack(parts, base.shape)
    del parts
    check_conventions(read, manifest.convention, manifest.base, manifest.states_include_base)
    if not manifest.regions:  # one UDIM tile without masks (pipeline.ingest_tiles)
        return base, states, np.zeros((0, 1, 1), np.float32), notes
    channels = [r.channel for r in manifest.regions]
    if any(c is not None for c in channels):
        masks = []
        for r in manifest.regions:
            m, _ = wm.read_mask(r.mask) if r.channel is None else (_mask_channel(r), None)
            masks.append(m)
        mask_arr = np.stack(masks).astype(np.float32)
    else:
        ms = wm.read_masks(
            [r.mask for r in manifest.regions],
            names=[r.name for r in manifest.regions],
            integers=True,  # held in the files' integers for the run (masks/stack.py)
        )
        mask_arr = ms.masks
    return base, states, mask_arr, notes


@dataclass
class Ingested:
    """What ingest read: the asset, notes, and for a glTF source the document (wrinkle
    attributes added to the wrinkled primitives) with where its wrinkle data goes; for a USD
    source its wrinkled meshes (``usd``)."""

    asset: WrinkleAsset
    notes: list[str] = field(default_factory=list)
    document: Document | None = None
    target: WrinkleTarget | None = None
    usd: UsdSource | None = None


@dataclass
class SourceDocument:
    """A glTF source read for conversion (see :func:`read_source_document`)."""

    doc: Document
    target: WrinkleTarget
    mesh: Mesh
    base: np.ndarray | HeldMap | None
    notes: list[str]
    #: the reader's problem-texel counts of the material's normalTexture (when it is the base)
    base_stats: dict[str, Any] | None = None
    #: the material's baseColorTexture, when it is the base colour of colour states
    color: MaterialColor | None = None


def read_source_document(manifest: Any) -> SourceDocument:
    """The manifest's glTF mesh as a document: repaired, the wrinkled primitives selected (shared
    materials cloned for a ``meshes`` restriction), tangents and vertex IDs added to them; the
    render mesh of those primitives; the material's normalTexture as the base when the manifest
    names none."""
    doc, sel, notes = open_wrinkled_document(manifest)
    base = None
    base_texture = None
    base_stats: dict[str, Any] | None = None
    if manifest.base is None:
        info = material_normal_texture(doc, sel.materials, manifest.path, sel.origin)
        base_texture = int(info["index"])
        key = f"/materials/{sel.materials[0]}/normalTexture"
        base_stats = {}
        base, n = texture_normals(doc, base_texture, key, base_stats, held=True)
        notes += n
    for part in add_wrinkle_attributes(doc, sel.refs):
        where = f"{doc.mesh_name(part.ref.mesh)}/{part.ref.primitive}"
        notes += [f"{where}: {n}" for n in part.notes]
    color = None
    if manifest.has_color and manifest.base_color is None:
        color = material_color(doc, sel.materials, manifest)
    mesh = wrinkled_mesh(doc, sel.refs)
    listing = ", ".join(f"{p.name} ({p.count} vertices)" for p in mesh.parts)
    mats = ", ".join(repr(doc.material_name(m)) for m in sel.materials)
    notes.append(f"wrinkled {noun(len(sel.materials), 'material')} {mats}: primitives {listing}")
    target = WrinkleTarget(
        tuple(sel.materials),
        tuple(sel.refs),
        base_texture,
        color.texture if color is not None else None,
    )
    return SourceDocument(doc, target, mesh, base, notes, base_stats, color)


def check_masks_on_mesh(masks: np.ndarray, mesh: Mesh, manifest: Any) -> None:
    """Every region's mask must touch the wrinkled primitives' UV layout (a texel of a UV
    triangle, or the texel under a vertex); one message naming the regions that do not."""
    if mesh.uvs is None or not len(masks):
        return
    r, h, w = masks.shape
    size = max(h, w)
    covered = triangle_ids(mesh.uvs, mesh.indices, size) >= 0  # once: not kept by the memo
    if (h, w) != (size, size):  # the texel of the square grid under each mask texel's centre
        rows = np.minimum((np.arange(h) + 0.5) / h * size, size - 1).astype(np.int64)
        cols = np.minimum((np.arange(w) + 0.5) / w * size, size - 1).astype(np.int64)
        covered = covered[np.ix_(rows, cols)]
    uv = np.asarray(mesh.uvs, np.float64)
    ok = np.isfinite(uv).all(axis=1)
    vy = np.clip(np.floor(uv[ok, 1] * h), 0, h - 1).astype(np.int64)
    vx = np.clip(np.floor(uv[ok, 0] * w), 0, w - 1).astype(np.int64)
    covered[vy, vx] = True
    # one mask at a time (no flags of every mask at full size)
    touched = [bool(np.logical_and(masks[i] > 0, covered).any()) for i in range(r)]
    missing = [reg.name for reg, t in zip(manifest.regions, touched) if not t]
    if missing:
        where = ", ".join(p.name for p in mesh.parts) or mesh.name
        raise input_error(
            manifest.path,
            f"the {noun(len(missing), 'mask')} of {noun(len(missing), 'region')} "
            f"{', '.join(map(repr, missing))} {noun(len(missing), 'falls', 'fall')} on no wrinkled "
            f"primitive: {noun(len(missing), 'it is', 'they are')} zero over the UV layout of "
            f"{where} (a mask painted for another part, or the wrong material)",
            "regions",
        )


def ingest_all(manifest: Any) -> Ingested:
    """Read every file a manifest names (see the module doc)."""
    stats: dict[str, Any] = {}
    if manifest.mesh is None:
        raise input_error(
            manifest.path, "the manifest names no mesh; glTF/USD output needs one", "mesh"
        )
    source = None
    usd = None
    fmt = format_of(manifest.mesh)
    if fmt is not None and fmt.name == "gltf":
        source = read_source_document(manifest)
        if source.base_stats:
            stats["base"] = source.base_stats  # counted as the manifest's own base file is
        mesh = source.mesh
        base, states, mask_arr, notes = read_maps(manifest, source.base, stats)
        notes = source.notes + notes
        check_masks_on_mesh(mask_arr, mesh, manifest)
    elif fmt is not None and fmt.name == "usd":
        usd = read_usd_source(manifest)
        mesh = usd.mesh
        base, states, mask_arr, notes = read_maps(manifest, None, stats)
        notes = usd.notes + notes
        check_masks_on_mesh(mask_arr, mesh, manifest)
    else:
        base, states, mask_arr, notes = read_maps(manifest, None, stats)
        mesh = _load_mesh(manifest.mesh)
    regions, warnings = _regions(manifest)
    b = stats.get("base", {}).get("stats", {})
    if b.get("non_unit") or b.get("z_negative"):
        warnings.append(
            f"{stats['base']['file']}: {b['non_unit']} of {b['texels']} texels not unit length, "
            f"{b['z_negative']} with z < 0 (renormalised to be blended and stored)"
        )
    asset = _asset(manifest, base, states, mask_arr, mesh, regions)
    asset.color, color_notes = read_colors(manifest, source.color if source is not None else None)
    notes += color_notes
    asset.color_only = tuple(k for k, s in enumerate(manifest.states) if s.map is None)
    asset.provenance["maps"] = stats
    asset.provenance["warnings"] = warnings
    if source is not None and source.target.base_texture is not None:
        asset.provenance["base_source"] = "material"
    if usd is not None and usd.problems:  # the validator reports them (WP-USD-xxx)
        asset.provenance["usd_composition"] = [p.to_json() for p in usd.problems]
    if source is None:
        return Ingested(asset, notes, usd=usd)
    return Ingested(asset, notes, source.doc, source.target)


def ingest(manifest: Any) -> tuple[WrinkleAsset, list[str]]:
    """Read every file a manifest names into a :class:`WrinkleAsset` (float maps, +Y)."""
    got = ingest_all(manifest)
    return got.asset, got.notes


def _asset(
    manifest: Any,
    base: np.ndarray,
    states: np.ndarray,
    mask_arr: np.ndarray,
    mesh: Mesh,
    regions: tuple[Region, ...],
) -> WrinkleAsset:
    return WrinkleAsset(
        name=manifest.name,
        base=base,
        states=states,
        state_names=tuple(s.name for s in manifest.states),
        masks=mask_arr,
        regions=regions,
        expressions={e: dict(row) for e, row in manifest.expressions.items()},
        encoding=manifest.encoding,
        policy=manifest.policy,
        pd_scale=1.0 if manifest.pd_scale == "auto" else float(manifest.pd_scale),
        mesh=mesh,
        drivers=[dict(d) for d in manifest.drivers],
        budget=manifest.budget,
        resolution=manifest.resolution.sizes(),
        provenance={
            "manifest": manifest.path.name,
            "auto_resolution": manifest.resolution.automatic(),
        },
    )


def _regions(manifest: Any) -> tuple[tuple[Region, ...], list[str]]:
    """The manifest's regions; a region without ``side`` whose name ends in _L / _R (or _left,
    .r ...) takes the side of its name, with a warning that says so."""
    raw = manifest.raw.get("regions", []) if isinstance(manifest.raw, dict) else []
    out, warnings = [], []
    for i, r in enumerate(manifest.regions):
        side = r.side
        given = i < len(raw) and isinstance(raw[i], dict) and "side" in raw[i]
        named = wm.infer_side(r.name)
        if not given and named != "center":
            side = named
            warnings.append(
                f"regions[{i}] {r.name!r}: no side given; the name says {named}, so it is "
                f'{named} (set side = "{named}" to say so, or "center")'
            )
        out.append(Region(r.name, side, tuple(r.states)))
    return tuple(out), warnings


def _mask_channel(region: Any) -> np.ndarray:
    values, _ = read_image(region.mask)
    return values[..., "rgba".index(region.channel)].astype(np.float32)
