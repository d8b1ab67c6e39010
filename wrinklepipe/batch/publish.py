"""Run a plan with progress, write its reports (JSON summary, JUnit, SARIF) and print its
tally: shared by ``wrinklepipe batch`` and ``wrinklepipe validate-asset`` over a folder of
outputs (:func:`run_and_publish`; :func:`publish` for a run already made)."""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.markup import escape

from wrinklepipe.atomic import dumps_json, write_output
from wrinklepipe.batch import reports
from wrinklepipe.batch.cache import Cache
from wrinklepipe.batch.engines import DaskEngine, LocalEngine
from wrinklepipe.batch.plan import BatchPlan
from wrinklepipe.batch.progress import BatchProgress
from wrinklepipe.batch.run import BatchRun, run_plan
from wrinklepipe.console import info, plural, problem


def run_and_publish(
    plan: BatchPlan,
    engine: LocalEngine | DaskEngine,
    cache: Cache | None,
    *,
    command: str,
    console: Console,
    summary_path: str | None = None,
    junit_path: str | None = None,
    sarif_path: str | None = None,
) -> tuple[BatchRun, dict[str, Any]]:
    """Run ``plan`` on ``engine`` (through ``cache``) with a progress display titled by
    ``command``, then :func:`publish` it; returns the run and the JSON summary."""
    title = f"wrinklepipe {command}: {plural(len(plan.jobs), 'asset')}"
    with BatchProgress(console, len(plan.jobs), title) as progress:
        run = run_plan(
            plan,
            engine,
            cache,
            progress.stage,
            progress.done,
            lambda text: console.print(f"[yellow]warning:[/] {escape(text)}", soft_wrap=True),
        )
    doc = publish(
        run,
        plan,
        command=command,
        engine=engine.description,
        console=console,
        summary_path=summary_path,
        junit_path=junit_path,
        sarif_path=sarif_path,
    )
    return run, doc


def publish(
    run: BatchRun,
    plan: BatchPlan,
    *,
    command: str,
    engine: str,
    console: Console,
    summary_path: str | None = None,
    junit_path: str | None = None,
    sarif_path: str | None = None,
) -> dict[str, Any]:
    """Write the requested reports (locked, atomically, never over an input), print the tally;
    returns the JSON summary."""
    doc = reports.summary(
        run.results,
        command=command,
        root=plan.root,
        output=plan.output,
        engine=engine,
        seconds=run.seconds,
        cache=run.cache.to_json() if run.cache else None,
    )
    inputs = [j.manifest for j in plan.jobs if j.kind == "convert"]
    if summary_path:
        write_output(summary_path, dumps_json(doc).encode("utf-8"), inputs)
    if junit_path:
        suite = f"wrinklepipe {command}"
        write_output(
            junit_path, reports.junit_xml(run.results, suite=suite, seconds=run.seconds), inputs
        )
    if sarif_path:
        log = reports.sarif_log(run.results, root=plan.root, output=plan.output, command=command)
        write_output(sarif_path, dumps_json(log).encode("utf-8"), inputs)
    c = doc["counts"]
    parts = [plural(c["assets"], "asset"), f"[green]{c['passed']} passed[/]"]
    if c["failed"]:
        parts.append(f"[yellow]{c['failed']} failed validation[/]")
    if c["error"]:
        parts.append(f"[bold red]{c['error']} could not run[/]")
    how = []
    for source, label in (
        ("converted", "converted"),
        ("cache", "from cache"),
        ("validated", "validated"),
    ):
        if c[source]:
            how.append(f"{c[source]} {label}")
    tail = f" ({', '.join(how)})" if how else ""
    line = f"{', '.join(parts)}{tail} in {run.seconds:.1f} s on {engine}"
    (problem if c["failed"] or c["error"] else info)(line, markup=True)
    return doc
