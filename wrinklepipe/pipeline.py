"""The conversion pipeline: manifest -> WrinkleAsset -> stages -> one output folder.

``convert(manifest_path, out, options)`` runs, in order::

    ingest        manifest + files -> WrinkleAsset (maps +Y, float unit normals; masks [R, H, W])
    resample      states and masks to the manifest's resolutions
    mesh          tangents (MikkTSpace) and spatial-hash vertex IDs on the render mesh
    drivers       weight curves [T, R] from the manifest's drivers
    package       encode + pack (wrinklepipe.io.package)
    write         glTF (+GLB), USD (.usda, +.usdc/.usdz), PNG textures, DDS/KTX2, curves
    validate      wrinklepipe.validate on what was written, against the source maps
    report        report.json + report.html

Everything is written into a temporary sibling folder that is renamed into place only when
complete (:func:`wrinklepipe.atomic.staged_folder`); inputs are never written; reruns are
byte-identical. Each stage is a plain function, usable on its own.
"""

from __future__ import annotations

import hashlib
import html
import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import model
from wrinklepipe.asset import Mesh, Region, WrinkleAsset
from wrinklepipe.atomic import dumps_json, staged_folder, write_bytes
from wrinklepipe.errors import input_error
from wrinklepipe.io.package import (
    PackOptions,
    WeightCurves,
    WrinklePackage,
    package_from_asset,
    resize_normals_pd,
    safe_name,
)

# ------------------------------------------------------------------------------------------------
# mesh stage


def prepare_mesh(mesh: Mesh) -> Mesh:
    """Give the render mesh what the writers need: normals, tangents (always) and vertex IDs."""
    notes = list(mesh.notes)
    if mesh.uvs is None:
        raise input_error(mesh.name, "mesh has no UVs (wrinkle maps need a UV layout)")
    if mesh.normals is None:
        from wrinklepipe.demo.character import vertex_normals

        mesh = replace(mesh, normals=vertex_normals(mesh.positions, mesh.indices))
        notes.append("computed area-weighted vertex normals")
    if mesh.tangents is None:
        from wrinklepipe.geometry.tangents import mikktspace_tangents

        tangents = mikktspace_tangents(mesh.positions, mesh.normals, mesh.uvs, mesh.indices)
        notes.append("computed MikkTSpace tangents")
        mesh = replace(mesh, tangents=np.asarray(tangents, np.float32))
    if mesh.vertex_ids is None:
        from wrinklepipe.geometry.vertex_ids import compute_vertex_ids

        ids = compute_vertex_ids(mesh.positions)
        notes.append("computed spatial-hash vertex IDs")
        mesh = replace(mesh, vertex_ids=np.asarray(ids, np.int64))
    return replace(mesh, notes=notes)


# ------------------------------------------------------------------------------------------------
# weights


def expression_cycle(asset: WrinkleAsset, seconds_per_expression: float = 1.0) -> WeightCurves:
    """Region weights ``[T, R]`` that visit each expression of the asset's table in turn.

    Keys: neutral at t = 0, expression i fully on at ``t = (i + 1) * seconds_per_expression``
    (linear in between, like the demo manifest's expression keys); rows are the table's region
    weights (Jimenez Table 1.1 for the demo).
    """
    names = asset.region_names
    exprs = list(asset.expressions)
    rows = [np.zeros(len(names), np.float32)]
    for e in exprs:
        rows.append(np.array([asset.expressions[e].get(r, 0.0) for r in names], np.float32))
    times = np.arange(len(rows), dtype=np.float32) * np.float32(seconds_per_expression)
    return WeightCurves("expressions", times, np.stack(rows))


def demo_package(size: int = 256, encoding: str = "pd") -> WrinklePackage:
    """The demo character, prepared and packaged (no files read): what the writers' tests use."""
    from wrinklepipe.demo import demo_asset

    asset = demo_asset(size, encoding=encoding)
    asset = replace(asset, mesh=prepare_mesh(asset.mesh))
    return package_from_asset(asset, curves=[expression_cycle(asset)])


def curves_from_weights(
    name: str, times: np.ndarray, weights: np.ndarray, region_states: np.ndarray
) -> tuple[WeightCurves, float]:
    """Driver weights ``[F, R, K]`` -> per-region curves ``[F, R]`` (+ the largest value lost).

    The extension animates one weight per region (spread over the states the region drives, as
    :meth:`DriverContext.spread` does); the value is read from the first state the region drives.
    The second value returned is ``max |w[f, r, k] - w_r[f] * region_states[r, k]|``, 0 when the
    driver's weights are of that form.
    """
    w = np.asarray(weights, np.float32)
    rs = np.asarray(region_states, np.float32)
    if w.shape[2] == 1:
        per_region = w[:, :, 0]
        lost = 0.0
    else:
        first = np.argmax(rs > 0, axis=1)
        per_region = np.take_along_axis(w, first[None, :, None], axis=2)[:, :, 0]
        lost = float(np.max(np.abs(w - per_region[:, :, None] * rs[None]), initial=0.0))
    return WeightCurves(name, np.asarray(times, np.float32), per_region.astype(np.float32)), lost


