"""Load what ``validate-asset`` is given into a :class:`ValidationInput`.

PATH may be:

- a folder written by ``convert`` (its ``.gltf``/``.glb``; BC5 copies under ``compressed/`` are
  used as the shipped base and state textures when present, as they are what ships);
- a ``.gltf``/``.glb`` that carries the ``WRINKLEPIPE_wrinkle_maps`` extension, or a
  ``.usda``/``.usdc``/``.usdz`` with the ``WrinkleMapsAPI`` schema (read by
  :mod:`wrinklepipe.io.gltf_read` / :mod:`wrinklepipe.io.usd_read`);
- a source manifest (``.toml``) before conversion: ingested, then packed as ``convert`` would
  (8-bit, no resampling), with the manifest's maps kept as the source;
- a validation bundle (``.wpv``, written by :func:`write_bundle`; the golden corpus uses it);
- ``demo[:ENCODING][@SIZE][+bc]``: the built-in demo shipped in memory.

Every failure is an :class:`~wrinklepipe.errors.InputError` naming the file and what is wrong.
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.asset import Mesh, Region, WrinkleAsset
from wrinklepipe.document.container import split_glb
from wrinklepipe.errors import InputError, input_error
from wrinklepipe.io.json_safe import loads_json
from wrinklepipe.validate.inputs import CHANNELS, FORMATS, ChannelEntry, Texture, ValidationInput

EXTENSION = "WRINKLEPIPE_wrinkle_maps"
BUNDLE_SUFFIX = ".wpv"
BUNDLE_VERSION = 1
_GLTF = (".gltf", ".glb")
_USD = (".usd", ".usda", ".usdc", ".usdz")
_MESH_FIELDS = (
    "positions",
    "indices",
    "uvs",
    "normals",
    "tangents",
    "morph_deltas",
    "joints",
    "skin_weights",
    "inverse_bind",
    "vertex_ids",
    "colors",
)


@dataclass(frozen=True)
class LoadOptions:
    """``textures``: ``"auto"`` uses compressed copies when a folder has them, ``"png"`` never,
    ``"compressed"`` requires them. ``source``: a manifest whose maps are the source to compare
    the shipped textures with (enables the shipping-error rules on converted outputs)."""

    textures: str = "auto"
    source: str | None = None
    max_gltf_bytes: int = 512 * 1024 * 1024


# ------------------------------------------------------------------------------------------------
# dispatch


def load_input(path: str | Path, options: LoadOptions | None = None) -> ValidationInput:
    """Load PATH (see the module docstring) for validation."""
    o = options or LoadOptions()
    text = str(path)
    if text == "demo" or text.startswith("demo:") or text.startswith("demo@"):
        inp = demo_input(text)
    else:
        p = Path(path)
        if not p.exists():
            raise input_error(p, "not found")
        suffix = p.suffix.lower()
        if p.is_dir():
            inp = _load_folder(p, o)
        elif suffix in _GLTF:
            check_gltf_claims_wrinkles(p, o.max_gltf_bytes)
            inp = _from_reader(p, "gltf")
        elif suffix in _USD:
            inp = _from_reader(p, "usd")
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


def _guard(fn: Any, path: Path, what: str) -> Any:
    """Run another stage's reader; anything but an InputError becomes one (no tracebacks)."""
    try:
        return fn()
    except InputError:
        raise
    except (MemoryError, KeyboardInterrupt):
        raise
    except Exception as exc:  # noqa: BLE001 - foreign readers: report, never crash
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise input_error(path, f"cannot read {what}: {msg}") from None


# ------------------------------------------------------------------------------------------------
# glTF / GLB: does it claim wrinkle data?


