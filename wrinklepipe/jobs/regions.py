"""``regions`` as a job: a mesh with morph targets -> masks, driver rows and a manifest.

:func:`regions_job` reads the character's wrinkled mesh as convert will
(:func:`~wrinklepipe.pipeline.character.read_character`), makes the regions, masks and rows
(:func:`~wrinklepipe.masks.targets.regions_from_targets`), packs the masks four to an RGBA
texture (the layout convert reads; the one asked for is checked now and recorded for convert
to ship) and writes, all or nothing (:func:`~wrinklepipe.atomic.staged_folder`):

  masks_<t>.png            the packed masks (8- or 16-bit, linear)
  channels.json            their channel table (:mod:`wrinklepipe.masks.files`)
  regions.json             what was made: targets, regions, rows, fit, symmetry plane, notes
  manifest_snippet.toml    a manifest convert accepts as is: the mesh, its material, the maps
                           (``maps``: a ``bake-states`` folder), the regions and a
                           ``blendshapes`` driver (the rows; keys: a range-of-motion sweep,
                           each target 0 -> 1 -> 0 in turn over one second)

Paths in the manifest are relative to the output folder; files outside it (the mesh, the maps)
need ``--allow-root`` when converting, and the job says which folders.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.atomic import staged_folder, write_bytes, write_json
from wrinklepipe.errors import input_error
from wrinklepipe.masks.files import write_packed
from wrinklepipe.masks.layouts import LAYOUTS, PackedMasks, pack
from wrinklepipe.masks.targets import STATES, TargetRegions, TargetRegionsOptions
from wrinklepipe.masks.targets import regions_from_targets as make_regions
from wrinklepipe.names import noun, plural
from wrinklepipe.outputs.manifest_snippet import Snippet, SnippetRegion, snippet_text
from wrinklepipe.pipeline.character import CharacterSource, read_character

SNIPPET_FILE = "manifest_snippet.toml"
REPORT_FILE = "regions.json"
#: What a ``bake-states`` folder holds (``maps``).
BASE_MAP = "base_normal.png"
STATE_MAP = "wrinkle_{}.png"


@dataclass(frozen=True)
class RegionsJobOptions:
    """Options of :func:`regions_job` (the command's defaults).

    material / meshes: the wrinkled material(s) and mesh restriction, as the manifest's keys.
    masks: the stage's options (size, supersampling, blur, padding, regions, ...).
    layout: the mask layout convert ships (recorded as ``formats.mask_layout``; checked now).
    bits: bits per channel of the mask PNGs.
    maps: a folder with ``base_normal.png`` (optional for glTF) and ``wrinkle_<state>.png``.
    force: replace a non-empty output folder.
    """

    material: str | None = None
    meshes: tuple[str, ...] = ()
    masks: TargetRegionsOptions = field(default_factory=TargetRegionsOptions)
    layout: str = "rgba"
    bits: int = 8
    maps: str | None = None
    force: bool = False


@dataclass
class RegionsJobResult:
    """What was written, and the stage's result."""

    output: Path
    regions: TargetRegions
    packed: PackedMasks
    snippet: str
    allow_roots: list[str]
    notes: list[str]


def _asset_name(stem: str) -> str:
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", stem).lstrip(".-")[:100]
    return name or "character"


def _rel(path: Path, folder: Path) -> str:
    """``path`` relative to ``folder`` when they share a folder below the root, else absolute."""
    p, f = path.resolve(), folder.resolve()
    if Path(os.path.commonpath([p, f])) == Path(p.anchor):
        return p.as_posix()
    return Path(os.path.relpath(p, f)).as_posix()


def _outside(paths: list[Path], folder: Path) -> list[str]:
    """The folders of ``paths`` that do not lie inside ``folder`` (for ``--allow-root``)."""
    f = folder.resolve()
    out = []
    for p in paths:
        d = p.resolve().parent
        if d != f and f not in d.parents and str(d) not in out:
            out.append(str(d))
    return out


def _maps(maps: str | None, states: list[str], mesh: Path) -> tuple[Path | None, list[Path]]:
    """The base map (None: the glTF material's own) and one map per state, from ``maps``."""
    if maps is None:
        return None, []
    folder = Path(maps)
    if not folder.is_dir():
        raise input_error(folder, "--maps must be a folder (the output of bake-states)", "--maps")
    missing = [STATE_MAP.format(s) for s in states if not (folder / STATE_MAP.format(s)).is_file()]
    if missing:
        raise input_error(
            folder,
            f"no {', '.join(missing)} here: the regions drive the "
            f"{noun(len(states), 'state')} {states}; bake them "
            f"with bake-states --state NAME=SCULPT, or name hand-made maps so",
            "--maps",
        )
    base = folder / BASE_MAP
    if not base.is_file():
        if mesh.suffix.lower() not in (".gltf", ".glb"):
            raise input_error(folder, f"no {BASE_MAP} here (needed for a non-glTF mesh)", "--maps")
        base = None
    return base, [folder / STATE_MAP.format(s) for s in states]


def _range_of_motion(targets: list[str]) -> dict[str, list[tuple[float, float]]]:
    """Each target 0 -> 1 -> 0 in turn, one second each (target i peaks at i + 0.5 s)."""
    return {t: [(i + 0.0, 0.0), (i + 0.5, 1.0), (i + 1.0, 0.0)] for i, t in enumerate(targets)}


def regions_job(
    mesh: str | Path,
    output: str | Path,
    options: RegionsJobOptions | None = None,
    say: Callable[[str], None] | None = None,
) -> RegionsJobResult:
    """Read ``mesh``, make the regions and write the folder ``output`` (see the module doc).
    ``say`` hears one line per stage."""
    o = options or RegionsJobOptions()
    tell = say or (lambda _line: None)
    mesh = Path(mesh)
    out = Path(output)
    if o.layout not in LAYOUTS:
        raise input_error("<arguments>", f"unknown layout {o.layout!r} ({', '.join(LAYOUTS)})")
    if o.masks.size < 4 or o.masks.size > 16384:
        raise input_error("<arguments>", f"--size must be 4..16384, got {o.masks.size}", "--size")
    src = CharacterSource(mesh, o.material, o.meshes)
    m, notes = read_character(src)
    tell(
        f"read {mesh}: {m.vertex_count} vertices, {m.triangle_count} triangles, "
        f"{len([n for n in m.morph_names if '@' not in n])} morph targets"
        + (f" (material {o.material!r})" if o.material else "")
    )
    res = make_regions(m, o.masks, str(mesh))
    tell(
        f"area change of {plural(len(res.targets), 'target')} at full weight, smoothed over "
        f"{int(m.vertex_ids.max()) + 1 if m.vertex_ids is not None else m.vertex_count} "
        f"vertex IDs" + (f"; {len(res.skipped)} change no area" if res.skipped else "")
    )
    names = [r.name for r in res.regions]
    sides = [r.side for r in res.regions]
    kind = "per target and state" if o.masks.regions is None else "clustered"
    tell(
        f"{plural(len(names), 'region')} ({kind}) rendered at {o.masks.size}^2, "
        f"{o.masks.supersample}^2 samples a texel, blur {o.masks.blur:g} px, "
        f"padding {o.masks.padding} px"
    )
    packed = pack(res.masks, names, "rgba")
    if o.layout != "rgba":
        pack(res.masks, names, o.layout, sides=sides)  # convert will ship it: refuse now
    driven = {row[1].partition(":")[2] for row in res.rows}
    states = [s for s in STATES if s in driven]
    base, maps = _maps(o.maps, states, mesh)
    folder = out if out.is_absolute() else Path.cwd() / out
    table = {e["region"]: e for e in packed.table}
    targets = [t for t in res.targets if any(row[0] == t for row in res.rows)]
    snippet = Snippet(
        name=_asset_name(mesh.stem),
        mesh=_rel(mesh, folder),
        material=o.material,
        meshes=o.meshes,
        base=_rel(base, folder) if base is not None else None,
        states=[
            (s, _rel(p, folder) if maps else STATE_MAP.format(s))
            for s, p in zip(states, maps or [Path(STATE_MAP.format(s)) for s in states])
        ],
        regions=[
            SnippetRegion(
                r.name,
                f"masks_{table[r.name]['texture']}.png",
                table[r.name]["channel"],
                r.side,
                r.states,
            )
            for r in res.regions
        ],
        mask_layout=o.layout,
        rows=res.rows,
        keys=_range_of_motion(targets),
        header=_header(mesh, o, maps),
    )
    text = snippet_text(snippet)
    roots = _outside([mesh, *([base] if base else []), *maps], folder)
    report = _report(mesh, o, res, packed, roots)
    with staged_folder(out, force=o.force, inputs=[mesh, *maps, *([base] if base else [])]) as tmp:
        write_packed(tmp, packed, bits=o.bits, inputs=[mesh])
        write_json(tmp / REPORT_FILE, report)
        write_bytes(tmp / SNIPPET_FILE, text.encode("utf-8"))
    tell(
        f"wrote {plural(packed.textures.shape[0], 'mask texture')}, "
        f"{plural(len(res.rows), 'driver row')} and "
        f"{SNIPPET_FILE} -> {out}"
    )
    return RegionsJobResult(out, res, packed, text, roots, notes + res.notes)


def _header(mesh: Path, o: RegionsJobOptions, maps: list[Path]) -> list[str]:
    lines = [
        f"wrinklepipe regions: masks and driver rows from the morph targets of {mesh.name}",
        "(one mask per target and state)"
        if o.masks.regions is None
        else f"({o.masks.regions} clustered regions at most, left/right split)",
        "Driver keys: a range-of-motion sweep, each target 0 -> 1 -> 0 in turn over one",
        'second; replace them with file = "performance.glb" (its morph-weight animation).',
    ]
    if not maps:
        lines += [
            "The states' maps are expected beside this file (wrinkle_<state>.png); or rerun",
            "with --maps DIR (a bake-states folder).",
        ]
    return lines


def _report(
    mesh: Path,
    o: RegionsJobOptions,
    res: TargetRegions,
    packed: PackedMasks,
    roots: list[str],
) -> dict[str, Any]:
    return {
        "mesh": mesh.name,
        "material": o.material,
        "options": dict(vars(o.masks)),
        "layout": o.layout,
        "targets": list(res.targets),
        "skipped_targets": list(res.skipped),
        "regions": [
            {
                "name": r.name,
                "side": r.side,
                "states": list(r.states),
                "coverage": round(float((res.masks[i] > 0).mean()), 6),
            }
            for i, r in enumerate(res.regions)
        ],
        "rows": [list(r) for r in res.rows],
        "fit_residual": {k: round(v, 6) for k, v in res.fit.items()},
        "symmetry_plane": {
            "normal": [round(float(x), 6) for x in res.plane.normal],
            "offset": round(float(res.plane.offset), 6),
            "residual": float(f"{res.plane.residual:.3e}"),
        },
        "channels": packed.table,
        "allow_roots_needed": len(roots) > 0,
        "notes": res.notes,
        "peak_change": {
            t: round(float(np.abs(c).max()), 6) for t, c in zip(res.targets, res.change)
        },
    }
