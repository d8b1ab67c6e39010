"""USD mesh ingest (usd-core): UsdGeom.Mesh + UsdSkel blend shapes and skinning -> Meshes.

- Points at the requested time (default: the default value; a mesh whose points are only
  time-sampled is read whole at the stage's ``startTimeCode`` when the stage authors one, else
  at its earliest sample, said in ``Mesh.notes``: :func:`mesh_time`);
  ``faceVertexCounts``/``faceVertexIndices`` fan-triangulated
  (``leftHanded`` orientation flips the winding); holes are not cut (noted when present).
- UVs: the ``st`` primvar (else the first ``texCoord2f`` primvar), with ``vertex``,
  ``faceVarying`` or ``uniform`` interpolation, indexed or not. USD's v points up: v is flipped
  to the glTF convention (noted). Normals: ``primvars:normals`` or ``normals`` likewise.
- Render vertices are the distinct (point, uv, normal) corner triples: the vertex split that UV
  seams and hard edges need; ``Mesh.notes`` says how many.
- UsdSkel blend shapes (``skel:blendShapes`` / ``skel:blendShapeTargets``): sparse
  ``pointIndices`` are expanded; each inbetween becomes an extra target named
  ``"<shape>@<weight>"`` (e.g. ``targetC@0.5``) that :func:`wrinklepipe.geometry.dynamic.morph_pose`
  interpolates piecewise-linearly, as UsdSkel does.
- UsdSkel skinning: joint influences (constant = rigid, or vertex; any ``elementSize``, the 4
  largest kept and renormalised), joint order (``skel:joints`` or the Skeleton's), inverse bind
  matrices from ``bindTransforms``; ``geomBindTransform`` is applied to the points. Matrices are
  converted from USD's row-vector convention to column vectors.
- Non-skinned meshes are baked to world space when ``bake_transforms``.
- Wrinkle data a wrinklepipe layer adds (``primvars:wrinkle:vertexId``, ``wrinkle:tangent``,
  ``wrinkle:bias``; vertex or faceVarying) is read per render vertex, tangents transformed
  with the points; a Skeleton's ``wrinkle:jointNames`` and ``wrinkle:inverseBindTransforms``
  (the glTF joint names and exact inverse binds wrinklepipe writes beside the joint tokens)
  name the joints and give their inverse binds. ``exact`` reads normals and joint weights as
  stored (the package reader of a stage wrinklepipe wrote); ingest renormalises them.
- ``Mesh.parts`` holds one :class:`~wrinklepipe.asset.MeshPart` per mesh: the prim path, the
  render vertex of every ``faceVertexIndices`` corner and the transform applied (what a layer
  over the source needs to write per-vertex data back in the prim's own topology and space).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.asset import Mesh, MeshPart, mesh_over_cap
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.polygons import drop_degenerate, fan_triangles, weld_corners
from wrinklepipe.io.confine import confine_usd
from wrinklepipe.io.usd_diagnostics import captured_diagnostics, error_text
from wrinklepipe.names import noun, plural
from wrinklepipe.usd.composition import UsdProblem, composition_problems


@dataclass(frozen=True)
class UsdMeshOptions:
    """Options of :func:`read_usd_meshes`.

    bake_transforms: apply the local-to-world transform of non-skinned meshes (default True).
    time: time code for points and transforms (default: the default time).
    prim: only read meshes at or under this prim path (default: all).
    paths: only read the Mesh prims at these paths (default: all; with ``prim``, both apply).
    rigid_at_rest: a mesh bound rigidly to one joint (constant ``jointIndices``, e.g. a head
    attached to a bone) is read as a rigid mesh at the skeleton's rest pose (UsdSkel's
    ``rest_k inv(bind_k) geomBindTransform``, then the skeleton's world transform), without
    skin, as glTF holds a mesh parented to a joint (default False: skinned, in bind space).
    exact: values as stored: normals and joint weights are not renormalised (a stage wrinklepipe
    wrote holds a package's mesh bit for bit; default False: ingest renormalises them).
    """

    bake_transforms: bool = True
    time: float | None = None
    prim: str | None = None
    paths: tuple[str, ...] | None = None
    rigid_at_rest: bool = False
    exact: bool = False


def open_stage(path: Path) -> Any:
    """``Usd.Stage.Open`` after :func:`~wrinklepipe.io.confine.confine_usd`; one clear error.
    USD's diagnostics are captured, never printed (:func:`open_stage_checked` returns them)."""
    return open_stage_checked(path)[0]


def open_stage_checked(path: Path) -> tuple[Any, list[UsdProblem]]:
    """:func:`open_stage` and the stage's composition problems (missing or cyclic sublayers,
    references, payloads; the other diagnostics USD posted while opening it)."""
    from pxr import Tf, Usd  # deferred: usd-core, USD only

    if not Path(path).is_file():
        raise input_error(path, "file not found")
    confine_usd(path)  # every path it names: inside the asset's folder
    with captured_diagnostics() as said:
        try:
            stage = Usd.Stage.Open(str(path))
        except Tf.ErrorException as exc:
            raise input_error(path, f"cannot open USD stage: {error_text(exc)[:300]}") from None
    if stage is None:
        raise input_error(path, "cannot open USD stage" + (f": {said[0]}" if said else ""))
    return stage, composition_problems(stage, said, str(path))


def read_usd_meshes(path: str | Path, options: UsdMeshOptions | None = None) -> list[Mesh]:
    """One :class:`Mesh` per ``UsdGeom.Mesh`` prim with faces (named by prim path)."""
    from pxr import Usd, UsdGeom  # deferred: usd-core, USD only

    opts = options or UsdMeshOptions()
    p = Path(path)
    stage = open_stage(p)
    time = Usd.TimeCode.Default() if opts.time is None else Usd.TimeCode(opts.time)
    out: list[Mesh] = []
    skipped: list[str] = []
    for prim in stage.Traverse(Usd.TraverseInstanceProxies()):
        if not prim.IsA(UsdGeom.Mesh):
            continue
        ppath = str(prim.GetPath())
        if opts.prim and not (ppath == opts.prim or ppath.startswith(opts.prim.rstrip("/") + "/")):
            continue
        if opts.paths is not None and ppath not in opts.paths:
            continue
        mesh = _read_mesh(p, prim, time, opts)
        if mesh is None:
            skipped.append(ppath)
            continue
        out.append(mesh)
    if not out:
        raise input_error(
            p, "no UsdGeom.Mesh with faces" + (f" under {opts.prim}" if opts.prim else "")
        )
    if skipped:
        out[0].notes.append(f"skipped {plural(len(skipped), 'mesh')} without faces: {skipped[:5]}")
    return out


def mesh_time(prim: Any, time: Any) -> tuple[Any, str]:
    """The time code a Mesh prim is read at, and a note when a choice was made: ``time``, except
    the default time for points that have no default value but time samples: the stage's
    ``startTimeCode`` when it authors a time-code range, else the earliest sample."""
    from pxr import Usd, UsdGeom  # deferred: usd-core, USD only

    if not time.IsDefault():
        return time, ""
    attr = UsdGeom.Mesh(prim).GetPointsAttr()
    if attr.Get(time) is not None:
        return time, ""
    samples = attr.GetTimeSamples()
    if not samples:
        return time, ""
    stage = prim.GetStage()
    if stage.HasAuthoredTimeCodeRange():
        code = float(stage.GetStartTimeCode())
        why = "the stage's startTimeCode"
    else:
        code = float(samples[0])
        why = f"the earliest of {len(samples)} samples"
    note = (
        f"points have no default value, only {plural(len(samples), 'time sample')}: read at time "
        "code "
        f"{code:g} ({why})"
    )
    return Usd.TimeCode(code), note


def _primvar_corners(
    pv: Any, time: Any, counts: np.ndarray, fvi: np.ndarray, n_points: int, width: int
) -> tuple[np.ndarray | None, str]:
    """Per-corner values ``[C, width]`` of a primvar, or None if unusable (with the reason)."""
    if not pv or not pv.HasValue():
        return None, ""
    vals = pv.ComputeFlattened(time)
    if vals is None:
        return None, ""
    try:
        a = np.asarray(vals, dtype=np.float64).reshape(-1, width)
    except (TypeError, ValueError):
        return None, f"{pv.GetName()}: values are not {width}-vectors"
    interp = pv.GetInterpolation()
    n_c = len(fvi)
    if interp == "faceVarying":
        if len(a) != n_c:
            return None, f"{pv.GetName()}: {len(a)} faceVarying values for {n_c} corners"
        return a, ""
    if interp in ("vertex", "varying"):
        if len(a) != n_points:
            return None, f"{pv.GetName()}: {len(a)} vertex values for {n_points} points"
        return a[fvi], ""
    if interp == "uniform":
        if len(a) != len(counts):
            return None, f"{pv.GetName()}: {len(a)} uniform values for {len(counts)} faces"
        return np.repeat(a, counts, axis=0), ""
    if interp == "constant" and len(a):
        return np.repeat(a[:1], n_c, axis=0), ""
    return None, f"{pv.GetName()}: unknown interpolation {interp}"


def uv_primvar(prim: Any) -> Any:
    """The primvar a mesh's texture coordinates are read from: ``st``, else the first
    texCoord2f primvar (or float2 one named ``uv*``/``st*``); None when it has none."""
    from pxr import UsdGeom  # deferred: usd-core, USD only

    api = UsdGeom.PrimvarsAPI(prim)
    st = api.GetPrimvar("st")
    if st and st.HasValue():
        return st
    return next(
        (
            pv
            for pv in api.GetPrimvarsWithValues()
            if str(pv.GetTypeName().role) == "TextureCoordinate"
            or pv.GetTypeName().cppTypeName.endswith("Vec2f>")
            and pv.GetName().lower().startswith(("primvars:uv", "primvars:st"))
        ),
        None,
    )


def _read_mesh(path: Path, prim: Any, time: Any, opts: UsdMeshOptions) -> Mesh | None:
    from pxr import UsdGeom, UsdSkel  # deferred: usd-core, USD only

    file = str(path)
    ppath = str(prim.GetPath())
    gm = UsdGeom.Mesh(prim)
    time, time_note = mesh_time(prim, time)
    # the counts first: the corners they declare are checked before the indices, points and
    # every per-corner array are read
    counts_v = gm.GetFaceVertexCountsAttr().Get(time)
    if counts_v is None or len(counts_v) == 0:
        return None
    declared = int(np.asarray(counts_v, dtype=np.int64).sum())
    if over := mesh_over_cap(0, max(declared, len(counts_v))):
        raise input_error(file, f"mesh {ppath} {over}", key=f"{ppath}.faceVertexCounts")
    fvi_v = gm.GetFaceVertexIndicesAttr().Get(time)
    if fvi_v is not None and (over := mesh_over_cap(0, len(fvi_v))):
        raise input_error(file, f"mesh {ppath} {over}", key=f"{ppath}.faceVertexIndices")
    pts_v = gm.GetPointsAttr().Get(time)
    if pts_v is not None and (over := mesh_over_cap(len(pts_v), 0)):
        raise input_error(file, f"mesh {ppath} {over}", key=f"{ppath}.points")
    if pts_v is None or fvi_v is None:
        return None
    pts = np.asarray(pts_v, dtype=np.float64).reshape(-1, 3)
    counts = np.asarray(counts_v, dtype=np.int64)
    fvi = np.asarray(fvi_v, dtype=np.int64)
    n_p = len(pts)
    notes: list[str] = [time_note] if time_note else []
    if counts.sum() != len(fvi) or (counts < 3).any():
        raise input_error(file, "faceVertexCounts do not match faceVertexIndices (or a face has"
                          " fewer than 3 corners)", key=f"{ppath}.faceVertexCounts")  # fmt: skip
    if len(fvi) and (fvi.min() < 0 or fvi.max() >= n_p):
        raise input_error(
            file, f"faceVertexIndices out of range 0..{n_p - 1}", key=f"{ppath}.faceVertexIndices"
        )
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        v = int(np.flatnonzero(bad)[0])
        n = int(bad.sum())
        raise input_error(file, f"{plural(n, 'point')} {noun(n, 'is', 'are')} NaN or infinite "
                          f"(first: {v})", key=f"{ppath}.points")  # fmt: skip
    if gm.GetHoleIndicesAttr().Get(time):
        notes.append("holeIndices ignored (holes are not cut)")

    api = UsdGeom.PrimvarsAPI(prim)
    st = uv_primvar(prim)
    uv_c, why = _primvar_corners(st, time, counts, fvi, n_p, 2)
    if why:
        notes.append(f"ignored UVs ({why})")
    n_c, why = _normal_corners(gm, api, time, counts, fvi, n_p)
    if why:
        notes.append(f"ignored normals ({why})")

    # Render vertices: distinct (point, uv, normal) corners, in point order (so a mesh without
    # splits keeps its points' order), copies of a point ordered by first appearance.
    cols = [fvi[:, None].astype(np.float64)]
    if uv_c is not None:
        cols.append(uv_c)
    if n_c is not None:
        cols.append(n_c)
    key = np.concatenate(cols, axis=1) + 0.0
    corner_v, src = weld_corners(key, fvi)  # src: a corner of each render vertex
    vmap = fvi[src]  # render vertex -> USD point
    if len(vmap) != n_p:
        notes.append(f"{len(vmap)} render vertices from {n_p} points (split by UVs/normals)")

    tris = corner_v[fan_triangles(counts)]
    if (counts > 3).any():
        notes.append(f"fan-triangulated {plural(int((counts > 3).sum()), 'polygon')}")
    if gm.GetOrientationAttr().Get(time) == UsdGeom.Tokens.leftHanded:
        tris = tris[:, [0, 2, 1]]
        notes.append("leftHanded orientation: winding flipped")

    positions = pts[vmap]
    uvs = None
    if uv_c is not None:
        uvs = uv_c[src].copy()
        uvs[:, 1] = 1.0 - uvs[:, 1]
        notes.append("flipped V (USD v up -> glTF v down)")
    normals = None
    if n_c is not None:
        nn = n_c[src]
        if not opts.exact:
            nn /= np.maximum(np.linalg.norm(nn, axis=1, keepdims=True), 1e-30)
        normals = nn

    vertex_ids, wrinkle4 = _wrinkle_primvars(api, time, counts, fvi, n_p, src, notes)
    mesh = Mesh(
        vertex_ids=vertex_ids,
        positions=positions.astype(np.float32),
        indices=tris.astype(np.uint32),
        uvs=None if uvs is None else uvs.astype(np.float32),
        normals=None if normals is None else normals.astype(np.float32),
        tangents=wrinkle4["tangent"],
        colors=wrinkle4["bias"],
        name=ppath,
        notes=notes,
    )
    applied = np.eye(4)

    skinned = False
    if prim.HasAPI(UsdSkel.BindingAPI):
        binding = UsdSkel.BindingAPI(prim)
        _blend_shapes(file, ppath, binding, mesh, vmap, n_p)
        skinned, applied = _skin(file, prim, mesh, vmap, n_p, time, opts)
    if not skinned and opts.bake_transforms:
        m = np.asarray(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time)).T
        if not np.allclose(m, np.eye(4)):
            _apply(mesh, m)
            applied = m
            mesh.notes.append("baked the local-to-world transform")
    mesh.parts = (MeshPart(ppath, ppath, 0, len(vmap), corners=corner_v, transform=applied),)

    tris2, n_degen = drop_degenerate(mesh.positions, mesh.indices.astype(np.int64))
    if n_degen:
        mesh.indices = tris2.astype(np.uint32)
        mesh.notes.append(f"skipped {plural(n_degen, 'degenerate triangle')}")
    if len(mesh.indices) == 0:
        raise input_error(file, "every triangle is degenerate", key=ppath)
    return mesh


