"""Turn what ``validate-asset`` is given into a :class:`ValidationInput` (the sources layer).

PATH may be:

- a folder written by ``convert`` (its ``.gltf``/``.glb``; BC5 copies under ``compressed/`` are
  used as the shipped base and state textures when present, as they are what ships);
- a ``.gltf``/``.glb`` that carries the ``WRINKLEPIPE_wrinkle_maps`` extension, or a
  ``.usda``/``.usdc``/``.usdz`` with the ``WrinkleMapsAPI`` schema (read by
  :mod:`wrinklepipe.gltf.package_read` / :mod:`wrinklepipe.usd.package_read`);
- a source manifest (``.toml``) before conversion: ingested and run through the stages
  ``convert`` runs (resampling, PD scale), then packed as it would (8-bit), with the manifest's
  maps kept as the source: validate-asset and convert judge the same thing;
- a validation bundle (``.wpv``, :func:`wrinklepipe.validate.loader.write_bundle`);
- ``demo[:ENCODING][@SIZE][+bc]``: the built-in demo shipped in memory.

Every failure is an :class:`~wrinklepipe.errors.InputError` naming the file and what is wrong.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import udim
from wrinklepipe.asset import WrinkleAsset
from wrinklepipe.demo import demo_asset
from wrinklepipe.errors import InputError, input_error
from wrinklepipe.fidelity.ship import edge_texels
from wrinklepipe.gltf.container import open_container
from wrinklepipe.gltf.document import read_document
from wrinklepipe.gltf.package_read import wrinkled_package
from wrinklepipe.model import ENCODINGS
from wrinklepipe.names import noun
from wrinklepipe.normals import uastc
from wrinklepipe.normals.dds import read_dds
from wrinklepipe.pipeline.drivers import evaluate_drivers
from wrinklepipe.pipeline.ingest import ingest
from wrinklepipe.pipeline.ingest_tiles import ingest_tiles
from wrinklepipe.pipeline.package import package_from_asset
from wrinklepipe.pipeline.prepare import prepare_mesh, run_stages
from wrinklepipe.pipeline.tiles import run_tile_stages
from wrinklepipe.readers.registry import Format, format_of, read_package_file
from wrinklepipe.sources.copies import check_copies, copy_path
from wrinklepipe.sources.manifest import load_manifest
from wrinklepipe.sources.package import asset_file
from wrinklepipe.usd.meshes import open_stage_checked
from wrinklepipe.validate.inputs import FORMATS, Texture, ValidationInput
from wrinklepipe.validate.loader import (
    BUNDLE_SUFFIX,
    EXTENSION,
    guard_reader,
    input_from_package,
    read_bundle,
)
from wrinklepipe.validate.ship import ShipOptions, ship_asset


@dataclass(frozen=True)
class LoadOptions:
    """``textures``: ``"auto"`` uses compressed copies when a folder has them, ``"png"`` never,
    ``"compressed"`` requires them. ``source``: a manifest whose maps are the source to compare
    the shipped textures with (enables the shipping-error rules on converted outputs).
    ``shipped_maps``: decode the shipped normal maps into the input's asset; False when a
    source's maps replace them (:func:`attach_source`; implied by ``source``)."""

    textures: str = "auto"
    source: str | None = None
    max_gltf_bytes: int = 512 * 1024 * 1024
    shipped_maps: bool = True


# ------------------------------------------------------------------------------------------------
# dispatch


