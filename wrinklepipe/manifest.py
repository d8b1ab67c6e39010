"""The source manifest: the TOML file an artist writes for one character.

:func:`load_manifest` parses it, validates it against ``schemas/manifest.schema.json`` and then
checks what a schema cannot (files exist, names are unique and referenced names exist, weights
lie in the policy's range, masks share one size), and reports *every* problem at once, each with
the file and the key, as one :class:`wrinklepipe.errors.InputError`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import jsonschema

from wrinklepipe.errors import InputError, ProblemList
from wrinklepipe.io.json_safe import loads_toml
from wrinklepipe.model import POLICY_WEIGHT_RANGE
from wrinklepipe.paths import SCHEMAS_DIR
from wrinklepipe.presets import jimenez

MESH_SUFFIXES = (".gltf", ".glb", ".usd", ".usda", ".usdc", ".usdz", ".obj")
_CHANNELS = "rgba"


@dataclass(frozen=True)
class StateSpec:
    name: str
    map: Path


@dataclass(frozen=True)
class RegionSpec:
    name: str
    mask: Path
    channel: str | None = None
    side: str = "center"
    states: tuple[str, ...] = ()


@dataclass
class Manifest:
    """A loaded, checked manifest. Paths are absolute."""

    path: Path
    name: str
    base: Path
    states: list[StateSpec]
    regions: list[RegionSpec]
    mesh: Path | None = None
    convention: str = "auto"
    encoding: str = "pd"
    policy: str = "clamp01"
    pd_scale: float | str = "auto"
    states_include_base: bool = True
    expressions: dict[str, dict[str, float]] = field(default_factory=dict)
    drivers: list[dict[str, Any]] = field(default_factory=list)
    resolution: dict[str, int | str] = field(default_factory=dict)
    formats: dict[str, str] = field(default_factory=dict)
    budget: dict[str, float] = field(default_factory=dict)
    raw: dict[str, Any] = field(default_factory=dict)

    @property
    def root(self) -> Path:
        return self.path.parent

    @property
    def input_files(self) -> list[Path]:
        """Every file the manifest reads (the manifest itself included)."""
        files = [
            self.path,
            self.base,
            *(s.map for s in self.states),
            *(r.mask for r in self.regions),
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


def _schema_problems(data: dict[str, Any], file: str, problems: ProblemList) -> None:
    validator = jsonschema.Draft202012Validator(manifest_schema())
    for error in sorted(
        validator.iter_errors(data), key=lambda e: (list(map(str, e.path)), e.message)
    ):
        key = _key(error.absolute_path)
        if error.validator == "additionalProperties":
            allowed = set(error.schema.get("properties", {}))
            unknown = sorted(set(error.instance) - allowed)
            for name in unknown:
                problems.add(file, "unknown key", f"{key}.{name}" if key else name)
            continue
        if error.validator == "required":
            missing = error.message.split("'")[1] if "'" in error.message else error.message
            problems.add(file, "missing required key", f"{key}.{missing}" if key else missing)
            continue
        if error.validator in ("oneOf", "enum", "const") and error.schema.get("description"):
            problems.add(
                file, f"invalid value {error.instance!r}: {error.schema['description']}", key
            )
            continue
        problems.add(file, error.message, key)


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

    _schema_problems(data, file, problems)
    problems.raise_if_any()  # the semantic checks below rely on well-typed data

    root = path.resolve().parent
    expressions = data.get("expressions", {})
    if expressions == "jimenez":
        expressions = jimenez.expression_table()
    m = Manifest(
        path=path.resolve(),
        name=data["name"],
        base=root / data["base"],
        states=[StateSpec(s["name"], root / s["map"]) for s in data["states"]],
        regions=[
            RegionSpec(
                r["name"],
                root / r["mask"],
                r.get("channel"),
                r.get("side", "center"),
                tuple(r.get("states", ())),
            )
            for r in data["regions"]
        ],
        mesh=(root / data["mesh"]) if "mesh" in data else None,
        convention=data.get("convention", "auto"),
        encoding=data.get("encoding", "pd"),
        policy=data.get("policy", "clamp01"),
        pd_scale=data.get("pd_scale", "auto"),
        states_include_base=data.get("states_include_base", True),
        expressions={e: {r: float(w) for r, w in row.items()} for e, row in expressions.items()},
        drivers=list(data.get("drivers", [])),
        resolution=dict(data.get("resolution", {})),
        formats=dict(data.get("formats", {})),
        budget={k: float(v) for k, v in data.get("budget", {}).items()},
        raw=data,
    )
    _semantic_problems(m, file, problems, check_files)
    problems.raise_if_any()
    return m


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
    if check_files:
        _file_problems(m, file, problems)


def _file_problems(m: Manifest, file: str, problems: ProblemList) -> None:
    from wrinklepipe.errors import InputError as _IE
    from wrinklepipe.io.images import read_header

    def exists(p: Path, key: str) -> bool:
        if p.is_dir():
            problems.add(file, f"is a folder, expected a file: {p}", key)
            return False
        if not p.is_file():
            problems.add(file, f"file not found: {p}", key)
            return False
        return True

    if m.mesh is not None:
        exists(m.mesh, "mesh")
    exists(m.base, "base")
    for i, s in enumerate(m.states):
        exists(s.map, f"states[{i}].map")
    for i, d in enumerate(m.drivers):
        if "file" in d:
            exists(m.root / d["file"], f"drivers[{i}].file")
    sizes: dict[tuple[int, int], str] = {}
    for i, r in enumerate(m.regions):
        key = f"regions[{i}].mask"
        if not exists(r.mask, key):
            continue
        try:
            info = read_header(r.mask)
        except _IE as exc:
            for p in exc.problems:
                problems.add(file, p.message, key)
            continue
        if r.channel is not None and _CHANNELS.index(r.channel) >= info.channels:
            problems.add(
                file, f"channel {r.channel!r} requested but {r.mask.name} has {info.channels}", key
            )
        sizes.setdefault((info.width, info.height), key)
    if len(sizes) > 1:
        listing = ", ".join(f"{w}x{h} ({k})" for (w, h), k in sizes.items())
        problems.add(file, f"masks have different sizes: {listing}", "regions")
