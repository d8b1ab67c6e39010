"""What each command's ``--help`` shows runs: every ``wrinklepipe NAME ...`` example of every
command's help, in the commands' order, in the documentation's sandbox
(``tests/docs_sandbox.py``), ending with the exit code it states (``# exit N``, else 0).
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Iterator
from pathlib import Path

import pytest
from docs_examples import Block
from docs_sandbox import (
    HAVE_SHARED,
    SHARED_FILES,
    build_sandbox,
    cli_server,
    environment,
    run_block,
)

from wrinklepipe.cli import build_parser

#: the files of ../shared/data the help examples may name (linked into the sandbox)
SHARED_NAMES = ("RobotExpressive", *(Path(rel).name for rel in SHARED_FILES))


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    with cli_server(tmp_path_factory.mktemp("help-server")) as sock:
        yield sock


#: Examples of the commands' own help not run here, and why (every other one runs).
HELP_SKIPS = {
    "wrinklepipe inspect --diff assets/hero.usd": "needs a USD character (tests/test_usd_layer.py)",
    "wrinklepipe view": "a server that runs until stopped (docs/commands.md's run as servers)",
    "wrinklepipe capture session/neutral.png": "the sfs solve runs a minute (test_capture_cli.py)",
    "wrinklepipe bench model-metahuman": "a benchmark: minutes of CPU (each runs quick in tests)",
    "wrinklepipe bench --quick": "every benchmark (each runs quick in tests/test_*_bench.py)",
    "wrinklepipe bench --record": "every benchmark, recorded (each runs quick in tests)",
}
#: Long help examples run cheaply: (text, replacement) in every example line, and options
#: added to a command's examples (the sandbox already has a ``maps/`` folder).
HELP_SUBS = [("--size 512", "--size 64"), ("--size 2048", "--size 64")]
HELP_ADD = {"demo": " --size 64", "regions": " --size 64", "bake-states": " --force"}


def _help_examples() -> list[tuple[str, int]]:
    """Every ``wrinklepipe NAME ...`` example line of every command's ``--help``, in the
    commands' order, with its expected exit code (a ``# exit N`` comment, else 0)."""
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    out = []
    for name, p in sub.choices.items():
        text = re.sub(r"\\\n\s*", " ", p.description or "")
        for line in text.splitlines():
            if re.match(rf"\s+wrinklepipe {re.escape(name)}\b", line):
                m = re.search(r"#\s*exit (\d+)", line)
                out.append((line.split("  #")[0].strip(), int(m.group(1)) if m else 0))
    return out


def test_help_examples_run(server: Path, tmp_path: Path) -> None:
    """What ``--help`` shows runs, in the sandbox (the commands' order: convert's output is
    there for inspect, export ...)."""
    cwd = build_sandbox(tmp_path)
    env = environment(cwd, server)
    skipped = []
    for example, expected in _help_examples():
        why = next((w for k, w in HELP_SKIPS.items() if example.startswith(k)), None)
        if why is None and not HAVE_SHARED and any(n in example for n in SHARED_NAMES):
            why = "../shared/data is absent"
        if why is not None:
            skipped.append(f"{example}: {why}")
            continue
        command = example
        for old, new in HELP_SUBS:
            command = command.replace(old, new)
        name = command.split()[1]
        if name in HELP_ADD and HELP_ADD[name].split()[0] not in command:
            command += HELP_ADD[name]
        block = Block(Path("--help"), 0, "sh", f"{command}  # exit {expected}")
        run_block(block, cwd, env)
    by_rule = [s for s in skipped if not s.endswith("../shared/data is absent")]
    assert len(by_rule) <= len(HELP_SKIPS) + 2, skipped  # running is the rule
    print("not run:", *skipped, sep="\n  ")
