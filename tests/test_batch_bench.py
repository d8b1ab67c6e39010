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
    # every converted asset reports its worker's CPU seconds; the cold steps are their sum
    # (and this process's), the cached rerun's only this process's (nothing converted)
    per_asset = res.extra["asset_cpu_s_jobs1"]
    assert len(per_asset) == 3 and all(s > 0 for s in per_asset.values())
    cpu = res.extra["cpu_s"]
    assert cpu["--jobs 1, cold"] >= round(sum(per_asset.values()), 2) - 0.01
    assert cpu["--jobs 2, cold"] > 0 and cpu["--jobs 2, cached rerun"] < cpu["--jobs 2, cold"]


def test_convert_bench_quick_runs():
    res = load_all()["convert"][1](True)
    steps = [r.step for r in res.rows]
    assert steps[:4] == [
        "decode inputs + encode outputs",
        "decode inputs (ingest)",
        "encode outputs (PNG, BC with mip chains, glTF, USD)",
        "convert (whole)",
    ]
    assert "convert: validating" in steps
    base = res.rows[0].median_s
    assert base == pytest.approx(res.rows[1].median_s + res.rows[2].median_s)
    assert res.rows[3].ratio > 1  # converting costs more than its I/O alone
    # the mip chains are encoded too: more than the level-0-only baseline of older records
    cpu = res.extra["cpu_s"]
    assert cpu["encode outputs (PNG, BC with mip chains, glTF, USD)"] > 0
    assert res.extra["level0_baseline_s"] > 0 and res.extra["cpu_ratio"] > 1
