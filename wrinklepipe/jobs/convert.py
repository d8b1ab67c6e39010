"""``convert``: manifest -> stages -> one output folder, written atomically.

The composition, in order::

    ingest        manifest + files -> WrinkleAsset           wrinklepipe.pipeline.ingest
    prepare       resample, mesh (tangents, vertex IDs), PD  wrinklepipe.pipeline.prepare
    drivers       weight curves [T, R]                       wrinklepipe.pipeline.drivers
    package       encode + pack                              wrinklepipe.pipeline.package
    outputs       glTF (+GLB), PNG, DDS/KTX2, curves, USD    wrinklepipe.outputs.folder
    validate      the validator on what was written          wrinklepipe.jobs.validation
    report        report.json + report.html                  wrinklepipe.outputs.report

Everything is written into a temporary sibling folder that is renamed into place only when
complete (:func:`wrinklepipe.atomic.staged_folder`); inputs are never written; reruns are
byte-identical.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import (
    console,  # console.status is looked up per call (tests hook it)
    udim,
)
from wrinklepipe import fidelity as fd
from wrinklepipe.asset import WrinkleAsset
from wrinklepipe.atomic import staged_folder
from wrinklepipe.drivers.clips import describe_clip
from wrinklepipe.drivers.poses import driver_poses
from wrinklepipe.errors import input_error
from wrinklepipe.fidelity.ship import edge_texels
from wrinklepipe.io.png import DEFAULT_PNG_LEVEL
from wrinklepipe.jobs.validation import validate_output
from wrinklepipe.outputs.folder import USD_FORMATS, build_outputs, write_folder
from wrinklepipe.outputs.report import (
    convert_report,
    decode_errors,
    input_rows,
    output_rows,
    write_report,
)
from wrinklepipe.package import WeightCurves
from wrinklepipe.pipeline.auto import formats_by_fidelity
from wrinklepipe.pipeline.color import (
    choose_color_format,
    choose_color_size,
    color_reference,
)
from wrinklepipe.pipeline.drivers import evaluate_drivers
from wrinklepipe.pipeline.ingest import ingest_all
from wrinklepipe.pipeline.ingest_tiles import ingest_tiles
from wrinklepipe.pipeline.package import PackOptions, package_from_asset
from wrinklepipe.pipeline.prepare import prepare_mesh, run_stages
from wrinklepipe.pipeline.tiles import run_tile_stages
from wrinklepipe.reuse import forget_rows, reuse
from wrinklepipe.sources.manifest import load_manifest
from wrinklepipe.sources.manifest_tiles import tile_notes


@dataclass(frozen=True)
class ConvertOptions:
    """What ``convert`` writes.

    ``glb``: also a self-contained ``NAME.glb``. ``usd_format``: ``"usda"`` (always written) plus
    ``"usdc"`` or ``"usdz"`` on request. ``force``: replace a non-empty output folder.
    ``compressed``: DDS + KTX2 copies of the base and states (format chosen against the budget).
    ``validate``: run :mod:`wrinklepipe.validate` on the written folder (``render``: with its GPU
    render pass). ``bits``: PNG
    depth of the base and state maps. ``mask_layout``: None = the manifest's ``formats``.
    ``png_level``: zlib level of every PNG texture written (the validator's pictures are at
    :data:`wrinklepipe.validate.report.PICTURE_PNG_LEVEL`); the same level gives the same bytes.
    """

    glb: bool = False
    usd_format: str = "usda"
    force: bool = False
    compressed: bool = True
    validate: bool = True
    render: bool = True
    bits: int = 8
    mask_layout: str | None = None
    png_level: int = DEFAULT_PNG_LEVEL


@dataclass
class ConvertResult:
    """What convert wrote and found: the folder, report (as written to report.json), exit code."""

    output: Path
    report: dict[str, Any]
    exit_code: int


def clipped_texels(pkg: Any) -> dict[str, int]:
    """Per PD state: texels stored at the end of the range (:func:`edge_texels`), counted on the
    shipped 8-bit texels, as the validator counts them (WP-MAP-004)."""
    if pkg.meta.encoding != "pd":
        return {}
    tex = {t.name: t for t in pkg.textures}
    return {
        s.name: edge_texels(tex[s.texture].pixels)
        for s in pkg.meta.states
        if tex[s.texture].pixels.dtype == np.uint8
    }


def judged_poses(asset: WrinkleAsset, curves: list[WeightCurves]) -> list[fd.Pose]:
    """The poses the automatic choices judge: those the drivers produce (neutral aside), as
    the validator's fidelity rules and render pass take them."""
    return [fd.Pose(p.name, p.weights) for p in driver_poses(asset, curves) if p.name != "neutral"]