def _normal_corners(
    gm: Any, api: Any, time: Any, counts: np.ndarray, fvi: np.ndarray, n_p: int
) -> tuple[np.ndarray | None, str]:
    """Normals per face corner (the primvar, else the attribute), or None and why not."""
    nrm_pv = api.GetPrimvar("normals")
    if nrm_pv and nrm_pv.HasValue():
        n_c, why = _primvar_corners(nrm_pv, time, counts, fvi, n_p, 3)
    else:
        n_c, why = None, ""
        nv = gm.GetNormalsAttr().Get(time)
        try:
            a = np.asarray(nv, dtype=np.float64).reshape(-1, 3) if nv is not None else None
        except (TypeError, ValueError):
            a, why = None, "normals: values are not 3-vectors"
        if a is not None and len(a):
            interp = gm.GetNormalsInterpolation()
            if interp == "faceVarying" and len(a) == len(fvi):
                n_c = a
            elif interp in ("vertex", "varying") and len(a) == n_p:
                n_c = a[fvi]
            elif interp == "uniform" and len(a) == len(counts):
                n_c = np.repeat(a, counts, axis=0)
            else:
                why = f"normals: {len(a)} values with interpolation {interp}"
    return n_c, why


def _wrinkle_primvars(
    api: Any, time: Any, counts: Any, fvi: Any, n_p: int, src: Any, notes: list[str]
) -> tuple[np.ndarray | None, dict[str, np.ndarray | None]]:
    """The vertex IDs and wrinkle:tangent/bias a USD wrinklepipe wrote has, per render vertex."""
    vertex_ids = None
    vid_pv = api.GetPrimvar("wrinkle:vertexId")
    if vid_pv and vid_pv.HasValue():
        vid_c, why = _primvar_corners(vid_pv, time, counts, fvi, n_p, 1)
        if vid_c is not None and np.all(vid_c >= 0) and np.all(vid_c == np.rint(vid_c)):
            vertex_ids = vid_c[src, 0].astype(np.int64)
        else:
            notes.append("ignored primvars:wrinkle:vertexId" + (f" ({why})" if why else ""))
    wrinkle4: dict[str, np.ndarray | None] = {}
    for name in ("tangent", "bias"):
        got = None
        p4 = api.GetPrimvar(f"wrinkle:{name}")
        if p4 and p4.HasValue():
            got, why = _primvar_corners(p4, time, counts, fvi, n_p, 4)
            if got is None or not np.isfinite(got).all():
                notes.append(f"ignored primvars:wrinkle:{name}" + (f" ({why})" if why else ""))
                got = None
        wrinkle4[name] = None if got is None else got[src].astype(np.float32)
    return vertex_ids, wrinkle4


