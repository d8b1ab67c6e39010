"""Validation inputs from data: a packed asset (:func:`input_from_package`) and bundles.

A bundle (``.wpv``, written by :func:`write_bundle`) is a :class:`ValidationInput` in one
deterministic zip; the golden corpus uses it. Turning a path (a convert folder, a glTF/USD file,
a manifest, ``demo...``) into a validation input is the sources layer's job
(:func:`wrinklepipe.sources.validation.load_input`).
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import udim
from wrinklepipe.asset import ColorMaps, Mesh, Region, WrinkleAsset
from wrinklepipe.atomic import write_output
from wrinklepipe.errors import InputError, input_error, plain_reason
from wrinklepipe.io.json_safe import loads_json
from wrinklepipe.options import BudgetOptions
from wrinklepipe.pipeline.package import asset_from_package, mapping_version
from wrinklepipe.validate.inputs import CHANNELS, ChannelEntry, Texture, ValidationInput

EXTENSION = "WRINKLEPIPE_wrinkle_maps"
BUNDLE_SUFFIX = ".wpv"
BUNDLE_VERSION = 1
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


def guard_reader(fn: Any, path: Path, what: str) -> Any:
    """Run another stage's reader; anything but an InputError becomes one (no tracebacks)."""
    try:
        return fn()
    except InputError:
        raise
    except (MemoryError, KeyboardInterrupt):
        raise
    except Exception as exc:  # noqa: BLE001 - foreign readers: report, never crash
        raise input_error(path, f"cannot read {what}: {plain_reason(exc)}") from None


# ------------------------------------------------------------------------------------------------
# packages (what the glTF/USD readers and the packer return)


def _fmt_for(pixels: np.ndarray) -> str:
    c = pixels.shape[-1] if pixels.ndim == 3 else 1
    bits = 16 if pixels.dtype == np.uint16 else 8
    return ("r", "rg", "rgb", "rgba")[c - 1] + str(bits)


def input_from_package(
    pkg: Any, path: str, kind: str, file_of: dict[str, str] | None = None, maps: bool = True
) -> ValidationInput:
    """A :class:`ValidationInput` from a :class:`wrinklepipe.package.WrinklePackage`; a UDIM
    package's has one input per tile (:func:`wrinklepipe.udim.tile_package`) and describes
    the whole (its textures every tile's, its mesh the whole mesh). ``maps=False``: the
    asset's normal maps are not decoded (:func:`asset_from_package`; a source replaces them)."""
    if pkg.tiles:
        tiles = {
            t: input_from_package(udim.tile_package(pkg, t), path, kind, file_of, maps)
            for t in pkg.tiles
        }
        for t, one in tiles.items():
            one.extra["tile"] = t
        first = tiles[pkg.tiles[0]]
        return replace(
            first,
            asset=replace(first.asset, mesh=pkg.mesh),
            textures=[x for one in tiles.values() for x in one.textures],
            tiles=tiles,
        )
    asset = guard_reader(lambda: asset_from_package(pkg, maps), Path(path), "the wrinkle data")
    meta = pkg.meta
    version = guard_reader(lambda: mapping_version(meta), Path(path), "the mapping version")
    state_of = {s.texture: s.name for s in meta.states}
    state_of.update({s.color: s.name for s in meta.states if s.color is not None})
    mask_names = list(meta.masks.textures)
    textures = []
    file_of = file_of or {}
    for t in pkg.textures:
        px = np.ascontiguousarray(t.pixels)
        if px.ndim == 2:
            px = px[..., None]
        role = {"base_normal": "base", "state": "state", "mask": "mask"}.get(t.role, t.role)
        fmt = _fmt_for(px)
        # the texels' bytes as a view of the package's pixels (a copy of each texture's bytes
        # beside them before: 192 MiB for an 8192² base)
        data = (px.astype("<u2", copy=False) if px.dtype == np.uint16 else px).reshape(-1)
        data = data.view(np.uint8)
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
                srgb=role in ("base_color", "state_color"),
            )
        )
    table = []
    for e in meta.masks.table:
        if e.layer is not None:
            tex, ch = mask_names[e.layer], 0
        else:
            tex = mask_names[e.index] if e.index < len(mask_names) else "?"
            ch = CHANNELS.index(e.channel) if e.channel in CHANNELS else 99
        entry = ChannelEntry(e.region, tex, ch)
        if e.split is not None:
            entry.split = (mask_names[e.split.texture], CHANNELS.index(e.split.channel))
            entry.side = e.side or "center"
        table.append(entry)
    curves = {
        str(c.name): np.asarray(c.values, np.float32) for c in getattr(pkg, "curves", []) or []
    }
    return ValidationInput(
        asset=asset,
        textures=textures,
        channel_table=table,
        weight_curves=curves,
        curves=list(getattr(pkg, "curves", []) or []),
        has_source=False,
        path=path,
        kind=kind,
        extra={
            "compressed": [c.to_json() for c in meta.compressed],
            **({"color_factor": list(meta.color_factor)} if meta.base_color is not None else {}),
        },
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
    if a.color is not None:
        arrays["color/base"] = np.asarray(a.color.base)
        arrays["color/states"] = np.asarray(a.color.states)
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
            "budget": a.budget.to_json(),
            "resolution": a.resolution,
            "provenance": a.provenance,
            **_color_meta(a),
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


def _color_meta(a: WrinkleAsset) -> dict[str, Any]:
    """The asset's colour description in a bundle's meta (nothing without colour states:
    bundles of other assets are as before)."""
    if a.color is None and not a.color_only:
        return {}
    out: dict[str, Any] = {"color_only": list(a.color_only)}
    if a.color is not None:
        out["color"] = {
            "state_index": list(a.color.state_index),
            "factor": list(a.color.factor),
            "from_material": a.color.from_material,
        }
    return out


def write_bundle(inp: ValidationInput, path: str | Path) -> Path:
    """Write a (self-contained) bundle atomically."""
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
        budget=BudgetOptions.from_json(am["budget"]),
        resolution=am["resolution"],
        provenance=am["provenance"],
        color_only=tuple(int(k) for k in am.get("color_only", ())),
    )
    if am.get("color") is not None:
        c = am["color"]
        asset.color = ColorMaps(
            arrays["color/base"],
            arrays["color/states"],
            tuple(int(k) for k in c["state_index"]),
            tuple(float(x) for x in c["factor"]),  # type: ignore[arg-type]
            bool(c.get("from_material", False)),
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
