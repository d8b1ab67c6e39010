"""Smoke run of ``wrinklepipe bench output-write --quick`` (performance is the benchmark's job)."""

from __future__ import annotations

import json

from wrinklepipe.cli import main


def test_output_bench_quick(capsys):
    assert main(["bench", "output-write", "--quick", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    result = out[0] if isinstance(out, list) else out.get("results", out)
    result = result[0] if isinstance(result, list) else result
    steps = {r["step"] for r in result["rows"]}
    assert {"zlib level 6 of raw texels", "png_bytes (ours, all textures)", "read_usd"} <= steps
    base = next(r for r in result["rows"] if r["step"] == "zlib level 6 of raw texels")
    assert base["ratio"] == 1.0
