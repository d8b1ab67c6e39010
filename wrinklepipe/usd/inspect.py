"""What a USD stage holds, as plain JSON-able data, comparable with
:func:`wrinklepipe.gltf.inspect.diff`.

:func:`usd_summary` opens the stage composed (sublayers, references, payloads, the selected
variants; instance proxies included) and lists its layers and stage metadata, then every prim
by path: its type, applied API schemas, variant sets (variants, selection), and each authored
attribute (``type (count)
interpolation``, ``N time samples``) and relationship (its targets); for a Mesh also its points
and faces, for a Skeleton its joints, for a Material its surface shader. ``inspect --diff
SOURCE LAYER`` therefore lists exactly what a layer over a source adds.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from wrinklepipe.usd.meshes import mesh_time, open_stage


def _value_label(attr: Any) -> str:
    """``float4[] (36) faceVarying`` / ``token = "st"`` / ``matrix4d[] (3), 2 time samples``."""
    from pxr import Sdf, UsdGeom  # deferred: usd-core, USD only

    type_name = str(attr.GetTypeName())
    samples = attr.GetNumTimeSamples()
    value = attr.Get()
    if value is not None and hasattr(value, "__len__") and not isinstance(value, str):
        text = f"{type_name} ({len(value)})"
    elif isinstance(value, Sdf.AssetPath):
        text = f"{type_name} = @{value.path}@"  # as authored (resolved paths are per machine)
    elif value is not None:
        shown = repr(value) if len(repr(value)) <= 60 else repr(value)[:57] + "..."
        text = f"{type_name} = {shown}"
    else:
        text = type_name
    pv = UsdGeom.Primvar(attr)
    if pv:
        text += f" {pv.GetInterpolation()}"
        if pv.GetElementSize() != 1:
            text += f" x{pv.GetElementSize()}"
    if attr.HasAuthoredConnections():
        text += " <- " + ", ".join(str(c) for c in attr.GetConnections())
    if samples:
        text += f", {samples} time samples"
    return text


def _prim(prim: Any) -> dict[str, Any]:
    from pxr import Usd, UsdGeom, UsdShade, UsdSkel  # deferred: usd-core, USD only

    row: dict[str, Any] = {"type": str(prim.GetTypeName()) or "(over)"}
    applied = list(prim.GetAppliedSchemas())
    ops = prim.GetMetadata("apiSchemas")
    for s in ops.ApplyOperations([]) if ops is not None else []:
        if s not in applied:
            applied.append(s)  # authored schemas this process has no definition for
    if applied:
        row["apiSchemas"] = applied
    if prim.IsInstance():
        row["instance"] = True
    vsets = prim.GetVariantSets()
    for name in vsets.GetNames():  # e.g. a glTF source's clips (usd.animation)
        vs = vsets.GetVariantSet(name)
        row.setdefault("variantSets", {})[name] = {
            "variants": list(vs.GetVariantNames()),
            "selected": vs.GetVariantSelection(),
        }
    if prim.IsA(UsdGeom.Mesh):
        m = UsdGeom.Mesh(prim)
        time, _ = mesh_time(prim, Usd.TimeCode.Default())  # only time-sampled: a sample's count
        row["points"] = len(m.GetPointsAttr().Get(time) or [])
        row["faces"] = len(m.GetFaceVertexCountsAttr().Get() or [])
        mat, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        row["material"] = str(mat.GetPath()) if mat else ""
        skel = UsdSkel.BindingAPI(prim).GetInheritedSkeleton()
        if skel:
            row["skeleton"] = str(skel.GetPath())
    elif prim.IsA(UsdSkel.Skeleton):
        row["joints"] = len(UsdSkel.Skeleton(prim).GetJointsAttr().Get() or [])
    elif prim.IsA(UsdShade.Material):
        shader = UsdShade.Material(prim).ComputeSurfaceSource()[0]
        row["surface"] = f"{shader.GetPath()} ({shader.GetIdAttr().Get()})" if shader else "none"
    attrs = {
        a.GetName(): _value_label(a)
        for a in prim.GetAttributes()
        if a.HasAuthoredValue() or a.HasAuthoredConnections()
    }
    if attrs:
        row["attributes"] = attrs
    rels = {r.GetName(): [str(t) for t in r.GetTargets()] for r in prim.GetRelationships()}
    if rels:
        row["relationships"] = rels
    return row


def usd_summary(path: str | Path) -> dict[str, Any]:
    """The summary of a USD file (see the module doc)."""
    from pxr import Usd, UsdGeom, UsdShade, UsdSkel  # deferred: usd-core, USD only

    p = Path(path)
    stage = open_stage(p)
    root = stage.GetRootLayer()
    prims = {str(q.GetPath()): _prim(q) for q in stage.Traverse(Usd.TraverseInstanceProxies())}
    kinds = [
        ("meshes", UsdGeom.Mesh),
        ("materials", UsdShade.Material),
        ("skeletons", UsdSkel.Skeleton),
        ("animations", UsdSkel.Animation),
    ]
    counts = {
        name: sum(1 for q in stage.Traverse(Usd.TraverseInstanceProxies()) if q.IsA(t))
        for name, t in kinds
    }
    return {
        "file": str(p),
        "layers": [str(x) for x in root.subLayerPaths],
        "used_layers": len(stage.GetUsedLayers()),
        "defaultPrim": stage.GetDefaultPrim().GetName() if stage.GetDefaultPrim() else "",
        "upAxis": str(UsdGeom.GetStageUpAxis(stage)),
        "metersPerUnit": UsdGeom.GetStageMetersPerUnit(stage),
        "timeCodes": [
            stage.GetStartTimeCode(),
            stage.GetEndTimeCode(),
            stage.GetTimeCodesPerSecond(),
        ],
        "counts": counts,
        "prims": prims,
    }
