"""USD writer for a :class:`~wrinklepipe.package.WrinklePackage` (usd-core).

Layout of the stage (``defaultPrim`` = the asset name, Y up, metres)::

    /NAME                    SkelRoot (Xform when the mesh has no morph targets)
      Skel                   Skeleton (one root joint) + Anim (SkelAnimation: blend-shape names)
      MESH                   Mesh: points, triangles, normals, primvars:st (v up),
                             primvars:wrinkle:vertexId (int), primvars:wrinkle:tangent (float4),
                             primvars:wrinkle:bias; SkelBindingAPI with one BlendShape per morph
      Looks/skin             Material + WrinkleMapsAPI (schemas/usd, codeless); outputs:surface
                             <- Surface, outputs:mtlx:surface <- SR_wrinkle
        Surface              UsdPreviewSurface; normal <- base_normal (raw, scale 2, bias -1)
        NG_wrinkle           the whole model as MaterialX nodes (wrinklepipe.usd.materialx;
                             the same document is NAME.mtlx beside the layer)
        SR_wrinkle           ND_standard_surface_surfaceshader; normal <- NG_wrinkle
        StReader             UsdPrimvarReader_float2 "st"
        base_normal          UsdUVTexture
        wrinkle_<state>      UsdUVTexture, inputs:file <- Material inputs:wrinkle:state:<state>
        mask_<i>             UsdUVTexture, inputs:file <- Material inputs:wrinkle:mask:mask_<i>
        base_color           UsdUVTexture (sourceColorSpace sRGB, scale = the colour factor);
                             Surface diffuseColor <- its rgb (with colour states only)
        color_<state>        UsdUVTexture (sRGB), inputs:file <- inputs:wrinkle:color:<state>

V flip: glTF's ``uv`` has v = 0 at the top of the image; USD's ``st`` has t = 0 at the bottom,
so ``st = (u, 1 - v)`` over the very same image files. Region weights go to ``wrinkle:weights``,
as time samples when there is a weight curve (time code = seconds x ``timeCodesPerSecond``).

That is the layout of a package on its own (an OBJ source, ``write_usd`` of a package). For a
glTF source convert writes the material only (``build_stage(with_mesh=False)``) and the whole
rigged scene beside it, the wrinkled primitives among its meshes
(:mod:`wrinklepipe.usd.scene`; the material lists them in ``wrinkle:meshes``).
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import codec
from wrinklepipe.asset import Mesh
from wrinklepipe.atomic import check_not_input, write_bytes
from wrinklepipe.errors import input_error
from wrinklepipe.gltf.package_write import skin_weights_normalized
from wrinklepipe.io.png import DEFAULT_PNG_LEVEL, png_bytes
from wrinklepipe.io.usd_diagnostics import quiet
from wrinklepipe.package import MAX_FLOAT_ID, WrinklePackage, safe_name
from wrinklepipe.paths import SCHEMAS_DIR
from wrinklepipe.udim import TOKEN as UDIM_TOKEN
from wrinklepipe.usd import materialx as mtlx
from wrinklepipe.usd.usdz import usdz_bytes

API_NAME = "WrinkleMapsAPI"
USD_SCHEMA_DIR = SCHEMAS_DIR / "usd"


#: The attributes of ``WrinkleMapsAPI`` and their types (as in schemas/usd/generatedSchema.usda;
#: a test keeps the two equal). They are authored with these types whether or not the schema
#: is registered in this process, so the output never depends on plugin load order.
API_ATTRIBUTES: dict[str, str] = {
    "wrinkle:encoding": "token",
    "wrinkle:scale": "double",
    "wrinkle:mapping": "int",
    "wrinkle:policy": "token",
    "wrinkle:stateNames": "token[]",
    "wrinkle:maskLayout": "token",
    "wrinkle:maskNames": "token[]",
    "wrinkle:regionNames": "token[]",
    "wrinkle:regionSides": "token[]",
    "wrinkle:regionStates": "string[]",
    "wrinkle:maskTexture": "int[]",
    "wrinkle:maskChannel": "token[]",
    "wrinkle:splitTexture": "int[]",
    "wrinkle:splitChannel": "token[]",
    "wrinkle:expressionNames": "token[]",
    "wrinkle:expressionWeights": "double[]",
    "wrinkle:drivers": "string",
    "wrinkle:weights": "float[]",
    "wrinkle:weightCurve": "token",
    "wrinkle:compressedTextures": "token[]",
    "wrinkle:compressedFormats": "token[]",
    "wrinkle:compressedLayouts": "token[]",
    "wrinkle:compressedLevels": "int[]",
}


#: The colour attributes of ``WrinkleMapsAPI``, authored only on a material whose states carry
#: colour (so an asset without colour is written as before).
COLOR_ATTRIBUTES: dict[str, str] = {
    "wrinkle:colorStates": "token[]",
    "wrinkle:colorOnlyStates": "token[]",
    "wrinkle:compressedColorSpaces": "token[]",
}


#: The UDIM attribute of ``WrinkleMapsAPI``, authored only on the material of a tiled
#: package (:mod:`wrinklepipe.udim`): its textures' file names say ``<UDIM>``.
TILE_ATTRIBUTES: dict[str, str] = {"wrinkle:tiles": "int[]"}


def udim_suffix(pkg: WrinklePackage) -> str:
    """What a texture's file stem takes in a USD of ``pkg``: ``.<UDIM>`` when it is tiled."""
    return f".{UDIM_TOKEN}" if pkg.tiles else ""


