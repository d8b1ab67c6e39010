"""Test harness, run by Blender 5's Python (``bpy``): a USD output judged by a pxr with UsdMtlx.

    .venv-blender/bin/python tests/blender_usd.py -- OUT.json LAYER.usda MATERIAL_PATH

Blender bundles USD (25.x) with UsdMtlx, which usd-core lacks: its shader registry knows
MaterialX's node definitions and its file format plugin reads ``.mtlx`` files. Writes OUT.json:

- ``errors``: every UsdValidation error on the layer's stage (all validators);
- ``unknown_ids``: shader ids of the stage that the shader registry does not know;
- ``surface``: the shader (path, id) the material's ``mtlx`` surface output resolves to, and
  ``preview``: the universal one's;
- ``layer_graph`` / ``mtlx_graph``: the MaterialX network as ``{node: [id, {input: value or
  connection}]}``, from the layer's NodeGraph and from the ``.mtlx`` the material names
  (``wrinkle:materialx``) as UsdMtlx translates it (connections relative to the graph);
- ``referenced``: the ``mtlx`` surface shader's id when a new layer references the ``.mtlx``'s
  material (a host that composes the file instead of the layer's copy).
"""

from __future__ import annotations

import json
import os
import sys

import bpy

sys.path.append(
    os.path.join(bpy.utils.system_resource("PYTHON"), "lib", "python3.11", "site-packages")
)

from pxr import Sdf, Sdr, Usd, UsdShade, UsdValidation  # noqa: E402


def _graph(stage, path) -> dict:
    out = {}
    root = str(path)
    for prim in stage.GetPrimAtPath(path).GetChildren():
        shader = UsdShade.Shader(prim)
        inputs = {}
        for inp in shader.GetInputs():
            conns = inp.GetAttr().GetConnections()
            if conns:
                inputs[inp.GetBaseName()] = "->" + str(conns[0]).replace(root, "")
            else:
                v = inp.Get()
                if isinstance(v, Sdf.AssetPath):
                    v = os.path.normpath(v.path)
                elif hasattr(v, "__len__") and not isinstance(v, str):
                    v = [round(float(x), 6) for x in v]
                elif isinstance(v, float):
                    v = round(v, 6)
                inputs[inp.GetBaseName()] = v
        out[prim.GetName()] = [shader.GetIdAttr().Get(), inputs]
    return out


def main() -> None:
    args = sys.argv[sys.argv.index("--") + 1 :]
    out_path, layer, material_path = args
    stage = Usd.Stage.Open(layer)
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = [
        e.GetMessage()
        for e in UsdValidation.ValidationContext(validators).Validate(stage)
        if e.GetType() == UsdValidation.ValidationErrorType.Error
    ]
    reg = Sdr.Registry()
    ids = {
        UsdShade.Shader(p).GetIdAttr().Get()
        for p in stage.Traverse()
        if p.IsA(UsdShade.Shader) and UsdShade.Shader(p).GetIdAttr().Get()
    }
    unknown = sorted(i for i in ids if reg.GetShaderNodeByIdentifier(i) is None)
    material = UsdShade.Material(stage.GetPrimAtPath(material_path))
    surface = material.ComputeSurfaceSource("mtlx")[0]
    preview = material.ComputeSurfaceSource()[0]
    graph_path = surface.GetInput("normal").GetAttr().GetConnections()[0].GetPrimPath()
    mtlx = os.path.join(
        os.path.dirname(layer), material.GetPrim().GetAttribute("wrinkle:materialx").Get()
    )
    mtlx_stage = Usd.Stage.Open(mtlx)
    ref_stage = Usd.Stage.CreateInMemory()
    ref = ref_stage.DefinePrim("/M")
    ref.GetReferences().AddReference(mtlx, "/MaterialX/Materials/M_wrinkle")
    referenced = UsdShade.Material(ref).ComputeSurfaceSource("mtlx")[0]
    summary = {
        "errors": errors,
        "unknown_ids": unknown,
        "shader_ids": len(ids),
        "surface": [str(surface.GetPath()), surface.GetIdAttr().Get()],
        "preview": [str(preview.GetPath()), preview.GetIdAttr().Get()],
        "layer_graph": _graph(stage, graph_path),
        "mtlx_graph": _graph(mtlx_stage, Sdf.Path("/MaterialX/NodeGraphs/NG_wrinkle")),
        "referenced": referenced.GetIdAttr().Get() if referenced else None,
        "usd": ".".join(map(str, Usd.GetVersion())),
    }
    with open(out_path, "w", encoding="utf-8") as f:
        json.dump(summary, f)


if __name__ == "__main__":
    main()