def verdict_notes(
    ingest_notes: list[str],
    stage_notes: list[str],
    drivers: list[dict[str, Any]],
    validation: dict[str, Any],
) -> list[str]:
    """The notes that matter to the verdict, each once (the terminal prints them, report.json
    and report.html hold them): why sizes were not searched, which clip of which file drove the
    poses (unless a rig rule's message says it: WP-WGT-004, WP-WGT-007), which UVs were
    generated."""
    said: set[str] = set()  # clips a rig rule's message names already
    for i in validation.get("issues", []):
        data = i.get("data", {})
        said.update([data["clip"]] if "clip" in data else data.get("clips", []))
    out = [n for n in ingest_notes if "UVs" in n and ("generat" in n or "project" in n)]
    out += stage_notes
    for d in drivers:
        clip = d.get("clip")
        if clip and clip.get("clip") not in said:
            out.append(f"drivers[{d['index']}] ({d['kind']}) read {describe_clip(clip)}")
    return list(dict.fromkeys(out))


def convert(
    manifest_path: str | Path, output: str | Path, options: ConvertOptions | None = None
) -> ConvertResult:
    """Run the whole pipeline on a manifest and write one output folder (atomically)."""
    opt = options or ConvertOptions()
    if opt.usd_format not in USD_FORMATS:
        raise ValueError(f"usd_format must be usda, usdc or usdz, got {opt.usd_format!r}")
    output = Path(output)
    manifest = load_manifest(manifest_path)
    if manifest.tiles:
        return _convert_tiles(manifest, output, opt)
    inputs = [manifest.root, *manifest.input_files]
    try:
        # The output checks (not an input, empty or --force) run first, before any work.
        with (
            staged_folder(output, force=opt.force, inputs=inputs) as tmp,
            reuse(),  # a resample, PNG or block encoding asked twice is computed once
        ):
            with console.status("reading inputs"):
                got = ingest_all(manifest)
            asset, notes = got.asset, got.notes
            source = asset  # as read: what validation measures the shipped maps against
            document = (got.document, got.target) if got.document is not None else None
            with console.status("evaluating drivers"):
                # before the choices: they are judged on the poses the drivers produce (the
                # curves depend on the regions and the mesh, not on the sizes chosen)
                if asset.mesh is not None and asset.mesh.uvs is not None:
                    asset = replace(asset, mesh=prepare_mesh(asset.mesh))
                curves, drivers_notes = evaluate_drivers(asset, manifest.root, manifest.path)
            records = [c.driver for c in curves if c.driver is not None]
            if records:  # what the drivers read: the validator's rig rules say it
                source = replace(source, provenance={**source.provenance, "drivers": records})
            poses = judged_poses(asset, curves)
            with console.status("choosing sizes, scale and formats by fidelity"):
                asset, stage_rep = run_stages(
                    asset,
                    auto_scale=manifest.pd_scale == "auto",
                    formats=manifest.formats,
                    compressed=opt.compressed,
                    poses=poses,
                )
            notes += stage_rep.notes + drivers_notes
            color_choice = color_format = color_ref = None
            if asset.color is not None:
                with console.status("choosing the colour states' size by CIEDE2000"):
                    color_ref = color_reference(source, poses)
                    asset, color_choice = choose_color_size(source, asset, poses, color_ref)
                notes.append(color_choice.describe())
            layout = opt.mask_layout or manifest.formats.mask_layout
            with console.status("encoding the maps and packing the masks"):
                pkg = package_from_asset(
                    asset, PackOptions(bits=opt.bits, mask_layout=layout), curves
                )
            if opt.compressed and not stage_rep.formats:  # not pd: the searches did not run
                with console.status("choosing block formats by fidelity"):
                    chosen, n, record = formats_by_fidelity(
                        source, asset, pkg, poses, manifest.formats
                    )
                stage_rep.formats, stage_rep.fidelity = chosen, record
                notes += n
            with console.status("compressing and building the files"):
                formats = replace(manifest.formats, **stage_rep.formats)
                if opt.compressed and color_ref is not None:
                    color_format = choose_color_format(
                        source, asset, poses, pkg, manifest.formats.color, color_ref
                    )
                    notes += color_format.notes
                files, n, choices = build_outputs(
                    pkg, opt.glb, opt.compressed, asset.budget, formats, document, opt.png_level,
                    color_format.copies if color_format is not None else None,
                )  # fmt: skip
                if color_format is not None:
                    choices["color"] = color_format.to_json()
            notes += n
            read = input_rows(manifest.root, manifest.input_files)
            with console.status("writing the output folder"):
                notes += write_folder(
                    tmp, files, pkg, opt.usd_format, document, got.usd, output, opt.png_level
                )
            del files  # written: the validator reads the folder back (no second copy held)
            forget_rows()  # the block encoder's row stores: validation encodes no block
            validation: dict[str, Any] = {"status": "skipped", "reason": "--no-validate"}
            if opt.validate:
                with console.status("validating"):
                    validation = validate_output(
                        tmp, manifest.path, opt.render, html_page=True, source=source
                    )
            key_notes = verdict_notes(got.notes, stage_rep.key_notes, records, validation)
            report = convert_report(
                manifest=manifest.path.name,
                inputs=read,
                pkg=pkg,
                pd_scale={
                    "value": stage_rep.pd_scale,
                    "source": stage_rep.pd_scale_source,
                    "clipped_texels": clipped_texels(pkg),
                },
                fidelity=stage_rep.fidelity,
                warnings=list(asset.provenance.get("warnings", [])),
                decode_error=decode_errors(asset, pkg),
                compression=choices,
                notes=notes,
                key_notes=key_notes,
                outputs=output_rows(tmp),
                validation=validation,
                color=None if color_choice is None else color_choice.to_json(),
            )
            write_report(tmp, report)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        where = f" ({exc.filename})" if exc.filename else ""
        raise input_error(
            output, f"conversion stopped: {reason}{where}; nothing was changed"
        ) from None
    errors = int(validation.get("counts", {}).get("error", 0))
    return ConvertResult(output, report, 1 if errors else 0)


