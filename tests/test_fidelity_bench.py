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
    assert search["median_s"] > 0
    # the choices on the 256^2 demo since the searches were built (the faster measure keeps
    # them; the 2048^2 run records its own: 512^2 states, 128^2 masks, 0.640625, BC5, BC7)
    assert search["note"] == "chose 256^2 states, 128^2 masks, scale 0.5, base png, states bc5"
    cpu = steps["automatic searches, CPU"]
    assert cpu["median_s"] > 0 and result["extra"]["cpu_ratio"] > 0
