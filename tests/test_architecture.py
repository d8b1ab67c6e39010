"""The package's shape: every module imports, every import goes down the layers of
:mod:`wrinklepipe.layers` (module level and deferred alike), the module graph has no circle,
imports sit at module level except named heavy optional dependencies, and
docs/architecture.md shows the table as it is."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import importlib
import sys
from pathlib import Path

import pytest

from wrinklepipe import cli, layers
from wrinklepipe.paths import ROOT

PACKAGE = ROOT / "wrinklepipe"

#: Third-party modules that may be imported inside a function (with a comment on the line
#: saying why): heavy, and needed by few code paths.
DEFERRED = {
    "pxr": "usd-core: ~0.3 s and its plugin registry, for USD files only",
    "trimesh": "~1.7 s to import, only the geometry benchmark's baseline uses it",
    "alktx2": "optional (Basis Universal UASTC only), may be absent",
    "moderngl": "imported where a GL context is made, inside the guard for 'no GL here'",
    "numba": "~0.5 s to import; only the BC4 encoder's compiled search needs it",
    "distributed": "Dask: about a second to import, only the Dask batch engine needs it",
    "colour": "colour-science: ~0.6 s to import (its whole library loads); only the colour "
    "states' CIEDE2000 measure needs it",
    "scipy.interpolate": "~0.4 s of import time with the scipy.optimize it imports (0.1-0.2 s "
    "of a command's start-up); only cubic curve keys need it on the convert path",
}

#: Imports that still run up the layers, each to be removed (the test fails when one is no
#: longer there, so this list only shrinks).
KNOWN_UPWARD: set[tuple[str, str]] = set()


def _modules() -> dict[str, Path]:
    """Every module of the package (files under folders without ``__init__.py``, such as the
    Blender script in ``data/``, are data, not modules)."""
    out = {}
    for p in sorted(PACKAGE.rglob("*.py")):
        if any(not (d / "__init__.py").is_file() for d in p.parents if PACKAGE in [d, *d.parents]):
            continue
        parts = list(p.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


MODULES = _modules()


def _owner(name: str) -> str:
    """The module a dotted name lives in (``wrinklepipe.io.png.png_bytes`` -> its module)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name


@functools.cache
def _imports(module: str) -> list[tuple[ast.stmt, list[str], bool]]:
    """Every import statement of ``module``: (node, wrinklepipe modules named, at module level)."""
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    top = {id(n) for n in tree.body}
    out = []
    for node in ast.walk(tree):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [_owner(a.name) for a in node.names if a.name.startswith("wrinklepipe")]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = (
                    module if MODULES[module].name == "__init__.py" else module.rpartition(".")[0]
                )
                for _ in range(node.level - 1):
                    base = base.rpartition(".")[0]
                name = f"{base}.{node.module}" if node.module else base
            else:
                name = node.module or ""
            if name.startswith("wrinklepipe"):
                for a in node.names:
                    full = f"{name}.{a.name}"
                    targets.append(full if full in MODULES else _owner(name))
        else:
            continue
        out.append((node, [t for t in targets if t and t != module], id(node) in top))
    return out


@functools.cache
def _graph() -> dict[str, set[str]]:
    return {m: {t for _, ts, _ in _imports(m) for t in ts} for m in MODULES}


def _with_package_inits(graph: dict[str, set[str]], modules: set[str]) -> dict[str, set[str]]:
    """``graph`` plus what Python runs on the way: importing ``a.b.c`` first runs the
    ``__init__`` of package ``a.b`` (unless the importer is inside it already), so its imports
    are part of any circle through ``a.b.c``."""
    out = {m: set(ts) for m, ts in graph.items()}
    for m, ts in graph.items():
        for t in ts:
            pkg = t.rpartition(".")[0]
            while pkg in modules and not (m == pkg or m.startswith(pkg + ".")):
                out[m].add(pkg)
                pkg = pkg.rpartition(".")[0]
    return out


