"""The source manifest: the TOML file an artist writes for one character.

:func:`load_manifest` parses it, validates it against ``schemas/manifest.schema.json`` and then
checks what a schema cannot (files exist, names are unique and referenced names exist, weights
lie in the policy's range, masks share one size), and reports *every* problem at once, each with
the file and the key, as one :class:`wrinklepipe.errors.InputError`.
"""

from __future__ import annotations

import difflib
import json
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import jsonschema

from wrinklepipe.errors import InputError, ProblemList
from wrinklepipe.errors import InputError as _IE
from wrinklepipe.io.confine import confine
from wrinklepipe.io.images import read_header
from wrinklepipe.io.json_safe import loads_toml
from wrinklepipe.model import POLICY_WEIGHT_RANGE
from wrinklepipe.options import BudgetOptions, FormatOptions, ResolutionOptions
from wrinklepipe.paths import SCHEMAS_DIR
from wrinklepipe.presets import jimenez
from wrinklepipe.readers.registry import MESH_SUFFIXES
from wrinklepipe.sources import manifest_tiles as mt
from wrinklepipe.suffixes import is_gltf, is_usd

_CHANNELS = "rgba"


@dataclass(frozen=True)
class StateSpec:
    """A wrinkle state: its normal map and/or its colour map (at least one of the two)."""

    name: str
    map: Path | None
    color: Path | None = None


@dataclass(frozen=True)
class RegionSpec:
    name: str
    mask: Path | None  # None only in one tile of a tiled manifest: no mask there (zero)
    channel: str | None = None
    side: str = "center"
    states: tuple[str, ...] = ()


@dataclass
class Manifest:
    """A loaded, checked manifest. Paths are absolute."""

    path: Path
    name: str
    base: Path | None  # None: the wrinkled glTF material's own normalTexture
    states: list[StateSpec]
    regions: list[RegionSpec]
    mesh: Path | None = None
    material: str | list[str] | None = None  # the wrinkled glTF/USD material(s); None: the only one
    meshes: tuple[str, ...] = ()  # restrict the wrinkled primitives to these meshes / nodes / prims
    convention: str = "auto"
    encoding: str = "pd"
    policy: str = "clamp01"
    pd_scale: float | str = "auto"
    states_include_base: bool = True
    expressions: dict[str, dict[str, float]] = field(default_factory=dict)
    drivers: list[dict[str, Any]] = field(default_factory=list)
    resolution: ResolutionOptions = field(default_factory=ResolutionOptions)
    formats: FormatOptions = field(default_factory=FormatOptions)
    budget: BudgetOptions = field(default_factory=BudgetOptions)
    raw: dict[str, Any] = field(default_factory=dict)
    #: the base colour map (None: the wrinkled glTF material's own baseColorTexture)
    base_color: Path | None = None
    #: UDIM tiles (:mod:`wrinklepipe.sources.manifest_tiles`): each tiled map field's files,
    #: ``{"base": {1001: path, ...}, "states[0].map": {...}, "regions[2].mask": {...}}``;
    #: a tiled field's own path above is its pattern (a label: :meth:`tile` reads the files)
    tile_paths: dict[str, dict[int, Path]] = field(default_factory=dict)

    @property
    def tiles(self) -> tuple[int, ...]:
        """The UDIM tiles (the base's), ascending; empty when the maps are not tiled."""
        return tuple(sorted(self.tile_paths.get("base", {})))

    def tile(self, tile: int) -> Manifest:
        """This manifest as one of its tiles: a manifest without tiles whose maps are that
        tile's files (:func:`wrinklepipe.sources.manifest_tiles.tile_manifest`)."""
        return mt.tile_manifest(self, tile)

    @property
    def has_color(self) -> bool:
        """Whether some state carries a colour map."""
        return any(s.color is not None for s in self.states)

    @property
    def root(self) -> Path:
        return self.path.parent

    @property
    def input_files(self) -> list[Path]:
        """Every file the manifest reads (the manifest itself included)."""
        if self.tile_paths:
            files = [self.path, *(p for got in self.tile_paths.values() for p in got.values())]
        else:
            files = [
                self.path,
                *([self.base] if self.base is not None else []),
                *([self.base_color] if self.base_color is not None else []),
                *(s.map for s in self.states if s.map is not None),
                *(s.color for s in self.states if s.color is not None),
                *(r.mask for r in self.regions if r.mask is not None),
            ]
        if self.mesh is not None:
            files.append(self.mesh)
        for d in self.drivers:
            if "file" in d:
                files.append(self.root / d["file"])
        return sorted(set(files))