def _gltf_json(path: Path, max_bytes: int) -> dict[str, Any]:
    size = path.stat().st_size
    if size == 0:
        raise input_error(path, "file is empty")
    if size > max_bytes:
        raise input_error(path, f"file is {size} bytes, over the cap of {max_bytes}")
    raw = path.read_bytes()
    if raw[:4] == b"glTF":
        raw, _ = split_glb(raw, str(path))  # the one GLB container parser
    elif path.suffix.lower() == ".glb":
        raise input_error(path, "not a GLB file (bad magic)")
    doc = loads_json(raw, path, "glTF JSON")
    if not isinstance(doc, dict):
        raise input_error(path, "glTF JSON must be an object")
    return doc


def check_gltf_claims_wrinkles(path: Path, max_bytes: int = 512 * 1024 * 1024) -> None:
    """Refuse a glTF/GLB that does not carry the ``WRINKLEPIPE_wrinkle_maps`` extension."""
    doc = _gltf_json(path, max_bytes)
    asset = doc.get("asset")
    if not isinstance(asset, dict) or not isinstance(asset.get("version"), str):
        raise input_error(path, "not a glTF 2.0 document: missing asset.version", "/asset")
    used = doc.get("extensionsUsed", [])
    claims = isinstance(used, list) and EXTENSION in used
    mats = doc.get("materials", [])
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


# ------------------------------------------------------------------------------------------------
# packages (what the glTF/USD readers and the packer return)


def _fmt_for(pixels: np.ndarray) -> str:
    c = pixels.shape[-1] if pixels.ndim == 3 else 1
    bits = 16 if pixels.dtype == np.uint16 else 8
    return ("r", "rg", "rgb", "rgba")[c - 1] + str(bits)


def input_from_package(
    pkg: Any, path: str, kind: str, file_of: dict[str, str] | None = None
) -> ValidationInput:
    """A :class:`ValidationInput` from a :class:`wrinklepipe.io.package.WrinklePackage`."""
    from wrinklepipe.io.package import asset_from_package, mapping_version

    asset = _guard(lambda: asset_from_package(pkg), Path(path), "the wrinkle data")
    meta = pkg.meta
    version = _guard(lambda: mapping_version(meta), Path(path), "the mapping version")
    state_of = {s["texture"]: s["name"] for s in meta.get("states", [])}
    mask_names = list(meta.get("masks", {}).get("textures", []))
    textures = []
    file_of = file_of or {}
    for t in pkg.textures:
        px = np.ascontiguousarray(t.pixels)
        if px.ndim == 2:
            px = px[..., None]
        role = {"base_normal": "base", "state": "state", "mask": "mask"}.get(t.role, t.role)
        fmt = _fmt_for(px)
        data = px.astype("<u2").tobytes() if px.dtype == np.uint16 else px.tobytes()
        layout = "rg" if (role == "state" and asset.encoding == "pd") else "rgb"
        textures.append(
            Texture(
                name=t.name,
                role=role,
                fmt=fmt,
                width=int(px.shape[1]),
                height=int(px.shape[0]),
                data=data,
                file=file_of.get(t.name, path),
                pointer="" if t.name in file_of else f"textures/{t.name}",
                state=state_of.get(t.name, ""),
                layout=layout if px.shape[-1] >= 3 else "rg",
                mapping=version if role == "state" else 1,
            )
        )
    table = []
    for e in meta.get("masks", {}).get("table", []):
        if "layer" in e:
            tex, ch = mask_names[int(e["layer"])], 0
        else:
            tex = mask_names[int(e["texture"])] if int(e["texture"]) < len(mask_names) else "?"
            ch = CHANNELS.index(e["channel"]) if e.get("channel") in CHANNELS else 99
        entry = ChannelEntry(str(e["region"]), tex, ch)
        if "split" in e:
            sp = e["split"]
            entry.split = (mask_names[int(sp["texture"])], CHANNELS.index(sp["channel"]))
            entry.side = str(e.get("side", "center"))
        table.append(entry)
    curves = {
        str(c.name): np.asarray(c.values, np.float32) for c in getattr(pkg, "curves", []) or []
    }
    return ValidationInput(
        asset=asset,
        textures=textures,
        channel_table=table,
        weight_curves=curves,
        has_source=False,
        path=path,
        kind=kind,
        pointers={
            "meta": f"{path}#/extensions/{EXTENSION}" if kind == "gltf" else path,
            "mesh": f"{path}#/meshes/0" if kind == "gltf" else path,
            "masks": path,
            "channels": f"{path}#/extensions/{EXTENSION}/masks" if kind == "gltf" else path,
            "expressions": f"{path}#/extensions/{EXTENSION}/expressions"
            if kind == "gltf"
            else path,
            "textures": path,
            "drivers": f"{path}#/extensions/{EXTENSION}/drivers" if kind == "gltf" else path,
        },
    )


