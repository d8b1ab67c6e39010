"""Benchmarks of the output stage: PNG encoding, glTF/GLB and USD writing, both readers.

Baseline: ``zlib.compress`` at the PNG level wrinklepipe writes (``DEFAULT_PNG_LEVEL``, 6) of
the raw texel bytes of every texture of the package, the irreducible cost of any lossless PNG
writer at that level. Our PNG encoder (Up filter, numpy) is
reported against it, next to OpenImageIO's PNG writer on the same texels, and the whole writers
and readers are reported as ratios to the same baseline.
"""

from __future__ import annotations

import tempfile
import zlib
from pathlib import Path

from wrinklepipe.bench import BenchResult, BenchRow, benchmark, median_time
from wrinklepipe.demo.package import demo_package
from wrinklepipe.gltf.package_read import read_wrinkled
from wrinklepipe.gltf.package_write import glb_bytes, gltf_document, write_gltf
from wrinklepipe.io.images import write_image
from wrinklepipe.io.png import DEFAULT_PNG_LEVEL, png_bytes
from wrinklepipe.usd.package_read import read_usd
from wrinklepipe.usd.package_write import build_stage, write_usd

ZLIB_STEP = f"zlib level {DEFAULT_PNG_LEVEL} of raw texels"


@benchmark("output-write", "glTF/GLB/USD writers and readers on the demo (1024^2 maps)")
def bench_output(quick: bool = False) -> BenchResult:
    size = 256 if quick else 1024
    repeat = 3 if quick else 5
    pkg = demo_package(size)
    texels = sum(t.pixels.shape[0] * t.pixels.shape[1] for t in pkg.textures)
    mpix = texels / 1e6
    res = BenchResult(
        "output-write",
        f"demo package, maps {size}^2, {len(pkg.textures)} textures, {pkg.mesh.vertex_count} "
        "vertices" + (" (quick)" if quick else ""),
        baseline=ZLIB_STEP,
    )
    raw = [t.pixels.tobytes() for t in pkg.textures]

    def zlib_all() -> None:
        for r in raw:
            zlib.compress(r, DEFAULT_PNG_LEVEL)

    def usda_text() -> str:
        stage = build_stage(pkg)  # keep the stage alive while its layer is exported
        return stage.GetRootLayer().ExportToString()

    def png_all() -> None:
        for t in pkg.textures:
            png_bytes(t.pixels)

    with tempfile.TemporaryDirectory() as work:
        w = Path(work)

        def oiio_all() -> None:
            for t in pkg.textures:
                write_image(w / f"oiio_{t.name}.png", t.pixels.astype("float32") / 255.0, 8)

        write_gltf(pkg, w / "g", "demo")
        write_usd(pkg, w / "u" / "demo.usda")
        rows = [
            (ZLIB_STEP, median_time(zlib_all, repeat), mpix),
            ("png_bytes (ours, all textures)", median_time(png_all, repeat), mpix),
            ("OpenImageIO PNG writer (all textures)", median_time(oiio_all, repeat), mpix),
            ("gltf_document (+PNGs)", median_time(lambda: gltf_document(pkg), repeat), mpix),
            (
                "GLB bytes",
                median_time(lambda: glb_bytes(*gltf_document(pkg, embed_images=True)[:2]), repeat),
                mpix,
            ),
            (
                "USD stage build + usda text",
                median_time(usda_text, repeat),
                None,
            ),
            (
                "read_wrinkled (glTF package)",
                median_time(lambda: read_wrinkled(w / "g" / "demo.gltf"), repeat),
                mpix,
            ),
            ("read_usd", median_time(lambda: read_usd(w / "u" / "demo.usda"), repeat), mpix),
        ]
    for step, t, mp in rows:
        res.rows.append(BenchRow(step, t, mpix_per_s=(mp / t) if mp else None))
    if not quick:
        res.limits = {"png_bytes (ours, all textures)": 1.5}
    res.extra = {"size": size, "texels": texels, "vertices": pkg.mesh.vertex_count}
    return res.finish()