def load_input(path: str | Path, options: LoadOptions | None = None) -> ValidationInput:
    """Load PATH (see the module docstring) for validation."""
    o = options or LoadOptions()
    if o.source:  # the source's maps replace the shipped ones: not decoded for nothing
        o = replace(o, shipped_maps=False)
    text = str(path)
    if text == "demo" or text.startswith("demo:") or text.startswith("demo@"):
        inp = demo_input(text)
    else:
        p = Path(path)
        if not p.exists():
            raise input_error(p, "not found")
        suffix = p.suffix.lower()
        fmt = format_of(p)
        if p.is_dir():
            inp = _load_folder(p, o)
        elif fmt is not None and fmt.package is not None:
            inp = _listed_copies(_from_written(p, fmt, o), p.parent)
        elif suffix == ".toml":
            inp = _load_manifest(p)
        elif suffix == BUNDLE_SUFFIX:
            inp = read_bundle(p)
        else:
            raise input_error(
                p,
                f"unsupported file type {suffix or '(no extension)'!r}: expected a convert "
                "folder, .gltf/.glb, .usda/.usdc/.usdz, a manifest (.toml) or a bundle (.wpv)",
            )
    if o.source:
        inp = _attach_source(inp, Path(o.source))
    return inp


# ------------------------------------------------------------------------------------------------
# glTF / GLB: does it claim wrinkle data?


def _check_size(path: Path, max_bytes: int) -> None:
    """Refuse an empty file, or one over ``max_bytes``, before it is read."""
    size = path.stat().st_size
    if size == 0:
        raise input_error(path, "file is empty")
    if size > max_bytes:
        raise input_error(path, f"file is {size} bytes, over the cap of {max_bytes}")


def claims_wrinkles(gltf: dict[str, Any], path: Path) -> None:
    """Refuse a glTF JSON tree that does not carry the ``WRINKLEPIPE_wrinkle_maps`` extension."""
    used = gltf.get("extensionsUsed", [])
    claims = isinstance(used, list) and EXTENSION in used
    mats = gltf.get("materials", [])
    if isinstance(mats, list):
        for m in mats:
            if isinstance(m, dict) and isinstance(m.get("extensions"), dict):
                claims = claims or EXTENSION in m["extensions"]
    if not claims:
        raise input_error(
            path,
            f"carries no wrinkle data: {EXTENSION} is not used (nothing to validate; the "
            "Khronos glTF-Validator checks plain glTF)",
            "/extensionsUsed",
        )


def check_gltf_claims_wrinkles(path: Path, max_bytes: int = 512 * 1024 * 1024) -> None:
    """Refuse a glTF/GLB that does not carry the ``WRINKLEPIPE_wrinkle_maps`` extension (its
    container parsed alone, geometry left undecoded)."""
    _check_size(path, max_bytes)
    claims_wrinkles(open_container(path).gltf, path)


def _from_written(p: Path, fmt: Format, o: LoadOptions) -> ValidationInput:
    """A written .gltf/.glb or USD file through the package reader of its format; a glTF is
    read once (:func:`~wrinklepipe.gltf.document.read_document`): its claim, its package and
    the pointers come from that one document."""
    kind = fmt.name
    what = "the glTF" if kind == "gltf" else "the USD stage"
    gltf: dict[str, Any] = {}
    if kind == "gltf":
        _check_size(p, o.max_gltf_bytes)
        doc = guard_reader(lambda: read_document(p), p, what)
        claims_wrinkles(doc.gltf, p)
        gltf = doc.gltf
        pkg = guard_reader(lambda: wrinkled_package(doc, p.stem), p, what)
    else:
        pkg = guard_reader(lambda: read_package_file(p), p, what)
    folder = p.parent
    files = {t.name: str(folder / "textures" / f"{t.name}.png") for t in pkg.textures}
    files = {k: v for k, v in files.items() if Path(v).exists()}
    inp = input_from_package(pkg, str(p), kind, files, o.shipped_maps)
    if kind == "usd":
        _usd_pointers(inp, p)
    else:
        _gltf_pointers(inp, p, gltf)
    return inp


def _listed_copies(inp: ValidationInput, folder: Path) -> ValidationInput:
    """A .gltf/.glb/USD file given alone: every compressed copy it lists, read whole and
    decoded (:func:`~wrinklepipe.sources.copies.check_copies`, the validator's WP-TEX-004),
    as for its folder; the PNGs stay the textures measured."""
    for one in _parts(inp):
        if one.extra.get("compressed"):
            problems = check_copies(one, folder)
            if problems:
                one.extra["copy_problems"] = problems
    return inp


