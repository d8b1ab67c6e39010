"""The ``wrinklepipe`` command line: a thin layer over the stages.

Each subcommand lives in its own module under :mod:`wrinklepipe.commands` and exposes ``NAME``,
``HELP``, ``DESCRIPTION``, ``add_arguments(parser)`` and ``run(args) -> int``. Modules are found by
name, so adding a command means adding a file. Exit codes: 0 success, 1 errors found (validation),
2 could not run (bad arguments or input).
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from collections.abc import Sequence

from wrinklepipe import __version__
from wrinklepipe.errors import InputError

#: Order in which subcommands are listed in ``--help``.
COMMAND_ORDER = (
    "demo",
    "convert",
    "validate-asset",
    "encode-normals",
    "pack-masks",
    "vertex-ids",
    "dynamic",
    "bake",
    "capture",
    "export",
    "bench",
)


def _command_modules() -> list:
    import wrinklepipe.commands as pkg

    mods = []
    for info in pkgutil.iter_modules(pkg.__path__):
        if info.name.startswith("_"):
            continue
        mods.append(importlib.import_module(f"wrinklepipe.commands.{info.name}"))
    order = {name: i for i, name in enumerate(COMMAND_ORDER)}
    mods.sort(key=lambda m: (order.get(m.NAME, len(order)), m.NAME))
    return mods


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wrinklepipe",
        description="Process and validate animated facial wrinkle maps.",
    )
    parser.add_argument("--version", action="version", version=f"wrinklepipe {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in _command_modules():
        p = sub.add_parser(
            mod.NAME,
            help=mod.HELP,
            description=getattr(mod, "DESCRIPTION", mod.HELP),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``wrinklepipe`` console script."""
    from rich.markup import escape

    from wrinklepipe.console import err

    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(args._run(args) or 0)
    except InputError as exc:
        for problem in exc.problems:
            err.print(f"[bold red]error:[/] {escape(str(problem))}", soft_wrap=True)
        return 2
    except KeyboardInterrupt:
        err.print("interrupted")
        return 2
