"""The shell examples of the README and the documentation pages, parsed for
``tests/test_docs_examples.py``.

Every fenced block marked ``sh`` (or ``bash``, ``shell``) is an example, and runs. A line's
trailing ``# exit N`` comment says the exit code it must end with (0 otherwise). An HTML comment
on the line before the block's fence (invisible on GitHub and on the site) tunes how it runs::

    <!-- docs-test: needs=shared -->          reads ../shared/data (skipped when it is absent)
    <!-- docs-test: sub="A" "B" -->           run it with the text A replaced by B (a small size
                                              for a long example; repeatable)
    <!-- docs-test: server -->                a server: started, asked for the address it
                                              prints, then stopped
    <!-- docs-test: checkout -->              run in the checkout itself, not the sandbox (a
                                              command that reads the source tree and writes
                                              nothing)
    <!-- docs-test: skip="why" -->            not run (only where running it is impossible)
    <!-- docs-test: edit=PATH -->             (on a toml block) the edit a reader makes: each
                                              ``key = value`` line replaces that key in PATH
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

SHELL = {"sh", "bash", "shell"}
_FENCE = re.compile(r"^(\s*)(```+|~~~+)\s*([\w+-]*)")
_DIRECTIVE = re.compile(r"<!--\s*docs-test:(.*?)-->")
_EXIT = re.compile(r"\s#\s*exit (\d+)\b")


@dataclass
class Block:
    """One fenced code block: where it is, its language, text and directives."""

    path: Path
    line: int  # 1-based line of the opening fence
    lang: str
    text: str
    needs_shared: bool = False
    server: bool = False
    checkout: bool = False
    skip: str | None = None
    edit: str | None = None
    subs: list[tuple[str, str]] = field(default_factory=list)

    @property
    def where(self) -> str:
        return f"{self.path.name}:{self.line}"

    def commands(self) -> list[tuple[str, int]]:
        """(command line, expected exit code) for each command of a shell block; backslash
        continuations joined, comment-only lines dropped, ``sub`` replacements made."""
        out: list[tuple[str, int]] = []
        pending = ""
        for raw in self.text.splitlines():
            line = pending + raw
            if line.rstrip().endswith("\\"):
                pending = line.rstrip()[:-1] + " "
                continue
            pending = ""
            if not line.strip() or line.lstrip().startswith("#"):
                continue
            m = _EXIT.search(line)
            expected = int(m.group(1)) if m else 0
            for old, new in self.subs:
                line = line.replace(old, new)
            out.append((line.strip(), expected))
        return out


def _directives(block: Block, text: str) -> None:
    tokens = shlex.split(text)
    i = 0
    while i < len(tokens):
        tok = tokens[i]
        if tok == "needs=shared":
            block.needs_shared = True
        elif tok == "server":
            block.server = True
        elif tok == "checkout":
            block.checkout = True
        elif tok.startswith("skip="):
            block.skip = tok[5:]
        elif tok.startswith("edit="):
            block.edit = tok[5:]
        elif tok.startswith("sub="):
            block.subs.append((tok[4:], tokens[i + 1]))
            i += 1
        else:
            raise ValueError(f"{block.where}: unknown docs-test directive {tok!r}")
        i += 1


def blocks(path: Path) -> list[Block]:
    """Every fenced block of the Markdown file ``path``, with its directives."""
    lines = path.read_text(encoding="utf-8").splitlines()
    found: list[Block] = []
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, fence, lang = m.groups()
        start = i
        body: list[str] = []
        i += 1
        while i < len(lines) and not lines[i].strip().startswith(fence):
            body.append(lines[i][len(indent) :] if lines[i].startswith(indent) else lines[i])
            i += 1
        block = Block(path, start + 1, lang.lower(), "\n".join(body))
        j = start - 1
        while j >= 0 and not lines[j].strip():
            j -= 1
        if j >= 0 and (d := _DIRECTIVE.search(lines[j])):
            _directives(block, d.group(1))
        found.append(block)
        i += 1
    return found


#: A line of a non-shell block that reads like a command a reader would copy: it starts with
#: ``wrinklepipe`` (or ``$ wrinklepipe``) and is not a synopsis (no UPPERCASE placeholders,
#: ``[options]`` or ``a|b`` alternatives).
_COMMAND = re.compile(r"^\s*(\$ )?wrinklepipe [a-z]")
_SYNOPSIS = re.compile(r"\b[A-Z][A-Z_]{1,}\b|\[|\w\|\w|\.\.\.")


def hidden_examples(block: Block) -> list[str]:
    """Command lines in a block that is not marked ``sh`` but shows a runnable example."""
    if block.lang in SHELL:
        return []
    return [
        line.strip()
        for line in block.text.splitlines()
        if _COMMAND.match(line) and not _SYNOPSIS.search(line.split("#")[0])
    ]


def apply_edit(block: Block, target: Path) -> None:
    """The reader's edit: each ``key = value`` line of ``block`` replaces that top-level key's
    line in ``target`` (or is added after ``name``)."""
    text = target.read_text(encoding="utf-8")
    for line in block.text.splitlines():
        m = re.match(r"^([A-Za-z_][\w-]*)\s*=", line)
        if not m:
            continue
        key = m.group(1)
        pattern = re.compile(rf"^{re.escape(key)}\s*=.*$", re.M)
        head, sep, tail = text.partition("\n[")  # top-level keys come before the first table
        if m := pattern.search(head):
            head = head[: m.start()] + line + head[m.end() :]
        elif m := re.search(r"^name\s*=.*$", head, flags=re.M):
            head = head[: m.end()] + "\n" + line + head[m.end() :]
        else:
            head = line + "\n" + head
        text = head + sep + tail
    target.write_text(text, encoding="utf-8")
