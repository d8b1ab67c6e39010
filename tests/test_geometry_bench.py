"""Smoke run of ``wrinklepipe bench geometry --quick`` (speed itself is the benchmark's job)."""

from __future__ import annotations

from wrinklepipe.bench import load_all


def test_geometry_bench_quick_runs():
    res = load_all()["geometry"][1](True)
    steps = {r.step for r in res.rows}
    assert {"vertex IDs (file order)", "unique_rows (file order)", "dynamic frame"} <= steps
    assert res.extra["distinct_ids"] == res.extra["unique_rows_groups"]
    assert all(r.median_s > 0 for r in res.rows)
