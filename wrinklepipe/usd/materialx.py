"""The MaterialX wrinkle material in a USD layer: UsdShade prims with MaterialX shader ids.

:func:`add_materialx` writes the document of :mod:`wrinklepipe.shading.materialx` into the
wrinkle material the way USD's UsdMtlx translates a ``.mtlx`` file (a NodeGraph whose nodes are
Shader prims with ``info:id`` = the MaterialX node definition, ``ND_image_vector3``,
``ND_multiply_float`` ...; a ``standard_surface`` Shader), and connects the material's
``outputs:mtlx:surface`` to it. Hosts that render MaterialX (Storm, Karma, Omniverse, ...)
pick the ``mtlx`` render context; every other host keeps rendering ``outputs:surface``, the
UsdPreviewSurface fallback. The layer needs no plugin to compose (usd-core opens it as is; its
shader registry, which has no MaterialX nodes, cannot check the ids: USD builds with UsdMtlx
can). The same document is written beside a ``.usda`` / ``.usdc`` layer as ``NAME.mtlx``
(``wrinkle:materialx`` on the material names it, a file name relative to the layer) for
MaterialX-native tools; a ``.usdz`` holds no ``.mtlx`` (the package format takes none) and
its layer names none (:func:`drop_materialx_file`).

Each region weight is an input of the NodeGraph, ``inputs:w_<region>``, animated with the
weight curve's time samples (the same values as ``wrinkle:weights``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import MaterialX as mx
import numpy as np

from wrinklepipe.package import WrinklePackage
from wrinklepipe.shading import materialx as wmx
from wrinklepipe.shading.setup import from_meta
from wrinklepipe.udim import TOKEN as UDIM_TOKEN

#: MaterialX type -> Sdf value type name (as UsdMtlx maps them).
SDF_TYPES = {
    "float": "Float",
    "integer": "Int",
    "boolean": "Bool",
    "string": "String",
    "filename": "Asset",
    "vector2": "Float2",
    "vector3": "Float3",
    "vector4": "Float4",
    "color3": "Color3f",
    "color4": "Color4f",
    "surfaceshader": "Token",
}
#: The attribute on the wrinkle material naming the ``.mtlx`` file written beside the layer (a
#: string, relative to the layer: not an asset path, which a usdz without the file would break).
MATERIALX_ATTRIBUTE = "wrinkle:materialx"


def _sdf_type(kind: str) -> Any:
    from pxr import Sdf  # deferred: usd-core, USD only

    return getattr(Sdf.ValueTypeNames, SDF_TYPES[kind])


def _value(inp: mx.Input, file_prefix: str) -> Any:
    from pxr import Gf, Sdf  # deferred: usd-core, USD only

    kind, value = inp.getType(), inp.getValue()
    if kind == "filename":
        return Sdf.AssetPath(file_prefix + inp.getValueString())
    if kind in ("vector2", "vector3", "vector4", "color3", "color4"):
        cls = {2: Gf.Vec2f, 3: Gf.Vec3f, 4: Gf.Vec4f}[len(list(value))]
        return cls(*[float(v) for v in value])
    return value


def _connect(stage: Any, usd_input: Any, mx_input: mx.Input, graph_path: Any) -> bool:
    """Connect ``usd_input`` as ``mx_input`` is connected (a node's output or the graph's
    interface input); False when it holds a value instead."""
    from pxr import Sdf  # deferred: usd-core, USD only

    if mx_input.getNodeName():
        node_path = graph_path.AppendChild(mx_input.getNodeName())
        usd_input.GetAttr().SetConnections([node_path.AppendProperty("outputs:out")])
        return True
    if mx_input.getInterfaceName():
        target = graph_path.AppendProperty(f"inputs:{mx_input.getInterfaceName()}")
        usd_input.GetAttr().SetConnections([Sdf.Path(target)])
        return True
    return False


def add_materialx(
    stage: Any,
    material: Any,
    doc: mx.Document,
    file_prefix: str,
    mtlx_file: str,
    curve: tuple[Sequence[float], np.ndarray] | None = None,
) -> Any:
    """Author ``doc`` (:func:`wrinklepipe.shading.materialx.wrinkle_document`) under
    ``material`` (a ``UsdShade.Material``) and connect its ``outputs:mtlx:surface``; image
    files get ``file_prefix`` (``"./"``: relative to the layer, as the document's are to the
    ``.mtlx``). ``curve``: (time codes, ``[T, R]`` region weights) authored as time samples on
    the weight inputs. Returns the surface Shader."""
    from pxr import Sdf, UsdShade  # deferred: usd-core, USD only

    checked = mx.createDocument()
    checked.copyContentFrom(doc)
    checked.importLibrary(wmx.definitions())
    mat_path = material.GetPath()
    graph_mx = checked.getNodeGraph(wmx.NODEGRAPH)
    graph = UsdShade.NodeGraph.Define(stage, mat_path.AppendChild(wmx.NODEGRAPH))
    gpath = graph.GetPath()
    weights = {}
    for inp in graph_mx.getInputs():
        usd_in = graph.CreateInput(inp.getName(), _sdf_type(inp.getType()))
        usd_in.Set(_value(inp, file_prefix))
        weights[inp.getName()] = usd_in
    for node in graph_mx.getNodes():
        shader = UsdShade.Shader.Define(stage, gpath.AppendChild(node.getName()))
        shader.CreateIdAttr(node.getNodeDef().getName())
        for inp in node.getInputs():
            usd_in = shader.CreateInput(inp.getName(), _sdf_type(inp.getType()))
            if not _connect(stage, usd_in, inp, gpath):
                usd_in.Set(_value(inp, file_prefix))
        shader.CreateOutput("out", _sdf_type(node.getType()))
    for out in graph_mx.getOutputs():
        usd_out = graph.CreateOutput(out.getName(), _sdf_type(out.getType()))
        usd_out.GetAttr().SetConnections(
            [gpath.AppendChild(out.getNodeName()).AppendProperty("outputs:out")]
        )
    surface_mx = checked.getNode(wmx.SHADER)
    surface = UsdShade.Shader.Define(stage, mat_path.AppendChild(wmx.SHADER))
    surface.CreateIdAttr(surface_mx.getNodeDef().getName())
    for inp in surface_mx.getInputs():
        usd_in = surface.CreateInput(inp.getName(), _sdf_type(inp.getType()))
        if inp.getNodeGraphString():
            usd_in.GetAttr().SetConnections(
                [gpath.AppendProperty(f"outputs:{inp.getOutputString()}")]
            )
        else:
            usd_in.Set(_value(inp, file_prefix))
    surface.CreateOutput("surface", Sdf.ValueTypeNames.Token)
    material.CreateSurfaceOutput("mtlx").ConnectToSource(surface.ConnectableAPI(), "surface")
    prim = material.GetPrim()
    prim.AddAppliedSchema("MaterialXConfigAPI")  # UsdMtlx's; metadata only without the plugin
    version = prim.CreateAttribute("config:mtlx:version", Sdf.ValueTypeNames.String, custom=False)
    version.Set(doc.getVersionString())
    ref = prim.CreateAttribute(MATERIALX_ATTRIBUTE, Sdf.ValueTypeNames.String)
    ref.SetCustom(True)
    ref.Set(mtlx_file)
    if curve is not None:
        times, values = curve
        names = [n for n in weights if n.startswith("w_")]
        for r, name in enumerate(names):
            attr = weights[name].GetAttr()
            for t, row in zip(times, np.asarray(values, np.float32)):
                attr.Set(float(row[r]), float(t))
    return surface


def drop_materialx_file(layer: Any) -> None:
    """Remove every ``wrinkle:materialx`` attribute from ``layer`` (an ``Sdf.Layer`` about to be
    packed in a ``.usdz``, which holds no ``.mtlx``): the MaterialX network stays, in the layer."""
    from pxr import Sdf  # deferred: usd-core, USD only

    found = []

    def visit(path: Any) -> None:
        if path.IsPropertyPath() and path.name == MATERIALX_ATTRIBUTE:
            found.append(path)

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    for path in found:
        owner = layer.GetPrimAtPath(path.GetPrimPath())
        owner.RemoveProperty(owner.properties[path.name])


def materialx_file(pkg: WrinklePackage) -> str:
    """The name of the MaterialX document written beside the package's USD layer."""
    return f"{pkg.name}.mtlx"


