"""A USD mesh posed: the world matrices of its joints and its blend-shape weights at a time (or the
rest pose), from the skeleton bound to its prim and the skeleton's animation source, on a stage
opened once by :func:`wrinklepipe.usd.meshes.open_stage`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.usd.meshes import open_stage


def usd_joint_world_matrices(
    path: str | Path,
    mesh: Mesh,
    time: float | None = None,
    at_rest: bool = False,
    stage: Any = None,
) -> np.ndarray:
    """World matrices ``[J, 4, 4]`` (column vectors) of ``mesh``'s joints at ``time``, from the
    skeleton bound to the mesh prim ``mesh.name`` and its animation source; ``at_rest``: the
    skeleton's ``restTransforms`` instead (no animation; UsdSkel's own ``atRest``; a skeleton
    without them: its ``bindTransforms``), placed by the skeleton's world transform at
    ``time``. ``stage``: ``path`` already opened (:func:`open_stage`), for a caller that asks
    about several prims."""
    from pxr import Usd, UsdGeom, UsdSkel  # deferred: usd-core, USD only

    p = Path(path)
    stage = stage or open_stage(p)
    prim = stage.GetPrimAtPath(mesh.name)
    if not prim:
        raise input_error(p, f"no prim {mesh.name}")
    tc = Usd.TimeCode.Default() if time is None else Usd.TimeCode(time)
    root = UsdSkel.Root.Find(prim)
    skel = UsdSkel.BindingAPI(prim).GetInheritedSkeleton()
    if not root or not skel:
        raise input_error(p, f"{mesh.name} is not bound to a skeleton")
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.TraverseInstanceProxies())
    skel_q = cache.GetSkelQuery(skel)
    names = [str(j) for j in skel_q.GetJointOrder()]
    xf = skel_q.ComputeJointSkelTransforms(tc, at_rest)
    if at_rest and not len(xf):  # no restTransforms: the bind pose is the rest
        xf = skel.GetBindTransformsAttr().Get()
    if xf is None or len(xf) != len(names):
        raise input_error(p, f"{skel.GetPath()}: no joint transforms of its {len(names)} joints")
    xf = np.asarray(xf, dtype=np.float64).transpose(0, 2, 1)
    skel_world = np.asarray(
        UsdGeom.Xformable(skel.GetPrim()).ComputeLocalToWorldTransform(tc), dtype=np.float64
    ).T
    world = skel_world @ xf
    missing = [j for j in mesh.joint_names if j not in names]
    if missing:
        raise input_error(p, f"joints {missing[:3]} are not in the skeleton")
    return world[[names.index(j) for j in mesh.joint_names]]


def usd_blend_shape_weights(
    path: str | Path, mesh: Mesh, time: float, stage: Any = None
) -> dict[str, float]:
    """The SkelAnimation blend-shape weights bound to ``mesh.name`` at ``time`` (``stage``:
    ``path`` already opened)."""
    from pxr import Usd, UsdSkel  # deferred: usd-core, USD only

    p = Path(path)
    stage = stage or open_stage(p)
    prim = stage.GetPrimAtPath(mesh.name)
    skel = UsdSkel.BindingAPI(prim).GetInheritedSkeleton() if prim else None
    if not skel:
        raise input_error(p, f"{mesh.name} is not bound to a skeleton")
    src = UsdSkel.BindingAPI(skel.GetPrim()).GetAnimationSource()
    if not src:
        raise input_error(p, f"{skel.GetPath()} has no animation source")
    anim = UsdSkel.Animation(src)
    names = [str(n) for n in (anim.GetBlendShapesAttr().Get() or [])]
    vals = anim.GetBlendShapeWeightsAttr().Get(Usd.TimeCode(time))
    if vals is None:
        return {}
    return dict(zip(names, map(float, vals)))
