"""A manifest's UDIM tiles: map files named per tile, and the manifest seen one tile at a time.

A map of the manifest (``base``, ``base_color``, a state's ``map`` / ``color``, a region's
``mask``) may name tiles (:mod:`wrinklepipe.udim`) in two ways:

- a pattern with ``<UDIM>``: ``base = "maps/face.<UDIM>.png"``: every file beside it whose
  name has a tile number there (``face.1001.png``, ``face.1002.png`` ...);
- a table, one file per tile: ``base = { 1001 = "face_front.png", 1002 = "neck.png" }``.

The base's tiles are the asset's. A state's normal map or a region's mask may leave tiles
out: there the state is the base (no wrinkle on that tile) and the mask zero. Every tiled map
names no tile the base lacks; one map's tiles share one size, and every mask file of every
tile has one size. When the base is tiled, the states and masks are too (one file for every
tile would be ambiguous). Colour maps, tiled or not, are refused with a tiled base, in one
message naming them (colour states do not take tiles yet). A glTF mesh cannot carry tiles
(glTF has no UDIM: UVs outside [0, 1] repeat the texture).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from wrinklepipe import udim
from wrinklepipe.errors import InputError, ProblemList
from wrinklepipe.io.confine import confine
from wrinklepipe.io.images import read_header
from wrinklepipe.names import noun
from wrinklepipe.suffixes import is_gltf

#: The manifest's map fields: (table, key) (table "" for the top level).
MAP_FIELDS: tuple[tuple[str, str], ...] = (
    ("", "base"),
    ("", "base_color"),
    ("states", "map"),
    ("states", "color"),
    ("regions", "mask"),
)


def tiled_value(value: Any) -> bool:
    """Whether a map field's value names tiles (a ``<UDIM>`` pattern or a tile table)."""
    return (isinstance(value, str) and udim.TOKEN in value) or isinstance(value, dict)


def map_values(data: dict[str, Any]) -> list[tuple[str, Any]]:
    """``(key, value)`` of every map field the manifest gives (``states[0].map`` ...)."""
    out = []
    for table, name in MAP_FIELDS:
        if not table:
            if name in data:
                out.append((name, data[name]))
            continue
        rows = data.get(table)
        for i, row in enumerate(rows if isinstance(rows, list) else []):
            if isinstance(row, dict) and name in row:
                out.append((f"{table}[{i}].{name}", row[name]))
    return out


def label(root: Path, key: str, value: Any) -> Path:
    """The path a tiled field stands under where one path is asked for (messages, names):
    the pattern (``face.<UDIM>.png``), or ``<key>.<UDIM>`` for a table."""
    if isinstance(value, str):
        return root / value
    return root / f"{key}.{udim.TOKEN}"


def expand(
    data: dict[str, Any], root: Path, file: str, problems: ProblemList, check_files: bool
) -> dict[str, dict[int, Path]]:
    """Every tiled map field's files, ``{key: {tile: path}}``: each confined to the manifest's
    folder (or an allowed root); a pattern's tiles are the files found beside it (none found:
    a problem)."""
    out: dict[str, dict[int, Path]] = {}
    for key, value in map_values(data):
        if not tiled_value(value):
            continue
        tiles: dict[int, Path] = {}
        if isinstance(value, dict):
            for t, ref in value.items():
                if not isinstance(ref, str) or not str(t).isdigit() or not udim.valid(int(t)):
                    continue  # the schema says what is wrong
                p = _confined(root, ref, file, f"{key}.{t}", problems)
                if p is None:
                    continue
                if check_files and not p.is_file():
                    problems.add(file, f"file not found: {p}", f"{key}.{t}")
                    continue
                tiles[int(t)] = p
        else:
            head, _, tail = value.partition(udim.TOKEN)
            if udim.TOKEN in tail:
                problems.add(file, f"{value!r} names {udim.TOKEN} twice", key)
                continue
            probe = _confined(root, udim.pattern_path(value, udim.FIRST), file, key, problems)
            if probe is None:
                continue
            folder = probe.parent
            name = Path(value).name
            found = (
                sorted(f.name for f in folder.iterdir() if f.is_file()) if folder.is_dir() else []
            )
            tiles = {t: folder / f for t, f in udim.tile_files(name, found).items()}
            if not tiles and check_files:
                problems.add(
                    file,
                    f"no tile matches {value!r}: no file {name.replace(udim.TOKEN, '1001')} "
                    f"(or another tile number 1001..9999 for {udim.TOKEN}) in {folder}",
                    key,
                )
        out[key] = tiles
    return out


def _confined(root: Path, ref: str, file: str, key: str, problems: ProblemList) -> Path | None:
    if not ref.strip():
        problems.add(file, "empty path", key)
        return None
    try:
        return confine(root, ref, file, key)
    except InputError as exc:
        problems.problems.extend(exc.problems)
        return None