def _parts(inp: ValidationInput) -> list[ValidationInput]:
    """What the validator measures: the input, or a UDIM input's tiles (each read on its
    own; the input itself shares the first tile's records)."""
    return list(inp.tiles.values()) if inp.tiles else [inp]


def _gltf_pointers(inp: ValidationInput, p: Path, gltf: dict[str, Any]) -> None:
    """JSON pointers to where the extension actually sits (a material's, or the document's)."""
    for one in _parts(inp):
        tile = one.extra.get("tile")  # a UDIM tile's material says which tile it is
        ext = f"/extensions/{EXTENSION}"
        for i, m in enumerate(gltf.get("materials", []) or []):
            block = (m.get("extensions") or {}).get(EXTENSION) if isinstance(m, dict) else None
            if isinstance(block, dict) and (tile is None or block.get("tile") == tile):
                ext = f"/materials/{i}/extensions/{EXTENSION}"
                break
        one.pointers.update(
            {
                "meta": f"{p}#{ext}",
                "channels": f"{p}#{ext}/masks/table",
                "masks": f"{p}#{ext}/masks",
                "expressions": f"{p}#{ext}/expressions",
                "drivers": f"{p}#{ext}/drivers",
            }
        )


def _usd_pointers(inp: ValidationInput, p: Path) -> None:
    """Point issues at prims: the material with WrinkleMapsAPI, its attributes, the mesh; and
    keep the stage's composition problems (the validator's WP-USD-xxx)."""
    from pxr import UsdGeom  # deferred: usd-core, USD only

    stage, problems = guard_reader(lambda: open_stage_checked(p), p, "the USD stage")
    if problems:
        for one in _parts(inp):
            one.extra["usd_composition"] = [x.to_json() for x in problems]
    mat = mesh = None
    for prim in stage.Traverse():
        if mat is None and "WrinkleMapsAPI" in prim.GetAppliedSchemas():
            mat = prim.GetPath()
        if mesh is None and prim.IsA(UsdGeom.Mesh):
            mesh = prim.GetPath()
    for one in _parts(inp):
        if mat is not None:
            one.pointers.update(
                {
                    "meta": f"{p}<{mat}>",
                    "channels": f"{p}<{mat}>.wrinkle:maskChannel",
                    "expressions": f"{p}<{mat}>.wrinkle:expressionWeights",
                    "drivers": f"{p}<{mat}>.wrinkle:drivers",
                    "masks": f"{p}<{mat}>",
                }
            )
        if mesh is not None:
            one.pointers["mesh"] = f"{p}<{mesh}>"


def _load_folder(p: Path, o: LoadOptions) -> ValidationInput:
    f = asset_file(p)
    if f is None:
        manifests = sorted(p.glob("manifest.toml"))
        if manifests:
            return _load_manifest(manifests[0])
        raise input_error(p, "no .gltf/.glb/.usd or manifest.toml in this folder")
    fmt = format_of(f)
    assert fmt is not None  # asset_file finds only suffixes the readers know
    inp = _from_written(f, fmt, o)
    inp.kind = "folder"
    if o.textures != "png":
        inp = _use_compressed(inp, p / "compressed", required=o.textures == "compressed")
    return inp


def _copy_layout(record: dict | None, fmt: str, png_layout: str | None) -> str | None:
    """Where a compressed copy keeps x, y (and z): the layout the extension / USD records for
    it; without a record, the codec's convention for the container's format (BC5: rg; a BC3
    normal map is DXT5nm: ag; BC1 / BC7: the PNG's layout, z in B for a normal map)."""
    if record is not None and record.get("layout") in ("rgb", "rg", "ag"):
        return str(record["layout"])
    if fmt == "bc3":
        return "ag"
    return "rg" if FORMATS[fmt][0] == 2 else png_layout