def _from_reader(p: Path, kind: str) -> ValidationInput:
    if kind == "gltf":
        from wrinklepipe.io.gltf_read import read_gltf

        pkg = _guard(lambda: read_gltf(p), p, "the glTF")
    else:
        from wrinklepipe.io.usd_read import read_usd

        pkg = _guard(lambda: read_usd(p), p, "the USD stage")
    folder = p.parent
    files = {t.name: str(folder / "textures" / f"{t.name}.png") for t in pkg.textures}
    files = {k: v for k, v in files.items() if Path(v).exists()}
    inp = input_from_package(pkg, str(p), kind, files)
    if kind == "usd":
        _usd_pointers(inp, p)
    else:
        _gltf_pointers(inp, p)
    return inp


def _gltf_pointers(inp: ValidationInput, p: Path) -> None:
    """JSON pointers to where the extension actually sits (a material's, or the document's)."""
    try:
        doc = _gltf_json(p, 1 << 30)
    except InputError:  # pragma: no cover - the reader already parsed it
        return
    ext = f"/extensions/{EXTENSION}"
    for i, m in enumerate(doc.get("materials", []) or []):
        if isinstance(m, dict) and EXTENSION in (m.get("extensions") or {}):
            ext = f"/materials/{i}/extensions/{EXTENSION}"
            break
    inp.pointers.update(
        {
            "meta": f"{p}#{ext}",
            "channels": f"{p}#{ext}/masks/table",
            "masks": f"{p}#{ext}/masks",
            "expressions": f"{p}#{ext}/expressions",
            "drivers": f"{p}#{ext}/drivers",
        }
    )


def _usd_pointers(inp: ValidationInput, p: Path) -> None:
    """Point issues at prims: the material with WrinkleMapsAPI, its attributes, the mesh."""
    try:
        from pxr import Usd, UsdGeom

        stage = Usd.Stage.Open(str(p))
        mat = mesh = None
        for prim in stage.Traverse():
            if mat is None and "WrinkleMapsAPI" in prim.GetAppliedSchemas():
                mat = prim.GetPath()
            if mesh is None and prim.IsA(UsdGeom.Mesh):
                mesh = prim.GetPath()
    except Exception:  # noqa: BLE001 - pointers are a convenience; the reader already worked
        return
    if mat is not None:
        inp.pointers.update(
            {
                "meta": f"{p}<{mat}>",
                "channels": f"{p}<{mat}>.wrinkle:maskChannel",
                "expressions": f"{p}<{mat}>.wrinkle:expressionWeights",
                "drivers": f"{p}<{mat}>.wrinkle:drivers",
                "masks": f"{p}<{mat}>",
            }
        )
    if mesh is not None:
        inp.pointers["mesh"] = f"{p}<{mesh}>"