def morph_inputs(
    ctx: Any, spec: dict[str, Any], times: np.ndarray, names: tuple[str, ...]
) -> np.ndarray | None:
    """The morph-target weights ``[T, M]`` a blendshapes driver reads, sampled at ``times``
    (its glTF animation, keys or constant morphs, through :mod:`wrinklepipe.drivers.curves`),
    so the output plays the face and its wrinkles together. None when it has none."""
    from wrinklepipe.drivers.base import resolve
    from wrinklepipe.drivers.curves import load_keys, read_gltf_morph_animation, sample_keys

    t = np.asarray(times, np.float64)
    file = spec.get("file")
    if file is not None and Path(str(file)).suffix.lower() in (".gltf", ".glb"):
        _, got, x = read_gltf_morph_animation(resolve(ctx, str(file)), t)
        out = np.zeros((t.size, len(names)), np.float32)
        for j, n in enumerate(got):
            if n in names:
                out[:, names.index(n)] = x[:, j]
        return out
    if "morphs" in spec and "keys" not in spec and file is None:
        row = [float(spec["morphs"].get(n, 0.0)) for n in names]
        return np.tile(np.array(row, np.float32), (t.size, 1))
    keys, interp, _ = load_keys(ctx, spec)
    if not keys:
        return None
    return sample_keys(keys, names, t, interp or "linear").astype(np.float32)


def evaluate_drivers(asset: WrinkleAsset, root: Path) -> tuple[list[WeightCurves], list[str]]:
    """Weight curves for each driver of the asset (wrinklepipe.drivers); notes on what happened."""
    notes: list[str] = []
    if not asset.drivers:
        return [expression_cycle(asset)] if asset.expressions else [], [
            "no drivers: a curve visiting each expression of the table was written"
        ]
    from wrinklepipe import drivers as wd

    ctx = wd.DriverContext.from_asset(asset, root)
    curves: list[WeightCurves] = []
    used: set[str] = set()
    for i, spec in enumerate(asset.drivers):
        kind = str(spec["kind"])
        res = wd.evaluate(kind, ctx, spec)
        if res.per_vertex:
            notes.append(f"drivers[{i}] ({kind}) gives per-vertex weights; not written as a curve")
            continue
        name = str(spec.get("name") or kind)
        while name in used:
            name = f"{name}_{i}"
        used.add(name)
        curve, lost = curves_from_weights(name, res.times, res.weights, asset.region_state_matrix())
        if kind == "blendshapes" and asset.mesh is not None and asset.mesh.morph_names:
            curve.morph_weights = morph_inputs(ctx, spec, res.times, asset.mesh.morph_names)
        if lost > 1e-6:
            notes.append(f"drivers[{i}] ({kind}): per-state weights differ by up to {lost:.3g}")
        notes.extend(f"drivers[{i}] ({kind}): {n}" for n in res.notes)
        curves.append(curve)
    return curves, notes


# ------------------------------------------------------------------------------------------------
# ingest


def _read_normals(path: Path, convention: str) -> tuple[np.ndarray, list[str]]:
    """A normal map file -> unit normals ``[H, W, 3]`` (+Y) and notes (wrinklepipe.normals.read)."""
    from wrinklepipe.normals.read import ReadOptions, read_normal_map

    nm = read_normal_map(path, ReadOptions(convention=convention))
    notes = [f"{path.name}: {nm.source_format}, convention {nm.convention}"]
    return np.asarray(nm.normals, np.float32), notes


def _load_mesh(path: Path) -> Mesh:
    """The render mesh (:func:`wrinklepipe.io.mesh.load_mesh`: glTF, USD, OBJ)."""
    from wrinklepipe.io.mesh import load_mesh

    return load_mesh(path)