@functools.cache
def _runtime_graph() -> dict[str, set[str]]:
    """:func:`_graph` with the package ``__init__`` each import runs."""
    return _with_package_inits(_graph(), set(MODULES))


def test_every_module_imports():
    for name in MODULES:
        if name.endswith("__main__"):
            continue
        importlib.import_module(name)


def test_every_module_has_a_layer():
    missing = []
    for name in MODULES:
        try:
            layers.layer_of(name)
        except KeyError:
            missing.append(name)
    assert not missing, f"add these to wrinklepipe/layers.py: {missing}"


def test_imports_go_down_the_layers():
    upward = set()
    for m, targets in _graph().items():
        for t in targets:
            if not layers.may_import(m, t):
                upward.add((m, t))
    new = sorted(upward - KNOWN_UPWARD)
    assert not new, "imports running up the layers:\n" + "\n".join(
        f"  {m} ({layers.layer_of(m).name}) -> {t} ({layers.layer_of(t).name})" for m, t in new
    )
    assert not (KNOWN_UPWARD - upward), f"fixed, remove from KNOWN_UPWARD: {KNOWN_UPWARD - upward}"


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(graph) + 100))

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_circle():
    assert _cycles(_graph()) == []
    assert _cycles(_runtime_graph()) == []


def test_a_package_init_closes_a_circle():
    """The circle a package's ``__init__`` makes is found: ``a.read`` importing ``p.container``
    runs ``p/__init__``, which imports ``p.model``; had the model imported back ``a.read``,
    Python would fail half-way, though no module imports ``a.read`` in a circle."""
    graph = {"a.read": {"p.container"}, "p": {"p.model"}, "p.container": set(), "p.model": set()}
    modules = {"a", "a.read", "p", "p.container", "p.model"}
    assert "p" in _with_package_inits(graph, modules)["a.read"]
    assert _cycles(_with_package_inits(graph, modules)) == []
    graph["p.model"] = {"a.read"}
    assert _cycles(graph) == []
    assert _cycles(_with_package_inits(graph, modules)) == [["a.read", "p", "p.model"]]


def test_the_circle_finder_finds_circles():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


#: Modules at the package's root that are not core: the program's faces, where Python and the
#: packaging tools look for them.
ROOT_FACES = {
    "wrinklepipe.__main__": "python -m wrinklepipe",
    "wrinklepipe.cli": "the console script (pyproject.toml: wrinklepipe = wrinklepipe.cli:main)",
    "wrinklepipe.reference": "python -m wrinklepipe.reference, the docs site's generated pages",
}


def _folder(module: str) -> str:
    """The folder (package) a module's file sits in: ``wrinklepipe.gltf.document`` and
    ``wrinklepipe.gltf`` (its ``__init__``) -> ``wrinklepipe.gltf``; a root module ->
    ``wrinklepipe``."""
    return ".".join(MODULES[module].parent.relative_to(ROOT).parts)


def _folders_and_layers() -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for m in MODULES:
        if m not in ROOT_FACES:
            out.setdefault(_folder(m), set()).add(layers.layer_of(m).name)
    return out


def test_a_folder_is_one_layer():
    """Every module of a folder is in the same layer (the root: core, besides its faces)."""
    mixed = {f: sorted(ls) for f, ls in _folders_and_layers().items() if len(ls) > 1}
    assert not mixed, f"folders spanning layers: {mixed}"
    assert _folders_and_layers()["wrinklepipe"] == {"core"}


def _folder_edges() -> dict[tuple[str, str], list[tuple[str, str]]]:
    """(importing folder, imported folder) -> the module imports behind it."""
    edges: dict[tuple[str, str], list[tuple[str, str]]] = {}
    for m, targets in _graph().items():
        if m in ROOT_FACES:
            continue
        for t in targets:
            a, b = _folder(m), _folder(t)
            if a != b:
                edges.setdefault((a, b), []).append((m, t))
    return edges