def _uastc_texture(t: Texture, path: Path, layout: str | None) -> Texture:
    """A texture replaced by its UASTC KTX2 copy, level 0 transcoded by basisu (alktx2) to
    RGBA8: what an engine that transcodes it samples."""
    px = guard_reader(lambda: uastc.decode_uastc(path.read_bytes()), path, "the KTX2 file")
    h, w = px.shape[:2]
    return replace(
        t,
        fmt="rgba8",
        width=w,
        height=h,
        data=px.tobytes(),
        file=str(path),
        pointer="",
        layout=layout,
    )


def _use_compressed(inp: ValidationInput, folder: Path, required: bool) -> ValidationInput:
    """Replace base/state textures by the BC copies that ship beside them (DDS), after reading
    every copy the asset lists whole (:func:`~wrinklepipe.sources.copies.check_copies`: DDS and
    KTX2, every level, decoded; what is wrong goes to ``extra["copy_problems"]``, the
    validator's WP-TEX-004). A copy that cannot be read leaves its PNG in place. A UDIM input's
    copies are read tile by tile."""
    if inp.tiles:
        inp.tiles = {t: _use_compressed(one, folder, required) for t, one in inp.tiles.items()}
        inp.textures = [x for one in inp.tiles.values() for x in one.textures]
        return inp
    if not folder.is_dir():
        if required:
            raise input_error(folder, "no compressed/ folder (--textures compressed)")
        return inp
    problems = check_copies(inp, folder.parent)
    if problems:
        inp.extra["copy_problems"] = problems
    broken = {Path(p["file"]).resolve() for p in problems}
    recorded = {str(c["texture"]): c for c in inp.extra.get("compressed", [])}
    out = []
    for t in inp.textures:
        dds = copy_path(inp, folder.parent, f"{folder.name}/{t.name}.dds", t.name)
        rec = recorded.get(t.name)
        ktx2 = copy_path(inp, folder.parent, f"{folder.name}/{t.name}.ktx2", t.name)
        uastc_copy = (
            t.role in ("base", "state")
            and rec is not None
            and rec.get("format") == "uastc"
            and ktx2.exists()
            and ktx2.resolve() not in broken
        )
        copied = dds.exists() or uastc_copy
        if t.role == "state" and copied and inp.asset.encoding == "pd" and t.fmt == "rgb8":
            # the clipped count is a property of the stored texels: count it on the lossless map
            px = np.frombuffer(t.data, np.uint8).reshape(t.height, t.width, -1)
            inp.extra.setdefault("pd_edge_texels", {})[t.name] = edge_texels(px)
        if uastc_copy:
            out.append(_uastc_texture(t, ktx2, _copy_layout(rec, "rgba8", t.layout)))
            continue
        if t.role in ("base", "state", "base_color", "state_color") and dds.exists():
            try:
                img = read_dds(dds)
            except InputError:
                out.append(t)  # said in copy_problems; the PNG is measured instead
                continue
            fmt = str(img.format).lower()
            if fmt not in FORMATS:
                raise input_error(dds, f"unsupported DDS format {img.format!r}")
            t = replace(
                t,
                fmt=fmt,
                width=int(img.width),
                height=int(img.height),
                data=bytes(img.levels[0]),
                file=str(dds),
                pointer="",
                layout=_copy_layout(recorded.get(t.name), fmt, t.layout),
                srgb=bool(img.srgb),
            )
        out.append(t)
    inp.textures = out
    return inp


# ------------------------------------------------------------------------------------------------
# manifests (before conversion) and the demo


