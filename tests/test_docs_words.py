"""What the README and the documentation pages name exists: the environment variables the code
reads, the commands and their options, the modes of ``ci/bootstrap.sh``, and the README's
command table lists every command. The README stays a start page (at most 300 lines).

The history and the changelog tell what *was* (an option that went, a variable that is gone), so
they are not held to today's names."""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pytest

from wrinklepipe.cli import COMMAND_ORDER, build_parser

ROOT = Path(__file__).resolve().parent.parent
SHELL = {"", "sh", "bash", "shell", "console"}
PAST = {"history.md", "changelog.md", "CHANGELOG.md"}
PAGES = [
    ROOT / "README.md",
    *(p for p in sorted((ROOT / "docs").rglob("*.md")) if p.name not in PAST),
]
CODE = [
    p
    for folder in ("wrinklepipe", "ci", "tests", "tools")
    for p in (ROOT / folder).rglob("*")
    if p.suffix in {".py", ".sh", ".mjs", ".js"} and "node_modules" not in p.parts
]


def _page_id(page: Path) -> str:
    return page.relative_to(ROOT).as_posix()


def _code_text() -> str:
    return "\n".join(p.read_text(encoding="utf-8", errors="replace") for p in CODE)


def _commands() -> dict[str, argparse.ArgumentParser]:
    (sub,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


def _snippets(text: str) -> list[str]:
    """The page's code: each line of its fenced blocks and each inline code span (continued
    lines joined)."""
    out: list[str] = []
    for lang, block in re.findall(r"^```([a-z]*)\n(.*?)^```", text, flags=re.S | re.M):
        if lang in SHELL:
            out += re.sub(r"\\\n\s*", " ", block).splitlines()
    prose = re.sub(r"^```[a-z]*\n.*?^```", "", text, flags=re.S | re.M)
    out += [s for s in re.findall(r"`([^`\n]+)`", prose) if re.match(r"(\$ )?wrinklepipe ", s)]
    return out


def _invocations(text: str) -> list[list[str]]:
    """Every ``wrinklepipe COMMAND ...`` the page's code shows, as words (up to a shell
    operator or comment)."""
    found = []
    for line in _snippets(text):
        for m in re.finditer(r"(?:^|[\s(;&|$])wrinklepipe ([a-z][^#;&|)>]*)", line):
            try:
                words = shlex.split(m.group(1), comments=True)
            except ValueError:
                words = m.group(1).split()
            found.append(words)
    return found


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_environment_variables_named_are_read_by_the_code(page: Path) -> None:
    named = set(re.findall(r"\bWRINKLEPIPE_[A-Z][A-Z0-9_]*\b", page.read_text(encoding="utf-8")))
    code = _code_text()
    stale = sorted(v for v in named if v not in code)
    assert not stale, f"{_page_id(page)} names variables nothing reads: {stale}"


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_commands_and_options_named_exist(page: Path) -> None:
    commands = _commands()
    problems = []
    for words in _invocations(page.read_text(encoding="utf-8")):
        name = words[0]
        if name.startswith("-"):
            continue  # wrinklepipe --help / --version
        if name not in commands:
            problems.append(f"`wrinklepipe {' '.join(words)}`: no command {name!r}")
            continue
        known = {s for a in commands[name]._actions for s in a.option_strings}
        for w in words[1:]:
            opt = w.strip("[]").split("=", 1)[0]  # [--opt X] in a synopsis
            if re.fullmatch(r"--?[a-zA-Z][-a-zA-Z0-9]*", opt) and opt not in known:
                problems.append(f"`wrinklepipe {' '.join(words)}`: {name} has no option {opt}")
    assert not problems, f"{_page_id(page)}:\n  " + "\n  ".join(problems)


def test_the_pages_show_commands() -> None:
    shown = [w for p in PAGES for w in _invocations(p.read_text(encoding="utf-8"))]
    assert len(shown) >= 100, "the pages' commands are not found: fix _snippets"


@pytest.mark.parametrize("page", PAGES, ids=_page_id)
def test_bootstrap_modes_named_exist(page: Path) -> None:
    script = (ROOT / "ci" / "bootstrap.sh").read_text(encoding="utf-8")
    modes = set(re.findall(r"^\s+([a-z]+)\)", script, flags=re.M))
    assert {"setup", "demo", "test"} <= modes
    named = re.findall(r"ci/bootstrap\.sh\"? ([a-z]+)", page.read_text(encoding="utf-8"))
    stale = sorted({m for m in named if m not in modes})
    assert not stale, f"{_page_id(page)}: ci/bootstrap.sh has no mode {stale}"


def test_readme_is_a_start_page_listing_every_command() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 300
    table = re.findall(r"^\| `([a-z-]+)[^`]*` \|", text, flags=re.M)
    assert table == list(COMMAND_ORDER), (
        "the README's command table: every command, in --help order"
    )
    assert set(COMMAND_ORDER) == set(_commands())
