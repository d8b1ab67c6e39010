"""A source manifest written by a tool (``manifest_snippet.toml``), for ``convert`` as is.

:func:`snippet_text` turns a :class:`Snippet` (the mesh, the maps, the regions with their mask
files and channels, the driver rows and keys) into TOML of the manifest schema
(``schemas/manifest.schema.json``), paths relative to the folder the snippet is written to.
Deterministic: the same snippet gives the same bytes.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

SCHEMA = "wrinklepipe/manifest@1"


@dataclass(frozen=True)
class SnippetRegion:
    """One ``[[regions]]`` table: a packed mask file and channel, side and states."""

    name: str
    mask: str
    channel: str | None = None
    side: str = "center"
    states: tuple[str, ...] = ()


@dataclass
class Snippet:
    """What the manifest says (paths as they are to be written, relative to its folder)."""

    name: str
    mesh: str
    states: list[tuple[str, str]]  # (state, map path)
    regions: list[SnippetRegion]
    material: str | list[str] | None = None
    meshes: tuple[str, ...] = ()
    base: str | None = None
    policy: str = "clamp01"
    mask_layout: str | None = None
    rows: list[tuple[str, str, float, float, float, float]] = field(default_factory=list)
    keys: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    header: list[str] = field(default_factory=list)  # comment lines at the top


def toml_str(s: str) -> str:
    """A TOML basic string (JSON's escapes are TOML's)."""
    return json.dumps(s, ensure_ascii=False)


def toml_key(s: str) -> str:
    """A TOML key: bare when it can be, quoted otherwise."""
    return s if s and all(c.isascii() and (c.isalnum() or c in "_-") for c in s) else toml_str(s)


def toml_num(x: float) -> str:
    """A number as TOML: integers without a point, others as Python's shortest repr."""
    f = float(x)
    return str(int(f)) if f.is_integer() and abs(f) < 1e15 else repr(f)


def _value(v: Any) -> str:
    if isinstance(v, str):
        return toml_str(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return toml_num(v)


def _rows_text(rows: Sequence[Sequence[Any]]) -> list[str]:
    lines = ["rows = ["]
    lines += [f"  {_value(list(r))}," for r in rows]
    lines.append("]")
    return lines


def snippet_text(s: Snippet) -> str:
    """The manifest's TOML text (see the module doc)."""
    lines = [f"# {h}" if h else "#" for h in s.header]
    lines += [f"schema = {toml_str(SCHEMA)}", f"name = {toml_str(s.name)}"]
    lines.append(f"mesh = {toml_str(s.mesh)}")
    if s.material is not None:
        lines.append(f"material = {_value(s.material)}")
    if s.meshes:
        lines.append(f"meshes = {_value(list(s.meshes))}")
    if s.base is not None:
        lines.append(f"base = {toml_str(s.base)}")
    lines.append(f"policy = {toml_str(s.policy)}")
    lines.append("")
    if s.mask_layout is not None:
        lines += ["[formats]", f"mask_layout = {toml_str(s.mask_layout)}", ""]
    for state, path in s.states:
        lines += ["[[states]]", f"name = {toml_str(state)}", f"map = {toml_str(path)}", ""]
    for r in s.regions:
        lines += ["[[regions]]", f"name = {toml_str(r.name)}", f"mask = {toml_str(r.mask)}"]
        if r.channel is not None:
            lines.append(f"channel = {toml_str(r.channel)}")
        lines.append(f"side = {toml_str(r.side)}")
        if r.states:
            lines.append(f"states = {_value(list(r.states))}")
        lines.append("")
    if s.rows:
        lines += ["[[drivers]]", 'kind = "blendshapes"', 'name = "targets"']
        lines += _rows_text(s.rows)
        if s.keys:
            lines.append("[drivers.keys]")
            for k, keys in s.keys.items():
                lines.append(f"{toml_key(k)} = {_value([list(x) for x in keys])}")
        lines.append("")
    return "\n".join(lines)
