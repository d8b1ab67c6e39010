"""Smoke run of ``wrinklepipe bench batch --quick`` (the speed-ups are the benchmark's job)."""

from __future__ import annotations

import pytest

from wrinklepipe.bench import load_all


def test_batch_bench_quick_runs():
    res = load_all()["batch"][1](True)
    steps = [r.step for r in res.rows]
    assert steps == ["--jobs 1, cold", "--jobs 2, cold", "--jobs 2, cached rerun"]
    assert res.extra["assets"] == 3 and res.extra["identical"]  # quick: 3 of the 8 variants
    assert res.extra["converted_in_cached_rerun"] == 0
    assert res.extra["statuses"] == ["passed"]
    assert res.rows[0].ratio == 1.0 and res.failures() == []


def test_convert_bench_quick_runs():
    res = load_all()["convert"][1](True)
    steps = [r.step for r in res.rows]
    assert steps[:4] == [
        "decode inputs + encode outputs",
        "decode inputs (ingest)",
        "encode outputs (PNG, BC, glTF, USD)",
        "convert (whole)",
    ]
    assert "convert: validating" in steps
    base = res.rows[0].median_s
    assert base == pytest.approx(res.rows[1].median_s + res.rows[2].median_s)
    assert res.rows[3].ratio > 1  # converting costs more than its I/O alone