def _load_folder(p: Path, o: LoadOptions) -> ValidationInput:
    found = (
        sorted(p.glob("*.gltf"))
        or sorted(p.glob("*.glb"))
        or sorted(q for q in p.iterdir() if q.suffix.lower() in _USD)
    )
    if not found:
        manifests = sorted(p.glob("manifest.toml"))
        if manifests:
            return _load_manifest(manifests[0])
        raise input_error(p, "no .gltf/.glb/.usd or manifest.toml in this folder")
    f = found[0]
    if f.suffix.lower() in _GLTF:
        check_gltf_claims_wrinkles(f, o.max_gltf_bytes)
    inp = _from_reader(f, "gltf" if f.suffix.lower() in _GLTF else "usd")
    inp.kind = "folder"
    if o.textures != "png":
        inp = _use_compressed(inp, p / "compressed", required=o.textures == "compressed")
    return inp


def _use_compressed(inp: ValidationInput, folder: Path, required: bool) -> ValidationInput:
    """Replace base/state textures by the BC copies that ship beside them (DDS)."""
    if not folder.is_dir():
        if required:
            raise input_error(folder, "no compressed/ folder (--textures compressed)")
        return inp
    from wrinklepipe.normals.dds import read_dds

    out = []
    for t in inp.textures:
        dds = folder / f"{t.name}.dds"
        if t.role in ("base", "state") and dds.exists():
            img = _guard(lambda dds=dds: read_dds(dds), dds, "the DDS file")
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
                layout="rg" if FORMATS[fmt][0] == 2 else t.layout,
            )
        out.append(t)
    inp.textures = out
    return inp


# ------------------------------------------------------------------------------------------------
# manifests (before conversion) and the demo


def _source_asset(manifest_path: Path) -> WrinkleAsset:
    from wrinklepipe.manifest import load_manifest
    from wrinklepipe.pipeline import ingest, prepare_mesh

    m = load_manifest(manifest_path)
    asset, _ = _guard(lambda: ingest(m), manifest_path, "the manifest's files")
    if asset.mesh is not None:
        asset = replace(asset, mesh=_guard(lambda: prepare_mesh(asset.mesh), manifest_path, "mesh"))
    return asset


def _load_manifest(p: Path) -> ValidationInput:
    from wrinklepipe.io.package import package_from_asset

    asset = _source_asset(p)
    pkg = _guard(lambda: package_from_asset(asset), p, "the packed asset")
    inp = input_from_package(pkg, str(p), "manifest")
    inp.asset = asset
    inp.has_source = True
    if asset.drivers:
        from wrinklepipe.pipeline import evaluate_drivers

        curves, _ = _guard(lambda: evaluate_drivers(asset, p.parent), p, "the drivers")
        inp.weight_curves = {str(c.name): np.asarray(c.values, np.float32) for c in curves}
    inp.pointers.update({k: str(p) for k in ("meta", "masks", "channels", "textures")})
    inp.pointers["expressions"] = f"{p} [expressions]"
    return inp


def _attach_source(inp: ValidationInput, manifest: Path) -> ValidationInput:
    src = _source_asset(manifest)
    a = inp.asset
    names = list(src.region_names)
    missing = [r for r in a.region_names if r not in names]
    if missing or list(src.state_names) != list(a.state_names):
        raise input_error(
            manifest,
            "does not describe the same asset (regions or states differ): "
            + ", ".join(missing[:5]),
        )
    masks = np.stack([src.masks[names.index(r)] for r in a.region_names])
    inp.asset = replace(
        a, base=src.base, states=src.states, masks=masks, budget=src.budget or a.budget
    )
    inp.has_source = True
    return inp


def demo_input(spec: str = "demo") -> ValidationInput:
    """``demo[:ENCODING][@SIZE][+bc]``: the demo shipped in memory (8-bit, or BC5/BC7 ``+bc``)."""
    from wrinklepipe.demo import demo_asset
    from wrinklepipe.validate.ship import ShipOptions, ship_asset

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
    from wrinklepipe.model import ENCODINGS

    if enc not in ENCODINGS:
        raise input_error(spec, f"unknown encoding {enc!r}; expected one of {', '.join(ENCODINGS)}")
    inp = ship_asset(demo_asset(size, encoding=enc), ShipOptions(compress=compress))
    inp.path = spec
    inp.kind = "demo"
    return inp


