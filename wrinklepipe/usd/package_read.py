"""Read a wrinklepipe USD (.usda/.usdc/.usdz written by :mod:`wrinklepipe.usd.package_write`).

Finds the Material with ``WrinkleMapsAPI`` and the Mesh bound to it, undoes the V flip
(``uv = (s, 1 - t)``), reads the textures through Ar (so files inside a .usdz work) and returns the
same :class:`~wrinklepipe.package.WrinklePackage` the glTF reader returns. Texture paths must be
relative and stay inside the layer's folder or package.

Its meshes are read by the one USD mesh reader, :func:`wrinklepipe.usd.meshes.read_usd_meshes`
(render vertices through the corner map, wrinkle primvars vertex or faceVarying, UsdSkel blend
shapes and skin, the glTF joint names and inverse binds a wrinklepipe Skeleton carries), and
merged; the kind of stage only sets its options:

- a stage :func:`~wrinklepipe.usd.package_write.build_stage` wrote (one Mesh): read ``exact``
  (normals and joint weights as stored, so glTF -> USD -> glTF is byte-identical), its one-joint
  Skeleton of a mesh without skin read as no skin (``rigid_at_rest``), named as its prim;
- the USD of a glTF source (:mod:`wrinklepipe.usd.scene`; its material lists the
  wrinkled prims in ``wrinkle:meshes``): in that order, meshes bound rigidly to a joint at the
  skeleton's rest pose (``UsdMeshOptions.rigid_at_rest``), skinned ones in bind space: the
  render mesh the glTF path reads from the glTF beside it;
- a layer over a USD source (:mod:`wrinklepipe.usd.layer`; its material carries
  ``wrinkle:layeredOver``): the meshes bound to its wrinkled material(s), the source's
  topology, as ingest reads them.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from wrinklepipe import udim
from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.normals import vertex_normals
from wrinklepipe.io.json_safe import loads_json
from wrinklepipe.io.png import png_pixels
from wrinklepipe.metadata import (
    CompressedCopy,
    MaskChannel,
    MaskMeta,
    RegionMeta,
    SplitRef,
    StateMeta,
    WrinkleMeta,
    sorted_expressions,
)
from wrinklepipe.package import PackedTexture, WeightCurves, WrinklePackage, safe_name
from wrinklepipe.udim import TOKEN as UDIM_TOKEN
from wrinklepipe.usd.meshes import UsdMeshOptions, open_stage, read_usd_meshes
from wrinklepipe.usd.package_write import (
    API_NAME,
    LAYERED_OVER,
    SCENE_MESH_NAME,
    SCENE_MESHES,
    register_schema,
)
from wrinklepipe.usd.source import merge_parts


@dataclass(frozen=True)
class UsdReadOptions:
    """Reader limits: ``max_pixels`` per texture, ``max_texture_bytes`` per texture file."""

    max_pixels: int = 8192 * 8192
    max_texture_bytes: int = 512 * 1024 * 1024


def _asset_bytes(layer_path: Path, asset: Any, file: str, key: str, opt: UsdReadOptions) -> bytes:
    from pxr import Ar  # deferred: usd-core, USD only

    raw = asset.path if hasattr(asset, "path") else str(asset)
    if not raw:
        raise input_error(file, "empty texture path", key)
    parts = PurePosixPath(raw.replace("\\", "/")).parts
    if raw.startswith(("/", "\\")) or (len(raw) > 1 and raw[1] == ":") or ".." in parts:
        raise input_error(
            file, f"texture path {raw!r} must be relative and inside the asset folder", key
        )
    resolved = asset.resolvedPath if hasattr(asset, "resolvedPath") else ""
    if not resolved:
        raise input_error(file, f"texture {raw!r} not found", key)
    handle = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
    if handle is None:
        raise input_error(file, f"texture {raw!r} cannot be opened", key)
    size = handle.GetSize()
    if size > opt.max_texture_bytes:
        raise input_error(file, f"texture {raw!r} is {size} bytes, over the cap", key)
    data = bytes(handle.GetBuffer())
    if data[:8] != b"\x89PNG\r\n\x1a\n" or len(data) < 24:
        raise input_error(file, f"texture {raw!r} is not a PNG", key)
    w, h = struct.unpack(">II", data[16:24])
    if w * h > opt.max_pixels:
        raise input_error(file, f"texture {raw!r} is {w} x {h}, over the pixel cap", key)
    return data


def _samples(attr: Any, codes: list[float], width: int, what: str, per: str, file: str) -> Any:
    """The time samples of an array attribute as ``[T, width]`` float32; every sample must hold
    ``width`` numbers (one message naming the attribute and the time otherwise)."""
    from pxr import Usd  # deferred: usd-core, USD only

    rows = []
    for c in codes:
        value = attr.Get(Usd.TimeCode(c))
        row = np.asarray(value if value is not None else [], np.float32).reshape(-1)
        if row.size != width:
            raise input_error(file, f"{attr.GetPath()} at time {c:g}: {row.size} {what} for {per}")
        rows.append(row)
    return np.stack(rows) if rows else np.zeros((0, width), np.float32)


def _compressed(prim: Any, mapping: int, tiled: bool = False) -> tuple[CompressedCopy, ...]:
    """The records of the block-compressed copies (``wrinkle:compressed*``), if authored (a
    UDIM asset's files name ``<UDIM>``)."""
    u = f".{UDIM_TOKEN}" if tiled else ""

    def get(name: str) -> list[Any]:
        a = prim.GetAttribute(f"wrinkle:{name}")
        return list(a.Get()) if a and a.HasAuthoredValue() else []

    names = [str(n) for n in get("compressedTextures")]
    fmts, lays, levels = get("compressedFormats"), get("compressedLayouts"), get("compressedLevels")
    spaces = [str(c) for c in get("compressedColorSpaces")] or ["linear"] * len(names)
    return tuple(
        CompressedCopy(
            texture=n,
            format=str(f),
            layout=str(lay),
            mapping=1 if n == "base_normal" or space == "srgb" else mapping,
            levels=int(lv),
            ktx2=f"compressed/{n}{u}.ktx2",
            dds="" if str(f) == "uastc" else f"compressed/{n}{u}.dds",  # UASTC: KTX2 only
            color_space=space,
        )
        for n, f, lay, lv, space in zip(names, fmts, lays, levels, spaces)
    )


def _mapping(prim: Any) -> int:
    """``wrinkle:mapping`` (the value-mapping version); stages written before it hold v1."""
    a = prim.GetAttribute("wrinkle:mapping")
    return int(a.Get()) if a and a.HasAuthoredValue() else 1


def _has_api(prim: Any) -> bool:
    """``WrinkleMapsAPI`` applied: by the schema registry, or as authored ``apiSchemas`` (USD
    filters schemas it does not know out of ``GetAppliedSchemas`` when the plugin was
    registered too late in this process)."""
    if API_NAME in prim.GetAppliedSchemas():
        return True
    op = prim.GetMetadata("apiSchemas")
    return op is not None and API_NAME in op.ApplyOperations([])


def _stem(asset: Any) -> str:
    return PurePosixPath(asset.path.replace("\\", "/")).stem


def _wrinkled_mesh(path: Path, file: str, prims: list[str], options: UsdMeshOptions) -> Mesh:
    """The wrinkled meshes ``prims``, read by the mesh reader
    (:func:`~wrinklepipe.usd.meshes.read_usd_meshes`: render vertices through the corner map,
    wrinkle primvars vertex or faceVarying, UsdSkel skin and blend shapes; only those prims) and
    merged."""
    parts = {m.name: m for m in read_usd_meshes(path, replace(options, paths=tuple(prims)))}
    got = []
    for p in prims:
        m = parts.get(p)
        if m is None:
            raise input_error(file, "the wrinkled mesh has no faces", p)
        for what, value in (("wrinkle:tangent", m.tangents), ("wrinkle:vertexId", m.vertex_ids)):
            if value is None:
                raise input_error(file, f"primvars:{what} missing or unreadable", p)
        if m.uvs is None:
            raise input_error(file, "texture coordinates (primvars:st) missing", p)
        got.append(m)
    mesh = merge_parts(got, keep_ids=True)
    if mesh.normals is None:  # as convert made them: area-weighted, over the merged meshes
        mesh.normals = vertex_normals(mesh.positions, mesh.indices).astype(np.float32)
    return mesh


def read_usd(path: str | Path, options: UsdReadOptions | None = None) -> WrinklePackage:
    """Load a wrinklepipe USD stage as a :class:`WrinklePackage`."""
    from pxr import UsdGeom, UsdShade  # deferred: usd-core, USD only

    opt = options or UsdReadOptions()
    path = Path(path)
    file = str(path)
    if not path.is_file():
        raise input_error(file, "file not found")
    register_schema()
    stage = open_stage(path)  # the one confined Stage.Open (usd.meshes)
    mat_prim = None
    for prim in stage.Traverse():
        if prim.IsA(UsdShade.Material) and _has_api(prim):
            mat_prim = prim
            break
    if mat_prim is None:
        raise input_error(file, f"no Material with {API_NAME}: not a wrinklepipe asset")
    layered = mat_prim.HasAttribute(LAYERED_OVER)
    wrinkled = {  # a layer over a source may wrinkle several of its materials alike
        p.GetPath()
        for p in stage.Traverse()
        if p.IsA(UsdShade.Material) and _has_api(p) and (layered or p == mat_prim)
    }
    meshes = [
        prim
        for prim in stage.Traverse()
        if prim.IsA(UsdGeom.Mesh)
        and (bound := UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0])
        and bound.GetPath() in wrinkled
    ]
    if not meshes:
        raise input_error(file, f"no Mesh bound to {mat_prim.GetPath()}")
    order = mat_prim.GetAttribute(SCENE_MESHES)
    if order and order.HasAuthoredValue():  # a glTF source's scene (usd.scene)
        listed = [str(p) for p in order.Get()]
        if sorted(listed) != sorted(str(m.GetPath()) for m in meshes):
            raise input_error(
                file,
                f"{SCENE_MESHES} does not list the meshes bound to the material",
                str(mat_prim.GetPath()),
            )
        mesh = _wrinkled_mesh(path, file, listed, UsdMeshOptions(rigid_at_rest=True))
        named = mat_prim.GetAttribute(SCENE_MESH_NAME)
        if named and named.HasAuthoredValue():
            mesh.name = str(named.Get())
    elif not layered and len(meshes) == 1:  # a stage build_stage wrote: its mesh as stored
        prim = str(meshes[0].GetPath())
        exact = UsdMeshOptions(rigid_at_rest=True, exact=True)
        mesh = replace(_wrinkled_mesh(path, file, [prim], exact), name=meshes[0].GetName())
    else:  # a layer over a source (wrinklepipe.usd.layer): the source's topology
        mesh = _wrinkled_mesh(path, file, [str(m.GetPath()) for m in meshes], UsdMeshOptions())

    # -- textures ----------------------------------------------------------------------------
    textures: list[PackedTexture] = []
    tiles = _tiles(mat_prim, file)

    def add_texture(asset: Any, key: str, role: str, name: str | None = None) -> str:
        stem = _stem(asset)
        if tiles:  # a UDIM set: NAME.<UDIM>.png, one file per tile
            if not stem.endswith(f".{UDIM_TOKEN}"):
                raise input_error(file, f"a texture of a UDIM asset names no {UDIM_TOKEN}", key)
            name = name or safe_name(stem[: -len(UDIM_TOKEN) - 1])
            for t in tiles:
                tile_name = udim.tiled_name(name, t)
                if not any(x.name == tile_name for x in textures):
                    data = _asset_bytes(path, _tile_asset(stage, asset, t), file, key, opt)
                    pixels = png_pixels(data, f"{file} {key} tile {t}")
                    textures.append(PackedTexture(tile_name, pixels, role))
            return name
        name = name or safe_name(stem)
        if not any(t.name == name for t in textures):
            data = _asset_bytes(path, asset, file, key, opt)
            textures.append(PackedTexture(name, png_pixels(data, f"{file} {key}"), role))
        return name

    base_shader = UsdShade.Shader(mat_prim.GetChild("base_normal"))
    if not base_shader:
        raise input_error(
            file, "material has no base_normal texture shader", str(mat_prim.GetPath())
        )
    base_file = base_shader.GetInput("file").Get()
    add_texture(base_file, f"{base_shader.GetPath()}.inputs:file", "base_normal", "base_normal")

    meta = _meta(mat_prim, add_texture, file)
    if tiles:
        meta = replace(meta, compressed=_compressed(mat_prim, meta.mapping, tiled=True))
        udim.triangle_tiles(mesh.uvs, mesh.indices, file)  # every triangle inside one tile
    curves = _curves(stage, mat_prim, len(meta.regions), len(mesh.morph_names), file)
    name = stage.GetDefaultPrim().GetName() if stage.GetDefaultPrim() else path.stem
    return WrinklePackage(name, mesh, textures, meta, curves, tiles)