@cache
def manifest_schema() -> dict[str, Any]:
    """The manifest's JSON Schema (``schemas/manifest.schema.json``)."""
    return json.loads((SCHEMAS_DIR / "manifest.schema.json").read_text(encoding="utf-8"))


def _key(path: Any) -> str:
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


# ------------------------------------------------------------------------------------------------
# schema errors in words: what is allowed, never the schema itself

_PATTERNS = {
    "^[A-Za-z0-9_]+$": "letters, digits and '_'",
    "^[A-Za-z0-9_][A-Za-z0-9_.-]{0,99}$": (
        "letters, digits, '_', '.' and '-' (a safe file stem: not starting with '.' or '-', "
        "at most 100 characters)"
    ),
}
_TYPES = {
    "string": "a string",
    "number": "a number",
    "integer": "an integer",
    "boolean": "true or false",
    "array": "an array",
    "object": "a table",
}


def _type_of(value: Any) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "a table"
    return type(value).__name__


def _bounds(schema: dict[str, Any]) -> str:
    parts = []
    if "exclusiveMinimum" in schema:
        parts.append(f"> {schema['exclusiveMinimum']}")
    if "minimum" in schema:
        parts.append(f">= {schema['minimum']}")
    if "exclusiveMaximum" in schema:
        parts.append(f"< {schema['exclusiveMaximum']}")
    if "maximum" in schema:
        parts.append(f"<= {schema['maximum']}")
    return " and ".join(parts)


def allowed(schema: dict[str, Any]) -> str:
    """What a (sub)schema accepts, in words: "one of 'a', 'b'", "a number > 0 and <= 64"."""
    if "const" in schema:
        return repr(schema["const"])
    if "enum" in schema:
        return "one of " + ", ".join(repr(v) for v in schema["enum"])
    if "oneOf" in schema or "anyOf" in schema:
        return " or ".join(allowed(s) for s in schema.get("oneOf", schema.get("anyOf", [])))
    t = schema.get("type")
    words = _TYPES.get(t, "a value") if isinstance(t, str) else "a value"
    if t in ("number", "integer") and _bounds(schema):
        words += " " + _bounds(schema)
    if t == "string" and "pattern" in schema:
        words += " of " + _PATTERNS.get(schema["pattern"], f"the form {schema['pattern']}")
    if t == "array" and isinstance(schema.get("items"), dict):
        words = f"an array of {_plural(allowed(schema['items']))}"
    return words


def _plural(words: str) -> str:
    for a in ("an ", "a "):
        if words.startswith(a):
            head, _, rest = words[len(a) :].partition(" ")
            return f"{head}s" + (f" {rest}" if rest else "")
    return words