def materialx_document(pkg: WrinklePackage, texture_dir: str = "textures") -> mx.Document | None:
    """The package's wrinkle material as a MaterialX document
    (:func:`wrinklepipe.shading.materialx.wrinkle_document`; maps as the USD layer names them,
    under ``texture_dir``), or None for an asset beyond what every shader target takes (the USD
    keeps its UsdPreviewSurface and WrinkleMapsAPI only)."""
    meta = pkg.meta
    tdir = f"{texture_dir}/" if texture_dir else ""
    channels = [
        1 if pkg.texture(n).pixels.ndim == 2 else pkg.texture(n).pixels.shape[-1]
        for n in meta.masks.textures
    ]
    bits = pkg.texture(meta.states[0].texture).bits if meta.states else 8
    setup = from_meta(meta, channels, state_bits=bits)
    if setup.problems():
        return None
    u = f".{UDIM_TOKEN}" if pkg.tiles else ""  # MaterialX reads <UDIM> in file names
    files = wmx.MapFiles(
        f"{tdir}{pkg.base_name}{u}.png",
        tuple(f"{tdir}{s.texture}{u}.png" for s in meta.states),
        tuple(f"{tdir}{n}{u}.png" for n in meta.masks.textures),
        f"{tdir}{meta.base_color}{u}.png" if meta.base_color else "",
        tuple(f"{tdir}{n}{u}.png" for n in meta.color_textures),
        meta.color_factor,
    )
    return wmx.wrinkle_document(setup, files, [float(w) for w in meta.weights])


def add_package_materialx(
    stage: Any, material: Any, pkg: WrinklePackage, texture_dir: str, fps: float
) -> None:
    """:func:`add_materialx` of the package's document (when it has one) on ``material``, its
    first weight curve as the weight inputs' time samples (time codes: seconds x ``fps``)."""
    doc = materialx_document(pkg, texture_dir)
    if doc is None:
        return
    c = pkg.curves[0] if pkg.curves else None
    curve = None if c is None else (np.asarray(c.times, np.float64) * fps, c.values)
    add_materialx(stage, material, doc, "./", materialx_file(pkg), curve)


def package_files(pkg: WrinklePackage, texture_dir: str = "textures") -> dict[str, bytes]:
    """``{NAME.mtlx: the document's XML}`` to write beside the layer (empty without one)."""
    doc = materialx_document(pkg, texture_dir)
    return {materialx_file(pkg): wmx.to_xml(doc)} if doc is not None else {}


def without_materialx_file(layer: Any) -> Any:
    """An anonymous copy of ``layer`` without ``wrinkle:materialx`` (for a ``.usdz``)."""
    from pxr import Sdf  # deferred: usd-core, USD only

    copy = Sdf.Layer.CreateAnonymous(".usda")
    copy.TransferContent(layer)
    drop_materialx_file(copy)
    return copy