def _tiles(mat_prim: Any, file: str) -> tuple[int, ...]:
    """``wrinkle:tiles`` (a UDIM asset's tiles), or () when not authored."""
    a = mat_prim.GetAttribute("wrinkle:tiles")
    if not a or not a.HasAuthoredValue():
        return ()
    got = tuple(int(t) for t in a.Get())
    if not got or not all(udim.valid(t) for t in got) or list(got) != sorted(set(got)):
        raise input_error(
            file,
            f"wrinkle:tiles must list UDIM tiles (1001..9999) ascending, got {list(got)}",
            str(mat_prim.GetPath()),
        )
    return got


class _TileAsset:
    """One tile of a ``<UDIM>`` asset path, resolved as USD resolves the layer's assets."""

    def __init__(self, path: str, resolved: str) -> None:
        self.path, self.resolvedPath = path, resolved


def _tile_asset(stage: Any, asset: Any, tile: int) -> _TileAsset:
    """The file of tile ``tile`` of ``asset`` (its ``<UDIM>`` replaced), resolved against the
    layer that authored it (the root layer: wrinklepipe writes its textures there)."""
    from pxr import Ar, Sdf  # deferred: usd-core, USD only

    raw = udim.pattern_path(asset.path, tile)
    anchored = Sdf.ComputeAssetPathRelativeToLayer(stage.GetRootLayer(), raw)
    return _TileAsset(raw, str(Ar.GetResolver().Resolve(anchored)))


