"""Smoke run of ``wrinklepipe bench fidelity --quick`` (performance is the benchmark's job)."""

from __future__ import annotations

import json

from wrinklepipe.cli import main


def test_fidelity_bench_quick(capsys):
    assert main(["bench", "fidelity", "--quick", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)["results"][0]
    steps = {r["step"]: r for r in result["rows"]}
    assert steps["full-resolution blend of every pose"]["ratio"] == 1.0
    search = steps["automatic searches (size, scale, masks, formats)"]
    assert search["median_s"] > 0 and "states" in search["note"]