#: Custom attribute on the wrinkled material of a layer over a USD source (the source's file
#: name; :mod:`wrinklepipe.usd.layer`): its meshes keep the source's topology.
LAYERED_OVER = "wrinkle:layeredOver"

#: Custom attribute on the wrinkle material of a glTF source's USD: the paths of the wrinkled
#: primitives' Mesh prims in its scene, in the package's order
#: (:mod:`wrinklepipe.usd.scene`); they are read back through the mesh reader.
SCENE_MESHES = "wrinkle:meshes"
#: ... and the name of the package mesh they make (the glTF path's name for it).
SCENE_MESH_NAME = "wrinkle:meshName"


def register_schema() -> None:
    """Register the codeless ``WrinkleMapsAPI`` (``schemas/usd/plugInfo.json``); idempotent.

    USD builds its schema registry once, the first time a stage needs it: registration only
    takes effect if it happens before that (this module registers on import; or set
    ``PXR_PLUGINPATH_NAME`` to ``schemas/usd``). Writing and reading never depend on it.
    """
    from pxr import Plug  # deferred: usd-core, USD only

    Plug.Registry().RegisterPlugins(str(USD_SCHEMA_DIR))


register_schema()


@dataclass(frozen=True)
class UsdOptions:
    """``texture_dir``: folder (relative to the layer) of the PNGs; ``fps``: timeCodesPerSecond."""

    texture_dir: str = "textures"
    fps: float = 24.0
    png_level: int = DEFAULT_PNG_LEVEL


def _ident(name: str) -> str:
    from pxr import Tf  # deferred: usd-core, USD only

    return Tf.MakeValidIdentifier(name)