def _shown(value: Any) -> str:
    """A value as the user wrote it, cut short when it is long."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _schema_message(error: Any) -> str:
    """One schema error as "what is wrong; what is allowed"."""
    v, inst, sch = error.validator, error.instance, error.schema
    if v in ("enum", "const", "oneOf", "anyOf", "type", "pattern"):
        return f"{_shown(inst)} is not allowed; expected {allowed(sch)}"
    if v in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        return f"{_shown(inst)} is out of range; expected {allowed(sch)}"
    if v == "minItems":
        return f"needs at least {sch['minItems']} entries, has {len(inst)}"
    if v == "maxItems":
        return f"allows at most {sch['maxItems']} entries, has {len(inst)}"
    if v == "uniqueItems":
        return "entries must be unique"
    return error.message


def _schema_problems(data: dict[str, Any], file: str, problems: ProblemList) -> bool:
    """Every schema error, each saying what is allowed (never quoting the schema). True when
    the only errors are unknown keys (the data is still well typed for the semantic checks)."""
    typed = True
    validator = jsonschema.Draft202012Validator(manifest_schema())
    for error in sorted(
        validator.iter_errors(data), key=lambda e: (list(map(str, e.path)), e.message)
    ):
        key = _key(error.absolute_path)
        if error.validator == "additionalProperties":
            allowed_keys = sorted(error.schema.get("properties", {}))
            for name in sorted(set(error.instance) - set(allowed_keys)):
                close = difflib.get_close_matches(name, allowed_keys, n=1)
                hint = f"did you mean {close[0]!r}? " if close else ""
                problems.add(
                    file,
                    f"unknown key ({hint}allowed: {', '.join(allowed_keys)})",
                    f"{key}.{name}" if key else name,
                )
            continue
        if error.validator == "anyOf" and all(
            set(alt) == {"required"} for alt in error.schema["anyOf"]
        ):
            keys = " or ".join(k for alt in error.schema["anyOf"] for k in alt["required"])
            problems.add(file, f"missing required key ({keys}, or both)", key)
            typed = False
            continue
        if error.validator == "required":
            missing = error.message.split("'")[1] if "'" in error.message else error.message
            problems.add(file, "missing required key", f"{key}.{missing}" if key else missing)
            typed = False
            continue
        problems.add(file, _schema_message(error), key)
        typed = False
    return typed


def load_manifest(path: str | Path, check_files: bool = True) -> Manifest:
    """Load and check a manifest; raise one :class:`InputError` listing every problem."""
    path = Path(path)
    file = str(path)
    problems = ProblemList()
    if not path.exists():
        raise InputError(file=path, problems="manifest not found")
    if path.is_dir():
        inside = path / "manifest.toml"
        hint = f" (did you mean {inside}?)" if inside.is_file() else ""
        raise InputError(file=path, problems=f"is a folder, expected the manifest file{hint}")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(file=path, problems="manifest is not UTF-8 text") from None
    except OSError as exc:
        raise InputError(file=path, problems=f"cannot read: {exc.strerror or exc}") from None
    data = loads_toml(text, path)

    root = path.resolve().parent
    typed = _schema_problems(data, file, problems)
    _path_problems(data, root, file, problems, check_files)  # reported with schema errors
    tile_paths = mt.expand(data, root, file, problems, check_files)
    if not typed:
        problems.raise_if_any()  # the semantic checks below rely on well-typed data

    def map_path(key: str, value: Any) -> Path:
        return mt.label(root, key, value) if mt.tiled_value(value) else root / value

    expressions = data.get("expressions", {})
    if expressions == "jimenez":
        expressions = jimenez.expression_table()
    m = Manifest(
        path=path.resolve(),
        name=data["name"],
        base=map_path("base", data["base"]) if "base" in data else None,
        states=[
            StateSpec(
                s["name"],
                map_path(f"states[{i}].map", s["map"]) if "map" in s else None,
                map_path(f"states[{i}].color", s["color"]) if "color" in s else None,
            )
            for i, s in enumerate(data["states"])
        ],
        regions=[
            RegionSpec(
                r["name"],
                map_path(f"regions[{i}].mask", r["mask"]),
                r.get("channel"),
                r.get("side", "center"),
                tuple(r.get("states", ())),
            )
            for i, r in enumerate(data["regions"])
        ],
        mesh=(root / data["mesh"]) if "mesh" in data else None,
        material=data.get("material"),
        meshes=tuple(data.get("meshes", ())),
        convention=data.get("convention", "auto"),
        encoding=data.get("encoding", "pd"),
        policy=data.get("policy", "clamp01"),
        pd_scale=data.get("pd_scale", "auto"),
        states_include_base=data.get("states_include_base", True),
        expressions={e: {r: float(w) for r, w in row.items()} for e, row in expressions.items()},
        drivers=list(data.get("drivers", [])),
        resolution=ResolutionOptions.from_json(data.get("resolution")),
        formats=FormatOptions.from_json(data.get("formats")),
        budget=BudgetOptions.from_json(data.get("budget")),
        raw=data,
        base_color=map_path("base_color", data["base_color"]) if "base_color" in data else None,
        tile_paths=tile_paths,
    )
    _semantic_problems(m, file, problems, check_files)
    mt.tile_problems(m, file, problems, check_files)
    problems.raise_if_any()
    return m


def _path_fields(data: dict[str, Any]) -> list[tuple[str, str]]:
    """(key, path) of every file the manifest names, wherever the value is a string (so this
    works on a manifest that also has schema errors)."""
    out = [
        (k, data[k])
        for k in ("mesh", "base", "base_color")
        if isinstance(data.get(k), str) and not mt.tiled_value(data[k])
    ]
    fields = (
        ("states", "map"),
        ("states", "color"),
        ("regions", "mask"),
        ("drivers", "file"),
    )
    for table, field_name in fields:
        rows = data.get(table)
        for i, row in enumerate(rows if isinstance(rows, list) else []):
            value = row.get(field_name) if isinstance(row, dict) else None
            if isinstance(value, str) and not mt.tiled_value(value):
                out.append((f"{table}[{i}].{field_name}", value))
    return out


def _path_problems(
    data: dict[str, Any], root: Path, file: str, problems: ProblemList, check_files: bool
) -> None:
    """Each named file lies inside the manifest's folder (or an ``--allow-root``) and exists."""
    for key, ref in _path_fields(data):
        if not ref.strip():
            problems.add(file, "empty path", key)
            continue
        try:
            p = confine(root, ref, file, key)
        except InputError as exc:
            problems.problems.extend(exc.problems)
            continue
        if not check_files:
            continue
        if p.is_dir():
            problems.add(file, f"is a folder, expected a file: {p}", key)
        elif not p.is_file():
            problems.add(file, f"file not found: {p}", key)