def _source_asset(manifest_path: Path, stages: bool = False) -> WrinkleAsset:
    """The manifest's asset as read (the full-resolution source), or with ``stages`` after the
    very stages ``convert`` runs (resampling, mesh preparation, the PD scale choice), so that
    validating a manifest judges what convert would ship."""
    m = load_manifest(manifest_path)
    asset, _ = guard_reader(lambda: ingest(m), manifest_path, "the manifest's files")
    if stages:
        auto = m.pd_scale == "auto"
        asset, _ = guard_reader(
            lambda: run_stages(asset, auto_scale=auto), manifest_path, "the stages"
        )
    elif asset.mesh is not None:
        asset = replace(
            asset, mesh=guard_reader(lambda: prepare_mesh(asset.mesh), manifest_path, "mesh")
        )
    return asset


def _load_manifest(p: Path) -> ValidationInput:
    m = load_manifest(p)
    if m.tiles:
        return _load_tiled_manifest(p, m)
    asset = _source_asset(p, stages=True)
    pkg = guard_reader(lambda: package_from_asset(asset), p, "the packed asset")
    inp = input_from_package(pkg, str(p), "manifest")
    inp.asset = asset
    inp.has_source = True
    _source_problems(inp, asset)
    if asset.drivers:
        curves, _ = guard_reader(lambda: evaluate_drivers(asset, p.parent, p), p, "the drivers")
        inp.weight_curves = {str(c.name): np.asarray(c.values, np.float32) for c in curves}
        inp.curves = list(curves)
        records = [c.driver for c in curves if c.driver is not None]
        if records:  # what the drivers read, for the rig rules
            inp.asset = replace(inp.asset, provenance={**inp.asset.provenance, "drivers": records})
    inp.pointers.update({k: str(p) for k in ("meta", "masks", "channels", "textures")})
    inp.pointers["expressions"] = f"{p} [expressions]"
    return inp


def _load_tiled_manifest(p: Path, m: Any) -> ValidationInput:
    """A manifest with UDIM tiles, run through the stages convert runs tile by tile
    (:func:`wrinklepipe.pipeline.tiles.run_tile_stages`) and packed as it would: one input per
    tile, its asset the tile's after the stages."""
    got = guard_reader(lambda: ingest_tiles(m), p, "the manifest's files")
    whole = replace(got.whole, mesh=guard_reader(lambda: prepare_mesh(got.whole.mesh), p, "mesh"))
    tiles = {t: replace(a, mesh=udim.tile_mesh(whole.mesh, t)) for t, a in got.tiles.items()}
    auto = m.pd_scale == "auto"
    staged = guard_reader(lambda: run_tile_stages(tiles, auto_scale=auto), p, "the stages")
    curves: list[Any] = []
    if whole.drivers:
        curves, _ = guard_reader(lambda: evaluate_drivers(whole, p.parent), p, "the drivers")
    pkgs = {t: package_from_asset(a, curves=curves) for t, a in staged.assets.items()}
    pkg = guard_reader(lambda: udim.join_tiles(pkgs, whole.mesh), p, "the packed asset")
    inp = input_from_package(pkg, str(p), "manifest")
    for t, one in inp.tiles.items():
        one.asset = staged.assets[t]
        one.has_source = True
        _source_problems(one, got.tiles[t])
        one.pointers.update({k: str(p) for k in ("meta", "masks", "channels", "textures")})
    inp.has_source = True
    if curves:
        inp.weight_curves = {str(c.name): np.asarray(c.values, np.float32) for c in curves}
        inp.curves = list(curves)
        for one in inp.tiles.values():
            one.weight_curves, one.curves = inp.weight_curves, inp.curves
    inp.pointers.update({k: str(p) for k in ("meta", "masks", "channels", "textures")})
    return inp


def _attach_source(inp: ValidationInput, manifest: Path) -> ValidationInput:
    m = load_manifest(manifest)
    if m.tiles:
        got = guard_reader(lambda: ingest_tiles(m), manifest, "the manifest's files")
        return attach_source(inp, got.tiles, manifest)
    src, _ = guard_reader(lambda: ingest(m), manifest, "the manifest's files")
    return attach_source(inp, src, manifest)


