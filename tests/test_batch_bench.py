"""Smoke run of ``wrinklepipe bench batch --quick`` (the speed-ups are the benchmark's job)."""

from __future__ import annotations

from wrinklepipe.bench import load_all


def test_batch_bench_quick_runs():
    res = load_all()["batch"][1](True)
    steps = [r.step for r in res.rows]
    assert steps == ["--jobs 1, cold", "--jobs 2, cold", "--jobs 2, cached rerun"]
    assert res.extra["assets"] == 8 and res.extra["identical"]
    assert res.extra["converted_in_cached_rerun"] == 0
    assert res.extra["statuses"] == ["passed"]
    assert res.rows[0].ratio == 1.0 and res.failures() == []