def _duplicates(names: list[str]) -> list[str]:
    seen: set[str] = set()
    dup = []
    for n in names:
        if n in seen and n not in dup:
            dup.append(n)
        seen.add(n)
    return dup


def _semantic_problems(m: Manifest, file: str, problems: ProblemList, check_files: bool) -> None:
    state_names = [s.name for s in m.states]
    region_names = [r.name for r in m.regions]
    for name in _duplicates(state_names):
        problems.add(file, f"duplicate state name {name!r}", f"states[{state_names.index(name)}]")
    for name in _duplicates(region_names):
        i = len(region_names) - 1 - region_names[::-1].index(name)
        problems.add(file, f"duplicate region name {name!r}", f"regions[{i}].name")
    for i, r in enumerate(m.regions):
        for s in r.states:
            if s not in state_names:
                problems.add(
                    file, f"unknown state {s!r} (states: {state_names})", f"regions[{i}].states"
                )
    if m.policy == "signed" and len(m.states) != 2:
        problems.add(
            file,
            f"policy 'signed' needs exactly two states (stretch, compress), got {len(m.states)}",
            "policy",
        )
    lo, hi = POLICY_WEIGHT_RANGE[m.policy].low, POLICY_WEIGHT_RANGE[m.policy].high
    for expr, row in m.expressions.items():
        for region, w in row.items():
            key = f"expressions.{expr}.{region}"
            if region not in region_names:
                problems.add(file, f"unknown region {region!r}", key)
            if not lo <= w <= hi:
                problems.add(
                    file, f"weight {w} out of range [{lo}, {hi}] for policy {m.policy!r}", key
                )
    if m.mesh is not None and m.mesh.suffix.lower() not in MESH_SUFFIXES:
        problems.add(
            file, f"unsupported mesh format {m.mesh.suffix!r} ({', '.join(MESH_SUFFIXES)})", "mesh"
        )
    _document_problems(m, file, problems)
    _driver_problems(m, file, problems)
    if check_files:
        _file_problems(m, file, problems)


def _document_problems(m: Manifest, file: str, problems: ProblemList) -> None:
    """``material``, ``meshes`` and an omitted ``base`` select parts of a glTF document."""
    gltf = m.mesh is not None and is_gltf(m.mesh)
    what = f"a {m.mesh.suffix} mesh" if m.mesh is not None else "no mesh"
    if m.base is None and not gltf:
        problems.add(
            file,
            f"missing required key (the base normal map may be omitted only with a .gltf/.glb "
            f"mesh, whose wrinkled material's normalTexture is then the base; here: {what})",
            "base",
        )
    if m.has_color and m.base_color is None and not gltf:
        problems.add(
            file,
            f"missing required key (the base colour map may be omitted only with a .gltf/.glb "
            f"mesh, whose wrinkled material's baseColorTexture is then the base; here: {what})",
            "base_color",
        )
    if m.base_color is not None and not m.has_color:
        problems.add(
            file,
            "a base colour map but no state has a colour map (add color = FILE to the states "
            "whose colour changes)",
            "base_color",
        )
    for i, st in enumerate(m.states):
        if st.map is not None and st.map == st.color:
            problems.add(
                file, "the same file is the state's normal map and its colour map", f"states[{i}]"
            )
    usd = m.mesh is not None and is_usd(m.mesh)
    for key, value in (("material", m.material), ("meshes", m.meshes)):
        if value and not (gltf or usd):
            problems.add(file, f"selects parts of a .gltf/.glb or USD mesh; here: {what}", key)