def _skel(stage: Any, root_path: Any, mesh: Any, m: Mesh) -> None:
    """Skeleton + SkelAnimation + binding: the mesh's skin (joints at their bind pose, flat, as
    in the glTF) or one root joint, and one BlendShape per morph target."""
    from pxr import Gf, Sdf, UsdSkel, Vt  # deferred: usd-core, USD only

    has_skin = m.joints is not None and m.skin_weights is not None and len(m.joint_names) > 0
    skel = UsdSkel.Skeleton.Define(stage, root_path.AppendChild("Skel"))
    if has_skin:
        n = len(m.joint_names)
        used: set[str] = set()
        joint_tokens = []
        for name in m.joint_names:
            tok = _ident(name)
            while tok in used:
                tok += "_"
            used.add(tok)
            joint_tokens.append(tok)
        ibm = (
            np.asarray(m.inverse_bind, np.float32)
            if m.inverse_bind is not None
            else np.tile(np.eye(4, dtype=np.float32), (n, 1, 1))
        )
        # Gf matrices act on row vectors: the math matrix M is stored as M^T.
        bind = [Gf.Matrix4d(np.linalg.inv(b.astype(np.float64)).T.tolist()) for b in ibm]
        exact = skel.GetPrim().CreateAttribute(
            "wrinkle:inverseBindTransforms", Sdf.ValueTypeNames.Matrix4dArray
        )
        exact.SetCustom(True)
        exact.Set(Vt.Matrix4dArray([Gf.Matrix4d(b.astype(np.float64).T.tolist()) for b in ibm]))
        names = skel.GetPrim().CreateAttribute("wrinkle:jointNames", Sdf.ValueTypeNames.StringArray)
        names.SetCustom(True)
        names.Set(Vt.StringArray([str(x) for x in m.joint_names]))
    else:
        joint_tokens = ["root"]
        bind = [Gf.Matrix4d(1.0)]
    skel.CreateJointsAttr(Vt.TokenArray(joint_tokens))
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray(bind))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray(bind))  # flat: local = world
    anim = UsdSkel.Animation.Define(stage, skel.GetPath().AppendChild("Anim"))
    anim.CreateJointsAttr(Vt.TokenArray(joint_tokens))
    translations, rotations, scales = [], [], []
    for b in bind:
        xf = Gf.Transform(b)
        translations.append(Gf.Vec3f(xf.GetTranslation()))
        rotations.append(Gf.Quatf(xf.GetRotation().GetQuat()))
        scales.append(Gf.Vec3h(xf.GetScale()))
    anim.CreateTranslationsAttr(Vt.Vec3fArray(translations))
    anim.CreateRotationsAttr(Vt.QuatfArray(rotations))
    anim.CreateScalesAttr(Vt.Vec3hArray(scales))
    shape_names = [_ident(n) for n in m.morph_names] if m.morph_deltas is not None else []
    if shape_names:
        anim.CreateBlendShapesAttr(Vt.TokenArray(shape_names))
        anim.CreateBlendShapeWeightsAttr(Vt.FloatArray([0.0] * len(shape_names)))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    if has_skin:
        w = skin_weights_normalized(m.skin_weights)
        j = np.where(w > 0, np.asarray(m.joints, np.int64), 0).astype(np.int32)
        k = j.shape[1]
        binding.CreateJointIndicesPrimvar(False, k).Set(Vt.IntArray.FromNumpy(j.reshape(-1)))
        binding.CreateJointWeightsPrimvar(False, k).Set(
            Vt.FloatArray.FromNumpy(np.ascontiguousarray(w.reshape(-1)))
        )
    else:
        binding.CreateJointIndicesPrimvar(True, 1).Set(Vt.IntArray([0]))
        binding.CreateJointWeightsPrimvar(True, 1).Set(Vt.FloatArray([1.0]))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    if shape_names:
        binding.CreateBlendShapesAttr(Vt.TokenArray(shape_names))
        targets = []
        for name, delta in zip(shape_names, m.morph_deltas):
            bs = UsdSkel.BlendShape.Define(stage, mesh.GetPath().AppendChild(name))
            bs.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(delta, np.float32)))
            targets.append(bs.GetPath())
        binding.CreateBlendShapeTargetsRel().SetTargets(targets)


def _morph_curves(stage: Any, root_path: Any, prim: Any, pkg: WrinklePackage, fps: float) -> None:
    """Morph-target weights of each curve: ``wrinkle:morphCurves:curve<i>`` time samples on the
    material (exact), and those of the first curve also as the SkelAnimation's
    ``blendShapeWeights`` time samples (what UsdSkel plays)."""
    from pxr import Sdf, Usd, UsdSkel, Vt  # deferred: usd-core, USD only

    for i, c in enumerate(pkg.curves):
        if c.morph_weights is None:
            continue
        mw = np.asarray(c.morph_weights, np.float32)
        if mw.shape != (len(c.times), len(pkg.mesh.morph_names)):
            raise input_error(pkg.name, f"curve {c.name!r}: morph weights of shape {mw.shape}")
        a = prim.CreateAttribute(f"wrinkle:morphCurves:curve{i}", Sdf.ValueTypeNames.FloatArray)
        a.SetCustom(True)
        codes = [Usd.TimeCode(float(t) * fps) for t in np.asarray(c.times, np.float32)]
        for code, row in zip(codes, mw):
            a.Set(Vt.FloatArray.FromNumpy(row), code)
        anim_prim = stage.GetPrimAtPath(root_path.AppendPath("Skel/Anim"))
        if i == 0 and anim_prim:  # none without the mesh: the scene's skeletons play them
            anim = UsdSkel.Animation(anim_prim)
            bsw = anim.GetBlendShapeWeightsAttr()
            for code, row in zip(codes, mw):
                bsw.Set(Vt.FloatArray.FromNumpy(row), code)