# ------------------------------------------------------------------------------------------------
# bundles: a ValidationInput in one deterministic zip (meta.json + .npy arrays)


def _npy(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.ascontiguousarray(arr), allow_pickle=False)
    return buf.getvalue()


def bundle_arrays(inp: ValidationInput) -> dict[str, np.ndarray]:
    """The arrays a bundle of ``inp`` holds (name -> array)."""
    return _bundle_parts(inp)[1]


def bundle_bytes(
    inp: ValidationInput, inherit: str | None = None, inherited: dict[str, np.ndarray] | None = None
) -> bytes:
    """Serialise a :class:`ValidationInput` (byte-identical for the same input).

    With ``inherit`` (a path relative to the bundle) arrays equal to ``inherited`` (that
    bundle's arrays) are left out and read from it (the corpus shares one source this way).
    """
    meta, arrays = _bundle_parts(inp)
    if inherit is not None and inherited is not None:
        meta["inherit"] = inherit
        arrays = {
            k: v
            for k, v in arrays.items()
            if not (
                k in inherited
                and inherited[k].dtype == v.dtype
                and inherited[k].shape == v.shape
                and np.array_equal(inherited[k], v)
            )
        }
        meta["omitted"] = sorted(k for k in _bundle_parts(inp)[1] if k not in arrays)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:

        def put(name: str, data: bytes) -> None:
            info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            z.writestr(info, data, compresslevel=9)

        put("meta.json", json.dumps(meta, sort_keys=True, indent=1).encode("utf-8"))
        for k in sorted(arrays):
            put(k + ".npy", _npy(arrays[k]))
    return buf.getvalue()


def _bundle_parts(inp: ValidationInput) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    a = inp.asset
    arrays: dict[str, np.ndarray] = {
        "base": np.asarray(a.base, np.float32),
        "states": np.asarray(a.states, np.float32),
        "masks": np.asarray(a.masks, np.float32),
    }
    mesh_meta = None
    if a.mesh is not None:
        mesh_meta = {
            "name": a.mesh.name,
            "morph_names": list(a.mesh.morph_names),
            "joint_names": list(a.mesh.joint_names),
        }
        for f in _MESH_FIELDS:
            v = getattr(a.mesh, f)
            if v is not None:
                arrays[f"mesh/{f}"] = np.asarray(v)
    for i, t in enumerate(inp.textures):
        arrays[f"texture/{i}"] = np.frombuffer(t.data, np.uint8)
    for name, v in inp.vertex_weights.items():
        arrays[f"vertex_weights/{name}"] = np.asarray(v, np.float32)
    for name, v in inp.weight_curves.items():
        arrays[f"weight_curves/{name}"] = np.asarray(v, np.float32)
    meta = {
        "version": BUNDLE_VERSION,
        "asset": {
            "name": a.name,
            "state_names": list(a.state_names),
            "regions": [
                {"name": r.name, "side": r.side, "states": list(r.states)} for r in a.regions
            ],
            "expressions": a.expressions,
            "encoding": a.encoding,
            "policy": a.policy,
            "pd_scale": float(a.pd_scale),
            "drivers": a.drivers,
            "budget": a.budget,
            "resolution": a.resolution,
            "provenance": a.provenance,
        },
        "mesh": mesh_meta,
        "textures": [
            {
                "name": t.name,
                "role": t.role,
                "fmt": t.fmt,
                "width": t.width,
                "height": t.height,
                "srgb": t.srgb,
                "file": t.file,
                "pointer": t.pointer,
                "state": t.state,
                "convention": t.convention,
                "layout": t.layout,
                **({"mapping": t.mapping} if t.mapping != 1 else {}),  # absent: v1
            }
            for t in inp.textures
        ],
        "channel_table": [
            {
                "region": e.region,
                "texture": e.texture,
                "channel": e.channel,
                **({"split": list(e.split), "side": e.side} if e.split else {}),
            }
            for e in inp.channel_table
        ],
        "has_source": inp.has_source,
        "pointers": inp.pointers,
        "extra": inp.extra,
    }
    return meta, arrays


