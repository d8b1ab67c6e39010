"""Named benchmarks for ``wrinklepipe bench``: medians and ratios against a same-run baseline.

Each module in this package registers functions with :func:`benchmark`. A benchmark function takes
``quick: bool`` (smaller sizes, for the test suite's smoke run) and returns a :class:`BenchResult`
whose rows are timed steps; one row is the baseline and every row reports ``ratio`` to it, so the
numbers compare across machines. ``limits`` are the ratios the issue asks for, checked and shown.
"""

from __future__ import annotations

import importlib
import pkgutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class BenchRow:
    step: str
    median_s: float
    ratio: float = float("nan")  # median / baseline median
    mpix_per_s: float | None = None
    note: str = ""


@dataclass
class BenchResult:
    name: str
    description: str
    baseline: str
    rows: list[BenchRow] = field(default_factory=list)
    limits: dict[str, float] = field(default_factory=dict)  # step -> max ratio to the baseline
    limits_s: dict[str, float] = field(default_factory=dict)  # step -> max median seconds
    #: step -> (another step, max ratio of the two medians): a limit against a second reference
    limits_to: dict[str, tuple[str, float]] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)
    #: failures the benchmark found itself (a limit that is not a time: memory, an exit code)
    extra_failures: list[str] = field(default_factory=list)

    def finish(self) -> BenchResult:
        base = next((r.median_s for r in self.rows if r.step == self.baseline), None)
        for r in self.rows:
            if base:
                r.ratio = r.median_s / base
        return self

    def failures(self) -> list[str]:
        out = list(self.extra_failures)
        for step, limit in self.limits.items():
            row = next((r for r in self.rows if r.step == step), None)
            if row is not None and not row.ratio <= limit:
                out.append(f"{self.name}: {step} ratio {row.ratio:.2f} > {limit}")
        for step, seconds in self.limits_s.items():
            row = next((r for r in self.rows if r.step == step), None)
            if row is not None and not row.median_s <= seconds:
                out.append(f"{self.name}: {step} {row.median_s:.4g} s > {seconds:g} s")
        for step, (ref, limit) in self.limits_to.items():
            ratio = self.ratio_to(step, ref)
            if ratio is not None and not ratio <= limit:
                out.append(f"{self.name}: {step} is {ratio:.3g}x {ref} > {limit:g}x")
        return out

    def ratio_to(self, step: str, ref: str) -> float | None:
        """Median of ``step`` over the median of ``ref`` (None when either is missing)."""
        a = next((r.median_s for r in self.rows if r.step == step), None)
        b = next((r.median_s for r in self.rows if r.step == ref), None)
        return None if a is None or not b else a / b

    def limit_text(self, step: str) -> str:
        """How the limits on ``step`` read in a table: ``<= 4x``, ``<= 2 ms``, both, or ''."""
        parts = []
        if step in self.limits:
            parts.append(f"<= {self.limits[step]:g}x")
        if step in self.limits_s:
            s = self.limits_s[step]
            parts.append(f"<= {s * 1e3:g} ms" if s < 1 else f"<= {s:g} s")
        if step in self.limits_to:
            ref, limit = self.limits_to[step]
            ratio = self.ratio_to(step, ref)
            got = f" (is {ratio:.3g}x)" if ratio is not None else ""
            parts.append(f"<= {limit:g}x {ref}{got}")
        return ", ".join(parts)

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "description": self.description,
            "baseline": self.baseline,
            "rows": [
                {
                    "step": r.step,
                    "median_s": r.median_s,
                    "ratio": r.ratio,
                    "mpix_per_s": r.mpix_per_s,
                    "note": r.note,
                }
                for r in self.rows
            ],
            "limits": self.limits,
            "limits_s": self.limits_s,
            "limits_to": {k: list(v) for k, v in self.limits_to.items()},
            "failures": self.failures(),
            "extra": self.extra,
        }


BenchFn = Callable[[bool], BenchResult]
BENCHMARKS: dict[str, tuple[str, BenchFn]] = {}


def benchmark(name: str, description: str) -> Callable[[BenchFn], BenchFn]:
    """Register a benchmark under ``name``."""

    def wrap(fn: BenchFn) -> BenchFn:
        BENCHMARKS[name] = (description, fn)
        return fn

    return wrap


def median_time(fn: Callable[[], Any], repeat: int = 5, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` over ``repeat`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def load_all() -> dict[str, tuple[str, BenchFn]]:
    """Import every benchmark module so they register, then return the registry."""
    for info in pkgutil.iter_modules(__path__):
        if not info.name.startswith("_"):
            importlib.import_module(f"{__name__}.{info.name}")
    return BENCHMARKS