@quiet
def build_stage(
    pkg: WrinklePackage, options: UsdOptions | None = None, with_mesh: bool = True
) -> Any:
    """Build an in-memory ``Usd.Stage`` for the package (textures referenced, not written).

    ``with_mesh=False``: the wrinkle material only (``/NAME`` an Xform, no ``MESH`` and no
    ``Skel``): a glTF source's wrinkled primitives are written into its scene instead, bound
    to that material and to the scene's skeleton
    (:func:`wrinklepipe.usd.scene.add_scene`). Keep the returned stage referenced
    while using its layers (they die with it).
    """
    from pxr import Sdf, Usd, UsdGeom, UsdShade, UsdSkel  # deferred: usd-core, USD only

    opt = options or UsdOptions()
    register_schema()
    m = pkg.mesh
    for t in pkg.textures:
        if safe_name(t.name) != t.name:
            raise input_error(pkg.name, f"texture name {t.name!r} is not a safe file name")
    if m.uvs is None or m.normals is None or m.tangents is None or m.vertex_ids is None:
        raise input_error(pkg.name, "USD output needs UVs, normals, tangents and vertex IDs")
    if int(np.max(m.vertex_ids, initial=0)) >= MAX_FLOAT_ID:
        raise input_error(pkg.name, f"vertex IDs must lie below {MAX_FLOAT_ID}")
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(opt.fps)
    stage.SetFramesPerSecond(opt.fps)
    root_name = _ident(pkg.name)
    root_path = Sdf.Path("/" + root_name)
    has_morphs = m.morph_deltas is not None and len(m.morph_names) > 0
    has_skin = m.joints is not None and m.skin_weights is not None and len(m.joint_names) > 0
    if with_mesh and (has_morphs or has_skin):
        root = UsdSkel.Root.Define(stage, root_path).GetPrim()
    else:
        root = UsdGeom.Xform.Define(stage, root_path).GetPrim()
    stage.SetDefaultPrim(root)
    Usd.ModelAPI(root).SetKind("component")

    if with_mesh:
        mesh = _mesh(stage, root_path, m)
        if has_morphs or has_skin:
            _skel(stage, root_path, mesh, m)
    mat = _material(stage, root_path, pkg, opt)
    if with_mesh:
        UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(mat)
    return stage


def _mesh(stage: Any, root_path: Any, m: Mesh) -> Any:
    """``/NAME/MESH``: the package's render mesh with the wrinkle primvars."""
    from pxr import Gf, Sdf, UsdGeom, Vt  # deferred: usd-core, USD only

    mesh = UsdGeom.Mesh.Define(stage, root_path.AppendChild(_ident(m.name)))
    pts = np.ascontiguousarray(m.positions, np.float32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(m.triangle_count, 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(
        Vt.IntArray.FromNumpy(np.ascontiguousarray(m.indices.reshape(-1), np.int32))
    )
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateExtentAttr(
        Vt.Vec3fArray([Gf.Vec3f(*pts.min(0).tolist()), Gf.Vec3f(*pts.max(0).tolist())])
    )
    mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(m.normals, np.float32)))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    pv = UsdGeom.PrimvarsAPI(mesh)
    st = np.ascontiguousarray(np.stack([m.uvs[:, 0], 1.0 - m.uvs[:, 1]], -1).astype(np.float32))
    pv.CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(
        Vt.Vec2fArray.FromNumpy(st)
    )
    pv.CreatePrimvar("wrinkle:vertexId", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.vertex).Set(
        Vt.IntArray.FromNumpy(np.ascontiguousarray(m.vertex_ids, np.int32))
    )
    pv.CreatePrimvar("wrinkle:tangent", Sdf.ValueTypeNames.Float4Array, UsdGeom.Tokens.vertex).Set(
        Vt.Vec4fArray.FromNumpy(np.ascontiguousarray(m.tangents, np.float32))
    )
    if m.colors is not None:
        pv.CreatePrimvar("wrinkle:bias", Sdf.ValueTypeNames.Float4Array, UsdGeom.Tokens.vertex).Set(
            Vt.Vec4fArray.FromNumpy(np.ascontiguousarray(m.colors, np.float32))
        )
    return mesh


