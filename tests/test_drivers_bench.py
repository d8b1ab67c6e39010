"""Smoke run of the masks / drivers benchmarks in quick mode (performance is not asserted here)."""

from __future__ import annotations

from wrinklepipe.bench import load_all


def test_benchmarks_run_quick():
    reg = load_all()
    for name in ("masks-pack", "drivers"):
        res = reg[name][1](True)
        assert res.rows and all(r.median_s > 0 for r in res.rows)
        assert any(r.step == res.baseline for r in res.rows)
