"""The ``wrinklepipe`` command line: a thin layer over the stages.

Each subcommand lives in its own module under :mod:`wrinklepipe.commands` and exposes ``NAME``,
``HELP``, ``DESCRIPTION``, ``add_arguments(parser)`` and ``run(args) -> int``. Modules are found by
name, so adding a command means adding a file. Exit codes: 0 success, 1 errors found (validation),
2 could not run (bad arguments or input), 128 + the signal's number when a signal ended the run
(130 Ctrl-C / SIGINT, 143 SIGTERM, 129 SIGHUP), as a shell reports a process killed by it.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import pkgutil
import shlex
import signal
import sys
import threading
from collections.abc import Iterator, Sequence

from rich.markup import escape

import wrinklepipe.commands as pkg
from wrinklepipe import __version__, console
from wrinklepipe.commands._options import HelpFormatter, Parser
from wrinklepipe.errors import InputError
from wrinklepipe.io.confine import allowed_roots

#: Order in which subcommands are listed in ``--help``.
COMMAND_ORDER = (
    "demo",
    "convert",
    "validate-asset",
    "inspect",
    "batch",
    "encode-normals",
    "pack-masks",
    "vertex-ids",
    "dynamic",
    "bake",
    "regions",
    "bake-states",
    "capture",
    "export",
    "view",
    "bench",
)


def _module_names() -> dict[str, str]:
    """Command name -> module name, from the files of :mod:`wrinklepipe.commands` (no import):
    a command ``NAME`` lives in ``commands/<NAME with - as _>.py``."""
    return {
        info.name.replace("_", "-"): info.name
        for info in pkgutil.iter_modules(pkg.__path__)
        if not info.name.startswith("_")
    }


def _command_modules(only: str | None = None) -> list:
    """The command modules (all of them, or only the command ``only``), in ``--help`` order."""
    names = _module_names()
    if only is not None:
        names = {only: names[only]}
    mods = [importlib.import_module(f"wrinklepipe.commands.{m}") for m in names.values()]
    order = {name: i for i, name in enumerate(COMMAND_ORDER)}
    mods.sort(key=lambda m: (order.get(m.NAME, len(order)), m.NAME))
    return mods


def _named_command(argv: Sequence[str]) -> str | None:
    """The command ``argv`` runs when its first word names one, else None (help, --version,
    a typo: those need every command's parser)."""
    return argv[0] if argv and argv[0] in _module_names() else None


#: The environment variables every command reads, as ``wrinklepipe --help`` lists them.
ENVIRONMENT = """environment:
  WRINKLEPIPE_WORKING_SET  memory a run may spend beyond the source maps it holds (default 1G;
                           e.g. 512M): smaller costs time, never a byte of output
  WRINKLEPIPE_SCRATCH      where source maps larger than an eighth of the working set wait
                           (default /var/tmp); off keeps them in memory
  WRINKLEPIPE_THREADS      threads one run may use at once (default: the CPU count; batch
                           sets each worker's share)
  WRINKLEPIPE_CACHE        where generated sources (demo, fixtures, head cases) are kept
                           (default $XDG_CACHE_HOME/wrinklepipe, else ~/.cache/wrinklepipe)
  WRINKLEPIPE_NODE_MODULES the npm folder holding gltf-validator (default tools/node)
  WRINKLEPIPE_THREE        the three.js package folder `view` serves (default tools/node)
  WRINKLEPIPE_DEBUG=1      show the traceback of an internal error

docs/scale.md explains the first two."""


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or (``only``) of that one command alone: running one
    command imports its module only, not the other commands' stages (``wrinklepipe convert``
    starts without loading capture's solvers or the batch engines)."""
    parser = Parser(
        prog="wrinklepipe",
        description="Process and validate animated facial wrinkle maps.",
        epilog=ENVIRONMENT,
        formatter_class=HelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"wrinklepipe {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in _command_modules(only):
        p = sub.add_parser(
            mod.NAME,
            help=mod.HELP,
            description=getattr(mod, "DESCRIPTION", mod.HELP),
            formatter_class=HelpFormatter,
        )
        mod.add_arguments(p)
        p.add_argument(
            "--allow-root",
            action="append",
            default=[],
            metavar="DIR",
            help="also read files under DIR when an input names them (repeatable; by default "
            "only files inside the folder of the file that names them are read)",
        )
        noise = p.add_mutually_exclusive_group()
        noise.add_argument(
            "-q",
            "--quiet",
            action="store_true",
            help="print only warnings and errors: no progress, no summary",
        )
        noise.add_argument(
            "-v",
            "--verbose",
            action="store_true",
            help="also print details: every note, and each step's time on a terminal",
        )
        p.set_defaults(_run=mod.run)
    return parser


class Interrupted(BaseException):
    """A termination signal, raised in the main thread so every ``finally`` (locks, staging
    folders) runs before the process ends."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextlib.contextmanager
def _signals_raise() -> Iterator[None]:
    """SIGTERM and SIGHUP raise :class:`Interrupted` for the duration (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: object) -> None:
        raise Interrupted(signum)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def _os_message(exc: OSError) -> str:
    where = exc.filename or "output"
    return f"{where}: {exc.strerror or exc}"


def _out_of_memory(parser: argparse.ArgumentParser, command: str) -> str:
    """The message for a run that ran out of memory: the options of ``command`` that bound an
    input's size, when it has any (the inputs' declared sizes are checked before they are
    allocated, so this is the rare case of many inputs within their caps at once)."""
    sub = next(
        (
            a.choices[command]
            for a in parser._actions
            if isinstance(a, argparse._SubParsersAction) and command in a.choices
        ),
        None,
    )
    have = {s for a in (sub._actions if sub else []) for s in a.option_strings}
    hints = [o for o in ("--max-pixels", "--size", "--jobs") if o in have]
    tip = f"; try {' or '.join(hints)}" if hints else ""
    return f"out of memory: the inputs need more memory than this machine has{tip}"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``wrinklepipe`` console script.

    Every failure ends in one message per problem and exit code 2, never a traceback; an
    unexpected error is reported as an internal error (``WRINKLEPIPE_DEBUG=1`` re-raises it)."""

    argv = list(sys.argv[1:] if argv is None else argv)
    command = _named_command(argv)
    # Before the command's own modules load (a second or more): a log sees the run start at once.
    console.configure(quiet=bool({"-q", "--quiet"} & set(argv)), start=True)
    if command and not {"-h", "--help"} & set(argv):
        console.started("wrinklepipe " + shlex.join(argv))
    parser = build_parser(command)
    args = parser.parse_args(argv)
    if not getattr(args, "_run", None):
        parser.print_help(sys.stderr)
        return 2

    def fail(message: str) -> int:
        console.problem(f"[bold red]error:[/] {escape(message)}", markup=True)
        return 2

    console.configure(quiet=args.quiet, verbose=args.verbose)
    debug = bool(os.environ.get("WRINKLEPIPE_DEBUG"))
    try:
        with _signals_raise(), allowed_roots(args.allow_root):
            return int(args._run(args) or 0)
    except InputError as exc:
        for problem in exc.problems:
            fail(str(problem))
        return 2
    except (KeyboardInterrupt, Interrupted) as exc:
        signum = exc.signum if isinstance(exc, Interrupted) else signal.SIGINT
        fail(
            f"interrupted ({signal.Signals(signum).name}); outputs are complete or absent, "
            "never partial"
        )
        return 128 + int(signum)
    except OSError as exc:
        if debug:
            raise
        return fail(_os_message(exc))
    except MemoryError:
        if debug:
            raise
        return fail(_out_of_memory(parser, args.command))
    except RecursionError:
        if debug:
            raise
        return fail("an input is nested too deeply to read")
    except Exception as exc:  # noqa: BLE001 - the last line of defence: one message, no traceback
        if debug:
            raise
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        return fail(
            f"internal error ({type(exc).__name__}: {msg}) in `wrinklepipe {args.command}`; "
            "please report it with the input (WRINKLEPIPE_DEBUG=1 shows the traceback)"
        )
