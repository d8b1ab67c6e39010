"""The issue-code table of the docs (``docs/ISSUES.md``), generated from the rule catalogue
(:data:`wrinklepipe.validate.catalogue.RULES`): ``python -m wrinklepipe.validate
docs/ISSUES.md``."""

from __future__ import annotations

import sys
from pathlib import Path

from wrinklepipe.atomic import write_output
from wrinklepipe.validate.catalogue import AREAS, RULES, SEVERITIES


def issues_markdown() -> str:
    """The docs table (``docs/ISSUES.md``), generated from :data:`RULES`."""
    lines = [
        "# validate-asset issue codes",
        "",
        "Generated from `wrinklepipe/validate/catalogue.py` by",
        "`python -m wrinklepipe.validate docs/ISSUES.md`; do not edit by hand.",
        "",
        "Severities are the defaults; a config file (`--config`) can ignore a code or change its "
        "severity.",
        "",
    ]
    counts = {s: sum(r.severity == s for r in RULES) for s in SEVERITIES}
    lines.append(
        f"{len(RULES)} rules: "
        + ", ".join(f"{counts[s]} {s}{'s' if counts[s] != 1 else ''}" for s in SEVERITIES)
        + "."
    )
    for area, title in AREAS.items():
        rules = [r for r in RULES if r.code.split("-")[1] == area]
        lines += ["", f"## {area}: {title}", ""]
        lines.append("| Code | Severity | Title | Description | Suggested fix |")
        lines.append("|---|---|---|---|---|")
        for r in rules:
            cells = [f"`{r.code}`", r.severity, r.title, r.description, r.fix or "-"]
            lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write the docs table to the given path (stdout without one)."""
    args = sys.argv[1:] if argv is None else argv
    text = issues_markdown()
    if args:
        write_output(Path(args[0]), text.encode("utf-8"))
    else:
        sys.stdout.write(text)
    return 0