def _meta(mat_prim: Any, add_texture: Callable[[Any, str, str], str], file: str) -> WrinkleMeta:
    """The wrinkle description the material's ``WrinkleMapsAPI`` attributes and inputs hold (a
    map onto :class:`~wrinklepipe.metadata.WrinkleMeta`, checked by the extension's schema);
    ``add_texture(asset, key, role)`` reads each texture input and names it."""
    from pxr import Tf, Usd, UsdShade  # deferred: usd-core, USD only

    mat = UsdShade.Material(mat_prim)

    def api(name: str) -> Any:
        a = mat_prim.GetAttribute(f"wrinkle:{name}")
        if not a or not a.HasAuthoredValue():
            raise input_error(file, f"wrinkle:{name} missing", str(mat_prim.GetPath()))
        return a.Get()

    state_names = [str(s) for s in api("stateNames")]
    states = []
    for s in state_names:
        inp = mat.GetInput(f"wrinkle:state:{Tf.MakeValidIdentifier(s)}")
        if not inp:
            raise input_error(file, f"inputs:wrinkle:state:{s} missing", str(mat_prim.GetPath()))
        states.append(
            StateMeta(s, add_texture(inp.Get(), inp.GetAttr().GetPath().pathString, "state"))
        )
    states, base_color, factor = _colors(mat_prim, states, add_texture, file)
    mask_names = []
    for n in api("maskNames"):
        inp = mat.GetInput(f"wrinkle:mask:{n}")
        if not inp:
            raise input_error(file, f"inputs:wrinkle:mask:{n} missing", str(mat_prim.GetPath()))
        mask_names.append(add_texture(inp.Get(), inp.GetAttr().GetPath().pathString, "mask"))

    region_names = [str(n) for n in api("regionNames")]
    sides = [str(n) for n in api("regionSides")]
    rstates = [str(n) for n in api("regionStates")]
    layout = str(api("maskLayout"))
    mtex = list(api("maskTexture"))
    mch = [str(c) for c in api("maskChannel")]
    stex = list(api("splitTexture"))
    sch = [str(c) for c in api("splitChannel")]
    r = len(region_names)
    if not (len(sides) == len(rstates) == len(mtex) == len(mch) == len(stex) == len(sch) == r):
        raise input_error(
            file, "per-region arrays of WrinkleMapsAPI differ in length", str(mat_prim.GetPath())
        )
    table = tuple(
        MaskChannel(name, layer=int(mtex[i]))
        if layout == "array"
        else MaskChannel(
            name,
            texture=int(mtex[i]),
            channel=mch[i],
            side=sides[i] if layout == "lr-split" else None,
            split=SplitRef(int(stex[i]), sch[i]) if int(stex[i]) >= 0 else None,
        )
        for i, name in enumerate(region_names)
    )
    expr_names = [str(n) for n in api("expressionNames")]
    ew = (
        np.asarray(api("expressionWeights"), np.float64).reshape(len(expr_names), r)
        if expr_names
        else np.zeros((0, r), np.float64)
    )
    drivers = loads_json(str(api("drivers")), file, "wrinkle:drivers JSON", str(mat_prim.GetPath()))
    weights_attr = mat_prim.GetAttribute("wrinkle:weights")
    default = weights_attr.Get(Usd.TimeCode.Default())
    where = str(mat_prim.GetPath())
    if not isinstance(drivers, list) or not all(isinstance(d, dict) for d in drivers):
        raise input_error(file, "wrinkle:drivers must be a JSON array of objects", where)
    mapping = _mapping(mat_prim)
    meta = WrinkleMeta(
        encoding=str(api("encoding")),
        policy=str(api("policy")),
        states=tuple(states),
        masks=MaskMeta(layout, tuple(mask_names), table),
        regions=tuple(
            RegionMeta(n, sides[i], tuple(x for x in rstates[i].split(",") if x))
            for i, n in enumerate(region_names)
        ),
        scale=float(api("scale")),
        mapping=mapping,
        expressions=sorted_expressions(
            {e: dict(zip(region_names, row.tolist())) for e, row in zip(expr_names, ew)}
        ),
        drivers=tuple(drivers),
        weights=tuple(float(w) for w in (default if default is not None else [0.0] * r)),
        compressed=_compressed(mat_prim, mapping),
        base_color=base_color,
        color_factor=factor,
    ).check(lambda message, key: input_error(file, message, key), where)
    return meta


