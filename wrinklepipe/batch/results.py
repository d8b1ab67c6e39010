"""What became of one asset: plain data, picklable, the same however the asset ran."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from wrinklepipe.validate.catalogue import SEVERITIES

#: status -> exit code: passed (written, no issue at or above fail_on), failed (written, but
#: validation found such issues), error (could not run: nothing written).
EXIT_CODES = {"passed": 0, "failed": 1, "error": 2}


@dataclass
class AssetResult:
    """One asset's outcome.

    ``source``: ``converted`` (ran here or on a worker), ``cache`` (restored), ``validated``
    (validate-asset on an existing output) or ``none`` (could not run). ``problems``: why it
    could not run (file, key, message); ``issues``: validation issues (code, severity, message,
    pointer, fix). ``stages``: seconds per stage, in order. ``cpu_seconds``: CPU time (all
    threads) of the process that ran it, while it ran (on a Dask worker running several tasks
    at once, theirs too); 0 when restored from the cache."""

    id: str
    manifest: str
    output: str
    status: str
    source: str
    name: str = ""
    fail_on: str = "error"
    seconds: float = 0.0
    cpu_seconds: float = 0.0
    stages: dict[str, float] = field(default_factory=dict)
    problems: list[dict[str, str]] = field(default_factory=list)
    issues: list[dict[str, Any]] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    key: str = ""
    validation: str = ""  # "ran" | "skipped" | ""
    worker: str = ""

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.status]

    def failing_issues(self) -> list[dict[str, Any]]:
        """The issues at or above ``fail_on``."""
        limit = SEVERITIES.index(self.fail_on)
        return [i for i in self.issues if SEVERITIES.index(i.get("severity", "info")) <= limit]

    @classmethod
    def could_not_run(
        cls, job: Any, problems: list[dict[str, str]], worker: str = ""
    ) -> AssetResult:
        """The result of a :class:`~wrinklepipe.batch.plan.Job` that could not run:
        ``status="error"``, nothing written, with its ``problems`` (file, key, message)."""
        return cls(
            id=job.id,
            manifest=job.manifest_rel,
            output=job.id,
            status="error",
            source="none",
            fail_on=job.options.fail_on,
            problems=problems,
            worker=worker,
        )

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["exit_code"] = self.exit_code
        return out


def status_for(issues: list[dict[str, Any]], fail_on: str) -> str:
    """``failed`` when an issue is at or above ``fail_on``, else ``passed``."""
    limit = SEVERITIES.index(fail_on)
    bad = any(SEVERITIES.index(i.get("severity", "info")) <= limit for i in issues)
    return "failed" if bad else "passed"


def counts_of(issues: list[dict[str, Any]]) -> dict[str, int]:
    return {s: sum(i.get("severity") == s for i in issues) for s in SEVERITIES}


def worst_exit_code(results: list[AssetResult]) -> int:
    """The batch's exit code: the worst asset's (0 when there are none)."""
    return max((r.exit_code for r in results), default=0)
