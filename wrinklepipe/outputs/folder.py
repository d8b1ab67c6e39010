"""The convert folder's files: glTF (+GLB), PNG textures, block-compressed copies, curves, USD.

:func:`build_outputs` returns every file but the USD layers as ``{relative path: bytes}``;
:func:`write_folder` writes them (and the USD, through usd-core) into a staged folder.

The glTF: for a glTF source, the source document with the wrinkle data added
(:func:`wrinklepipe.gltf.wrinkle_maps.add_wrinkle_maps`, written by
:func:`wrinklepipe.gltf.write.document_files`: every untouched element as it was, images
byte for byte); for other sources (OBJ, USD) a new document of the package
(:func:`wrinklepipe.gltf.package_write.gltf_document`).
"""

from __future__ import annotations

import copy
import functools
from dataclasses import replace
from pathlib import Path
from typing import Any

from wrinklepipe import reuse
from wrinklepipe.atomic import dumps_json, write_bytes
from wrinklepipe.color.copies import ColorCopy
from wrinklepipe.gltf.document import Document
from wrinklepipe.gltf.package_write import GltfOptions, glb_bytes, gltf_document
from wrinklepipe.gltf.wrinkle_maps import WrinkleTarget, add_wrinkle_maps
from wrinklepipe.gltf.write import document_files
from wrinklepipe.io.png import DEFAULT_PNG_LEVEL, png_bytes
from wrinklepipe.normals.copies import files as copy_files
from wrinklepipe.normals.copies import records as copy_records
from wrinklepipe.options import BudgetOptions, FormatOptions
from wrinklepipe.outputs.compression import compressed_copies
from wrinklepipe.outputs.curves import curve_files
from wrinklepipe.package import WrinklePackage
from wrinklepipe.udim import untiled_copies
from wrinklepipe.usd.layer import (
    flattened_usdz,
    layer_bytes,
    layer_stage,
    source_reference,
)
from wrinklepipe.usd.materialx import package_files
from wrinklepipe.usd.package_write import UsdOptions, build_stage, write_usd
from wrinklepipe.usd.scene import add_scene, wrinkled_prims
from wrinklepipe.usd.source import UsdSource

#: The USD layers convert can add beside the always-written ``.usda``.
USD_FORMATS: tuple[str, ...] = ("usda", "usdc", "usdz")


def document_outputs(
    source: Document,
    target: WrinkleTarget,
    pkg: WrinklePackage,
    glb: bool,
    png_level: int = DEFAULT_PNG_LEVEL,
) -> tuple[dict[str, bytes], list[str]]:
    """``NAME.gltf`` + ``NAME.bin`` + images (and ``NAME.glb``): the source document with the
    package's wrinkle data added (the source document object is left as it was)."""
    doc = copy.copy(source)
    doc.gltf = copy.deepcopy(source.gltf)
    doc.views = list(source.views)
    doc.images = dict(source.images)
    notes = add_wrinkle_maps(doc, target, pkg, png_level)
    files = document_files(doc, pkg.name, glb=False)
    if glb:
        files.update(document_files(doc, pkg.name, glb=True))
    return files, notes


