"""The USD output of a USD source: a layer over the source, and a flattened usdz.

``NAME.usda`` (and ``NAME.usdc`` on request) sublayers the source file, unchanged, and holds only
what convert adds, as opinions over the source's prims::

    #usda 1.0
    (subLayers = [@../assets/hero.usda@]      the source, by a path relative to the output folder
     defaultPrim, upAxis, metersPerUnit, timeCodesPerSecond, ...: the source's stage metadata)
    over "<each wrinkled Mesh>"               primvars:wrinkle:vertexId (int), wrinkle:tangent
                                              (float4, the prim's own space), wrinkle:bias, and
                                              primvars:st where the source has no UVs
    over "<the wrinkled Material>"            prepend apiSchemas = ["WrinkleMapsAPI"],
        (apiSchemas, wrinkle:* attributes,    the wrinkle:* attributes (weights animated as time
         inputs:wrinkle:state:* / mask:*)     samples), inputs:wrinkle:state:* / mask:* and the
        def Shader StReader, base_normal,     texture shaders reading them (textures/*.png beside
            wrinkle_<state>, mask_<i>         the layer)
        over "<its UsdPreviewSurface>"        inputs:normal.connect = base_normal.outputs:rgb
                                              (and inputs:diffuseColor.connect =
                                              base_color.outputs:rgb with colour states)

Per-vertex data is written ``vertex`` where every point of the prim has one value, else
``faceVarying`` (one value per ``faceVertexIndices`` corner, through the reader's corner map):
either way it lines up with the source topology. When no material is bound, the layer defines
one under ``/<defaultPrim>/WrinkleLooks`` and binds the meshes to it; when the wrinkled material
is also bound to meshes that are not wrinkled (a ``meshes`` restriction), the layer wrinkles a
clone (``def Material "<name>_wrinkled" (prepend references = </the source material>)``) bound to
the wrinkled meshes only. Skeleton bindings, joints, weights, blend shapes and animation stay
the source's: composition keeps them.

Layering policy: the source stays where the studio keeps it. The layer names it by a path
relative to the output folder (absolute only where no relative path exists, another drive);
nothing is written outside the output folder, and the source's bytes are never touched (the
layer is composed in memory and exported as text). ``NAME.usdz`` is the composed stage
flattened into one usdc with every texture it uses (the source's packed under
``textures/source/``) for consumers that want one file.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from wrinklepipe.errors import input_error
from wrinklepipe.io.confine import allowed, confine_usd
from wrinklepipe.io.png import DEFAULT_PNG_LEVEL, png_bytes
from wrinklepipe.io.usd_diagnostics import quiet
from wrinklepipe.names import noun, plural
from wrinklepipe.package import WrinklePackage
from wrinklepipe.udim import TOKEN, split_name
from wrinklepipe.usd.materialx import drop_materialx_file
from wrinklepipe.usd.meshes import mesh_time
from wrinklepipe.usd.package_write import LAYERED_OVER, UsdOptions, build_stage
from wrinklepipe.usd.source import UsdSource
from wrinklepipe.usd.usdz import usdz_bytes

#: Stage metadata copied from the source's root layer (only a stage's root layer sets them).
STAGE_METADATA = (
    "defaultPrim",
    "upAxis",
    "metersPerUnit",
    "timeCodesPerSecond",
    "framesPerSecond",
    "startTimeCode",
    "endTimeCode",
)
WRINKLE_SCOPE = "WrinkleLooks"


def source_reference(source: Path, output: Path) -> str:
    """How the layer in ``output`` names ``source``: relative to the output folder (posix), or
    absolute where there is no relative path (Windows: another drive)."""
    src, out = Path(source).resolve(), Path(output).resolve()
    try:
        return Path(os.path.relpath(src, out)).as_posix()
    except ValueError:
        return src.as_posix()


def _unique_child(stage: Any, parent: Any, name: str) -> Any:
    path = parent.AppendChild(name)
    k = 1
    while stage.GetPrimAtPath(path):
        path = parent.AppendChild(f"{name}_{k}")
        k += 1
    return path


@quiet
def layer_stage(src: UsdSource, pkg: WrinklePackage) -> tuple[Any, list[str]]:
    """The source sublayered into an in-memory stage whose root layer holds the wrinkle data
    (see the module doc); returns the stage and notes. The root layer names the source by its
    absolute path: :func:`layer_bytes` writes it relative."""
    from pxr import Sdf, Usd  # deferred: usd-core, USD only

    confine_usd(src.path)  # every path the source names: inside its folder, before it opens
    source_layer = Sdf.Layer.FindOrOpen(str(src.path))
    if source_layer is None:
        raise input_error(src.path, "cannot open the USD source layer")
    stage = Usd.Stage.CreateInMemory()
    root = stage.GetRootLayer()
    root.subLayerPaths.append(str(src.path))
    for key in STAGE_METADATA:
        if source_layer.pseudoRoot.HasInfo(key):
            root.pseudoRoot.SetInfo(key, source_layer.pseudoRoot.GetInfo(key))
    fps = stage.GetTimeCodesPerSecond()
    notes: list[str] = []
    _explicit_stage_metadata(stage, source_layer, notes)
    _deinstance(stage, [part.pointer for part in pkg.mesh.parts] + list(src.materials), notes)
    mat_paths = _materials(stage, src, pkg, fps, notes)
    for mat_path in mat_paths:
        _read_uvs_of_meshes(stage, mat_path, src, notes)
        marker = stage.GetPrimAtPath(mat_path).CreateAttribute(
            LAYERED_OVER, Sdf.ValueTypeNames.String, custom=True
        )
        marker.Set(src.path.name)  # read_usd reads the meshes in the source's topology
    for part in pkg.mesh.parts:
        _mesh_overs(stage, part, pkg, src.added_uvs, src.uv_names.get(part.pointer, "st"))
    if pkg.curves:  # the source's playback range stays; a source without one gets the curves'
        times = np.concatenate([np.asarray(c.times, np.float64) for c in pkg.curves]) * fps
        start, end = float(times.min()), float(times.max())
        if not (
            root.pseudoRoot.HasInfo("startTimeCode") and root.pseudoRoot.HasInfo("endTimeCode")
        ):
            stage.SetStartTimeCode(start)
            stage.SetEndTimeCode(end)
        elif start < stage.GetStartTimeCode() or end > stage.GetEndTimeCode():
            notes.append(
                f"USD: the wrinkle weights are sampled over time codes {start:g}..{end:g}, the "
                f"source plays {stage.GetStartTimeCode():g}..{stage.GetEndTimeCode():g} (kept)"
            )
    notes.append(
        f"USD: {pkg.name}.usda sublayers the source {src.path.name} unchanged and adds the "
        f"wrinkle data over {plural(len(pkg.mesh.parts), 'mesh')} and the "
        f"{noun(len(mat_paths), 'material')} "
        f"{', '.join(map(str, mat_paths))}; {pkg.name}.usdz is it flattened"
    )
    return stage, notes


def _explicit_stage_metadata(stage: Any, source_layer: Any, notes: list[str]) -> None:
    """What the source leaves to USD's fallbacks, said explicitly in the layer (the same
    meaning; a stage without them fails UsdValidation): ``upAxis`` (the fallback axis),
    ``metersPerUnit`` (0.01, centimetres), and ``defaultPrim`` when there is one root prim."""
    from pxr import UsdGeom  # deferred: usd-core, USD only

    said = []
    info = source_layer.pseudoRoot
    if not info.HasInfo("upAxis"):
        UsdGeom.SetStageUpAxis(stage, UsdGeom.GetFallbackUpAxis())
        said.append(f"upAxis {UsdGeom.GetFallbackUpAxis()}")
    if not info.HasInfo("metersPerUnit"):
        UsdGeom.SetStageMetersPerUnit(stage, UsdGeom.LinearUnits.centimeters)
        said.append("metersPerUnit 0.01")
    roots = list(stage.GetPseudoRoot().GetChildren())
    if not stage.HasDefaultPrim() and len(roots) == 1:
        stage.SetDefaultPrim(roots[0])
        said.append(f"defaultPrim {roots[0].GetName()} (its only root prim)")
    if said:
        notes.append(
            f"USD: the source leaves {', '.join(said)} to USD's fallbacks; the layer says them "
            "(same meaning)"
        )


def _read_uvs_of_meshes(stage: Any, material: Any, src: UsdSource, notes: list[str]) -> None:
    """The wrinkle textures of ``material`` read the UV primvar of the meshes bound to it."""
    names = sorted({n for p, n in src.uv_names.items() if _bound(stage, p) == str(material)})
    if not names or names == ["st"]:
        return
    reader = stage.GetPrimAtPath(material.AppendChild("StReader"))
    reader.GetAttribute("inputs:varname").Set(names[0])
    if len(names) > 1:
        notes.append(
            f"the meshes bound to {material} keep their UVs in different primvars "
            f"({', '.join(names)}): its wrinkle textures read {names[0]!r}"
        )


def _deinstance(stage: Any, paths: list[str], notes: list[str]) -> None:
    """Instance proxies cannot be overridden: the instances holding a wrinkled mesh or
    material become ordinary prims (``instanceable = false`` over the instance root; nested
    instances likewise), which composes to the same prims and values."""
    from pxr import Sdf  # deferred: usd-core, USD only

    done: list[str] = []
    # each pass uninstances one level of nesting: at most as many passes as a path has parts
    for _ in range(max((p.count("/") for p in paths), default=0) + 1):
        roots = set()
        for p in paths:
            prim = stage.GetPrimAtPath(p)
            if prim and prim.IsInstanceProxy():
                while prim.IsInstanceProxy():
                    prim = prim.GetParent()
                roots.add(prim.GetPath())
        if not roots:
            break
        for r in sorted(roots):
            Sdf.CreatePrimInLayer(stage.GetRootLayer(), r).SetInfo("instanceable", False)
            done.append(str(r))
    else:
        raise RuntimeError(f"instances over {', '.join(paths)} stay instances in the layer")
    if done:
        notes.append(
            f"USD: {', '.join(done)} made not instanceable in the layer (instance proxies "
            "cannot hold the wrinkle overrides; the composed prims are the same)"
        )


def _materials(
    stage: Any, src: UsdSource, pkg: WrinklePackage, fps: float, notes: list[str]
) -> list[Any]:
    """Put the package's wrinkle material on each wrinkled source material (or its clone), or
    on a new one bound to the meshes when none is bound; returns where it went."""
    from pxr import Sdf, Tf  # deferred: usd-core, USD only

    root = stage.GetRootLayer()
    built = build_stage(pkg, UsdOptions(fps=fps))  # the wrinkle material, as a new asset has it
    built_path = built.GetDefaultPrim().GetPath().AppendPath("Looks/skin")
    wrinkled = {part.pointer for part in pkg.mesh.parts}
    if not src.materials:
        top = stage.GetDefaultPrim() or next(iter(stage.GetPseudoRoot().GetChildren()), None)
        if top is None:
            raise input_error(src.path, "the USD source has no root prim")
        scope_path = _unique_child(stage, top.GetPath(), WRINKLE_SCOPE)
        scope = Sdf.CreatePrimInLayer(root, scope_path)
        scope.specifier = Sdf.SpecifierDef
        scope.typeName = "Scope"
        dest = scope_path.AppendChild(Tf.MakeValidIdentifier(pkg.name))
        Sdf.CopySpec(built.GetRootLayer(), built_path, root, dest)
        _bind(stage, dest, sorted(wrinkled))
        notes.append(f"no material is bound to the wrinkled meshes: defined {dest} and bound it")
        return [dest]
    out = []
    for material in src.materials:
        source_mat = Sdf.Path(material)
        if material in src.cloned:
            dest = _unique_child(stage, source_mat.GetParentPath(), f"{source_mat.name}_wrinkled")
            spec = Sdf.CreatePrimInLayer(root, dest)
            spec.specifier = Sdf.SpecifierDef
            spec.typeName = "Material"
            spec.referenceList.Prepend(Sdf.Reference(primPath=source_mat))
            meshes = [p for p in sorted(wrinkled) if _bound(stage, p) == material]
            _bind(stage, dest, meshes)
            notes.append(
                f"material {source_mat} is also bound to meshes that are not wrinkled: "
                f"{', '.join(meshes)} are bound to {dest} (an internal reference to it) with the "
                "wrinkle data"
            )
        else:
            dest = source_mat
            Sdf.CreatePrimInLayer(root, dest)  # an over
        _wrinkle_inputs(stage, built.GetRootLayer(), built_path, dest, src.path)
        _connect_base(stage, dest, notes, pkg.meta.base_color is not None)
        out.append(dest)
    return out


def _bound(stage: Any, mesh: str) -> str:
    from pxr import UsdShade  # deferred: usd-core, USD only

    mat, _ = UsdShade.MaterialBindingAPI(stage.GetPrimAtPath(mesh)).ComputeBoundMaterial()
    return str(mat.GetPath()) if mat else ""


def _wrinkle_inputs(stage: Any, built: Any, built_path: Any, dest: Any, source: Path) -> None:
    """Everything of the built wrinkle material but its Surface shader and surface output onto
    ``dest`` (over a source material): apiSchemas, wrinkle:* attributes, interface inputs, the
    texture shaders (their connections re-pointed to ``dest``)."""
    from pxr import Sdf  # deferred: usd-core, USD only

    scratch = Sdf.Layer.CreateAnonymous(".usda")
    Sdf.CreatePrimInLayer(scratch, dest.GetParentPath())
    Sdf.CopySpec(built, built_path, scratch, dest)  # connections inside re-pointed to dest
    made = scratch.GetPrimAtPath(dest)
    composed = stage.GetPrimAtPath(dest)
    root = stage.GetRootLayer()
    spec = root.GetPrimAtPath(dest)
    clash = [c.name for c in made.nameChildren if c.name != "Surface" and composed.GetChild(c.name)]
    clash += [p.name for p in made.properties if composed.HasProperty(p.name)]
    clash = [n for n in clash if n != "outputs:surface"]
    if clash:
        raise input_error(
            source,
            f"material {dest} already has {', '.join(clash)}: the wrinkle material's shaders and "
            "inputs would replace them (is it already wrinkled?)",
        )
    ops = spec.GetInfo("apiSchemas") if spec.HasInfo("apiSchemas") else Sdf.TokenListOp()
    added = made.GetInfo("apiSchemas")
    ops.prependedItems = list(ops.prependedItems) + [
        s for s in added.ApplyOperations([]) if s not in ops.prependedItems
    ]
    spec.SetInfo("apiSchemas", ops)
    for prop in made.properties:
        if prop.name != "outputs:surface":
            Sdf.CopySpec(scratch, prop.path, root, prop.path)
    for child in made.nameChildren:
        if child.name != "Surface":
            Sdf.CopySpec(scratch, child.path, root, child.path)


def _connect_base(stage: Any, dest: Any, notes: list[str], color: bool = False) -> None:
    """The material's UsdPreviewSurface reads the normal from the shipped base map (and, with
    colour states, its diffuseColor from the base colour they blend over)."""
    from pxr import Sdf, UsdShade  # deferred: usd-core, USD only

    mat = UsdShade.Material(stage.GetPrimAtPath(dest))
    shader = mat.ComputeSurfaceSource()[0]
    if not shader or shader.GetIdAttr().Get() != "UsdPreviewSurface":
        what = f"{shader.GetPath()} ({shader.GetIdAttr().Get()})" if shader else "none"
        notes.append(
            f"material {dest}: the surface shader is not a UsdPreviewSurface ({what}): the base "
            "normal map is in the material, connected to no surface input"
        )
        return
    normal = shader.GetInput("normal")
    if normal and normal.HasConnectedSource():
        notes.append(
            f"material {dest}: {shader.GetPath()}.inputs:normal now reads the manifest's base "
            "normal map (base_normal) instead of its source connection"
        )
    normal = normal or shader.CreateInput("normal", Sdf.ValueTypeNames.Normal3f)
    normal.GetAttr().SetConnections([dest.AppendChild("base_normal").AppendProperty("outputs:rgb")])
    if not color:
        return
    diffuse = shader.GetInput("diffuseColor")
    if diffuse and diffuse.HasConnectedSource():
        notes.append(
            f"material {dest}: {shader.GetPath()}.inputs:diffuseColor now reads the manifest's "
            "base colour (base_color) instead of its source connection"
        )
    diffuse = diffuse or shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f)
    diffuse.GetAttr().SetConnections([dest.AppendChild("base_color").AppendProperty("outputs:rgb")])


def _bind(stage: Any, material: Any, meshes: list[str]) -> None:
    from pxr import UsdShade  # deferred: usd-core, USD only

    mat = UsdShade.Material(stage.GetPrimAtPath(material))
    for mesh in meshes:
        prim = stage.GetPrimAtPath(mesh)
        api = UsdShade.MaterialBindingAPI(prim)
        if not prim.HasAPI(UsdShade.MaterialBindingAPI):  # applied only where it is not yet
            api = UsdShade.MaterialBindingAPI.Apply(prim)
        api.Bind(mat)


def topology_values(
    values: np.ndarray, corners: np.ndarray, fvi: np.ndarray, n_points: int
) -> tuple[str, np.ndarray]:
    """Per-render-vertex ``values`` -> (interpolation, values in the prim's topology): ``vertex``
    (one per point) when every point's corners agree, else ``faceVarying`` (one per corner)."""
    per_corner = values[corners]
    per_point = np.zeros((n_points,) + values.shape[1:], values.dtype)
    per_point[fvi] = per_corner
    if np.array_equal(per_point[fvi], per_corner):
        return "vertex", per_point
    return "faceVarying", per_corner


def _mesh_overs(
    stage: Any, part: Any, pkg: WrinklePackage, added_uvs: tuple[str, ...], uv_name: str
) -> None:
    from pxr import Sdf, Usd, UsdGeom, Vt  # deferred: usd-core, USD only

    prim = stage.GetPrimAtPath(part.pointer)
    gm = UsdGeom.Mesh(prim)
    fvi = np.asarray(gm.GetFaceVertexIndicesAttr().Get(), np.int64)
    n_p = len(gm.GetPointsAttr().Get(mesh_time(prim, Usd.TimeCode.Default())[0]) or [])
    if part.corners is None or len(part.corners) != len(fvi):
        raise input_error(part.pointer, "the render mesh does not map onto the prim's corners")
    rows = slice(part.start, part.start + part.count)
    m = pkg.mesh
    lin = np.asarray(part.transform, np.float64)[:3, :3]
    t = m.tangents[rows, :3].astype(np.float64) @ np.linalg.inv(lin).T  # back to prim space
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-30)
    w = m.tangents[rows, 3:] * np.sign(np.linalg.det(lin))
    tangents = np.concatenate([t, w], axis=1).astype(np.float32)
    pv = UsdGeom.PrimvarsAPI(prim)

    def put(name: str, type_name: Any, values: np.ndarray, array: Any) -> None:
        interp, data = topology_values(values, part.corners, fvi, n_p)
        flat = np.ascontiguousarray(data)
        pv.CreatePrimvar(name, type_name, interp).Set(array.FromNumpy(flat))

    put(
        "wrinkle:vertexId",
        Sdf.ValueTypeNames.IntArray,
        np.asarray(m.vertex_ids[rows], np.int32),
        Vt.IntArray,
    )
    put("wrinkle:tangent", Sdf.ValueTypeNames.Float4Array, tangents, Vt.Vec4fArray)
    if m.colors is not None:
        put(
            "wrinkle:bias",
            Sdf.ValueTypeNames.Float4Array,
            np.asarray(m.colors[rows], np.float32),
            Vt.Vec4fArray,
        )
    if part.pointer in added_uvs:
        uv = np.asarray(m.uvs[rows], np.float32)
        st = np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1).astype(np.float32)
        put(uv_name, Sdf.ValueTypeNames.TexCoord2fArray, st, Vt.Vec2fArray)