def read_maps(manifest: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """The manifest's maps as read: base ``[H, W, 3]``, wrinkled-face states ``[K, H, W, 3]``
    (unit normals, +Y; wrinkle-only maps get the base added in PD space), masks ``[R, h, w]``,
    and notes on what was read."""
    from wrinklepipe import masks as wm

    notes: list[str] = []
    base, n = _read_normals(manifest.base, manifest.convention)
    notes += n
    states = []
    for s in manifest.states:
        st, n = _read_normals(s.map, manifest.convention)
        notes += n
        if st.shape != base.shape:
            raise input_error(
                s.map,
                f"size {st.shape[1]}x{st.shape[0]} differs from the base map "
                f"{base.shape[1]}x{base.shape[0]}",
            )
        if not manifest.states_include_base:  # wrinkle-only normals: add the base in PD space
            st = model.pd_to_normal(model.normal_to_pd(base) + model.normal_to_pd(st))
        states.append(st)
    channels = [r.channel for r in manifest.regions]
    if any(c is not None for c in channels):
        masks = []
        for r in manifest.regions:
            m, _ = wm.read_mask(r.mask) if r.channel is None else (_mask_channel(r), None)
            masks.append(m)
        mask_arr = np.stack(masks).astype(np.float32)
    else:
        ms = wm.read_masks(
            [r.mask for r in manifest.regions], names=[r.name for r in manifest.regions]
        )
        mask_arr = np.asarray(ms.masks, np.float32)
    return base, np.stack(states), mask_arr, notes


def ingest(manifest: Any) -> tuple[WrinkleAsset, list[str]]:
    """Read every file a manifest names into a :class:`WrinkleAsset` (float maps, +Y)."""
    base, states, mask_arr, notes = read_maps(manifest)
    mesh = _load_mesh(manifest.mesh) if manifest.mesh is not None else None
    if mesh is None:
        raise input_error(
            manifest.path, "the manifest names no mesh; glTF/USD output needs one", "mesh"
        )
    asset = WrinkleAsset(
        name=manifest.name,
        base=base,
        states=states,
        state_names=tuple(s.name for s in manifest.states),
        masks=mask_arr,
        regions=tuple(Region(r.name, r.side, tuple(r.states)) for r in manifest.regions),
        expressions={e: dict(row) for e, row in manifest.expressions.items()},
        encoding=manifest.encoding,
        policy=manifest.policy,
        pd_scale=1.0 if manifest.pd_scale == "auto" else float(manifest.pd_scale),
        mesh=mesh,
        drivers=[dict(d) for d in manifest.drivers],
        budget=dict(manifest.budget),
        resolution={k: v for k, v in manifest.resolution.items() if isinstance(v, int)},
        provenance={
            "manifest": manifest.path.name,
            "auto_resolution": sorted(k for k, v in manifest.resolution.items() if v == "auto"),
        },
    )
    return asset, notes


def _mask_channel(region: Any) -> np.ndarray:
    from wrinklepipe.io.images import read_image

    values, _ = read_image(region.mask)
    return values[..., "rgba".index(region.channel)].astype(np.float32)


# ------------------------------------------------------------------------------------------------
# stages on the asset


def _resize_normals(normals: np.ndarray, size: int) -> np.ndarray:
    return resize_normals_pd(normals, size, size)


def auto_pd_scale(slopes: np.ndarray, percentile: float = 99.9) -> float:
    """Smallest power of two >= the ``percentile`` of ``max(|dx|, |dy|)`` of the wrinkle slopes
    (:func:`wrinklepipe.normals.encode.auto_pd_scale`)."""
    from wrinklepipe.normals.encode import auto_pd_scale as _auto

    return float(_auto(slopes, percentile))


def auto_wrinkle_size(asset: WrinkleAsset) -> tuple[int | None, dict[int, float]]:
    """Smallest power-of-two state size whose blended error over the expressions meets the
    budget (:func:`wrinklepipe.normals.resample.auto_size`); None when it cannot be chosen."""
    from wrinklepipe.normals.compress import Budget as budget_cls
    from wrinklepipe.normals.resample import auto_size

    if asset.encoding != "pd" or not asset.expressions:
        return None, {}
    if asset.policy == "signed":
        return None, {}
    h = asset.states.shape[1]
    base = _resize_normals(asset.base, h)
    slopes = model.normal_to_pd(asset.states) - model.normal_to_pd(base)[None]
    masks = asset.masks
    if masks.shape[1] != h:
        from wrinklepipe import masks as wm

        masks = np.asarray(wm.resample_masks(masks, h), np.float32)
    weights = [asset.expression_weights({e: 1.0}) for e in sorted(asset.expressions)]
    b = asset.budget
    limits = budget_cls(b.get("max_mean_deg"), b.get("max_p99_deg", 2.0))
    size, tried = auto_size(base, slopes, masks, weights, limits, policy=asset.policy)
    return int(size), {int(k): float(v.p99_deg) for k, v in tried.items()}


@dataclass
class StageReport:
    """What the stages did, for report.json."""

    notes: list[str] = field(default_factory=list)
    pd_scale: float | None = None
    pd_scale_source: str = ""
    clipped_texels: dict[str, int] = field(default_factory=dict)


def run_stages(asset: WrinkleAsset, auto_scale: bool) -> tuple[WrinkleAsset, StageReport]:
    """Resample to the target resolutions, prepare the mesh, choose the PD scale."""
    rep = StageReport()
    res = dict(asset.resolution)
    base, states, masks = asset.base, asset.states, asset.masks
    if "wrinkle" in asset.provenance.get("auto_resolution", ()):
        size, tried = auto_wrinkle_size(asset)
        if size is not None:
            res["wrinkle"] = size
            rep.notes.append(
                "wrinkle resolution auto: "
                + ", ".join(f"{k}: p99 {v:.2f} deg" for k, v in sorted(tried.items()))
                + f" -> {size}"
            )
    if "base" in res and res["base"] != base.shape[0]:
        base = _resize_normals(base, int(res["base"]))
        rep.notes.append(f"base resampled to {res['base']}")
    if "wrinkle" in res and res["wrinkle"] != states.shape[1]:
        states = np.stack([_resize_normals(s, int(res["wrinkle"])) for s in states])
        rep.notes.append(f"wrinkle states resampled to {res['wrinkle']} (PD space)")
    if "mask" in res and res["mask"] != masks.shape[1]:
        from wrinklepipe import masks as wm

        masks = np.asarray(wm.resample_masks(masks, int(res["mask"])), np.float32)
        rep.notes.append(f"masks resampled to {res['mask']}")
    mesh = prepare_mesh(asset.mesh)
    rep.notes.extend(mesh.notes)
    asset = replace(asset, base=base, states=states, masks=masks, mesh=mesh)
    if asset.encoding == "pd":
        b = base
        if b.shape[:2] != states.shape[1:3]:
            b = _resize_normals(base, states.shape[1])
        slopes = model.normal_to_pd(states) - model.normal_to_pd(b)[None]
        if auto_scale:
            asset = replace(asset, pd_scale=auto_pd_scale(slopes))
            rep.pd_scale_source = "auto (99.9th percentile of wrinkle slopes, power of two)"
        else:
            rep.pd_scale_source = "manifest"
        rep.pd_scale = float(asset.pd_scale)
        s = np.float32(asset.pd_scale)
        for k, name in enumerate(asset.state_names):
            rep.clipped_texels[name] = int(np.count_nonzero(np.any(np.abs(slopes[k]) > s, -1)))
    return asset, rep


# ------------------------------------------------------------------------------------------------
# writing the folder


@dataclass(frozen=True)
class ConvertOptions:
    """What ``convert`` writes.

    ``glb``: also a self-contained ``NAME.glb``. ``usd_format``: ``"usda"`` (always written) plus
    ``"usdc"`` or ``"usdz"`` on request. ``force``: replace a non-empty output folder.
    ``compressed``: DDS + KTX2 copies of the base and states (format chosen against the budget).
    ``validate``: run :mod:`wrinklepipe.validate` on the written folder (``render``: with its GPU
    render pass). ``bits``: PNG
    depth of the base and state maps. ``mask_layout``: None = the manifest's ``formats``.
    """

    glb: bool = False
    usd_format: str = "usda"
    force: bool = False
    compressed: bool = True
    validate: bool = True
    render: bool = True
    bits: int = 8
    mask_layout: str | None = None


@dataclass
class ConvertResult:
    """What convert wrote and found: the folder, report (as written to report.json), exit code."""

    output: Path
    report: dict[str, Any]
    exit_code: int


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _fmt(x: float) -> str:
    return format(float(np.float32(x)), ".9g")


def curve_files(
    curve: WeightCurves, regions: list[str], taken: set[str] | None = None
) -> dict[str, bytes]:
    """A weight curve as ``curves/NAME.json`` and ``curves/NAME.csv`` (time, then the regions)."""
    stem = safe_name(curve.name, taken)  # the name stays exact inside the JSON
    rows = ["time," + ",".join(regions)]
    for t, row in zip(curve.times, curve.values):
        rows.append(",".join([_fmt(t)] + [_fmt(v) for v in row]))
    js = {
        "name": curve.name,
        "regions": regions,
        "times": [float(np.float32(t)) for t in curve.times],
        "weights": [[float(np.float32(v)) for v in row] for row in curve.values],
        "interpolation": "linear",
    }
    return {
        f"curves/{stem}.csv": ("\n".join(rows) + "\n").encode("utf-8"),
        f"curves/{stem}.json": dumps_json(js).encode("utf-8"),
    }


#: Block formats tried for a two-channel normal map when the manifest says ``auto``.
AUTO_FORMATS: tuple[str, ...] = ("bc5", "bc3nm", "bc7", "bc1")
_BLOCK = ("bc5", "bc1", "bc3nm", "bc7")


def compressed_files(
    pkg: WrinklePackage,
    budget: dict[str, float] | None = None,
    formats: dict[str, str] | None = None,
) -> tuple[dict[str, bytes], list[str], dict[str, Any]]:
    """Block-compressed copies (DDS + KTX2) of the base and the PD state maps.

    For each map the format is the manifest's ``formats.base`` / ``formats.wrinkle``; ``auto``
    (default) tries :data:`AUTO_FORMATS` and keeps the smallest that meets the budget for every
    map of the group (error of the decoded map against the stored 8-bit map, measured by
    :func:`wrinklepipe.normals.compress.compress_and_check`); all states share one format. When
    no format passes, the group ships as PNG only and a note says why.
    Returns (files, notes, per-map choices for the report).
    """
    from wrinklepipe.normals import compress as nc
    from wrinklepipe.normals.dds import dds_bytes
    from wrinklepipe.normals.ktx2 import ktx2_bytes

    files: dict[str, bytes] = {}
    notes: list[str] = []
    choices: dict[str, Any] = {}
    budget = budget or {}
    limits = nc.Budget(budget.get("max_mean_deg"), budget.get("max_p99_deg", 2.0))
    formats = formats or {}
    meta = pkg.meta
    lut = np.arange(256, dtype=np.float32) / np.float32(255.0)
    groups: list[tuple[str, str, Any, list[Any]]] = [
        (
            "base",
            formats.get("base", "auto"),
            nc.decoder_for("full"),
            [t for t in pkg.textures if t.role == "base_normal"],
        ),
    ]
    if meta["encoding"] == "pd":  # every state ships in one format (shaders sample them alike)
        groups.append(
            (
                "wrinkle",
                formats.get("wrinkle", "auto"),
                nc.decoder_for("pd", scale=float(meta["scale"])),
                [t for t in pkg.textures if t.role == "state"],
            )
        )
    else:
        notes.append(f"{meta['encoding']} states ship as PNG only (block copies are for pd)")
    for group, want, decode, maps in groups:
        if any(t.bits != 8 for t in maps):
            notes.append(f"{group}: 16-bit maps ship as PNG only (block formats are 8-bit)")
        maps = [t for t in maps if t.bits == 8]
        if not maps or (want not in _BLOCK and want != "auto"):
            continue
        # Smallest blocks first (BC1: 8 bytes; then BC5, BC3nm, BC7: 16), stop at the first
        # format every map of the group passes with: that is the smallest that meets the budget.
        candidates = (
            tuple(
                sorted(
                    AUTO_FORMATS, key=lambda f: (nc.block_data_size(f, 4, 4), AUTO_FORMATS.index(f))
                )
            )
            if want == "auto"
            else (want,)
        )
        references = []
        for t in maps:
            stored = t.pixels[..., :2]
            references.append((stored, decode(lut[stored], slice(0, stored.shape[0]))))
        checks: dict[str, list[Any]] = {}
        for f in candidates:
            checks[f] = [
                nc.compress_and_check(st, ref, f, decode, limits, keep_decoded=False)
                for st, ref in references
            ]
            if all(c.verdict == "pass" for c in checks[f]):
                break
        candidates = tuple(checks)
        passing = [f for f in candidates if all(c.verdict == "pass" for c in checks[f])]
        if want != "auto":
            pick = want
            if not passing:
                notes.append(f"{group}: {want} as requested, over the error budget")
        elif passing:
            pick = passing[0]
        else:
            pick = None
            best = min(candidates, key=lambda f: max(c.error.mean_deg for c in checks[f]))
            worst = max(checks[best], key=lambda c: c.error.mean_deg)
            notes.append(
                f"{group}: no block format meets the budget (best {best}: mean "
                f"{worst.error.mean_deg:.2f}, p99 {worst.error.p99_deg:.2f} deg); PNG only"
            )
        choices[group] = {
            "requested": want,
            "chosen": pick or "png",
            "checks": {
                f: {t.name: c.to_json() for t, c in zip(maps, cs)} for f, cs in checks.items()
            },
        }
        if pick is None:
            continue
        for t, c in zip(maps, checks[pick]):
            h, w = t.pixels.shape[:2]
            files[f"compressed/{t.name}.dds"] = dds_bytes(pick, w, h, [c.data])
            files[f"compressed/{t.name}.ktx2"] = ktx2_bytes(pick, w, h, [c.data])
    return files, notes, choices


def decode_errors(asset: WrinkleAsset, pkg: WrinklePackage) -> dict[str, dict[str, float]]:
    """Angular error (degrees) between each state as given and as decoded from what is stored."""
    from wrinklepipe.io.package import asset_from_package

    back = asset_from_package(pkg)
    out = {}
    for k, name in enumerate(asset.state_names):
        e = model.angular_error_deg(asset.states[k], back.states[k]).ravel()
        out[name] = {
            "mean_deg": round(float(e.mean()), 6),
            "p99_deg": round(float(np.percentile(e, 99)), 6),
            "max_deg": round(float(e.max()), 6),
        }
    return out


def _scrub(obj: Any, replacements: dict[str, str]) -> Any:
    """Replace machine-specific path prefixes in every string of a JSON-able value."""
    if isinstance(obj, str):
        for old, new in replacements.items():
            obj = obj.replace(old, new)
        return obj
    if isinstance(obj, dict):
        return {k: _scrub(v, replacements) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_scrub(v, replacements) for v in obj]
    return obj


VALIDATION_HTML = "validation.html"


def validate_output(
    folder: Path, manifest_path: Path | None = None, render: bool = True, html_page: bool = False
) -> dict[str, Any]:
    """Run :mod:`wrinklepipe.validate` on a written folder.

    With ``manifest_path`` the shipped textures are compared with the source maps. Only
    deterministic parts go into the report (counts and issues, no timings); paths are written
    relative to the output folder (``.``) and the manifest's folder (``<source>``). With
    ``html_page`` the validator's own page (contact sheet of renders, error heat maps, mask
    overlay, metrics) is written into the folder as ``validation.html`` + ``validation_files/``.
    """
    from wrinklepipe.validate import ValidateOptions, validate
    from wrinklepipe.validate.loader import LoadOptions, load_input
    from wrinklepipe.validate.report import html_images
    from wrinklepipe.validate.report import report_html as validation_page

    src = str(manifest_path) if manifest_path is not None else None
    report = validate(load_input(folder, LoadOptions(source=src)), ValidateOptions(render=render))
    issues = [i.to_json() for i in report.issues]
    replacements = {str(folder): "."}
    if manifest_path is not None:
        replacements[str(manifest_path.parent)] = "<source>"
    if html_page:
        files_dir = Path(VALIDATION_HTML).stem + "_files"
        for image, data in html_images(report).items():
            write_bytes(folder / files_dir / image, data)
        page = _scrub(validation_page(report, files_dir), replacements)
        write_bytes(folder / VALIDATION_HTML, page.encode("utf-8"))
    counts = {k: int(v) for k, v in report.counts.items()}
    return _scrub({"status": "ran", "counts": counts, "issues": issues}, replacements)


def _validation_html(validation: dict[str, Any], table: Any) -> str:
    if validation.get("status") != "ran":
        return f"<p>{html.escape(str(validation.get('reason', 'skipped')))}</p>"
    counts = validation.get("counts", {})
    head = ", ".join(f"{v} {k}(s)" for k, v in sorted(counts.items()))
    rows = [
        [i.get("severity", ""), i.get("code", ""), i.get("message", ""), i.get("pointer", "")]
        for i in validation.get("issues", [])
    ]
    link = f"<p>The validator's page: <a href='{VALIDATION_HTML}'>{VALIDATION_HTML}</a></p>"
    return (
        f"<p>{html.escape(head)}</p>" + link + table(rows, ["severity", "code", "message", "where"])
    )


def report_html(report: dict[str, Any]) -> str:
    """A static, self-contained HTML summary of report.json (textures linked, not embedded)."""
    esc = html.escape

    def table(rows: list[list[Any]], head: list[str]) -> str:
        th = "".join(f"<th>{esc(h)}</th>" for h in head)
        body = "".join(
            "<tr>" + "".join(f"<td>{esc(str(c))}</td>" for c in r) + "</tr>" for r in rows
        )
        return f"<table><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>"

    a = report["asset"]
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>wrinklepipe convert: {esc(report['name'])}</title>",
        "<style>body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}"
        "td,th{border:1px solid #ccc;padding:2px 6px;text-align:left}"
        "img{width:128px;image-rendering:pixelated;margin:2px}</style></head><body>",
        f"<h1>{esc(report['name'])}</h1>",
        f"<p>encoding <b>{esc(a['encoding'])}</b>, scale {a['scale']}, policy "
        f"<b>{esc(a['policy'])}</b>; {a['vertices']} vertices, {a['triangles']} triangles, "
        f"{len(a['morph_targets'])} morph targets.</p>",
        "<h2>Textures</h2><div>",
        "".join(
            f"<figure style='display:inline-block'><img src='{esc(o['file'])}' "
            # masks keep a region in alpha: show them on black, texels unsmoothed
            "style='width:160px;background:#000;image-rendering:pixelated' "
            f"alt='{esc(o['file'])}'><figcaption>{esc(o['file'])}</figcaption></figure>"
            for o in report["outputs"]
            if o["file"].startswith("textures/")
        ),
        "</div><h2>Regions</h2>",
        table(
            [[r["name"], r["side"], json.dumps(r["mask"])] for r in a["regions"]],
            ["region", "side", "channel table"],
        ),
        "<h2>Decode error of the stored states</h2>",
        table(
            [
                [k, v["mean_deg"], v["p99_deg"], v["max_deg"]]
                for k, v in report["decode_error"].items()
            ],
            ["state", "mean deg", "p99 deg", "max deg"],
        ),
        "<h2>Stages</h2><ul>",
        "".join(f"<li>{esc(n)}</li>" for n in report["notes"]),
        "</ul><h2>Block compression</h2>",
        table(
            [[g, c["requested"], c["chosen"]] for g, c in sorted(report["compression"].items())],
            ["maps", "requested", "chosen"],
        ),
        "<h2>Validation</h2>",
        _validation_html(report["validation"], table),
        "<h2>Outputs</h2>",
        table(
            [[o["file"], o["bytes"], o["sha256"][:16]] for o in report["outputs"]],
            ["file", "bytes", "sha256"],
        ),
        "<h2>Inputs</h2>",
        table(
            [[i["file"], i["bytes"], i["sha256"][:16]] for i in report["inputs"]],
            ["file", "bytes", "sha256"],
        ),
        "</body></html>\n",
    ]
    return "".join(parts)


