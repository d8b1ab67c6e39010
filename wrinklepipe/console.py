"""Terminal output: messages and progress on stderr, machine-readable JSON on stdout.

Where the output goes decides its form. On a terminal, long steps show rich's live spinner and
tables fit the window. Anywhere else (a pipe, a CI log, a file) every step is one plain line as
it starts and one as it ends, with the time since the command started, written at once; lines
and tables are never cut or wrapped to a width nobody has (80 columns is rich's guess for a
pipe). :func:`configure` (called by the CLI for every run) sets the verbosity: ``--quiet`` keeps
only warnings and errors (:func:`problem`), ``--verbose`` adds details (:func:`detail`) and the
time each step took on a terminal too. Progress never goes to stdout, so ``--json`` output stays
clean.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from contextvars import ContextVar
from typing import Any, TypeVar

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from wrinklepipe.atomic import dumps_json
from wrinklepipe.names import plural

T = TypeVar("T")

#: Width used for a stream that is not a terminal: wide enough that no line or table is ever cut.
UNBOUNDED_WIDTH = 100_000

err = Console(stderr=True, highlight=False)  # messages and progress (silenced by --quiet)
out = Console(highlight=False)  # a command's own text output (inspect's tables, bench's)
_loud = Console(stderr=True, highlight=False)  # warnings and errors: always shown

_state: dict[str, Any] = {"verbosity": 0, "t0": time.monotonic()}


def _fit(console: Console) -> None:
    """Terminal (or COLUMNS set): follow its width. Otherwise: unbounded, so nothing is cut."""
    try:
        tty = console.file.isatty()
    except (AttributeError, ValueError):
        tty = False
    console._width = None if tty or os.environ.get("COLUMNS") else UNBOUNDED_WIDTH


def configure(quiet: bool = False, verbose: bool = False, start: bool = False) -> None:
    """Set up the consoles for one run: widths for where they write, the verbosity; with
    ``start``, the run starts now (the clock progress lines count from)."""
    for console in (err, out, _loud):
        _fit(console)
    _state["verbosity"] = -1 if quiet else 1 if verbose else 0
    err.quiet = quiet
    if start:
        _state["t0"] = time.monotonic()


def verbosity() -> int:
    """-1 quiet, 0 normal, 1 verbose."""
    return int(_state["verbosity"])


def elapsed() -> float:
    """Seconds since the run started (``configure(start=True)``, the first thing the CLI
    does; else this module's import)."""
    return time.monotonic() - float(_state["t0"])


def started(text: str) -> None:
    """The first progress line of a run in a log (nothing on a terminal or with --quiet)."""
    if verbosity() >= 0 and not live():
        _plain(text)


def live() -> bool:
    """True when progress is drawn live (stderr is a terminal)."""
    return err.is_terminal


def info(text: str, markup: bool = False) -> None:
    """A normal message (not shown with ``--quiet``)."""
    err.print(as_typed(text), markup=markup, highlight=False, soft_wrap=True)


def detail(text: str, markup: bool = False) -> None:
    """A detail shown only with ``--verbose``."""
    if verbosity() > 0:
        err.print(text, markup=markup, highlight=False, soft_wrap=True)


def problem(text: Any, markup: bool = False) -> None:
    """A warning or an error (a line, or a rich table of them): shown even with ``--quiet``;
    paths inside the working folder as the user types them there."""
    if isinstance(text, str):
        _loud.print(as_typed(text), markup=markup, highlight=False, soft_wrap=True)
    else:  # a table: its cells carry their own markup
        _loud.print(text, highlight=False)


def as_typed(text: str) -> str:
    """``text`` with every absolute path inside the working folder written relative to it, as
    a user types it there (``/home/me/chars/ada/manifest.toml`` -> ``chars/ada/manifest.toml``)."""
    try:
        cwd = os.getcwd()
    except OSError:
        return text
    if cwd == os.sep:
        return text
    return text.replace(cwd + os.sep, "")


def emit_json(obj: Any) -> None:
    """Print deterministic JSON on stdout (for ``--json``)."""
    sys.stdout.write(dumps_json(obj))
    sys.stdout.flush()


def issue_counts(counts: dict[str, int]) -> str:
    """``0 errors, 1 warning, 2 info``: validation's counts, always in this order."""
    return ", ".join(plural(int(counts.get(k, 0)), k) for k in ("error", "warning", "info"))


def _plain(text: str) -> None:
    """One progress line for a log: the time since the start, then the text (flushed)."""
    err.print(f"{elapsed():7.1f} s  {text}", markup=False, highlight=False, soft_wrap=True)
    with contextlib.suppress(OSError, ValueError):
        err.file.flush()


def track(items: Iterable[T], description: str, total: int | None = None) -> Iterator[T]:
    """A progress bar on a terminal; elsewhere a line as the loop starts and one as it ends."""
    if verbosity() < 0:
        yield from items
        return
    if not live():
        with status(f"{description} ({total} items)" if total is not None else description):
            yield from items
        return
    progress = Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(),
        console=err,
        transient=True,
    )
    with progress:
        yield from progress.track(items, description=description, total=total)


#: Who hears about each step :func:`status` announces (``wrinklepipe batch`` forwards them from
#: its worker processes as per-asset progress). Per context, so threads do not mix them up.
_STAGE_LISTENER: ContextVar[Callable[[str], None] | None] = ContextVar(
    "wrinklepipe_stage_listener", default=None
)


@contextlib.contextmanager
def stage_listener(listener: Callable[[str], None]) -> Iterator[None]:
    """Call ``listener(message)`` for every :func:`status` step inside the block (instead of
    showing it)."""
    token = _STAGE_LISTENER.set(listener)
    try:
        yield
    finally:
        _STAGE_LISTENER.reset(token)


#: The spinner of the outermost step on a terminal: a step inside it changes its text (rich
#: draws one live display at a time).
_SPINNER: list[Any] = []


@contextlib.contextmanager
def _stage(message: str) -> Iterator[None]:
    start = time.monotonic()
    spinner = None
    if not live():
        _plain(message)
    elif _SPINNER:
        _SPINNER[0].update(escape(message))
    else:
        spinner = err.status(escape(message))
        spinner.__enter__()
        _SPINNER.append(spinner)
    ok = False
    try:
        yield
        ok = True
    finally:
        took = time.monotonic() - start
        if spinner is not None:
            _SPINNER.clear()
            spinner.__exit__(None, None, None)
        if live():
            if verbosity() > 0 and ok:
                err.print(f"{escape(message)}: done in {took:.1f} s", highlight=False)
        elif ok:
            _plain(f"{message}: done in {took:.1f} s")
        else:
            _plain(f"{message}: stopped after {took:.1f} s")


def status(message: str) -> Any:
    """A context for one long step: a spinner on a terminal, a start and an end line elsewhere,
    nothing with ``--quiet``; told instead to the :func:`stage_listener` of the current context,
    if any."""
    listener = _STAGE_LISTENER.get()
    if listener is not None:
        listener(message)
        return contextlib.nullcontext()
    if verbosity() < 0:
        return contextlib.nullcontext()
    return _stage(message)