def _convert_tiles(manifest: Any, output: Path, opt: ConvertOptions) -> ConvertResult:
    """:func:`convert` of a manifest with UDIM tiles: the mesh and the drivers once, each tile
    through the stages on its own with one joint choice for all
    (:func:`wrinklepipe.pipeline.tiles.run_tile_stages`), packed per tile and joined into one
    tiled package (:func:`wrinklepipe.udim.join_tiles`), written (USD with ``<UDIM>`` paths,
    glTF one primitive and material per tile) and validated tile by tile and over the face."""
    inputs = [manifest.root, *manifest.input_files]
    try:
        with staged_folder(output, force=opt.force, inputs=inputs) as tmp, reuse():
            with console.status("reading inputs (UDIM tiles)"):
                got = ingest_tiles(manifest)
            notes = tile_notes(manifest) + got.notes
            with console.status("evaluating drivers"):
                whole = replace(got.whole, mesh=prepare_mesh(got.whole.mesh))
                curves, drivers_notes = evaluate_drivers(whole, manifest.root)
            poses = judged_poses(whole, curves)
            tiles = {
                t: replace(a, mesh=udim.tile_mesh(whole.mesh, t)) for t, a in got.tiles.items()
            }
            with console.status("choosing sizes, scale and formats by fidelity, tile by tile"):
                staged = run_tile_stages(
                    tiles,
                    auto_scale=manifest.pd_scale == "auto",
                    formats=manifest.formats,
                    compressed=opt.compressed,
                    poses=poses,
                )
            for t, rep in staged.reports.items():
                notes += [f"tile {t}: {n}" for n in rep.notes]
            notes += staged.notes + whole.mesh.notes + drivers_notes
            layout = opt.mask_layout or manifest.formats.mask_layout
            pack = PackOptions(bits=opt.bits, mask_layout=layout)
            pkgs = {t: package_from_asset(a, pack, curves) for t, a in staged.assets.items()}
            formats = replace(manifest.formats, **staged.formats)
            with console.status("encoding, packing, compressing"):
                pkg = udim.join_tiles(pkgs, whole.mesh)
                files, n, choices = build_outputs(
                    pkg, opt.glb, opt.compressed, whole.budget, formats, None, opt.png_level
                )
            notes += n
            read = input_rows(manifest.root, manifest.input_files)
            notes += write_folder(
                tmp, files, pkg, opt.usd_format, None, got.usd, output, opt.png_level
            )
            with console.status("validating, tile by tile"):
                validation = (
                    validate_output(
                        tmp, manifest.path, opt.render, html_page=True, source=got.tiles
                    )
                    if opt.validate
                    else {"status": "skipped", "reason": "--no-validate"}
                )
            first = staged.reports[min(staged.reports)]
            report = convert_report(
                manifest=manifest.path.name,
                inputs=read,
                pkg=pkg,
                pd_scale={
                    "value": float(pkg.meta.scale) if pkg.meta.encoding == "pd" else None,
                    "source": first.pd_scale_source,
                    "clipped_texels": {
                        f"{s} (tile {t})": c
                        for t in pkg.tiles
                        for s, c in clipped_texels(udim.tile_package(pkg, t)).items()
                    },
                },
                fidelity=staged.fidelity(),
                warnings=list(whole.provenance.get("warnings", [])),
                decode_error={
                    f"{s} (tile {t})": e
                    for t in pkg.tiles
                    for s, e in decode_errors(staged.assets[t], pkgs[t]).items()
                },
                compression=choices,
                notes=notes,
                outputs=output_rows(tmp),
                validation=validation,
            )
            report["udim"] = {"tiles": list(pkg.tiles)}
            write_report(tmp, report)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        where = f" ({exc.filename})" if exc.filename else ""
        raise input_error(
            output, f"conversion stopped: {reason}{where}; nothing was changed"
        ) from None
    errors = int(validation.get("counts", {}).get("error", 0))
    return ConvertResult(output, report, 1 if errors else 0)
