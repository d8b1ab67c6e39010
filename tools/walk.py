"""Follow one parameter through the calls that pass it on, and count the files the walk enters.

    python tools/walk.py wrinklepipe/jobs/convert.py:convert:manifest_path [--route]

A static reading of the code (nothing is run): starting in FUNCTION with PARAM as "me", every
name assigned from an expression that uses me becomes me too; every call that is given me (as an
argument, or as the object a method is called on) is followed into the function it names, with
the parameters that receive me. Calls are taken in the order the code is written, each
function is walked once per set of parameters that receive me, a call in a ``raise`` (a
complaint about me) is not followed, and a callee the reading cannot name (a method several
classes define, a function passed in) ends that branch.

The route is the sequence of files the walk stays in: a stay each time it enters a function
(given me) in another file than the one it entered last, a function walked before included
(it is not walked again). It prints the
files entered, the moves between them and the *climbs back up*: moves to a file on a higher
floor, where a file's floor is one more than the highest floor of the project files it imports
(floor 1 imports none). A data flow that goes down the layers and comes back once climbs
little; one that bounces between two files climbs at each bounce. ``docs/architecture.md``
quotes the figures for ``convert``'s ``manifest_path``.
"""

from __future__ import annotations

import argparse
import ast
import sys
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "wrinklepipe"


@dataclass
class Module:
    name: str
    path: Path
    tree: ast.Module
    functions: dict[str, ast.FunctionDef] = field(default_factory=dict)
    classes: dict[str, dict[str, ast.FunctionDef]] = field(default_factory=dict)
    names: dict[str, tuple[str, str | None]] = field(default_factory=dict)  # alias -> (mod, attr)
    others: set[str] = field(default_factory=set)  # names bound to modules outside the project