@quiet
def layer_bytes(stage: Any, reference: str, suffix: str = ".usda") -> bytes:
    """The stage's root layer as a file (``.usda`` text or ``.usdc``), the source sublayered by
    ``reference`` (:func:`source_reference`)."""
    from pxr import Sdf  # deferred: usd-core, USD only

    out = Sdf.Layer.CreateAnonymous(".usda")
    out.TransferContent(stage.GetRootLayer())
    del out.subLayerPaths[:]
    out.subLayerPaths.append(reference)
    if suffix == ".usda":
        return out.ExportToString().encode("utf-8")
    with tempfile.TemporaryDirectory(prefix="wrinklepipe-layer-") as work:
        tmp = Path(work) / f"layer{suffix}"
        if not out.Export(str(tmp)):
            raise OSError(f"USD export to {suffix} failed")
        return tmp.read_bytes()


def _retype_varnames(layer: Any) -> list[str]:
    """UsdPrimvarReader ``inputs:varname`` authored as a token (older exporters; the shader's
    input is a string since USD 20.11) rewritten as a string in the flattened layer, where we
    own the spec (a layer over the source cannot retype an attribute)."""
    from pxr import Sdf  # deferred: usd-core, USD only

    fixed: list[str] = []

    def visit(path: Any) -> None:
        if not path.IsPrimPropertyPath() or path.name != "inputs:varname":
            return
        spec = layer.GetAttributeAtPath(path)
        if spec is None or spec.typeName != Sdf.ValueTypeNames.Token:
            return
        owner = layer.GetPrimAtPath(path.GetPrimPath())
        info = owner.attributes.get("info:id") if owner else None
        if info is None or not str(info.default).startswith("UsdPrimvarReader"):
            return
        value = str(spec.default) if spec.HasDefaultValue() else None
        variability = spec.variability
        owner.RemoveProperty(spec)
        new = Sdf.AttributeSpec(owner, "inputs:varname", Sdf.ValueTypeNames.String, variability)
        if value is not None:
            new.default = value
        fixed.append(str(path))

    paths: list[Any] = []
    layer.Traverse(Sdf.Path.absoluteRootPath, paths.append)
    for path in paths:
        visit(path)
    if not fixed:
        return []
    return [
        f"usdz: {', '.join(fixed)} authored as a token; written as a string (the type "
        "UsdPrimvarReader's varname has had since USD 20.11)"
    ]