def build_outputs(
    pkg: WrinklePackage,
    options: ConvertOptions,
    budget: dict[str, float] | None = None,
    formats: dict[str, str] | None = None,
) -> tuple[dict[str, bytes], list[str], dict[str, Any]]:
    """Every output file as ``{relative path: bytes}`` (except USD, written by usd-core), notes,
    and the block-format choices."""
    from wrinklepipe.io.gltf_write import glb_bytes, gltf_document
    from wrinklepipe.io.package import png_bytes

    name = pkg.name
    files: dict[str, bytes] = {}
    doc, data, images = gltf_document(pkg)
    doc["buffers"][0]["uri"] = f"{name}.bin"
    files[f"{name}.gltf"] = dumps_json(doc).encode("utf-8")
    files[f"{name}.bin"] = data
    files.update(images)
    for t in pkg.textures:  # the same PNGs serve glTF and USD
        files.setdefault(f"textures/{t.name}.png", png_bytes(t.pixels))
    if options.glb:
        gdoc, gdata, _ = gltf_document(pkg, embed_images=True)
        files[f"{name}.glb"] = glb_bytes(gdoc, gdata)
    notes: list[str] = []
    choices: dict[str, Any] = {}
    if options.compressed:
        comp, n, choices = compressed_files(pkg, budget, formats)
        files.update(comp)
        notes += n
    regions = [r["name"] for r in pkg.meta["regions"]]
    taken: set[str] = set()
    for c in pkg.curves:
        files.update(curve_files(c, regions, taken))
    return files, notes, choices