def _colors(
    mat_prim: Any, states: list[StateMeta], add_texture: Callable[..., str], file: str
) -> tuple[list[StateMeta], str | None, tuple[float, float, float]]:
    """The colour half (``wrinkle:colorStates``, the ``base_color`` shader and each state's
    ``inputs:wrinkle:color:<state>``), when authored: the states with their colour maps, the
    base colour's texture and its factor (the shader's ``inputs:scale``)."""
    from pxr import Tf, UsdShade  # deferred: usd-core, USD only

    where = str(mat_prim.GetPath())

    def tokens(name: str) -> list[str]:
        a = mat_prim.GetAttribute(f"wrinkle:{name}")
        return [str(x) for x in a.Get()] if a and a.HasAuthoredValue() else []

    colored, only = tokens("colorStates"), set(tokens("colorOnlyStates"))
    names = [s.name for s in states]
    for n in [*colored, *only]:
        if n not in names:
            raise input_error(file, f"wrinkle colour attributes name an unknown state {n!r}", where)
    out = [replace(s, normal=s.name not in only) for s in states]
    if not colored:
        return out, None, (1.0, 1.0, 1.0)
    mat = UsdShade.Material(mat_prim)
    shader = UsdShade.Shader(mat_prim.GetChild("base_color"))
    if not shader:
        raise input_error(file, "colour states but no base_color texture shader", where)
    base_file = shader.GetInput("file").Get()
    base = add_texture(base_file, f"{shader.GetPath()}.inputs:file", "base_color", "base_color")
    scale = shader.GetInput("scale")
    sc = scale.Get() if scale else None
    factor = (float(sc[0]), float(sc[1]), float(sc[2])) if sc is not None else (1.0, 1.0, 1.0)
    for k, s in enumerate(out):
        if s.name not in colored:
            continue
        inp = mat.GetInput(f"wrinkle:color:{Tf.MakeValidIdentifier(s.name)}")
        if not inp:
            raise input_error(file, f"inputs:wrinkle:color:{s.name} missing", where)
        key = inp.GetAttr().GetPath().pathString
        out[k] = replace(s, color=add_texture(inp.Get(), key, "state_color"))
    return out, base, factor