def _apply(mesh: Mesh, m: np.ndarray) -> None:
    lin = m[:3, :3]
    mesh.positions = (mesh.positions.astype(np.float64) @ lin.T + m[:3, 3]).astype(np.float32)
    if mesh.morph_deltas is not None:
        mesh.morph_deltas = (mesh.morph_deltas.astype(np.float64) @ lin.T).astype(np.float32)
    if mesh.normals is not None:
        n = mesh.normals.astype(np.float64) @ np.linalg.inv(lin)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
        mesh.normals = n.astype(np.float32)
    if mesh.tangents is not None:  # tangent vectors move with the points; handedness with det
        t = mesh.tangents[:, :3].astype(np.float64) @ lin.T
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-30)
        w = mesh.tangents[:, 3:] * np.sign(np.linalg.det(lin))
        mesh.tangents = np.concatenate([t, w], axis=1).astype(np.float32)
    if np.linalg.det(lin) < 0:
        mesh.indices = mesh.indices[:, [0, 2, 1]].copy()


def _blend_shapes(
    file: str, ppath: str, binding: Any, mesh: Mesh, vmap: np.ndarray, n_p: int
) -> None:
    from pxr import UsdSkel  # deferred: usd-core, USD only

    names_attr = binding.GetBlendShapesAttr().Get()
    targets = binding.GetBlendShapeTargetsRel().GetTargets()
    if not names_attr:
        return
    names = [str(n) for n in names_attr]
    if len(targets) != len(names):
        mesh.notes.append(f"skipped blend shapes: {len(names)} names for {len(targets)} targets")
        return
    stage = binding.GetPrim().GetStage()
    out_names: list[str] = []
    deltas: list[np.ndarray] = []
    skipped = 0

    def dense(offsets: Any, idx: np.ndarray | None, label: str) -> np.ndarray | None:
        if offsets is None:  # a normal-only shape: no point motion
            mesh.notes.append(
                f"blend shape {label} has no point offsets (normal-only): zero deltas"
            )
            return np.zeros((len(vmap), 3), np.float32)
        try:
            o = np.asarray(offsets, dtype=np.float64).reshape(-1, 3)
        except (TypeError, ValueError):
            mesh.notes.append(f"skipped blend shape {label}: offsets are not 3-vectors")
            return None
        full = np.zeros((n_p, 3))
        if idx is None:
            if len(o) != n_p:
                mesh.notes.append(f"skipped blend shape {label}: {len(o)} offsets for {n_p} points")
                return None
            full[:] = o
        else:
            if len(o) != len(idx) or (len(idx) and (idx.min() < 0 or idx.max() >= n_p)):
                mesh.notes.append(f"skipped blend shape {label}: pointIndices do not match offsets")
                return None
            full[idx] = o
        return full[vmap].astype(np.float32)

    for name, tpath in zip(names, targets):
        bs = UsdSkel.BlendShape(stage.GetPrimAtPath(tpath))
        if not bs:
            skipped += 1
            mesh.notes.append(f"skipped blend shape {name}: {tpath} is not a BlendShape")
            continue
        pi = bs.GetPointIndicesAttr().Get()
        idx = None if pi is None or len(pi) == 0 else np.asarray(pi, dtype=np.int64)
        d = dense(bs.GetOffsetsAttr().Get(), idx, name)
        if d is None:
            skipped += 1
            continue
        out_names.append(name)
        deltas.append(d)
        for ib in bs.GetInbetweens():
            w = ib.GetWeight()
            o = ib.GetOffsets()
            label = f"{name}@{w:g}"
            di = dense(o, idx, label) if o is not None else None
            if di is not None:
                out_names.append(label)
                deltas.append(di)
    if deltas:
        mesh.morph_names = tuple(out_names)
        mesh.morph_deltas = np.stack(deltas)
        n_ib = sum("@" in n for n in out_names)
        mesh.notes.append(
            f"{plural(len(out_names) - n_ib, 'blend shape')}"
            + (f", {plural(n_ib, 'inbetween')}" if n_ib else "")
        )


