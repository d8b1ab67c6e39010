"""The documentation site's generated reference pages: every command's options (from the
argparse parsers themselves) and the manifest and batch-file keys (from their JSON schemas).

The pages are built when the site is (``ci/mkdocs_hooks.py``), so they can never disagree with
``--help`` or with what the loaders accept. ``python -m wrinklepipe.reference commands`` (or
``manifest``, ``batch``) prints one.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Iterator
from typing import Any

from wrinklepipe.cli import build_parser
from wrinklepipe.paths import SCHEMAS_DIR

_MD_SPECIAL = str.maketrans({c: "\\" + c for c in "\\`*_[]<>|#"})


def _md(text: str) -> str:
    """``text`` shown literally in Markdown (one line; special characters escaped)."""
    return " ".join(text.split()).translate(_MD_SPECIAL)


def _code(text: str) -> str:
    """``text`` as inline code (backticks inside are doubled around)."""
    fence = "``" if "`" in text else "`"
    pad = " " if fence == "``" else ""
    return f"{fence}{pad}{text}{pad}{fence}"


# -- commands ---------------------------------------------------------------------------------


def _subparsers(parser: argparse.ArgumentParser) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            yield from action.choices.items()


def _option_label(action: argparse.Action, formatter: argparse.HelpFormatter) -> str:
    """``-o OUT, --output OUT`` or ``MANIFEST``: how the option is written on the command line."""
    if not action.option_strings:
        return formatter._metavar_formatter(action, action.dest)(1)[0]
    if action.nargs == 0:
        return ", ".join(action.option_strings)
    args = formatter._format_args(action, action.dest.upper())
    return ", ".join(f"{o} {args}" for o in action.option_strings)


def _help_text(action: argparse.Action, formatter: argparse.HelpFormatter) -> str:
    if not action.help or action.help == argparse.SUPPRESS:
        return ""
    return formatter._expand_help(action)


def command_reference() -> str:
    """The command reference page: usage, description and an option table per command."""
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"  # argparse wraps usage lines to the terminal: fix the width
    try:
        parser = build_parser()
        lines = [
            "# Command reference",
            "",
            "Generated from the command line's own parsers (what `wrinklepipe COMMAND --help`",
            "prints), so it always matches the installed tool. The guides explain when to use",
            "each command: [Commands](../commands.md).",
            "",
            "Exit codes of every command: **0** success, **1** validation found issues at or",
            "above `--fail-on` (or a benchmark exceeded its limit, or `inspect --diff` found a",
            "difference), **2** could not run (bad arguments or input: one message per problem,",
            "nothing written), **130** interrupted (Ctrl-C, SIGINT), **143** terminated (SIGTERM);",
            "an interrupted run leaves its outputs complete or absent, never partial.",
            "",
        ]
        for name, sub in _subparsers(parser):
            formatter = sub._get_formatter()
            lines += [f"## {name}", ""]
            usage = "\n".join(
                line.removeprefix("usage: ").removeprefix(" " * len("usage: "))
                for line in sub.format_usage().strip().splitlines()
            )
            lines += ["```text", usage, "```", ""]
            if sub.description:
                lines += ["```text", sub.description.rstrip(), "```", ""]
            lines += ["| option | what it does |", "|---|---|"]
            for action in sub._actions:
                if action.help == argparse.SUPPRESS or isinstance(
                    action, argparse._SubParsersAction
                ):
                    continue
                label = _code(_option_label(action, formatter))
                lines.append(f"| {label} | {_md(_help_text(action, formatter))} |")
            lines.append("")
        return "\n".join(lines)
    finally:
        if previous is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = previous


# -- schemas ----------------------------------------------------------------------------------


def _resolve(node: dict[str, Any], root: dict[str, Any]) -> dict[str, Any]:
    ref = node.get("$ref")
    if isinstance(ref, str) and ref.startswith("#/"):
        target: Any = root
        for part in ref[2:].split("/"):
            target = target[part]
        merged = dict(target)
        merged.update({k: v for k, v in node.items() if k != "$ref"})
        return _resolve(merged, root)
    return node


def _type_of(node: dict[str, Any], root: dict[str, Any]) -> str:
    """A short human type: ``"pd" | "diff"``, ``integer 4..16384 or "auto"``, ``[string]``."""
    node = _resolve(node, root)
    if "const" in node:
        return json.dumps(node["const"])
    if "enum" in node:
        return " \\| ".join(json.dumps(v) for v in node["enum"])
    for key in ("oneOf", "anyOf"):
        if key in node:
            return " or ".join(_type_of(n, root) for n in node[key])
    t = node.get("type")
    if isinstance(t, list):
        return " or ".join(t)
    if t == "array":
        items = node.get("items")
        inner = _type_of(items, root) if isinstance(items, dict) else "any"
        return f"[{inner}]" if "object" not in inner else "[table]"
    if t == "object":
        return "table"
    if t in ("integer", "number"):
        low = node.get("minimum", node.get("exclusiveMinimum"))
        high = node.get("maximum", node.get("exclusiveMaximum"))
        if low is not None or high is not None:
            lo = "" if low is None else f"{'>' if 'exclusiveMinimum' in node else ''}{low:g}"
            hi = "" if high is None else f"{high:g}"
            return f"{t} {lo}..{hi}" if lo and hi else f"{t} {lo or '<= ' + hi}"
        return t
    return t or "any"


def _object_tables(node: dict[str, Any], root: dict[str, Any], path: str, out: list[str]) -> None:
    """One table for the object at ``path`` (its keys), then one per nested table."""
    node = _resolve(node, root)
    props: dict[str, Any] = node.get("properties", {})
    if not props:
        return
    required = set(node.get("required", []))
    heading = f"`{path}`" if path else "Top level"
    out += [f"### {heading}", ""]
    if path and node.get("description"):
        out += [_md(node["description"]), ""]
    out += ["| key | type | default | what it is |", "|---|---|---|---|"]
    nested: list[tuple[str, dict[str, Any]]] = []
    for key, sub in props.items():
        sub = _resolve(sub, root)
        default = "required" if key in required else ""
        if "default" in sub:
            default = _code(json.dumps(sub["default"]))
        desc = _md(sub.get("description", ""))
        out.append(f"| `{key}` | {_type_of(sub, root)} | {default} | {desc} |")
        child = f"{path}.{key}" if path else key
        if sub.get("type") == "object" and sub.get("properties"):
            nested.append((child, sub))
        items = sub.get("items")
        if sub.get("type") == "array" and isinstance(items, dict):
            items = _resolve(items, root)
            if items.get("properties"):
                nested.append((f"{child}[]", items))
    out.append("")
    if node.get("additionalProperties") is False or node.get("unevaluatedProperties") is False:
        out += ['Other keys are refused (with a "did you mean").', ""]
    for child, sub in nested:
        _object_tables(sub, root, child, out)


def schema_reference(filename: str, title: str, intro: str) -> str:
    """A reference page for the JSON schema ``schemas/<filename>``: one table per TOML table."""
    schema = json.loads((SCHEMAS_DIR / filename).read_text(encoding="utf-8"))
    out = [f"# {title}", "", intro, ""]
    if schema.get("description"):
        out += [_md(schema["description"]), ""]
    out += [
        f"Generated from the JSON schema `schemas/{filename}`, which the loader checks every",
        "file against; `[]` after a key marks an array of tables (`[[states]]` in TOML).",
        "",
    ]
    _object_tables(schema, schema, "", out)
    return "\n".join(out)


def manifest_reference() -> str:
    return schema_reference(
        "manifest.schema.json",
        "Manifest reference",
        "Every key of the source manifest (`manifest.toml`). The guide with a worked example is "
        "[The source manifest](../manifest.md).",
    )


def batch_reference() -> str:
    return schema_reference(
        "batch.schema.json",
        "Batch file reference",
        "Every key of a batch file (`wrinklepipe batch studio-batch.toml`). The guide is the "
        "batch section of [Commands](../commands.md#batch).",
    )


PAGES = {
    "reference/commands.md": command_reference,
    "reference/manifest.md": manifest_reference,
    "reference/batch-file.md": batch_reference,
}


if __name__ == "__main__":  # pragma: no cover - prints a page
    which = sys.argv[1] if len(sys.argv) > 1 else "commands"
    print(PAGES[f"reference/{which}.md"]())