def convert(
    manifest_path: str | Path, output: str | Path, options: ConvertOptions | None = None
) -> ConvertResult:
    """Run the whole pipeline on a manifest and write one output folder (atomically)."""
    from wrinklepipe import __version__
    from wrinklepipe.console import status
    from wrinklepipe.io.usd_write import write_usd
    from wrinklepipe.manifest import load_manifest

    opt = options or ConvertOptions()
    if opt.usd_format not in ("usda", "usdc", "usdz"):
        raise ValueError(f"usd_format must be usda, usdc or usdz, got {opt.usd_format!r}")
    output = Path(output)
    manifest = load_manifest(manifest_path)
    inputs = [manifest.root, *manifest.input_files]
    try:
        # The output checks (not an input, empty or --force) run first, before any work.
        with staged_folder(output, force=opt.force, inputs=inputs) as tmp:
            with status("reading inputs"):
                asset, notes = ingest(manifest)
            with status("resampling, tangents, vertex IDs"):
                asset, stage_rep = run_stages(asset, auto_scale=manifest.pd_scale == "auto")
            notes += stage_rep.notes
            with status("evaluating drivers"):
                curves, n = evaluate_drivers(asset, manifest.root)
            notes += n
            layout = opt.mask_layout or manifest.formats.get("mask_layout", "rgba")
            pkg = package_from_asset(asset, PackOptions(bits=opt.bits, mask_layout=layout), curves)
            with status("encoding, packing, compressing"):
                files, n, choices = build_outputs(pkg, opt, asset.budget, manifest.formats)
            notes += n
            name = pkg.name
            input_rows = []
            for p in manifest.input_files:
                data = p.read_bytes()
                rel = (
                    p.relative_to(manifest.root).as_posix()
                    if manifest.root in p.parents
                    else p.name
                )
                input_rows.append({"file": rel, "bytes": len(data), "sha256": _sha256(data)})
            for rel, data in sorted(files.items()):
                write_bytes(tmp / rel, data)
            usd_names = [f"{name}.usda"] + (
                [f"{name}.{opt.usd_format}"] if opt.usd_format != "usda" else []
            )
            for u in usd_names:
                write_usd(pkg, tmp / u, write_textures=False)
            with status("validating"):
                validation = (
                    validate_output(tmp, manifest.path, opt.render, html_page=True)
                    if opt.validate
                    else {"status": "skipped", "reason": "--no-validate"}
                )
            outputs = []
            for p in sorted(tmp.rglob("*")):
                if p.is_file():
                    data = p.read_bytes()
                    rel = p.relative_to(tmp).as_posix()
                    outputs.append({"file": rel, "bytes": len(data), "sha256": _sha256(data)})
            m = pkg.mesh
            report = {
                "tool": "wrinklepipe",
                "version": __version__,
                "name": name,
                "manifest": manifest.path.name,
                "inputs": input_rows,
                "asset": {
                    "encoding": pkg.meta["encoding"],
                    "scale": pkg.meta["scale"],
                    "policy": pkg.meta["policy"],
                    "states": [s["name"] for s in pkg.meta["states"]],
                    "regions": [
                        {**r, "mask": e}
                        for r, e in zip(pkg.meta["regions"], pkg.meta["masks"]["table"])
                    ],
                    "mask_layout": pkg.meta["masks"]["layout"],
                    "sizes": {t.name: list(t.pixels.shape) for t in pkg.textures},
                    "vertices": m.vertex_count,
                    "triangles": m.triangle_count,
                    "morph_targets": list(m.morph_names),
                    "curves": [
                        {
                            "name": c.name,
                            "keys": int(c.times.size),
                            "duration_s": float(c.times[-1] - c.times[0]),
                        }
                        for c in pkg.curves
                    ],
                },
                "pd_scale": {
                    "value": stage_rep.pd_scale,
                    "source": stage_rep.pd_scale_source,
                    "clipped_texels": stage_rep.clipped_texels,
                },
                "decode_error": decode_errors(asset, pkg),
                "compression": choices,
                "notes": notes,
                "outputs": outputs,
                "validation": validation,
            }
            write_bytes(tmp / "report.json", dumps_json(report).encode("utf-8"))
            write_bytes(tmp / "report.html", report_html(report).encode("utf-8"))
    except OSError as exc:
        reason = exc.strerror or str(exc)
        where = f" ({exc.filename})" if exc.filename else ""
        raise input_error(
            output, f"conversion stopped: {reason}{where}; nothing was changed"
        ) from None
    errors = int(validation.get("counts", {}).get("error", 0))
    return ConvertResult(output, report, 1 if errors else 0)


