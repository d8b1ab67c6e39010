"""Benchmark ``convert``: the 2048^2 demo's whole conversion against the I/O it cannot avoid.

Baseline (same run): **decoding its inputs** (``ingest``: the 16-bit maps, the masks, the mesh)
plus **encoding its outputs** (the shipped package read back from the folder convert wrote,
encoded again: every PNG at the level convert writes, every block-compressed map in the format
convert chose, the glTF JSON and buffer, the USD layer). Steps:

* ``convert (whole)``: ``convert`` with its defaults (validation and render pass included);
  limit 3x the baseline;
* ``convert: <stage>``: the stages of that run, from its own stage announcements (``validating``
  includes writing the folder; the automatic choices, fidelity's, are their own stage).

Each step runs once (a 2048 convert is a minute of work). ``extra.cpu_s`` holds each step's
CPU seconds (all threads): on a shared machine the wall times grow with the load, the CPU
times much less (the limit is still on the wall-time ratio).
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from wrinklepipe.bench import BenchResult, BenchRow, benchmark
from wrinklepipe.console import stage_listener
from wrinklepipe.demo.source import demo_source_dir
from wrinklepipe.io.gltf_write import gltf_document
from wrinklepipe.io.package import png_bytes
from wrinklepipe.io.usd_write import write_usd
from wrinklepipe.manifest import load_manifest
from wrinklepipe.normals.compress import encode_bc, pack_rgba, pad_to_blocks
from wrinklepipe.pipeline.convert import convert
from wrinklepipe.pipeline.ingest import ingest
from wrinklepipe.sources.package import read_package

BASELINE = "decode inputs + encode outputs"
WHOLE = "convert (whole)"
_BLOCK = ("bc1", "bc3nm", "bc5", "bc7")
_GROUP = {"base_normal": "base", "state": "wrinkle"}


def _timed(fn: Callable[[], Any], cpu: dict[str, float], name: str) -> tuple[float, Any]:
    """Wall seconds and result of ``fn()``; its CPU seconds (all threads) go in ``cpu[name]``."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    cpu[name] = round(time.process_time() - c0, 3)
    return time.perf_counter() - t0, out


def _encode_outputs(pkg: Any, chosen: dict[str, str], folder: Path) -> None:
    for t in pkg.textures:
        png_bytes(t.pixels)
        fmt = chosen.get(_GROUP.get(t.role, ""), "png")
        if fmt in _BLOCK and t.bits == 8:
            padded, _ = pad_to_blocks(t.pixels[..., :2])
            encode_bc(pack_rgba(padded, fmt), fmt)
    gltf_document(pkg)
    write_usd(pkg, folder / f"{pkg.name}.usda", write_textures=False)


@benchmark("convert", "convert the 2048^2 demo against decoding its inputs + encoding its outputs")
def bench_convert(quick: bool = False) -> BenchResult:
    size = 64 if quick else 2048
    load_before = os.getloadavg()
    manifest = demo_source_dir(size)
    stages: dict[str, float] = {}
    cpu: dict[str, float] = {}  # CPU seconds (all threads): what a shared machine cannot inflate
    current: list[Any] = [None, 0.0, 0.0]

    def on_stage(name: str) -> None:
        now, c = time.perf_counter(), time.process_time()
        if current[0] is not None:
            stages[current[0]] = stages.get(current[0], 0.0) + now - current[1]
            key = f"convert: {current[0]}"
            cpu[key] = round(cpu.get(key, 0.0) + c - current[2], 3)
        current[:] = [name, now, c]

    with tempfile.TemporaryDirectory() as work:
        w = Path(work)
        with stage_listener(on_stage):
            t_convert, result = _timed(lambda: convert(manifest, w / "out"), cpu, WHOLE)
        on_stage("")
        m = load_manifest(manifest)
        t_decode, _ = _timed(lambda: ingest(m), cpu, "decode inputs (ingest)")
        pkg = read_package(w / "out")
        chosen = {g: c["chosen"] for g, c in result.report.get("compression", {}).items()}
        (w / "enc").mkdir()
        t_encode, _ = _timed(
            lambda: _encode_outputs(pkg, chosen, w / "enc"),
            cpu,
            "encode outputs (PNG, BC, glTF, USD)",
        )
    res = BenchResult(
        "convert",
        f"demo at {size}^2 (wrinkle = auto, validation with the render pass)"
        + (" (quick)" if quick else ""),
        baseline=BASELINE,
    )
    res.rows = [
        BenchRow(BASELINE, t_decode + t_encode),
        BenchRow("decode inputs (ingest)", t_decode),
        BenchRow("encode outputs (PNG, BC, glTF, USD)", t_encode),
        BenchRow(WHOLE, t_convert),
        *[BenchRow(f"convert: {k}", v) for k, v in stages.items() if k],
    ]
    if not quick:
        res.limits = {WHOLE: 3.0}
    res.extra = {
        "size": size,
        "compression": chosen,
        "cores": os.cpu_count(),
        "cpu_s": cpu,
        "load_average_before": [round(x, 2) for x in load_before],
        "load_average_after": [round(x, 2) for x in os.getloadavg()],
    }
    return res.finish()