def write_bundle(inp: ValidationInput, path: str | Path) -> Path:
    """Write a (self-contained) bundle atomically."""
    from wrinklepipe.atomic import write_output

    return write_output(path, bundle_bytes(inp))


def _read_zip(p: Path, depth: int = 0) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    try:
        with zipfile.ZipFile(p) as z:
            meta = loads_json(z.read("meta.json"), p, "bundle meta.json")
            arrays = {
                n[:-4]: np.lib.format.read_array(io.BytesIO(z.read(n)), allow_pickle=False)
                for n in z.namelist()
                if n.endswith(".npy")
            }
    except (zipfile.BadZipFile, KeyError, ValueError, json.JSONDecodeError, OSError) as exc:
        raise input_error(p, f"not a validation bundle: {exc}") from None
    if not isinstance(meta, dict):
        raise input_error(p, "not a validation bundle: meta.json is not an object")
    inherit = meta.get("inherit")
    if inherit:
        parent = (p.parent / str(inherit)).resolve()
        if depth > 4 or not parent.is_file():
            raise input_error(p, f"inherits from {inherit!r}, which is missing", "inherit")
        _, base = _read_zip(parent, depth + 1)
        for k in meta.get("omitted", []):
            if k not in base:
                raise input_error(p, f"array {k!r} is in neither bundle", "inherit")
            arrays[k] = base[k]
    return meta, arrays


def read_bundle(path: str | Path) -> ValidationInput:
    """Read a bundle written by :func:`write_bundle`."""
    p = Path(path)
    meta, arrays = _read_zip(p)
    if meta.get("version") != BUNDLE_VERSION:
        raise input_error(p, f"bundle version {meta.get('version')!r}, expected {BUNDLE_VERSION}")
    am = meta["asset"]
    mesh = None
    if meta.get("mesh") is not None:
        kw = {f: arrays[f"mesh/{f}"] for f in _MESH_FIELDS if f"mesh/{f}" in arrays}
        mesh = Mesh(
            name=meta["mesh"]["name"],
            morph_names=tuple(meta["mesh"]["morph_names"]),
            joint_names=tuple(meta["mesh"]["joint_names"]),
            **kw,
        )
    asset = WrinkleAsset(
        name=am["name"],
        base=arrays["base"],
        states=arrays["states"],
        state_names=tuple(am["state_names"]),
        masks=arrays["masks"],
        regions=tuple(Region(r["name"], r["side"], tuple(r["states"])) for r in am["regions"]),
        expressions=am["expressions"],
        encoding=am["encoding"],
        policy=am["policy"],
        pd_scale=am["pd_scale"],
        mesh=mesh,
        drivers=am["drivers"],
        budget=am["budget"],
        resolution=am["resolution"],
        provenance=am["provenance"],
    )
    textures = [
        Texture(data=arrays[f"texture/{i}"].tobytes(), **t) for i, t in enumerate(meta["textures"])
    ]
    table = []
    for e in meta["channel_table"]:
        entry = ChannelEntry(e["region"], e["texture"], e["channel"])
        if "split" in e:
            entry.split = (e["split"][0], int(e["split"][1]))
            entry.side = e["side"]
        table.append(entry)
    vw = {k.split("/", 1)[1]: v for k, v in arrays.items() if k.startswith("vertex_weights/")}
    wc = {k.split("/", 1)[1]: v for k, v in arrays.items() if k.startswith("weight_curves/")}
    return ValidationInput(
        asset=asset,
        textures=textures,
        channel_table=table,
        has_source=bool(meta["has_source"]),
        path=str(p),
        kind="bundle",
        pointers=dict(meta["pointers"]),
        vertex_weights=vw,
        weight_curves=wc,
        extra=dict(meta.get("extra", {})),
    )
