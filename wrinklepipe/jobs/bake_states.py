"""``bake-states`` as a job: sculpts of the neutral face and of each wrinkled pose -> maps.

:func:`bake_states_job` reads the character's mesh as convert will
(:func:`~wrinklepipe.pipeline.character.read_character`: the wrinkled material's primitives,
their UVs and the tangents convert ships), reads each high-resolution mesh (any mesh format;
no UVs needed), bakes them all in one sampling and one frame
(:func:`~wrinklepipe.geometry.bake.bake_normal_maps`) and writes, all or nothing
(:func:`~wrinklepipe.atomic.staged_folder`):

  base_normal.png        the neutral sculpt, baked: the base (16-bit, OpenGL +Y, linear)
  wrinkle_<NAME>.png     each state's sculpt, baked (16-bit)
  mask_<NAME>.png        with ``masks``: a mask proposed where the state differs from the base
  bake.json              sizes, ray distance, misses per mesh, notes

This folder is what ``regions --maps`` and a manifest's ``base`` / ``states`` read.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.atomic import staged_folder, write_json
from wrinklepipe.errors import InputError, Problem, input_error
from wrinklepipe.geometry.bake import BakeOptions, BakeResult, HighMesh, bake_normal_maps
from wrinklepipe.io.images import write_image
from wrinklepipe.masks.from_states import ProposalOptions, propose_masks
from wrinklepipe.names import plural
from wrinklepipe.pipeline.character import CharacterSource, read_character
from wrinklepipe.readers.meshes import LoadOptions, load_mesh

BASE_FILE = "base_normal.png"
STATE_FILE = "wrinkle_{}.png"
MASK_FILE = "mask_{}.png"
REPORT_FILE = "bake.json"
#: A state name: what the manifest allows (letters, digits, ``_``).
STATE_NAME = re.compile(r"^[A-Za-z0-9_]+$")
#: More samples than this fraction missing every surface of a sculpt is an error.
MAX_MISSED = 0.5


@dataclass(frozen=True)
class BakeStatesOptions:
    """Options of :func:`bake_states_job` (the command's defaults).

    material / meshes: the wrinkled material(s) of the low mesh, as a manifest names them.
    bake: the baker's options (size, supersampling, ray distance, padding).
    masks: also propose a mask per state (``mask_<NAME>.png``).
    force: replace a non-empty output folder.
    """

    material: str | None = None
    meshes: tuple[str, ...] = ()
    bake: BakeOptions = field(default_factory=BakeOptions)
    masks: bool = False
    proposal: ProposalOptions = field(default_factory=ProposalOptions)
    force: bool = False


@dataclass
class BakeStatesResult:
    output: Path
    bake: BakeResult
    states: list[str]
    notes: list[str]


def _check_states(states: Sequence[tuple[str, str | Path]]) -> None:
    problems = []
    seen: set[str] = set()
    for name, _ in states:
        if not STATE_NAME.match(name):
            problems.append(
                Problem("<arguments>", f"state name {name!r}: use letters, digits and _", "--state")
            )
        elif name in seen:
            problems.append(Problem("<arguments>", f"state {name!r} given twice", "--state"))
        seen.add(name)
    if not states:
        problems.append(Problem("<arguments>", "give at least one --state NAME=SCULPT", "--state"))
    if problems:
        raise InputError(problems)


def _read_high(path: Path) -> HighMesh:
    if not path.is_file():
        raise input_error(path, "file not found" if not path.exists() else "is not a file")
    m = load_mesh(path, LoadOptions(generate_uvs=False))
    return HighMesh(m.positions, m.indices, m.normals, path.name)


def bake_states_job(
    low: str | Path,
    neutral: str | Path,
    states: Sequence[tuple[str, str | Path]],
    output: str | Path,
    options: BakeStatesOptions | None = None,
    say: Callable[[str], None] | None = None,
) -> BakeStatesResult:
    """Bake ``neutral`` and every ``(name, sculpt)`` of ``states`` onto ``low`` into the folder
    ``output`` (see the module doc). ``say`` hears one line per stage."""
    o = options or BakeStatesOptions()
    tell = say or (lambda _line: None)
    _check_states(states)
    low, neutral, out = Path(low), Path(neutral), Path(output)
    paths = [neutral, *(Path(p) for _, p in states)]
    mesh, notes = read_character(CharacterSource(low, o.material, o.meshes))
    tell(
        f"read {low}: {mesh.vertex_count} vertices, {mesh.triangle_count} triangles"
        + (f" (material {o.material!r})" if o.material else "")
    )
    cache: dict[Path, HighMesh] = {}
    highs = []
    for p in paths:
        key = p.resolve()
        if key not in cache:
            cache[key] = _read_high(p)
            h = cache[key]
            tell(f"read {p}: {len(h.positions)} vertices, {len(h.indices)} triangles")
        highs.append(cache[key])
    res = bake_normal_maps(mesh, highs, o.bake)
    b = o.bake
    how = "given" if b.max_distance else "measured"
    tell(
        f"baked {plural(len(highs), 'map')} at {b.size}^2, {b.supersample}^2 samples a texel "
        f"({res.samples} samples), rays {res.max_distance:.4g} either side ({how}), "
        f"padding {b.padding_px} px"
    )
    for p, miss, tex in zip(paths, res.missed_samples, res.missed_texels):
        share = miss / max(res.samples, 1)
        if share > MAX_MISSED:
            raise input_error(
                p,
                f"{100 * share:.0f}% of the rays from {low.name} found no surface within "
                f"{res.max_distance:.4g}: the sculpt does not lie on the mesh (another scale, "
                "position or part?) or needs a larger --max-distance",
            )
        if miss:
            res.notes.append(
                f"{p.name}: {miss} of {res.samples} rays found no surface ({tex} texels left flat)"
            )
    names = [n for n, _ in states]
    masks = None
    if o.masks:
        masks = propose_masks(res.maps[0], np.stack(res.maps[1:]), res.covered, o.proposal)
        tell(f"proposed {plural(len(names), 'mask')} from the states' differences to the base")
    report = _report(low, paths, names, o, res)
    with staged_folder(out, force=o.force, inputs=[low, *paths]) as tmp:
        write_image(tmp / BASE_FILE, res.maps[0] * 0.5 + 0.5, 16)
        for name, m in zip(names, res.maps[1:]):
            write_image(tmp / STATE_FILE.format(name), m * 0.5 + 0.5, 16)
        if masks is not None:
            for name, m in zip(names, masks):
                write_image(tmp / MASK_FILE.format(name), m, 8)
        write_json(tmp / REPORT_FILE, report)
    tell(f"wrote {BASE_FILE} and {len(names)} wrinkle maps (16-bit) -> {out}")
    return BakeStatesResult(out, res, names, notes + res.notes)


def _report(
    low: Path, paths: list[Path], names: list[str], o: BakeStatesOptions, res: BakeResult
) -> dict[str, Any]:
    return {
        "low": low.name,
        "material": o.material,
        "size": o.bake.size,
        "supersample": o.bake.supersample,
        "padding": o.bake.padding_px,
        "max_distance": float(f"{res.max_distance:.6g}"),
        "max_distance_measured": o.bake.max_distance is None,
        "samples": res.samples,
        "maps": [
            {
                "file": BASE_FILE if i == 0 else STATE_FILE.format(names[i - 1]),
                "sculpt": p.name,
                "missed_samples": res.missed_samples[i],
                "flat_texels": res.missed_texels[i],
            }
            for i, p in enumerate(paths)
        ],
        "masks": [MASK_FILE.format(n) for n in names] if o.masks else [],
        "notes": res.notes,
    }