def test_no_two_folders_import_each_other():
    """Folders form a one-way graph: when a module of ``a/`` imports one of ``b/``, no module of
    ``b/`` imports one of ``a/`` (the lower folder knows nothing of the higher)."""
    edges = _folder_edges()
    both = sorted((a, b) for a, b in edges if a < b and (b, a) in edges)
    assert not both, "folders importing each other:\n" + "\n".join(
        f"  {a} <-> {b}: {sorted(edges[a, b])[:2]} / {sorted(edges[b, a])[:2]}" for a, b in both
    )


#: Size limits: a module over MODULE_LINES lines or a function over FUNCTION_LINES lines is
#: split, or listed in ALLOWED_LONG with the reason it stays whole.
MODULE_LINES = 600
FUNCTION_LINES = 120
ALLOWED_LONG: dict[str, str] = {}
#: Over the limits when the check came (issue 40), to be split: this list only shrinks (the
#: test fails when an entry is no longer over, so it is struck).
TO_SPLIT: set[str] = set()


def _too_long() -> set[str]:
    """Modules over :data:`MODULE_LINES` lines (``path``) and functions over
    :data:`FUNCTION_LINES` (``path:name``), methods and nested functions included."""
    out = set()
    for path in MODULES.values():
        text = path.read_text(encoding="utf-8")
        rel = path.relative_to(ROOT).as_posix()
        if text.count("\n") > MODULE_LINES:
            out.add(rel)
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                if node.end_lineno - node.lineno + 1 > FUNCTION_LINES:
                    out.add(f"{rel}:{node.name}")
    return out


def test_modules_and_functions_are_short_or_say_why():
    long = _too_long()
    new = sorted(long - set(ALLOWED_LONG) - TO_SPLIT)
    assert not new, (
        f"over {MODULE_LINES} lines (module) or {FUNCTION_LINES} (function); split, or add to "
        f"ALLOWED_LONG with the reason: {new}"
    )
    assert not (TO_SPLIT - long), f"split now, strike from TO_SPLIT: {sorted(TO_SPLIT - long)}"
    assert not (set(ALLOWED_LONG) - long), f"no longer long: {sorted(set(ALLOWED_LONG) - long)}"
    assert not (set(ALLOWED_LONG) & TO_SPLIT)
    assert all(len(why) > 20 for why in ALLOWED_LONG.values()), "each entry says why"


def test_layer_rules_by_hand():
    assert layers.layer_of("wrinklepipe.jobs.convert").name == "jobs"
    assert layers.layer_of("wrinklepipe.pipeline.ingest").name == "pipeline"
    assert layers.layer_of("wrinklepipe").name == "core"
    assert layers.may_import("wrinklepipe.validate.ship", "wrinklepipe.pipeline.prepare")
    assert not layers.may_import("wrinklepipe.pipeline.prepare", "wrinklepipe.validate.run")
    with pytest.raises(KeyError):
        layers.layer_of("wrinklepipe.newpackage.thing")


def test_imports_are_at_module_level():
    """Every import inside a function names a heavy optional dependency of :data:`DEFERRED`
    and says why in a comment on (or just above) its line; wrinklepipe's own modules are always
    imported at module level."""
    bad = []
    for m, path in MODULES.items():
        lines = path.read_text(encoding="utf-8").split("\n")
        for node, _, top in _imports(m):
            if top:
                continue
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            name = names[0] if names else (node.module or "")
            if isinstance(node, ast.ImportFrom) and node.module == "__future__":
                continue
            allowed = any(name == k or name.startswith(f"{k}.") for k in DEFERRED)
            # the reason: a comment on the statement's lines or the line above
            said = "#" in "".join(lines[node.lineno - 2 : node.end_lineno])
            if not allowed or not said:
                bad.append(
                    f"{path.relative_to(ROOT)}:{node.lineno}: {lines[node.lineno - 1].strip()}"
                )
    assert not bad, "imports inside functions:\n" + "\n".join(bad)


#: Modules that load modules by name (the commands and benchmarks found by their names).
BY_NAME = {"wrinklepipe.cli", "wrinklepipe.bench"}