# ------------------------------------------------------------------------------------------------
# engine export presets (a thin layer over the same package and writers)


@dataclass(frozen=True)
class EnginePreset:
    """How one engine wants the data: green convention, normal-map container, extra files."""

    name: str
    convention: str  # "opengl" (+Y) | "directx" (-Y)
    normal_format: str  # "png" | "bc5" (DDS, PNG if the compression stage is missing)
    gltf: bool  # also ship the glTF (mesh + +Y maps) for the engine's glTF importer
    shader: str  # "hlsl" | "glsl" | ""


ENGINE_PRESETS: dict[str, EnginePreset] = {
    "unreal": EnginePreset("unreal", "directx", "bc5", False, "hlsl"),
    "unity": EnginePreset("unity", "opengl", "png", True, "hlsl"),
    "godot": EnginePreset("godot", "opengl", "png", True, "glsl"),
    "blender": EnginePreset("blender", "opengl", "png", True, ""),
}

_HLSL = """// wrinklepipe: base normal + PD wrinkle states (encoding "pd", policy "{policy}").
// Inputs are the raw texture samples (values in [0, 1]); returns a unit tangent-space normal
// in this engine's convention ({convention}). SCALE = {scale}.
static const float SCALE = {scale};
// z is rebuilt from x, y, so a two-channel (BC5) base works too.
float3 WrinkleNormal(float2 baseSample, float2 stateSamples[{k}], float activation[{k}])
{{
    float2 bxy = baseSample * 2.0 - 1.0;
    float bz = sqrt(saturate(1.0 - dot(bxy, bxy)));
    float2 d = bxy / max(bz, 1e-6);
    [unroll] for (int k = 0; k < {k}; ++k)
        d += activation[k] * (stateSamples[k] * (2.0 * SCALE) - SCALE);
    return normalize(float3(d, 1.0));
}}
"""