def tile_problems(m: Any, file: str, problems: ProblemList, check_files: bool) -> None:
    """What a tiled manifest must hold (module doc), each problem once with its key."""
    paths = m.tile_paths
    if not paths:
        return
    if "base" not in paths:
        for key in paths:
            problems.add(
                file,
                "names UDIM tiles but the base does not: tile the base too "
                f'(base = "...{udim.TOKEN}..." or a table of tiles)',
                key,
            )
        return
    tiles = set(paths["base"])
    if m.mesh is not None and is_gltf(m.mesh):
        problems.add(
            file,
            "UDIM tiles need a USD or OBJ mesh: glTF has no UDIM (its UVs outside [0, 1] repeat "
            "one texture); give the mesh as .usd/.usda/.usdc/.usdz or .obj",
            "mesh",
        )
    colors = ["base_color"] if m.base_color is not None else []
    colors += [f"states[{i}].color" for i, s in enumerate(m.states) if s.color is not None]
    if colors:
        problems.add(
            file,
            f"colour maps do not take UDIM tiles yet ({', '.join(colors)}): a tiled asset is "
            "converted with its normal maps and masks only (leave the colour maps out, or "
            "convert the colours of an untiled asset)",
            colors[0],
        )
    for i, s in enumerate(m.states):
        key = f"states[{i}].map"
        if s.map is not None and key not in paths:
            problems.add(file, _untiled(key), key)
    for i in range(len(m.regions)):
        key = f"regions[{i}].mask"
        if key not in paths:
            problems.add(file, _untiled(key), key)
    for key, got in paths.items():
        extra = sorted(set(got) - tiles)
        if extra:
            problems.add(
                file,
                f"{noun(len(extra), 'tile')} {', '.join(map(str, extra))} "
                f"{noun(len(extra), 'is not a tile', 'are not tiles')} of the base "
                f"({', '.join(map(str, sorted(tiles)))})",
                key,
            )
    if check_files:
        _size_problems(m, file, problems)


def _untiled(key: str) -> str:
    del key
    return (
        f"one file for a tiled base: name its tiles ({udim.TOKEN} in the file name, or a table "
        "of tiles); a tile it leaves out is the base there (a state) or zero (a mask)"
    )


def _size_problems(m: Any, file: str, problems: ProblemList) -> None:
    """One size per map over its tiles, one size for every mask file (of every tile)."""
    masks: dict[tuple[int, int], str] = {}
    for key, got in m.tile_paths.items():
        sizes: dict[tuple[int, int], int] = {}
        for t, p in got.items():
            try:
                info = read_header(p)
            except InputError as exc:
                for prob in exc.problems:
                    problems.add(file, f"{p.name}: {prob.message}", f"{key}.{t}")
                continue
            sizes.setdefault((info.width, info.height), t)
            if key.startswith("regions"):
                masks.setdefault((info.width, info.height), f"{key} tile {t}")
        if len(sizes) > 1:
            listing = ", ".join(f"{w}x{h} (tile {t})" for (w, h), t in sizes.items())
            problems.add(file, f"tiles of one map have different sizes: {listing}", key)
    if len(masks) > 1:
        listing = ", ".join(f"{w}x{h} ({k})" for (w, h), k in masks.items())
        problems.add(file, f"masks have different sizes: {listing}", "regions")


def tile_manifest(m: Any, tile: int) -> Any:
    """The manifest as one tile of it: a plain manifest (no tiles) whose maps are that
    tile's files; a state's normal map the tile lacks is the base's tile (the state adds no
    wrinkle there), a region's mask the tile lacks is None (zero)."""
    paths = m.tile_paths
    if not paths:
        return m
    if tile not in paths.get("base", {}):
        raise ValueError(f"tile {tile} is not a tile of {m.path}")
    base = paths["base"][tile]
    states = [
        replace(s, map=paths[f"states[{i}].map"].get(tile, base)) if s.map is not None else s
        for i, s in enumerate(m.states)
    ]
    regions = [
        replace(r, mask=paths[f"regions[{i}].mask"].get(tile)) for i, r in enumerate(m.regions)
    ]
    return replace(m, base=base, states=states, regions=regions, tile_paths={})


def tile_notes(m: Any) -> list[str]:
    """What the tiles leave out, said once: the states that are the base on a tile, the
    masks that are zero there."""
    paths = m.tile_paths
    if not paths:
        return []
    tiles = sorted(paths["base"])
    notes = [f"UDIM tiles {', '.join(map(str, tiles))} (from the base's files)"]
    for i, s in enumerate(m.states):
        missing = [t for t in tiles if t not in paths.get(f"states[{i}].map", {})]
        if s.map is not None and missing:
            notes.append(
                f"state {s.name!r} has no map on {noun(len(missing), 'tile')} "
                f"{', '.join(map(str, missing))}: it is the "
                "base there (no wrinkle)"
            )
    for i, r in enumerate(m.regions):
        missing = [t for t in tiles if t not in paths.get(f"regions[{i}].mask", {})]
        if missing:
            notes.append(
                f"region {r.name!r} has no mask on {noun(len(missing), 'tile')} "
                f"{', '.join(map(str, missing))}: "
                "zero there"
            )
    return notes