def test_no_module_is_imported_by_name_behind_the_graph():
    """``importlib.import_module`` / ``__import__`` hide an import from the checks above:
    only the command and benchmark tables load modules by name."""
    found = set()
    for m, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            name = getattr(node, "attr", None) or getattr(node, "id", None)
            if name in ("import_module", "__import__"):
                found.add(m)
    assert found == BY_NAME, found


def test_architecture_page_shows_the_table():
    page = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    start, end = "<!-- layers: start -->\n", "<!-- layers: end -->"
    assert start in page and end in page
    shown = page.split(start, 1)[1].split(end, 1)[0]
    assert shown == layers.markdown_table(), "regenerate: python -m wrinklepipe.layers"


def test_commands_import_no_other_command():
    """A command is a thin layer over a job or a stage: what two commands share lives below
    them (e.g. ``outputs.per_vertex`` for vertex-ids and dynamic), never in one of them. The
    command line's own shared parts (the option vocabulary, convert's terminal summary that
    demo prints too) live in private modules of ``commands/`` (``_options``, ``_summary``: a
    leading underscore, so no command), which import no command."""
    shared = sorted(
        (m, t)
        for m, ts in _graph().items()
        if m.startswith("wrinklepipe.commands.")
        for t in ts
        if t.startswith("wrinklepipe.commands.")
        and t != m
        and not t.startswith("wrinklepipe.commands._")
    )
    assert not shared, f"commands importing commands: {shared}"


#: Objects whose ``.meta`` is some other dict (a batch cache entry's record), not a package's.
_OTHER_META = {"self", "entry"}


def _string_keyed_meta(tree: ast.AST) -> list[int]:
    """Lines reading a package's metadata by string key: ``X.meta["k"]`` or ``X.meta.get()``."""

    def is_meta(node: ast.AST) -> bool:
        return (
            isinstance(node, ast.Attribute)
            and node.attr == "meta"
            and not (isinstance(node.value, ast.Name) and node.value.id in _OTHER_META)
        )

    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Subscript) and is_meta(node.value):
            lines.append(node.lineno)
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "get"
            and is_meta(node.func.value)
        ):
            lines.append(node.lineno)
    return lines


def test_package_metadata_is_read_by_field():
    """``WrinklePackage.meta`` is a typed :class:`wrinklepipe.metadata.WrinkleMeta`: the package
    reads its fields (``pkg.meta.states[0].texture``), never string keys."""
    found = [
        f"{name}:{line}"
        for name, path in _modules().items()
        for line in _string_keyed_meta(ast.parse(path.read_text(encoding="utf-8")))
    ]
    assert not found, found
    assert _string_keyed_meta(ast.parse('pkg.meta["states"]\nex.pkg.meta.get("x")')) == [1, 2]


def _options_defaults(module: object) -> dict[str, object]:
    """Field -> default of every ``*Options`` dataclass a command module names."""
    out: dict[str, object] = {}
    for name, obj in vars(module).items():
        if name.endswith("Options") and dataclasses.is_dataclass(obj) and isinstance(obj, type):
            try:
                d = obj()
            except TypeError:  # a required field: no defaults to feed
                continue
            for f in dataclasses.fields(obj):
                out.setdefault(f.name, getattr(d, f.name))
    return out


def test_command_defaults_come_from_their_options():
    """A command's argparse defaults are its job's options defaults (one place): every option
    whose destination is a field of an options dataclass the command uses defaults to the
    field's default (None: the job decides), and pack-masks has one."""
    parser = cli.build_parser()
    subs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    checked = {}
    for name, sub in subs.choices.items():
        module = sys.modules[f"wrinklepipe.commands.{name.replace('-', '_')}"]
        defaults = _options_defaults(module)
        fed = [a for a in sub._actions if a.dest in defaults and a.default is not None]
        for a in fed:
            assert a.default == defaults[a.dest], (name, a.dest, a.default, defaults[a.dest])
        checked[name] = len(fed)
    assert checked["pack-masks"] >= 3 and checked["convert"] >= 4, checked