_GLSL = """// wrinklepipe: base normal + PD wrinkle states (encoding "pd", policy "{policy}").
// Inputs are raw texture samples in [0, 1]; returns a unit tangent-space normal (+Y).
const float SCALE = {scale};
vec3 wrinkle_normal(vec2 base_sample, vec2 state_samples[{k}], float activation[{k}]) {{
    vec2 bxy = base_sample * 2.0 - 1.0;
    float bz = sqrt(clamp(1.0 - dot(bxy, bxy), 0.0, 1.0));
    vec2 d = bxy / max(bz, 1e-6);
    for (int k = 0; k < {k}; ++k)
        d += activation[k] * (state_samples[k] * (2.0 * SCALE) - SCALE);
    return normalize(vec3(d, 1.0));
}}
"""


def flip_green(pkg: WrinklePackage) -> WrinklePackage:
    """OpenGL <-> DirectX: stored green ``q -> top - q`` on the base and state maps.

    For every encoding this negates the tangent-space y: ``0.5 + 0.5 (-y) = 1 - (0.5 + 0.5 y)``
    (base, ``full``, ``composite``), likewise the PD slope ``d.y`` and the ``diff`` delta's y.
    Exact on integers, and its own inverse. Masks are unchanged.
    """
    out = []
    for t in pkg.textures:
        if t.role in ("base_normal", "state"):
            px = t.pixels.copy()
            top = np.iinfo(px.dtype).max
            px[..., 1] = top - px[..., 1]
            t = replace(t, pixels=px)
        out.append(t)
    return replace(pkg, textures=out)