def build_outputs(
    pkg: WrinklePackage,
    glb: bool = False,
    compressed: bool = True,
    budget: BudgetOptions | None = None,
    formats: FormatOptions | None = None,
    source: tuple[Document, WrinkleTarget] | None = None,
    png_level: int = DEFAULT_PNG_LEVEL,
    color_copies: list[ColorCopy] | None = None,
) -> tuple[dict[str, bytes], list[str], dict[str, Any]]:
    """Every output file as ``{relative path: bytes}`` (except USD, written by usd-core), notes,
    and the block-format choices. ``glb``: also a self-contained ``NAME.glb``; ``compressed``:
    DDS + KTX2 copies (:func:`wrinklepipe.outputs.compression.compressed_copies`), recorded in
    ``pkg.meta.compressed`` (``pkg.meta`` is replaced) before the glTF is written, with the
    colour maps' sRGB copies ``color_copies`` (made in the format chosen by CIEDE2000,
    :func:`wrinklepipe.pipeline.color.choose_color_format`); ``source``: the glTF source
    document and where its wrinkle data goes (see the module doc); every PNG at zlib
    ``png_level``."""
    name = pkg.name
    files: dict[str, bytes] = {}
    notes: list[str] = []
    choices: dict[str, Any] = {}
    # the PNGs (zlib, off the GIL) encode on another core while the block copies are made;
    # the document and the textures folder below then take them from the run's memo
    pngs_ready = reuse.warm(
        [functools.partial(png_bytes, t.pixels, png_level) for t in pkg.textures]
    )
    if compressed:  # first: the glTF extension and the USD schema record the copies
        made, n, choices = compressed_copies(pkg, budget, formats)
        files.update(copy_files(made))
        notes += n
        records = copy_records(made)
        if pkg.tiles:  # one record per UDIM set (compressed/NAME.<UDIM>.dds)
            records = untiled_copies(records)
        for c in color_copies or []:
            files.update(c.files())
        if color_copies:
            records = tuple(
                sorted([*records, *(c.record() for c in color_copies)], key=lambda r: r.texture)
            )
        # the USD layers written next read the records from the same package
        pkg.meta = replace(pkg.meta, compressed=records)
    pngs_ready()
    if source is not None:
        got, n = document_outputs(source[0], source[1], pkg, glb, png_level)
        files.update(got)
        notes += n
    else:
        options = GltfOptions(png_level=png_level)
        doc, data, images = gltf_document(pkg, options)
        doc["buffers"][0]["uri"] = f"{name}.bin"
        files[f"{name}.gltf"] = dumps_json(doc).encode("utf-8")
        files[f"{name}.bin"] = data
        files.update(images)
        if glb:
            gdoc, gdata, _ = gltf_document(pkg, options, embed_images=True)
            files[f"{name}.glb"] = glb_bytes(gdoc, gdata)
    for t in pkg.textures:  # the same PNGs serve glTF and USD
        files.setdefault(f"textures/{t.name}.png", png_bytes(t.pixels, png_level))
    regions = pkg.meta.region_names
    taken: set[str] = set()
    for c in pkg.curves:
        files.update(curve_files(c, regions, taken))
    return files, notes, choices


def write_folder(
    folder: Path,
    files: dict[str, bytes],
    pkg: WrinklePackage,
    usd_format: str = "usda",
    source: tuple[Document, WrinkleTarget] | None = None,
    usd_source: UsdSource | None = None,
    final: Path | None = None,
    png_level: int = DEFAULT_PNG_LEVEL,
) -> list[str]:
    """Write ``files`` (sorted) under ``folder``, then ``NAME.usda`` and, when ``usd_format`` is
    ``usdc`` or ``usdz``, that layer too (textures are the PNGs already in ``files``).
    ``source``: a glTF source document, whose other parts the USD layers carry too
    (:func:`wrinklepipe.usd.scene.add_scene`); returns notes on what USD cannot hold.
    ``usd_source``: a USD source: ``NAME.usda`` (+ ``.usdc``) is a layer over it naming it
    relative to ``final`` (the folder ``folder`` becomes), and ``NAME.usdz`` that layer
    flattened (:mod:`wrinklepipe.usd.layer`). PNGs made here are at zlib ``png_level``."""
    if usd_source is not None:
        return _write_layered(
            folder, files, pkg, usd_format, usd_source, final or folder, png_level
        )
    stage = build_stage(pkg, with_mesh=source is None)
    extra: dict[str, bytes] = {}
    notes: list[str] = []
    if source is not None:
        extra, notes = add_scene(
            stage,
            stage.GetDefaultPrim().GetPath(),
            source[0],
            wrinkled_prims(stage, pkg, source[1].refs),
            "textures",
            png_level,
        )
    for rel, data in sorted({**files, **extra}.items()):
        write_bytes(folder / rel, data)
    usd_names = [f"{pkg.name}.usda"] + (
        [f"{pkg.name}.{usd_format}"] if usd_format != "usda" else []
    )
    for u in usd_names:
        write_usd(
            pkg,
            folder / u,
            UsdOptions(png_level=png_level),
            write_textures=False,
            stage=stage,
            extra=extra if u.endswith(".usdz") else None,
        )
    return notes


def _write_layered(
    folder: Path, files: dict[str, bytes], pkg: WrinklePackage, usd_format: str,
    usd_source: UsdSource, final: Path, png_level: int,
) -> list[str]:  # fmt: skip
    stage, notes = layer_stage(usd_source, pkg)
    ref = source_reference(usd_source.path, final)
    out = dict(files)
    out[f"{pkg.name}.usda"] = layer_bytes(stage, ref, ".usda")
    if usd_format == "usdc":
        out[f"{pkg.name}.usdc"] = layer_bytes(stage, ref, ".usdc")
    out[f"{pkg.name}.usdz"], n = flattened_usdz(stage, pkg, pkg.name, png_level, usd_source.path)
    out.update(package_files(pkg))  # the MaterialX document the layer's material names
    for rel, data in sorted(out.items()):
        write_bytes(folder / rel, data)
    return notes + n