def _driver_problems(m: Manifest, file: str, problems: ProblemList) -> None:
    """What a driver names that the manifest must define, checked at load (not after the
    expensive stages): expressions of an ``expressions`` driver, its preset."""
    for i, d in enumerate(m.drivers):
        if d.get("kind") != "expressions":
            continue
        preset = d.get("preset")
        if preset is not None and preset != "jimenez":
            problems.add(
                file,
                f"unknown expression preset {preset!r}; expected 'jimenez'",
                f"drivers[{i}].preset",
            )
            continue
        table = jimenez.expression_table() if preset == "jimenez" else m.expressions
        if not table:
            problems.add(
                file,
                "expressions driver without an expression table: add [expressions] or "
                "preset = 'jimenez'",
                f"drivers[{i}]",
            )
            continue
        for field_name in ("keys", "morphs"):
            names = d.get(field_name, {})
            for name in sorted(set(names) - set(table)) if isinstance(names, dict) else ():
                close = difflib.get_close_matches(name, list(table), n=1)
                hint = f"did you mean {close[0]!r}? " if close else ""
                problems.add(
                    file,
                    f"unknown expression {name!r} ({hint}expressions: {', '.join(sorted(table))})",
                    f"drivers[{i}].{field_name}.{name}",
                )


def _rel(p: Path, root: Path) -> str:
    return p.relative_to(root).as_posix() if root in p.parents else str(p)


def _file_problems(m: Manifest, file: str, problems: ProblemList) -> None:
    sizes: dict[tuple[int, int], str] = {}  # existence and confinement: _path_problems
    for i, r in enumerate(m.regions):
        key = f"regions[{i}].mask"
        if r.mask is None or not r.mask.is_file():  # tiles: manifest_tiles checks them
            continue
        try:
            info = read_header(r.mask)
        except _IE as exc:
            for p in exc.problems:
                problems.add(file, f"{_rel(r.mask, m.root)}: {p.message}", key)
            continue
        if r.channel is not None and _CHANNELS.index(r.channel) >= info.channels:
            problems.add(
                file, f"channel {r.channel!r} requested but {r.mask.name} has {info.channels}", key
            )
        sizes.setdefault((info.width, info.height), key)
    if len(sizes) > 1:
        listing = ", ".join(f"{w}x{h} ({k})" for (w, h), k in sizes.items())
        problems.add(file, f"masks have different sizes: {listing}", "regions")
    _color_file_problems(m, file, problems)


#: Image formats of colour maps (sRGB integer texels); float images hold linear data.
_COLOR_FORMATS = ("uint8", "uint16")


def _color_file_problems(m: Manifest, file: str, problems: ProblemList) -> None:
    """Colour maps are 8- or 16-bit RGB(A) images of one size (the base colour's)."""
    files = [("base_color", m.base_color)] if m.base_color is not None else []
    files += [(f"states[{i}].color", s.color) for i, s in enumerate(m.states)]
    sizes: dict[tuple[int, int], str] = {}
    for key, path in files:
        if path is None or not path.is_file():
            continue
        try:
            info = read_header(path)
        except _IE as exc:
            for p in exc.problems:
                problems.add(file, f"{_rel(path, m.root)}: {p.message}", key)
            continue
        rel = _rel(path, m.root)
        if info.channels < 3:
            problems.add(
                file, f"{rel}: a colour map needs RGB or RGBA channels, it has {info.channels}", key
            )
            continue
        if info.format not in _COLOR_FORMATS:
            problems.add(
                file,
                f"{rel}: a colour map holds 8- or 16-bit sRGB texels, this one is {info.format} "
                "(linear data): save it as an sRGB PNG",
                key,
            )
            continue
        sizes.setdefault((info.width, info.height), key)
    if len(sizes) > 1:
        listing = ", ".join(f"{w}x{h} ({k})" for (w, h), k in sizes.items())
        problems.add(
            file,
            f"colour maps have different sizes: {listing}; every state's colour map is painted "
            "on the base colour's UV layout, at its size",
            "states",
        )
