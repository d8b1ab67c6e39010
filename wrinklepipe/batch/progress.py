"""Progress of a batch on the terminal: an overall bar and one line per running asset with its
stage (rich); on a non-terminal (CI logs) one plain line per finished asset instead."""

from __future__ import annotations

import threading
from typing import Any

from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from wrinklepipe.batch.results import AssetResult
from wrinklepipe.console import detail, elapsed, problem, verbosity

_STYLE = {"passed": "green", "failed": "yellow", "error": "bold red"}
_HOW = {"converted": "converted", "cache": "from cache", "validated": "validated", "none": ""}


def result_line(r: AssetResult) -> str:
    """One line on a finished asset (rich markup)."""
    how = _HOW[r.source]
    extra = f", {how}" if how else ""
    text = f"[{_STYLE[r.status]}]{r.status:6s}[/] {escape(r.id)} ({r.seconds:.1f} s{extra})"
    if r.status == "error" and r.problems:
        p = r.problems[0]
        key = f" [{p['key']}]" if p.get("key") else ""
        text += f": {escape(p['file'] + key)}: {escape(p['message'])}"
        if len(r.problems) > 1:
            text += f" (+{len(r.problems) - 1} more)"
    elif r.status == "failed":
        codes = sorted({i["code"] for i in r.failing_issues()})
        text += f": {', '.join(codes)}"
    return text


class BatchProgress:
    """Call :meth:`stage` as stages start (any thread) and :meth:`done` per finished asset."""

    def __init__(self, console: Console, total: int, title: str) -> None:
        self.console = console
        self.live = console.is_terminal
        self._lock = threading.Lock()
        self._tasks: dict[str, Any] = {}
        self.progress = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=console,
            transient=True,
            disable=not self.live,
        )
        self.overall = self.progress.add_task(f"[bold]{escape(title)}", total=total)

    def __enter__(self) -> BatchProgress:
        self.progress.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.progress.__exit__(*exc)

    def stage(self, job_id: str, stage: str) -> None:
        if not self.live:
            detail(f"{elapsed():7.1f} s  {job_id}: {stage}")  # --verbose: every asset's steps
            return
        with self._lock:
            text = f"  {escape(job_id)}: [dim]{escape(stage)}[/]"
            task = self._tasks.get(job_id)
            if task is None:
                self._tasks[job_id] = self.progress.add_task(text, total=None)
            else:
                self.progress.update(task, description=text)

    def done(self, result: AssetResult) -> None:
        with self._lock:
            task = self._tasks.pop(result.id, None)
            if task is not None:
                self.progress.remove_task(task)
            self.progress.advance(self.overall)
            line = result_line(result)
            if result.status != "passed" and (not self.live or verbosity() < 0):
                problem(line, markup=True)  # a failure: shown with --quiet too
            else:
                self.progress.console.print(line, soft_wrap=True, highlight=False)