def _material(stage: Any, root_path: Any, pkg: WrinklePackage, opt: UsdOptions) -> Any:
    """``/NAME/Looks/skin``: the wrinkle material (``WrinkleMapsAPI``, its textures, the weight
    curves as time samples)."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, Vt  # deferred: usd-core, USD only

    looks = UsdGeom.Scope.Define(stage, root_path.AppendChild("Looks"))
    mat = UsdShade.Material.Define(stage, looks.GetPath().AppendChild("skin"))
    surf = UsdShade.Shader.Define(stage, mat.GetPath().AppendChild("Surface"))
    surf.CreateIdAttr("UsdPreviewSurface")
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.8, 0.62, 0.52))
    surf.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.55)
    surf.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    reader = UsdShade.Shader.Define(stage, mat.GetPath().AppendChild("StReader"))
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    tdir = f"./{opt.texture_dir}/" if opt.texture_dir else "./"

    def texture(name: str, scale: tuple, bias: tuple, space: str = "raw") -> Any:
        tex = UsdShade.Shader.Define(stage, mat.GetPath().AppendChild(_ident(name)))
        tex.CreateIdAttr("UsdUVTexture")
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
            reader.ConnectableAPI(), "result"
        )
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(space)
        tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("clamp")
        tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("clamp")
        tex.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*scale))
        tex.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*bias))
        tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
        tex.CreateOutput("rgba", Sdf.ValueTypeNames.Float4)
        return tex

    tiled = udim_suffix(pkg)  # ".<UDIM>": every texture is a UDIM set
    base = texture("base_normal", (2, 2, 2, 1), (-1, -1, -1, 0))
    base.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(
        Sdf.AssetPath(f"{tdir}{pkg.base_name}{tiled}.png")
    )
    surf.CreateInput("normal", Sdf.ValueTypeNames.Normal3f).ConnectToSource(
        base.ConnectableAPI(), "rgb"
    )
    meta = pkg.meta
    enc, scale = meta.encoding, float(meta.scale)
    version = int(meta.mapping)

    def state_scale_bias(name: str) -> tuple[tuple, tuple]:
        """UsdUVTexture scale and bias that turn the stored values into the quantity: pd slopes
        in [-s, s], diff deltas W - B, unit normals (the codec's affine mapping, per bit depth)."""
        e = codec.encoding(enc)
        mul, add = e.mapping(version).affine(pkg.texture(name).bits)
        if enc == "pd":
            return (mul * scale, mul * scale, 1, 1), (add * scale, add * scale, 0, 0)
        if enc == "diff":
            return (mul / scale,) * 3 + (1,), (add / scale,) * 3 + (0,)
        return (mul, mul, mul, 1), (add, add, add, 0)

    def interface_texture(
        kind: str, key: str, name: str, sc: tuple, bi: tuple, space: str = "raw"
    ) -> None:
        inp = mat.CreateInput(f"wrinkle:{kind}:{key}", Sdf.ValueTypeNames.Asset)
        inp.Set(Sdf.AssetPath(f"{tdir}{name}{tiled}.png"))
        tex = texture(name, sc, bi, space)
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).ConnectToSource(inp)

    for s in meta.states:
        interface_texture("state", _ident(s.name), s.texture, *state_scale_bias(s.texture))
    for name in meta.masks.textures:
        interface_texture("mask", _ident(name), name, (1, 1, 1, 1), (0, 0, 0, 0))
    if meta.base_color is not None:
        _color_textures(surf, meta, texture, interface_texture, tdir)

    prim = mat.GetPrim()
    prim.AddAppliedSchema(API_NAME)  # metadata only: works whether or not the schema is loaded
    attrs = {
        name: prim.CreateAttribute(name, Sdf.ValueTypeNames.Find(t), custom=False)
        for name, t in API_ATTRIBUTES.items()
    }
    values = _api_values(meta)
    for attr_name, value in values.items():
        attrs[attr_name].Set(value)
    if pkg.tiles:
        a = prim.CreateAttribute("wrinkle:tiles", Sdf.ValueTypeNames.IntArray, custom=False)
        a.Set(Vt.IntArray(list(pkg.tiles)))
    for attr_name, value in _color_values(meta).items():
        a = prim.CreateAttribute(attr_name, Sdf.ValueTypeNames.Find(COLOR_ATTRIBUTES[attr_name]))
        a.SetCustom(False)
        a.Set(Vt.TokenArray(value))
    if [e.region for e in meta.masks.table] != meta.region_names:
        raise input_error(pkg.name, "channel table must list the regions in region order")
    weights = attrs["wrinkle:weights"]
    weights.Set(Vt.FloatArray([float(w) for w in meta.weights]))
    if pkg.curves:
        c = pkg.curves[0]
        attrs["wrinkle:weightCurve"].Set(c.name)
        for t, row in zip(np.asarray(c.times, np.float32), np.asarray(c.values, np.float32)):
            weights.Set(Vt.FloatArray.FromNumpy(row), Usd.TimeCode(float(t) * opt.fps))
        stage.SetStartTimeCode(float(c.times[0]) * opt.fps)
        stage.SetEndTimeCode(float(c.times[-1]) * opt.fps)
        order = prim.CreateAttribute("wrinkle:curveNames", Sdf.ValueTypeNames.StringArray)
        order.SetCustom(True)
        order.Set(Vt.StringArray([str(x.name) for x in pkg.curves]))
        for i, extra in enumerate(pkg.curves[1:], start=1):
            a = prim.CreateAttribute(f"wrinkle:curves:curve{i}", Sdf.ValueTypeNames.FloatArray)
            a.SetCustom(True)
            for t, row in zip(
                np.asarray(extra.times, np.float32), np.asarray(extra.values, np.float32)
            ):
                a.Set(Vt.FloatArray.FromNumpy(row), Usd.TimeCode(float(t) * opt.fps))
        _morph_curves(stage, root_path, prim, pkg, opt.fps)
    mtlx.add_package_materialx(stage, mat, pkg, opt.texture_dir, opt.fps)
    return mat