def export_files(pkg: WrinklePackage, engine: str) -> tuple[dict[str, bytes], list[str]]:
    """The files of an engine export as ``{relative path: bytes}`` and notes."""
    from wrinklepipe.io.gltf_write import gltf_document
    from wrinklepipe.io.package import png_bytes

    preset = ENGINE_PRESETS[engine]
    notes: list[str] = []
    files: dict[str, bytes] = {}
    if preset.gltf:
        doc, data, images = gltf_document(pkg)
        doc["buffers"][0]["uri"] = f"{pkg.name}.bin"
        files[f"{pkg.name}.gltf"] = dumps_json(doc).encode("utf-8")
        files[f"{pkg.name}.bin"] = data
        files.update(images)
    shipped = flip_green(pkg) if preset.convention == "directx" else pkg
    if preset.convention == "directx":
        notes.append("normal maps converted to DirectX (-Y): stored green q -> 255 - q")
    tex_files: dict[str, str] = {}
    compressed: dict[str, bytes] = {}
    if preset.normal_format == "bc5":
        compressed, n, _ = compressed_files(shipped, {}, {"base": "bc5", "wrinkle": "bc5"})
        notes += n
    for t in shipped.textures:
        dds = f"compressed/{t.name}.dds"
        if dds in compressed:
            rel = f"{engine}/{t.name}.dds"
            files[rel] = compressed[dds]
        else:
            rel = f"{engine}/{t.name}.png"
            files[rel] = png_bytes(t.pixels)
        tex_files[t.name] = rel
    meta = shipped.meta
    regions = [r["name"] for r in meta["regions"]]
    taken: set[str] = set()
    curve_paths = []
    for c in pkg.curves:
        for rel, data in curve_files(c, regions, taken).items():
            files[f"{engine}/{rel}"] = data
            if rel.endswith(".csv"):
                curve_paths.append(f"{engine}/{rel}")
    setup = {
        "engine": engine,
        "convention": preset.convention,
        "encoding": meta["encoding"],
        "scale": meta["scale"],
        "policy": meta["policy"],
        "base": tex_files["base_normal"],
        "states": [{"name": s["name"], "file": tex_files[s["texture"]]} for s in meta["states"]],
        "masks": {
            "layout": meta["masks"]["layout"],
            "files": [tex_files[n] for n in meta["masks"]["textures"]],
            "table": meta["masks"]["table"],
        },
        "regions": meta["regions"],
        "expressions": meta["expressions"],
        "curves": curve_paths,
        "notes": notes,
    }
    files[f"{engine}/wrinkle_setup.json"] = dumps_json(setup).encode("utf-8")
    if preset.shader and meta["encoding"] == "pd":
        template = _HLSL if preset.shader == "hlsl" else _GLSL
        text = template.format(
            policy=meta["policy"],
            convention=preset.convention,
            scale=_fmt(meta["scale"]),
            k=len(meta["states"]),
        )
        files[f"{engine}/wrinkle.{preset.shader}"] = text.encode("utf-8")
    return files, notes


def read_package(path: str | Path) -> WrinklePackage:
    """A written asset: a convert folder (its glTF), a .gltf/.glb or a .usda/.usdc/.usdz file."""
    from wrinklepipe.io.gltf_read import read_gltf
    from wrinklepipe.io.usd_read import read_usd

    path = Path(path)
    if path.is_dir():
        found = sorted(path.glob("*.gltf")) or sorted(path.glob("*.glb"))
        if not found:
            raise input_error(path, "no .gltf or .glb in this folder (is it a convert output?)")
        path = found[0]
    suffix = path.suffix.lower()
    if suffix in (".gltf", ".glb"):
        return read_gltf(path)
    if suffix in (".usda", ".usdc", ".usd", ".usdz"):
        return read_usd(path)
    raise input_error(path, "expected a convert folder, .gltf/.glb or .usda/.usdc/.usdz")


def export(
    source: str | Path, output: str | Path, engine: str, force: bool = False
) -> tuple[dict[str, bytes], list[str]]:
    """Export a written asset for one engine into ``output`` (atomically)."""
    if engine not in ENGINE_PRESETS:
        raise input_error(engine, f"unknown engine; expected one of {', '.join(ENGINE_PRESETS)}")
    source = Path(source)
    pkg = read_package(source)
    files, notes = export_files(pkg, engine)
    inputs = [source] if source.is_dir() else [source, source.parent]
    try:
        with staged_folder(output, force=force, inputs=inputs) as tmp:
            for rel, data in sorted(files.items()):
                write_bytes(tmp / rel, data)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise input_error(
            output, f"could not write the export ({reason}); nothing was changed"
        ) from None
    return files, notes
