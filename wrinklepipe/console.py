"""Terminal output through rich: messages to stderr, machine-readable JSON to stdout."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterable, Iterator
from contextvars import ContextVar
from typing import Any, TypeVar

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from wrinklepipe.atomic import dumps_json

T = TypeVar("T")

err = Console(stderr=True, highlight=False)
out = Console(highlight=False)


def emit_json(obj: Any) -> None:
    """Print deterministic JSON on stdout (for ``--json``)."""
    sys.stdout.write(dumps_json(obj))
    sys.stdout.flush()


def track(items: Iterable[T], description: str, total: int | None = None) -> Iterator[T]:
    """A progress bar on stderr (hidden when stderr is not a terminal)."""
    progress = Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(),
        console=err,
        transient=True,
        disable=not err.is_terminal,
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
    """Call ``listener(message)`` for every :func:`status` step inside the block."""
    token = _STAGE_LISTENER.set(listener)
    try:
        yield
    finally:
        _STAGE_LISTENER.reset(token)


def status(message: str) -> Any:
    """A spinner for a single long step (no-op context when stderr is not a terminal); the
    step is also told to the :func:`stage_listener` of the current context, if any."""
    listener = _STAGE_LISTENER.get()
    if listener is not None:
        listener(message)
    if err.is_terminal and listener is None:
        return err.status(message)
    return contextlib.nullcontext()
