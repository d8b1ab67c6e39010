"""Benchmark ``convert``: the 2048^2 demo's whole conversion against the I/O it cannot avoid.

Baseline (same run): **decoding its inputs** (``ingest``: the 16-bit maps, the masks, the mesh)
plus **encoding its outputs** (the shipped package read back from the folder convert wrote,
encoded again: every PNG at the level convert writes, every block-compressed map in the format
convert chose with its mip chain as the DDS / KTX2 copies hold it (the levels decoded from the
written DDS and encoded again, the way convert encodes them; KTX2 holds the same blocks), the
glTF JSON and buffer, the USD layer). Until 2026-12-02 the baseline encoded level 0 only, which
left out a quarter of the block-compressed bytes convert must write; ``extra`` keeps that
baseline's time and the ratios to it for comparison with older records. Steps:

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

import numpy as np

from wrinklepipe.bench import BenchResult, BenchRow, benchmark
from wrinklepipe.console import stage_listener
from wrinklepipe.demo.source import demo_source_dir
from wrinklepipe.gltf.package_write import gltf_document
from wrinklepipe.io.png import png_bytes
from wrinklepipe.jobs.convert import convert
from wrinklepipe.normals.bc4 import encode_bc5_many
from wrinklepipe.normals.compress import decode_bc, encode_bc, pack_rgba, pad_to_blocks
from wrinklepipe.normals.dds import mip_dims, read_dds
from wrinklepipe.pipeline.ingest import ingest
from wrinklepipe.sources.manifest import load_manifest
from wrinklepipe.sources.package import read_package
from wrinklepipe.usd.package_write import write_usd

BASELINE = "decode inputs + encode outputs"
WHOLE = "convert (whole)"
ENCODE = "encode outputs (PNG, BC with mip chains, glTF, USD)"
LEVEL0 = "encode outputs, BC level 0 only (the baseline before 2026-12-02)"
_BLOCK = ("bc1", "bc3nm", "bc5", "bc7")
_GROUP = {"base_normal": "base", "state": "wrinkle"}


def _timed(fn: Callable[[], Any], cpu: dict[str, float], name: str) -> tuple[float, Any]:
    """Wall seconds and result of ``fn()``; its CPU seconds (all threads) go in ``cpu[name]``."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    cpu[name] = round(time.process_time() - c0, 3)
    return time.perf_counter() - t0, out


def _mip_levels(out: Path) -> list[tuple[str, list[np.ndarray]]]:
    """Per DDS copy convert wrote: its format and the RGBA texels of its mip levels 1..
    (decoded from the file: what the baseline encodes again; level 0 comes from the package)."""
    got = []
    for f in sorted((out / "compressed").glob("*.dds")):
        img = read_dds(f)
        fmt = "bc3nm" if img.format == "bc3" else img.format
        levels = []
        for data, (w, h) in zip(
            img.levels[1:], mip_dims(img.width, img.height, len(img.levels))[1:]
        ):
            levels.append(decode_bc(data, -(-w // 4) * 4, -(-h // 4) * 4, fmt))
        got.append((fmt, levels))
    return got


def _encode_outputs(
    pkg: Any, chosen: dict[str, str], folder: Path, mips: list[tuple[str, list[np.ndarray]]]
) -> None:
    for t in pkg.textures:
        png_bytes(t.pixels)
        fmt = chosen.get(_GROUP.get(t.role, ""), "png")
        if fmt in _BLOCK and t.bits == 8:
            padded, _ = pad_to_blocks(t.pixels[..., :2])
            encode_bc(pack_rgba(padded, fmt), fmt)
    for fmt, levels in mips:  # the copies' mip chains, encoded as convert encodes them
        if fmt == "bc5":
            encode_bc5_many([(a[..., 0], a[..., 1]) for a in levels])
        else:
            for a in levels:
                encode_bc(a, fmt)
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
        mips = _mip_levels(w / "out")
        # first the baseline as recorded before the mip chains were counted (level 0 only;
        # first, as it ran then: it pays the encoders' first-call costs, not the new one)
        (w / "enc0").mkdir()
        t_level0, _ = _timed(lambda: _encode_outputs(pkg, chosen, w / "enc0", []), cpu, LEVEL0)
        (w / "enc").mkdir()
        t_encode, _ = _timed(
            lambda: _encode_outputs(pkg, chosen, w / "enc", mips),
            cpu,
            ENCODE,
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
        BenchRow(ENCODE, t_encode),
        BenchRow(WHOLE, t_convert),
        *[BenchRow(f"convert: {k}", v) for k, v in stages.items() if k],
    ]
    if not quick:
        res.limits = {WHOLE: 3.0}
    t_old = t_decode + t_level0
    cpu_old = cpu["decode inputs (ingest)"] + cpu[LEVEL0]
    cpu_new = cpu["decode inputs (ingest)"] + cpu[ENCODE]
    res.extra = {
        "size": size,
        "compression": chosen,
        "cores": os.cpu_count(),
        "cpu_s": cpu,
        "cpu_ratio": round(cpu[WHOLE] / cpu_new, 3),
        # for comparison with records made before the mip chains were counted
        "level0_baseline_s": round(t_old, 3),
        "ratio_to_level0_baseline": round(t_convert / t_old, 3),
        "cpu_ratio_to_level0_baseline": round(cpu[WHOLE] / cpu_old, 3),
        "load_average_before": [round(x, 2) for x in load_before],
        "load_average_after": [round(x, 2) for x in os.getloadavg()],
    }
    return res.finish()