def _api_values(meta: Any) -> dict[str, Any]:
    """The values of the WrinkleMapsAPI attributes (the compressed copies' when there are)."""
    from pxr import Vt  # deferred: usd-core, USD only

    table, regions, names = meta.masks.table, meta.regions, meta.region_names
    expr_names = list(meta.expressions)
    expr = np.array(
        [[meta.expressions[e].get(n, 0.0) for n in names] for e in expr_names], np.float64
    ).reshape(-1)
    values = {
        "wrinkle:encoding": meta.encoding,
        "wrinkle:scale": float(meta.scale),
        "wrinkle:mapping": int(meta.mapping),
        "wrinkle:policy": meta.policy,
        "wrinkle:stateNames": Vt.TokenArray(meta.state_names),
        "wrinkle:maskLayout": meta.masks.layout,
        "wrinkle:maskNames": Vt.TokenArray([_ident(n) for n in meta.masks.textures]),
        "wrinkle:regionNames": Vt.TokenArray(names),
        "wrinkle:regionSides": Vt.TokenArray([r.side for r in regions]),
        "wrinkle:regionStates": Vt.StringArray([",".join(r.states) for r in regions]),
        "wrinkle:maskTexture": Vt.IntArray(
            [-1 if e.layer is None and e.texture is None else e.index for e in table]
        ),
        "wrinkle:maskChannel": Vt.TokenArray([e.channel or "" for e in table]),
        "wrinkle:splitTexture": Vt.IntArray([e.split.texture if e.split else -1 for e in table]),
        "wrinkle:splitChannel": Vt.TokenArray([e.split.channel if e.split else "" for e in table]),
        "wrinkle:expressionNames": Vt.TokenArray(expr_names),
        "wrinkle:expressionWeights": Vt.DoubleArray.FromNumpy(expr),
        "wrinkle:drivers": json.dumps(list(meta.drivers), sort_keys=True),
    }
    comp = meta.compressed
    if comp:  # the block-compressed copies beside the PNGs (compressed/NAME.ktx2 and .dds)
        values["wrinkle:compressedTextures"] = Vt.TokenArray([c.texture for c in comp])
        values["wrinkle:compressedFormats"] = Vt.TokenArray([c.format for c in comp])
        values["wrinkle:compressedLayouts"] = Vt.TokenArray([c.layout for c in comp])
        values["wrinkle:compressedLevels"] = Vt.IntArray([c.levels for c in comp])
    return values