def _skin(
    file: str, prim: Any, mesh: Mesh, vmap: np.ndarray, n_p: int, time: Any, opts: UsdMeshOptions
) -> tuple[bool, np.ndarray]:
    """Read the UsdSkel skin onto ``mesh``: (placed by the skeleton, the transform applied:
    the geomBindTransform, or for ``rigid_at_rest`` the rigid joint's rest placement).

    The joint names and inverse bind matrices wrinklepipe authors on a Skeleton
    (``wrinkle:jointNames``: the glTF names the joint tokens were made from;
    ``wrinkle:inverseBindTransforms``: the glTF matrices, exact) win over the tokens and
    ``inv(bindTransforms)``."""
    from pxr import Usd, UsdGeom, UsdSkel  # deferred: usd-core, USD only

    root = UsdSkel.Root.Find(prim)
    if not root:
        return False, np.eye(4)
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.TraverseInstanceProxies())
    sq = cache.GetSkinningQuery(prim)
    if not sq or not sq.HasJointInfluences():
        return False, np.eye(4)
    skel = UsdSkel.BindingAPI(prim).GetInheritedSkeleton()
    if not skel:
        return False, np.eye(4)
    skel_q = cache.GetSkelQuery(skel)
    skel_joints = [str(j) for j in skel_q.GetJointOrder()]
    order = sq.GetJointOrder()
    joint_names = [str(j) for j in order] if order else skel_joints
    missing = [j for j in joint_names if j not in skel_joints]
    if missing:
        mesh.notes.append(f"skin ignored: joints {missing[:3]} are not in the skeleton")
        return False, np.eye(4)
    inf = sq.ComputeJointInfluences(time)
    if not inf:
        return False, np.eye(4)
    ji, jw = inf
    k = sq.GetNumInfluencesPerComponent()
    ji = np.asarray(ji, dtype=np.int64).reshape(-1, k)
    jw = np.asarray(jw, dtype=np.float64).reshape(-1, k)
    if sq.IsRigidlyDeformed():
        ji = np.repeat(ji[:1], n_p, axis=0)
        jw = np.repeat(jw[:1], n_p, axis=0)
    if len(ji) != n_p:
        mesh.notes.append(f"skin ignored: {len(ji)} influences for {n_p} points")
        return False, np.eye(4)
    if k > 4:
        top = np.argsort(-jw, axis=1, kind="stable")[:, :4]
        ji = np.take_along_axis(ji, top, 1)
        jw = np.take_along_axis(jw, top, 1)
        mesh.notes.append(f"kept the 4 largest of {k} joint influences per point")
    elif k < 4:
        ji = np.pad(ji, ((0, 0), (0, 4 - k)))
        jw = np.pad(jw, ((0, 0), (0, 4 - k)))
    if not opts.exact:
        total = jw.sum(axis=1, keepdims=True)
        jw = np.where(total > 0, jw / np.where(total > 0, total, 1.0), 0.0)
    if ji.max(initial=0) >= len(joint_names) or ji.min(initial=0) < 0:
        raise input_error(file, "joint indices out of range", key=f"{prim.GetPath()}.skel")
    bind = skel.GetBindTransformsAttr().Get()
    if bind is None or len(bind) != len(skel_joints):
        mesh.notes.append("skin ignored: Skeleton bindTransforms missing or wrong length")
        return False, np.eye(4)
    bind_col = np.asarray(bind, dtype=np.float64).transpose(0, 2, 1)  # row- to column-vector
    rows = [skel_joints.index(j) for j in joint_names]
    ibm = np.linalg.inv(bind_col)[rows]
    authored = _authored_joints(file, skel, len(skel_joints))
    if authored is not None:
        names, exact_ibm = authored
        if exact_ibm is not None:
            ibm = exact_ibm[rows]
    geom = np.asarray(sq.GetGeomBindTransform(time), dtype=np.float64).T
    if opts.rigid_at_rest and sq.IsRigidlyDeformed():
        k0 = skel_joints.index(joint_names[int(ji[0, 0])])
        rest = np.asarray(skel_q.ComputeJointSkelTransforms(time, True), np.float64)[k0].T
        world = np.asarray(
            UsdGeom.Xformable(skel.GetPrim()).ComputeLocalToWorldTransform(time), np.float64
        ).T
        placed = world @ rest @ np.linalg.inv(bind_col[k0]) @ geom
        if not (opts.exact and np.allclose(placed, np.eye(4))):  # exact: as stored
            _apply(mesh, placed)
        mesh.notes.append(
            f"rigidly bound to joint {joint_names[int(ji[0, 0])]}: read at the skeleton's rest pose"
        )
        return True, placed
    if not np.allclose(geom, np.eye(4)):
        _apply(mesh, geom)
        mesh.notes.append("applied geomBindTransform")
    mesh.joints = ji[vmap]
    mesh.skin_weights = jw[vmap].astype(np.float32)
    mesh.joint_names = tuple(joint_names if authored is None else [names[r] for r in rows])
    mesh.inverse_bind = ibm.astype(np.float32)
    mesh.notes.append(
        f"UsdSkel skin: {len(joint_names)} joints, {plural(k, 'influence')} per point"
    )
    return True, geom


def _authored_joints(file: str, skel: Any, n: int) -> tuple[list[str], np.ndarray | None] | None:
    """A Skeleton's ``wrinkle:jointNames`` and ``wrinkle:inverseBindTransforms`` (column
    vectors; None when not authored), in its joint order; None without the names."""
    names_attr = skel.GetPrim().GetAttribute("wrinkle:jointNames")
    if not names_attr or not names_attr.HasAuthoredValue():
        return None
    names = [str(x) for x in names_attr.Get()]
    if len(names) != n:
        raise input_error(file, "wrinkle:jointNames differs from the joints", str(skel.GetPath()))
    ibm_attr = skel.GetPrim().GetAttribute("wrinkle:inverseBindTransforms")
    value = ibm_attr.Get() if ibm_attr and ibm_attr.HasAuthoredValue() else None
    ibm = None
    if value is not None:
        ibm = np.asarray(value, np.float64).transpose(0, 2, 1)  # row- to column-vector
        if ibm.shape != (n, 4, 4):
            raise input_error(
                file, "wrinkle:inverseBindTransforms differs from the joints", str(skel.GetPath())
            )
    return names, ibm