def _modules() -> dict[str, Module]:
    out = {}
    for p in sorted((ROOT / PACKAGE).rglob("*.py")):
        if not (p.parent / "__init__.py").is_file():
            continue
        parts = list(p.relative_to(ROOT).with_suffix("").parts)
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = Module(name, p, ast.parse(p.read_text(encoding="utf-8")))
    for m in out.values():
        for node in m.tree.body:
            if isinstance(node, ast.FunctionDef):
                m.functions[node.name] = node
            elif isinstance(node, ast.ClassDef):
                m.classes[node.name] = {
                    f.name: f for f in node.body if isinstance(f, ast.FunctionDef)
                }
        for node in ast.walk(m.tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(PACKAGE):
                for a in node.names:
                    full = f"{node.module}.{a.name}"
                    target = (full, None) if full in out else (node.module, a.name)
                    m.names[a.asname or a.name] = target
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.startswith(PACKAGE) and a.asname:
                        m.names[a.asname] = (a.name, None)
                    elif not a.name.startswith(PACKAGE):  # numpy as np, os, json ...
                        m.others.add(a.asname or a.name.split(".")[0])
    return out


MODULES = _modules()


@cache
def floor(module: str) -> int:
    """1 + the highest floor of the project modules ``module`` imports (1: none)."""
    deps = {t for t, _ in MODULES[module].names.values() if t in MODULES and t != module}
    return 1 + max((floor(d) for d in deps), default=0)


Target = tuple[str, str | None, str]  # (module, class or None, function)


def _resolve(m: Module, cls: str | None, call: ast.Call) -> tuple[Target | None, bool]:
    """The function a call names, and whether its first parameter is the object (a method)."""
    f = call.func
    if isinstance(f, ast.Name):
        if f.id in m.functions:
            return (m.name, None, f.id), False
        if f.id in m.classes:
            return (
                ((m.name, f.id, "__init__"), True)
                if "__init__" in m.classes[f.id]
                else (None, False)
            )
        if f.id in m.names:
            mod, attr = m.names[f.id]
            if mod in MODULES and attr is not None:
                t = MODULES[mod]
                if attr in t.functions:
                    return (mod, None, attr), False
                if attr in t.classes and "__init__" in t.classes[attr]:
                    return (mod, attr, "__init__"), True
        return None, False
    if isinstance(f, ast.Attribute):
        v = f.value
        if isinstance(v, ast.Name) and v.id in m.names:
            mod, attr = m.names[v.id]
            if attr is None and mod in MODULES and f.attr in MODULES[mod].functions:
                return (mod, None, f.attr), False
        if isinstance(v, ast.Name) and v.id == "self" and cls and f.attr in m.classes[cls]:
            return (m.name, cls, f.attr), True
        if isinstance(v, ast.Name) and v.id in m.others and v.id not in m.names:
            return None, False  # np.where(...): the other module's function, not a method here
        owners = [
            (n, c) for n, mm in MODULES.items() for c, fs in mm.classes.items() if f.attr in fs
        ]
        if len(owners) == 1:
            return (owners[0][0], owners[0][1], f.attr), True
    return None, False


def _uses(node: ast.AST, me: set[str]) -> bool:
    return any(isinstance(n, ast.Name) and n.id in me for n in ast.walk(node))


def _targets(node: ast.AST) -> list[str]:
    return [n.id for n in ast.walk(node) if isinstance(n, ast.Name)]


@dataclass
class Walk:
    route: list[str] = field(default_factory=list)
    done: set[tuple[Target, frozenset[str]]] = field(default_factory=set)

    def stay(self, module: str) -> None:
        if not self.route or self.route[-1] != module:
            self.route.append(module)

    def function(self, target: Target, me: set[str]) -> None:
        key = (target, frozenset(me))
        self.stay(target[0])
        if key in self.done or not me:
            return
        self.done.add(key)
        mod, cls, name = target
        m = MODULES[mod]
        fn = m.classes[cls][name] if cls else m.functions[name]
        me = set(me)
        for stmt in fn.body:
            self.statement(m, cls, stmt, me)

    def statement(self, m: Module, cls: str | None, stmt: ast.stmt, me: set[str]) -> None:
        raised = {id(c) for r in ast.walk(stmt) if isinstance(r, ast.Raise) for c in ast.walk(r)}
        kinds = (ast.Call, ast.Assign, ast.AnnAssign, ast.AugAssign, ast.For, ast.withitem)
        kinds += (ast.comprehension, ast.NamedExpr)
        nodes = [n for n in ast.walk(stmt) if isinstance(n, kinds) and id(n) not in raised]
        nodes.sort(key=lambda n: (getattr(n, "lineno", 0), getattr(n, "col_offset", 0)))
        for n in nodes:
            if isinstance(n, ast.Call):
                self.call(m, cls, n, me)
                continue
            value = getattr(n, "value", None) or getattr(n, "iter", None)
            value = value or getattr(n, "context_expr", None)
            if value is not None and _uses(value, me):
                for t in getattr(n, "targets", None) or [getattr(n, "target", None)]:
                    me.update(_targets(t) if t is not None else [])
                if isinstance(n, ast.withitem) and n.optional_vars is not None:
                    me.update(_targets(n.optional_vars))

    def call(self, m: Module, cls: str | None, call: ast.Call, me: set[str]) -> None:
        target, method = _resolve(m, cls, call)
        if target is None:
            return
        mod, tcls, name = target
        t = MODULES[mod]
        fn = t.classes[tcls][name] if tcls else t.functions[name]
        params = [a.arg for a in [*fn.args.posonlyargs, *fn.args.args]]
        got: set[str] = set()
        if method:
            receiver = call.func.value if isinstance(call.func, ast.Attribute) else None
            if receiver is not None and _uses(receiver, me) and params:
                got.add(params[0])
            params = params[1:]
        for p, a in zip(params, call.args):
            if _uses(a, me):
                got.add(p)
        for k in call.keywords:
            if k.arg and _uses(k.value, me):
                got.add(k.arg)
        if got:
            self.function(target, got)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "start", help="FILE:FUNCTION:PARAM, e.g. wrinklepipe/jobs/convert.py:convert:manifest_path"
    )
    ap.add_argument("--route", action="store_true", help="print every stay")
    a = ap.parse_args(argv)
    file, func, param = a.start.rsplit(":", 2)
    mod = ".".join(Path(file).with_suffix("").parts)
    w = Walk()
    w.function((mod, None, func), {param})
    route = w.route
    while len(route) > 1 and route[-1] == route[0]:  # the final return to the start
        route = route[:-1]
    climbs = sum(floor(b) > floor(a) for a, b in zip(route, route[1:]))
    if a.route:
        for i, r in enumerate(route, 1):
            print(f"{i:4d}. floor {floor(r):2d}  {r}")
    print(
        f"{len(set(route))} files entered, {len(route) - 1} moves between them, "
        f"{climbs} climbs back up, {len(route) - len(set(route))} returns to a file left before"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