def _curves(stage: Any, mat_prim: Any, r: int, n_morphs: int, file: str) -> list[WeightCurves]:
    """The weight curves: ``wrinkle:weights`` time samples (the first), ``wrinkle:curves:curveI``
    (the others, named by ``wrinkle:curveNames``) and each one's ``wrinkle:morphCurves:curveI``
    morph weights."""

    weights_attr = mat_prim.GetAttribute("wrinkle:weights")
    fps = stage.GetTimeCodesPerSecond()

    def curve(attr: Any, name: str) -> WeightCurves | None:
        codes = attr.GetTimeSamples()
        if not codes:
            return None
        times = np.array([c / fps for c in codes], np.float32)
        values = _samples(attr, codes, r, "weights", f"{r} regions", file)
        return WeightCurves(name, times, values)

    curves = []
    first = curve(
        weights_attr, str(mat_prim.GetAttribute("wrinkle:weightCurve").Get() or "weights")
    )
    if first is not None:
        curves.append(first)

    def morphs(i: int, c: WeightCurves) -> WeightCurves:
        a = mat_prim.GetAttribute(f"wrinkle:morphCurves:curve{i}")
        if not a or not a.GetTimeSamples():
            return c
        codes = a.GetTimeSamples()
        if len(codes) != len(c.times):
            raise input_error(file, f"{a.GetPath()}: morph weights do not match the curve")
        mw = _samples(a, codes, n_morphs, "morph weights", f"{n_morphs} morph targets", file)
        return WeightCurves(c.name, c.times, c.values, mw)

    order = mat_prim.GetAttribute("wrinkle:curveNames")
    names = [str(n) for n in order.Get()] if order and order.HasAuthoredValue() else []
    for i, curve_name in enumerate(names[1:], start=1):
        attr = mat_prim.GetAttribute(f"wrinkle:curves:curve{i}")
        if not attr:
            raise input_error(file, f"wrinkle:curves:curve{i} missing", str(mat_prim.GetPath()))
        c = curve(attr, curve_name)
        if c is not None:
            curves.append(c)
    curves = [morphs(i, c) for i, c in enumerate(curves)]
    return curves