def attach_source(
    inp: ValidationInput, src: WrinkleAsset | dict[int, WrinkleAsset], manifest: Path
) -> ValidationInput:
    """Use ``src`` (an ingested asset at its source resolution: base, states, masks, budget) as
    the source the shipped textures are measured against. ``convert`` passes the asset it has
    just ingested, so the validator neither re-reads nor re-decodes the source files; the
    shipped side is still what was read back from the written folder. A UDIM input takes one
    source asset per tile (``{tile: asset}``), and every tile needs its own."""
    if inp.tiles or isinstance(src, dict):
        return _attach_tiles(inp, src, manifest)
    a = inp.asset
    names = list(src.region_names)
    missing = [r for r in a.region_names if r not in names]
    if missing or list(src.state_names) != list(a.state_names):
        raise input_error(
            manifest,
            "does not describe the same asset (regions or states differ): "
            + ", ".join(missing[:5]),
        )
    order = [names.index(r) for r in a.region_names]
    # the source's own array when the regions come in its order (a full-size copy of every
    # mask otherwise: 2 GB for eight 8192² masks)
    masks = src.masks if order == list(range(len(names))) else src.masks[order]
    inp.asset = replace(
        a,
        base=src.base,
        states=src.states,
        masks=masks,
        # the colour maps too: the shipped ones may be smaller (the colour states' auto size)
        color=src.color if src.color is not None else a.color,
        budget=src.budget if src.budget.given else a.budget,
        provenance={
            **a.provenance,
            "maps": src.provenance.get("maps", {}),
            **({"drivers": src.provenance["drivers"]} if "drivers" in src.provenance else {}),
        },
    )
    inp.has_source = True
    _source_problems(inp, src)
    return inp


def _source_problems(inp: ValidationInput, src: WrinkleAsset) -> None:
    """The USD source's composition problems (recorded at ingest) for the validator."""
    found = src.provenance.get("usd_composition")
    if found:
        inp.extra["usd_composition"] = list(found)


def _attach_tiles(
    inp: ValidationInput, src: WrinkleAsset | dict[int, WrinkleAsset], manifest: Path
) -> ValidationInput:
    """:func:`attach_source` tile by tile."""
    if not isinstance(src, dict) or not inp.tiles:
        what = "has UDIM tiles" if isinstance(src, dict) else "has no UDIM tiles"
        raise input_error(
            manifest,
            f"does not describe the same asset: the manifest {what}, {inp.path} "
            + ("does not" if isinstance(src, dict) else "does"),
        )
    missing = sorted(set(inp.tiles) - set(src))
    if missing:
        raise input_error(
            manifest,
            f"does not describe the same asset: no source for "
            f"{noun(len(missing), 'tile')} "
            f"{', '.join(map(str, missing))} of {inp.path}",
        )
    inp.tiles = {t: attach_source(one, src[t], manifest) for t, one in inp.tiles.items()}
    first = inp.tiles[min(inp.tiles)]
    inp.asset = replace(first.asset, mesh=inp.asset.mesh)
    inp.has_source = True
    return inp


def demo_input(spec: str = "demo") -> ValidationInput:
    """``demo[:ENCODING][@SIZE][+bc]``: the demo shipped in memory (8-bit, or BC5/BC7 ``+bc``)."""
    rest = spec[4:]
    compress = rest.endswith("+bc")
    rest = rest.removesuffix("+bc")
    size = 256
    if "@" in rest:
        rest, s = rest.split("@", 1)
        if not s.isdigit() or not 16 <= int(s) <= 4096:
            raise input_error(spec, f"demo size {s!r} must be an integer in 16..4096")
        size = int(s)
    enc = rest.lstrip(":") or "pd"
    if enc not in ENCODINGS:
        raise input_error(spec, f"unknown encoding {enc!r}; expected one of {', '.join(ENCODINGS)}")
    inp = ship_asset(demo_asset(size, encoding=enc), ShipOptions(compress=compress))
    inp.path = spec
    inp.kind = "demo"
    return inp
