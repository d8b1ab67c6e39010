"""Terminal output through rich: messages to stderr, machine-readable JSON to stdout."""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
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


def status(message: str) -> Any:
    """A spinner for a single long step (no-op context when stderr is not a terminal)."""
    if err.is_terminal:
        return err.status(message)
    import contextlib

    return contextlib.nullcontext()