def _color_textures(
    surf: Any, meta: Any, texture: Callable[..., Any], interface: Callable[..., Any], tdir: str
) -> None:
    """The base colour (sRGB, its factor as the texture's scale) into the surface's
    ``diffuseColor``, and each colour state's map as an sRGB texture on an interface input
    ``wrinkle:color:<state>``."""
    from pxr import Sdf  # deferred: usd-core, USD only

    r, g, b = (float(x) for x in meta.color_factor)
    base = texture(meta.base_color, (r, g, b, 1.0), (0, 0, 0, 0), "sRGB")
    base.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(
        Sdf.AssetPath(f"{tdir}{meta.base_color}.png")
    )
    surf.GetInput("diffuseColor").ConnectToSource(base.ConnectableAPI(), "rgb")
    for s in meta.states:
        if s.color is not None:
            interface("color", _ident(s.name), s.color, (1, 1, 1, 1), (0, 0, 0, 0), "sRGB")


def _color_values(meta: Any) -> dict[str, list[str]]:
    """The colour attributes' values (empty without colour states; each only when it has
    entries)."""
    if meta.base_color is None:
        return {}
    out = {"wrinkle:colorStates": [s.name for s in meta.states if s.color is not None]}
    only = [s.name for s in meta.states if not s.normal]
    if only:
        out["wrinkle:colorOnlyStates"] = only
    if any(c.color_space != "linear" for c in meta.compressed):
        out["wrinkle:compressedColorSpaces"] = [c.color_space for c in meta.compressed]
    return out


def write_usd(
    pkg: WrinklePackage,
    path: str | Path,
    options: UsdOptions | None = None,
    write_textures: bool = True,
    stage: Any = None,
    extra: dict[str, bytes] | None = None,
) -> list[Path]:
    """Write ``.usda`` / ``.usdc`` (+ the PNGs beside it), or a self-contained ``.usdz``.

    ``stage``: the package's stage (:func:`build_stage`) with additions (a glTF source's other
    parts, :func:`wrinklepipe.usd.scene.add_scene`); ``extra``: files it references
    ``{path relative to the layer: bytes}``, written beside the layer or packed into the usdz."""
    opt = options or UsdOptions()
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".usda", ".usdc", ".usd", ".usdz"):
        raise input_error(path, "USD output must end in .usda, .usdc, .usd or .usdz")
    check_not_input(path)
    stage = build_stage(pkg, opt) if stage is None else stage
    extra = extra or {}
    written: list[Path] = []
    if suffix == ".usda":
        text = stage.GetRootLayer().ExportToString()
        written.append(write_bytes(path, text.encode("utf-8")))
    elif suffix in (".usdc", ".usd"):
        written.append(_export_via_temp(stage.GetRootLayer(), path, "usdc"))
    if suffix != ".usdz" and write_textures:
        tdir = path.parent / opt.texture_dir if opt.texture_dir else path.parent
        for t in pkg.textures:
            written.append(write_bytes(tdir / f"{t.name}.png", png_bytes(t.pixels, opt.png_level)))
    if suffix != ".usdz":
        for rel, data in sorted({**extra, **mtlx.package_files(pkg, opt.texture_dir)}.items()):
            written.append(write_bytes(path.parent / rel, data))
    if suffix == ".usdz":
        written.append(_write_usdz(stage, pkg, path, opt, extra))
    return written


def _export_via_temp(layer: Any, path: Path, fmt: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".{fmt}", dir=path.parent)
    os.close(fd)
    try:
        if not layer.Export(tmp):
            raise OSError(f"{path}: USD export failed")
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    return path


def _write_usdz(
    stage: Any, pkg: WrinklePackage, path: Path, opt: UsdOptions, extra: dict[str, bytes]
) -> Path:
    """A usdz holding a usdc root layer and the PNGs it references."""
    layer = mtlx.without_materialx_file(stage.GetRootLayer())  # a usdz holds no .mtlx
    with tempfile.TemporaryDirectory(prefix="wrinklepipe-usdz-") as work:
        layer_path = Path(work) / f"{path.stem}.usdc"
        if not layer.Export(str(layer_path)):
            raise OSError(f"{path}: USD export failed")
        entries = [(layer_path.name, layer_path.read_bytes())]
    for t in pkg.textures:
        rel = f"{opt.texture_dir}/{t.name}.png" if opt.texture_dir else f"{t.name}.png"
        entries.append((rel, png_bytes(t.pixels, opt.png_level)))
    entries += sorted(extra.items())
    return write_bytes(path, usdz_bytes(entries))