@quiet
def flattened_usdz(
    stage: Any,
    pkg: WrinklePackage,
    name: str,
    png_level: int = DEFAULT_PNG_LEVEL,
    source: Path | None = None,
) -> tuple[bytes, list[str]]:
    """The composed stage flattened into one usdc, packed with every texture it uses: the
    package's under ``textures/`` (PNGs at zlib ``png_level``), the source's byte for byte
    under ``textures/source/``. An asset path naming one of the stage's own layers
    (``assetInfo`` identifiers) names the flattened layer instead.

    Only files the confined stage resolved are read (``source``: the source layer, whose folder
    and the ``--allow-root`` folders bound them; :func:`~wrinklepipe.io.confine.confine_usd`
    checked every path before the stage was opened): an absolute path inside them, a file or a
    package (a ``.usdz`` holding it). A path USD left unresolved (a search path, a ``<UDIM>``
    pattern, a missing file) is left as it is and noted, never looked up beside the current
    folder; one outside is refused."""
    from pxr import Ar, UsdUtils  # deferred: usd-core, USD only

    folder = Path(source).resolve().parent if source is not None else None
    flat = stage.Flatten()
    drop_materialx_file(flat)  # a usdz holds no .mtlx; the network is in the layer
    layers = {
        os.path.realpath(x.realPath) for x in stage.GetUsedLayers() if x.realPath
    }  # the layers the flattened one replaces
    ours = {f"./textures/{t.name}.png": f"textures/{t.name}.png" for t in pkg.textures}
    files: dict[str, bytes] = {
        ours[k]: png_bytes(t.pixels, png_level) for k, t in zip(ours, pkg.textures)
    }
    if pkg.tiles:  # the layer names each UDIM set (its tiles are packed beside it)
        for stem in sorted({split_name(t.name)[0] for t in pkg.textures}):
            ours[f"./textures/{stem}.{TOKEN}.png"] = f"textures/{stem}.{TOKEN}.png"
    by_source: dict[str, str] = {}
    notes: list[str] = []

    def remap(asset: str) -> str:
        if not asset or asset in ours:
            return ours.get(asset, asset)
        if asset in by_source:
            return by_source[asset]
        if os.path.realpath(asset) in layers:
            return f"{name}.usdc"
        file = asset[: asset.index("[")] if asset.endswith("]") and "[" in asset else asset
        if not os.path.isabs(file):
            notes.append(f"usdz: {asset} not found: left as it is")
            return asset
        real = Path(file).resolve()
        if folder is None or not allowed(real, folder):
            raise input_error(
                source or name,
                f"USD asset path @{asset}@ is outside {folder} ({real}); only files inside the "
                "folder of the source are packed (allow another folder with --allow-root DIR)",
            )
        handle = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(asset)) if real.is_file() else None
        if handle is None:
            notes.append(f"usdz: {asset} not found: left as it is")
            return asset
        data = bytes(handle.GetBuffer())
        inner = asset[asset.rindex("[") + 1 : -1] if asset.endswith("]") else asset
        base = PurePosixPath(inner.replace("\\", "/")).name
        rel = f"textures/source/{base}"
        if rel in files and files[rel] != data:
            stem, dot, ext = base.rpartition(".")
            rel = f"textures/source/{stem}_{hashlib.sha256(data).hexdigest()[:8]}{dot}{ext}"
        files[rel] = data
        by_source[asset] = rel
        return rel

    UsdUtils.ModifyAssetPaths(flat, remap)
    notes += _retype_varnames(flat)
    with tempfile.TemporaryDirectory(prefix="wrinklepipe-usdz-") as work:
        tmp = Path(work) / f"{name}.usdc"
        if not flat.Export(str(tmp)):
            raise OSError(f"{name}.usdz: USD export failed")
        entries = [(tmp.name, tmp.read_bytes())]
    return usdz_bytes(entries + sorted(files.items())), notes
