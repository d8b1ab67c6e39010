"""The whole glTF source scene in the USD output, rigged, its wrinkled primitives included.

For a glTF source, the USD convert writes holds the wrinkle material (``/NAME/Looks/skin``
with ``WrinkleMapsAPI``: :func:`wrinklepipe.usd.package_write.build_stage` with
``with_mesh=False``) and, from :func:`add_scene`, the whole character below ``/NAME/Scene``::

    Scene                        Xform (SkelRoot when /NAME is none)
      <node>/<node>/...          Xform per glTF node: its name (as displayName where it is no
                                 USD identifier), its local matrix (TRS / matrix)
        <mesh>[_<k>]             Mesh per primitive of a non-skinned node (its local space):
                                 points, triangles, normals, st (v flipped), st1, displayColor,
                                 doubleSided, blend shapes (offsets, normalOffsets, names)
      Skinned/<node>[_<k>]       Mesh per primitive of a skinned node (skeleton space, as glTF
                                 ignores a skinned node's transform): jointIndices/jointWeights
      Skeletons/<skin>           Skeleton per skin: joints as paths of the glTF joint hierarchy,
                                 restTransforms = each joint's local matrix (roots: world),
                                 bindTransforms = inverse(inverseBindMatrices), the glTF joint
                                 names in ``wrinkle:jointNames``
      Skeletons/Morphs           one-joint Skeleton (identity) for rigid meshes with morph
                                 targets under no joint: blend shapes play only when bound
      Animations/<clip>          SkelAnimation per glTF clip, and ``wrinkle`` (convert's first
                                 weight curve's morph weights), chosen by the variant set
                                 ``animation`` on Scene (:mod:`wrinklepipe.usd.animation`)
        Camera                   UsdGeom.Camera of a node's glTF camera (perspective: yfov and
                                 aspectRatio as apertures; orthographic: xmag / ymag; clipping)
      Looks/<material>           UsdPreviewSurface per glTF material: base colour (factor,
                                 texture, alpha), metallic / roughness, normal, occlusion,
                                 emissive; PNG / JPEG images copied byte for byte

A rigid primitive (a non-skinned node) whose node is a joint or lies below one (RobotExpressive's
head under the ``Head`` bone) is bound rigidly to that joint of the first skin holding it:
constant ``jointIndices`` ``[k]``, weight 1, ``geomBindTransform = bind_k inv(rest_k) world``,
so UsdSkel puts it at its glTF rest place (``rest_k inv(bind_k) geomBind = world``) and moves it
with the joint; its points stay in the node's space below the node Xforms (what an app without
UsdSkel shows: the same rest place).

The wrinkled primitives (``WrinkledPrims.refs``, the package's order) are written like the
others, in place, bound to the wrinkle material, with ``primvars:wrinkle:vertexId`` (int),
``wrinkle:tangent`` (float4: the primitive's TANGENT, in its own space) and ``wrinkle:bias``
(from ``_WRINKLE_BIAS`` where present), all ``vertex``: the glTF output's wrinkled primitives,
one for one. The material lists their prim paths in ``wrinkle:meshes``;
:func:`wrinklepipe.usd.package_read.read_usd` reads them back through the mesh reader, rigid ones at
the skeleton's rest pose: what the glTF path measures. A wrinkled primitive no scene node
instances goes below ``Scene/Unplaced`` in the space the render mesh reads it in (noted).

Materials and their images: :mod:`wrinklepipe.usd.looks` (texture transforms as
``UsdTransform2d``, KTX2 / WebP images transcoded to PNG); animations:
:mod:`wrinklepipe.usd.animation`. The glTF output beside it keeps everything as it
was.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from wrinklepipe.gltf.document import Document, PrimitiveRef
from wrinklepipe.gltf.primitive import (  # the one TRS, the one skin, the one bias
    bias_channels,
    node_matrix,
    read_skin,
)
from wrinklepipe.gltf.scene import node_world_matrices, primitive_triangles
from wrinklepipe.io.png import DEFAULT_PNG_LEVEL
from wrinklepipe.metadata import BIAS_ATTRIBUTE, VERTEX_ID_ATTRIBUTE
from wrinklepipe.package import WrinklePackage
from wrinklepipe.usd.animation import (
    SkeletonInfo,
    add_animations,
    xform_animated_nodes,
)
from wrinklepipe.usd.looks import Looks, Names, gf_matrix
from wrinklepipe.usd.package_write import SCENE_MESH_NAME, SCENE_MESHES


@dataclass(frozen=True)
class WrinkledPrims:
    """The wrinkled primitives and what binds them: ``refs`` in the package's order,
    ``material`` the wrinkle material's prim path, ``morph_names`` the package mesh's morph
    target names and ``morph_curve`` the first weight curve's (time codes ``[F]``, morph weights
    ``[F, M]``) when it drives them; ``mesh_name`` the package mesh's name (the material's
    ``wrinkle:meshName``: what read_usd names the merged mesh, as the glTF path does)."""

    refs: tuple[PrimitiveRef, ...]
    material: Any
    morph_names: tuple[str, ...] = ()
    morph_curve: tuple[np.ndarray, np.ndarray] | None = None
    mesh_name: str = ""


class _Scene:
    def __init__(
        self,
        stage: Any,
        root: Any,
        doc: Document,
        texture_dir: str,
        wrinkled: WrinkledPrims,
        png_level: int,
    ) -> None:
        self.stage, self.root, self.doc = stage, root, doc
        self.names = Names()
        self.looks = Looks(stage, root, doc, texture_dir, self.names, png_level)
        self.material = self.looks.material
        self.notes: list[str] = []
        self.skeletons: dict[int, Any] = {}
        self.morph_skeleton: Any = None
        self.skel_info: dict[str, SkeletonInfo] = {}  # skeleton path -> joints, morph meshes
        self.worlds = node_world_matrices(doc)
        self.wrinkled = wrinkled
        nodes = doc.array("nodes")
        self.parent = {int(c): i for i, n in enumerate(nodes) for c in n.get("children", [])}
        # each wrinkled primitive -> its index and the node whose instance the render mesh reads
        self.wrinkle_index: dict[tuple[int, int], tuple[int, int | None]] = {}
        for k, r in enumerate(wrinkled.refs):
            inst = doc.mesh_nodes(r.mesh)
            first = next((i for i in inst if i in self.worlds), inst[0] if inst else None)
            self.wrinkle_index[(r.mesh, r.primitive)] = (k, first)
        self.wrinkled_paths: dict[int, Any] = {}
        self.morph_skeletons: list[Any] = []  # skeletons a wrinkled blend shape plays through
        self.xform_animated = xform_animated_nodes(doc)
        self.xform_paths: dict[int, Any] = {}
        self.joint_skin: dict[int, tuple[int, int]] = {}  # joint node -> (first skin, index)
        for si, sk in enumerate(doc.array("skins")):
            for k, j in enumerate(sk.get("joints", [])):
                self.joint_skin.setdefault(int(j), (si, k))

    # -- skins -------------------------------------------------------------------------------
    def skeleton(self, skin: int) -> Any:
        from pxr import Sdf, UsdGeom, UsdSkel, Vt  # deferred: usd-core, USD only

        if skin in self.skeletons:
            return self.skeletons[skin]
        doc = self.doc
        s = doc.array("skins")[skin]
        joints = [int(j) for j in s["joints"]]
        nodes = doc.array("nodes")
        parent = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}
        in_skin = set(joints)
        names = Names()
        tokens: dict[int, str] = {}

        def joint_parent(j: int) -> int | None:
            p = parent.get(j)
            while p is not None and p not in in_skin:
                p = parent.get(p)
            return p

        def token(j: int) -> str:  # the joint's path: its joint ancestors' names
            if j not in tokens:
                p = joint_parent(j)
                head = token(p) + "/" if p is not None else ""
                tokens[j] = head + names(head, doc.node_name(j))
            return tokens[j]

        rest = []
        for j in joints:
            p = joint_parent(j)
            world = self.worlds.get(j, node_matrix(nodes[j]))
            rest.append(world if p is None else np.linalg.inv(self.worlds[p]) @ world)
        ibm = read_skin(doc, skin).inverse_bind  # the one skin reader (identity when absent)
        holder = self.root.AppendChild("Skeletons")
        if not self.stage.GetPrimAtPath(holder):
            UsdGeom.Scope.Define(self.stage, holder)
        name = str(s.get("name") or f"skin_{skin}")
        skel = UsdSkel.Skeleton.Define(self.stage, holder.AppendChild(self.names(holder, name)))
        skel.CreateJointsAttr(Vt.TokenArray([token(j) for j in joints]))
        skel.CreateRestTransformsAttr(Vt.Matrix4dArray([gf_matrix(r) for r in rest]))
        bind = np.linalg.inv(np.asarray(ibm, np.float64))
        skel.CreateBindTransformsAttr(Vt.Matrix4dArray([gf_matrix(b) for b in bind]))
        a = skel.GetPrim().CreateAttribute("wrinkle:jointNames", Sdf.ValueTypeNames.StringArray)
        a.SetCustom(True)
        a.Set(Vt.StringArray([doc.node_name(j) for j in joints]))
        self.skeletons[skin] = skel
        self.skel_info[str(skel.GetPath())] = SkeletonInfo(skel, joints, [token(j) for j in joints])
        return skel

    def joint_of(self, node: int) -> tuple[int, int, int] | None:
        """The joint a rigid node moves with: itself or its nearest joint ancestor, as
        ``(joint node, skin, index in the skin)``; None when no joint is above it."""
        n: int | None = node
        while n is not None:
            if n in self.joint_skin:
                return (n, *self.joint_skin[n])
            n = self.parent.get(n)
        return None

    def rigid_bind(self, node: int) -> tuple[Any, int, np.ndarray]:
        """(skeleton, joint index, geomBindTransform) binding a rigid node's mesh: to its
        joint (``bind_k inv(rest_k) world``), else to the one-joint ``Morphs`` skeleton
        (``world``)."""
        from pxr import UsdGeom, UsdSkel, Vt  # deferred: usd-core, USD only

        world = self.worlds.get(node, np.eye(4))
        got = self.joint_of(node)
        if got is not None:
            j, skin, k = got
            skel = self.skeleton(skin)
            bind = np.asarray(skel.GetBindTransformsAttr().Get()[k], np.float64).T
            rest = self.worlds.get(j, node_matrix(self.doc.array("nodes")[j]))
            return skel, k, bind @ np.linalg.inv(rest) @ world
        if self.morph_skeleton is None:
            holder = self.root.AppendChild("Skeletons")
            if not self.stage.GetPrimAtPath(holder):
                UsdGeom.Scope.Define(self.stage, holder)
            path = holder.AppendChild(self.names(holder, "Morphs"))
            skel = UsdSkel.Skeleton.Define(self.stage, path)
            skel.CreateJointsAttr(Vt.TokenArray(["root"]))
            skel.CreateRestTransformsAttr(Vt.Matrix4dArray([gf_matrix(np.eye(4))]))
            skel.CreateBindTransformsAttr(Vt.Matrix4dArray([gf_matrix(np.eye(4))]))
            self.morph_skeleton = skel
            self.skel_info[str(skel.GetPath())] = SkeletonInfo(skel, [], ["root"])
        return self.morph_skeleton, 0, world

    def wrinkle_primvars(self, mesh: Any, ref: PrimitiveRef) -> None:
        """The wrinkle primvars of a wrinkled primitive, from the attributes ingest added."""
        from pxr import Sdf, UsdGeom, Vt  # deferred: usd-core, USD only

        doc = self.doc
        attrs = doc.primitive(ref).get("attributes", {})
        pv = UsdGeom.PrimvarsAPI(mesh)
        vid = np.rint(doc.accessor(attrs[VERTEX_ID_ATTRIBUTE]).reshape(-1)).astype(np.int32)
        pv.CreatePrimvar("wrinkle:vertexId", Sdf.ValueTypeNames.IntArray, "vertex").Set(
            Vt.IntArray.FromNumpy(np.ascontiguousarray(vid))
        )
        bias = doc.accessor(attrs[BIAS_ATTRIBUTE]) if BIAS_ATTRIBUTE in attrs else None
        if bias is None:
            bias = bias_channels(attrs, lambda n: doc.accessor(attrs[n]), doc.err, ref.pointer)
        tangent = doc.accessor(attrs["TANGENT"]) if "TANGENT" in attrs else None
        for a, name in ((tangent, "tangent"), (bias, "bias")):
            if a is not None:
                a = np.ascontiguousarray(a, np.float32)
                pv.CreatePrimvar(f"wrinkle:{name}", Sdf.ValueTypeNames.Float4Array, "vertex").Set(
                    Vt.Vec4fArray.FromNumpy(a)
                )

    def wrinkle_morphs(self) -> Any:
        """A callable authoring the first weight curve's morph weights (a SkelAnimation of
        blend-shape weights only) as the animation source of each skeleton a wrinkled blend
        shape is bound through, inside the ``wrinkle`` variant; None when the curve drives
        no morph target."""
        from pxr import Tf, Usd, UsdSkel, Vt  # deferred: usd-core, USD only

        w = self.wrinkled
        if w.morph_curve is None or not w.morph_names or not self.morph_skeletons:
            return None
        codes, weights = w.morph_curve
        tokens = Vt.TokenArray([Tf.MakeValidIdentifier(n) for n in w.morph_names])

        def author(variant: str) -> None:
            path = self.root.AppendPath(f"Animations/{variant}")
            anim = UsdSkel.Animation.Define(self.stage, path)
            anim.CreateBlendShapesAttr(tokens)
            attr = anim.CreateBlendShapeWeightsAttr()
            for code, row in zip(codes, np.asarray(weights, np.float32)):
                attr.Set(Vt.FloatArray.FromNumpy(np.ascontiguousarray(row)), Usd.TimeCode(code))
            for skel in self.morph_skeletons:
                UsdSkel.BindingAPI(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([path])

        return author

    # -- meshes ------------------------------------------------------------------------------
    def mesh(self, parent: Any, name: str, ref: PrimitiveRef, node: int | None) -> None:
        from pxr import Gf, Sdf, UsdGeom, UsdShade, UsdSkel, Vt  # deferred: usd-core, USD only

        doc = self.doc
        prim = doc.primitive(ref)
        attrs = prim.get("attributes", {})
        tris = primitive_triangles(doc, ref)
        if not len(tris):
            self.notes.append(
                f"USD: {ref.pointer} is not triangles (mode {prim.get('mode')}); left out"
            )
            return
        path = parent.AppendChild(self.names(parent, name))
        mesh = UsdGeom.Mesh.Define(self.stage, path)
        if path.name != name:
            mesh.GetPrim().SetDisplayName(name)
        pts = np.ascontiguousarray(doc.accessor(attrs["POSITION"]), np.float32)
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(tris), 3, np.int32)))
        mesh.CreateFaceVertexIndicesAttr(
            Vt.IntArray.FromNumpy(np.ascontiguousarray(tris.reshape(-1), np.int32))
        )
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateExtentAttr(
            Vt.Vec3fArray([Gf.Vec3f(*pts.min(0).tolist()), Gf.Vec3f(*pts.max(0).tolist())])
        )
        if "NORMAL" in attrs:
            n = np.ascontiguousarray(doc.accessor(attrs["NORMAL"]), np.float32)
            mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(n))
            mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        pv = UsdGeom.PrimvarsAPI(mesh)
        for k in range(8):
            key = f"TEXCOORD_{k}"
            if key not in attrs:
                continue
            uv = doc.accessor(attrs[key]).astype(np.float32)
            st = np.ascontiguousarray(np.stack([uv[:, 0], 1.0 - uv[:, 1]], -1), np.float32)
            pv.CreatePrimvar(
                "st" if k == 0 else f"st{k}", Sdf.ValueTypeNames.TexCoord2fArray, "vertex"
            ).Set(Vt.Vec2fArray.FromNumpy(st))
        if "COLOR_0" in attrs:
            c = doc.accessor(attrs["COLOR_0"]).astype(np.float32)
            mesh.CreateDisplayColorPrimvar("vertex").Set(
                Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(c[:, :3]))
            )
            if c.shape[1] == 4:
                mesh.CreateDisplayOpacityPrimvar("vertex").Set(
                    Vt.FloatArray.FromNumpy(np.ascontiguousarray(c[:, 3]))
                )
        material = prim.get("material")
        mat = doc.array("materials")[material] if isinstance(material, int) else {}
        mesh.CreateDoubleSidedAttr(bool(mat.get("doubleSided", False)))
        wrinkled = self.wrinkle_index.get((ref.mesh, ref.primitive))
        if wrinkled is not None:
            self.wrinkle_primvars(mesh, ref)
            bound = UsdShade.Material(self.stage.GetPrimAtPath(self.wrinkled.material))
            if wrinkled[1] == node:  # the instance the render mesh reads
                self.wrinkled_paths[wrinkled[0]] = path
        else:
            bound = self.material(material if isinstance(material, int) else None)
        if bound is not None:
            UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(bound)
        skin = doc.array("nodes")[node].get("skin") if node is not None else None
        targets = prim.get("targets") or []
        rigid = None
        if node is not None and not isinstance(skin, int):
            if targets or self.joint_of(node) is not None:
                rigid = self.rigid_bind(node)
        if not isinstance(skin, int) and rigid is None:
            return
        binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
        if rigid is not None:
            skel, k, geom = rigid
            binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
            binding.CreateJointIndicesPrimvar(True, 1).Set(Vt.IntArray([k]))
            binding.CreateJointWeightsPrimvar(True, 1).Set(Vt.FloatArray([1.0]))
            binding.CreateGeomBindTransformAttr(gf_matrix(geom))
        if targets:
            skel = rigid[0] if rigid is not None else self.skeleton(int(skin))
            info = self.skel_info[str(skel.GetPath())]
            if node is not None:
                info.morph_nodes.setdefault(node, doc.target_names(ref.mesh))
            if wrinkled is not None and all(
                s.GetPath() != skel.GetPath() for s in self.morph_skeletons
            ):
                self.morph_skeletons.append(skel)
        if isinstance(skin, int):
            skel = self.skeleton(skin)
            binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
            sets = [k for k in range(8) if f"JOINTS_{k}" in attrs and f"WEIGHTS_{k}" in attrs]
            j = np.concatenate(
                [doc.accessor(attrs[f"JOINTS_{k}"], normalize=False) for k in sets], 1
            ).astype(np.int64)
            w = np.concatenate([doc.accessor(attrs[f"WEIGHTS_{k}"]) for k in sets], 1)
            w = np.asarray(w, np.float32)
            j = np.where(w > 0, j, 0).astype(np.int32)
            binding.CreateJointIndicesPrimvar(False, j.shape[1]).Set(
                Vt.IntArray.FromNumpy(np.ascontiguousarray(j.reshape(-1)))
            )
            binding.CreateJointWeightsPrimvar(False, j.shape[1]).Set(
                Vt.FloatArray.FromNumpy(np.ascontiguousarray(w.reshape(-1)))
            )
            binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
        if targets:
            names = doc.target_names(ref.mesh) or [f"target_{t}" for t in range(len(targets))]
            shape_names = Names()
            tokens, paths = [], []
            for t, target in enumerate(targets):
                tok = shape_names(path, names[t] if t < len(names) else f"target_{t}")
                bs = UsdSkel.BlendShape.Define(self.stage, path.AppendChild(tok))
                zero = np.zeros_like(pts)
                d = doc.accessor(target["POSITION"]) if "POSITION" in target else zero
                bs.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(d, np.float32)))
                if "NORMAL" in target:
                    dn = np.ascontiguousarray(doc.accessor(target["NORMAL"]), np.float32)
                    bs.CreateNormalOffsetsAttr(Vt.Vec3fArray.FromNumpy(dn))
                tokens.append(tok)
                paths.append(bs.GetPath())
            binding.CreateBlendShapesAttr(Vt.TokenArray(tokens))
            binding.CreateBlendShapeTargetsRel().SetTargets(paths)

    def unplaced(self) -> None:
        """Wrinkled primitives no scene node instances (a mesh outside the scene): below
        ``Scene/Unplaced`` in the space the render mesh reads them in (noted)."""
        from pxr import UsdGeom  # deferred: usd-core, USD only

        for k, r in enumerate(self.wrinkled.refs):
            if k in self.wrinkled_paths:
                continue
            holder = self.root.AppendChild("Unplaced")
            if not self.stage.GetPrimAtPath(holder):
                UsdGeom.Xform.Define(self.stage, holder)
            node = self.wrinkle_index[(r.mesh, r.primitive)][1]
            self.wrinkle_index[(r.mesh, r.primitive)] = (k, node)
            self.mesh(holder, self.doc.mesh_name(r.mesh), r, node)
            self.notes.append(
                f"USD: wrinkled primitive {r.pointer} is in no scene: written below "
                f"{holder} in its mesh's space"
            )

    # -- nodes -------------------------------------------------------------------------------
    def node(self, parent: Any, i: int, seen: set[int]) -> None:
        from pxr import UsdGeom  # deferred: usd-core, USD only

        if i in seen or not 0 <= i < len(self.doc.array("nodes")):
            return
        seen.add(i)
        doc = self.doc
        n = doc.array("nodes")[i]
        name = doc.node_name(i)
        path = parent.AppendChild(self.names(parent, name))
        xf = UsdGeom.Xform.Define(self.stage, path)
        if path.name != name:  # the glTF name where it is no USD identifier ('Foot.L')
            xf.GetPrim().SetDisplayName(name)
        op = xf.AddTransformOp()
        if i in self.xform_animated:  # its value is the animation variants' (usd_animation)
            self.xform_paths[i] = path
        else:
            op.Set(gf_matrix(node_matrix(n)))
        if isinstance(n.get("mesh"), int):
            mi = int(n["mesh"])
            prims = doc.array("meshes")[mi].get("primitives", [])
            skinned = isinstance(n.get("skin"), int)
            holder = self.root.AppendChild("Skinned") if skinned else path
            if skinned and not self.stage.GetPrimAtPath(holder):
                UsdGeom.Xform.Define(self.stage, holder)
            for k in range(len(prims)):
                ref = PrimitiveRef(mi, k, prims[k].get("material"))
                label = doc.mesh_name(mi) if not skinned else name
                self.mesh(holder, label if len(prims) == 1 else f"{label}_{k}", ref, i)
        if isinstance(n.get("camera"), int):
            self.camera(path, int(n["camera"]))
        if "KHR_lights_punctual" in (n.get("extensions") or {}):
            self.notes.append(
                f"USD: node {name!r} holds a KHR_lights_punctual light: not carried (glTF's "
                "photometric units have no agreed UsdLux mapping; kept in the glTF)"
            )
        for c in n.get("children", []):
            self.node(path, int(c), seen)

    def camera(self, parent: Any, index: int) -> None:
        """A glTF camera as a UsdGeom.Camera below its node's Xform (both look down -Z, +Y
        up). Perspective: focal length 50 (tenths of a unit, USD's convention) and the vertical
        aperture that gives ``yfov``, the horizontal one by ``aspectRatio`` (1 when the glTF
        leaves it to the viewport, noted); orthographic: apertures ``2 xmag``, ``2 ymag``
        (in tenths of a unit); clipping ``znear`` .. ``zfar`` (1e6 when infinite)."""
        from pxr import Gf, UsdGeom  # deferred: usd-core, USD only

        cams = self.doc.array("cameras")
        if not 0 <= index < len(cams):
            return
        c = cams[index]
        cam = UsdGeom.Camera.Define(self.stage, parent.AppendChild(self.names(parent, "Camera")))
        if c.get("type") == "orthographic":
            o = c.get("orthographic") or {}
            cam.CreateProjectionAttr(UsdGeom.Tokens.orthographic)
            cam.CreateHorizontalApertureAttr(float(2 * 10 * float(o.get("xmag", 1.0))))
            cam.CreateVerticalApertureAttr(float(2 * 10 * float(o.get("ymag", 1.0))))
            near, far = float(o.get("znear", 0.0)), float(o.get("zfar", 1e6))
        else:
            p = c.get("perspective") or {}
            focal = 50.0
            vertical = 2 * focal * float(np.tan(float(p.get("yfov", 0.8)) / 2))
            aspect = p.get("aspectRatio")
            if aspect is None:
                self.notes.append(
                    f"USD: camera {index} leaves its aspect ratio to the viewport: square "
                    "aperture written"
                )
            cam.CreateProjectionAttr(UsdGeom.Tokens.perspective)
            cam.CreateFocalLengthAttr(focal)
            cam.CreateVerticalApertureAttr(vertical)
            cam.CreateHorizontalApertureAttr(vertical * float(aspect or 1.0))
            near, far = float(p.get("znear", 0.01)), float(p.get("zfar", 1e6))
        cam.CreateClippingRangeAttr(Gf.Vec2f(near, far))


def wrinkled_prims(
    stage: Any, pkg: WrinklePackage, refs: tuple[PrimitiveRef, ...]
) -> WrinkledPrims:
    """What binds the package's wrinkled primitives in a stage :func:`~wrinklepipe.io.
    usd_write.build_stage` made (``with_mesh=False``): its wrinkle material, the morph names
    and the first curve's morph weights at the stage's time codes."""
    material = stage.GetDefaultPrim().GetPath().AppendPath("Looks/skin")
    curve = None
    c = pkg.curves[0] if pkg.curves else None
    if c is not None and c.morph_weights is not None:
        fps = stage.GetTimeCodesPerSecond()
        codes = np.asarray(c.times, np.float32).astype(np.float64) * fps
        curve = (codes, np.asarray(c.morph_weights, np.float32))
    return WrinkledPrims(
        tuple(refs), material, tuple(pkg.mesh.morph_names), curve, str(pkg.mesh.name)
    )


def add_scene(
    stage: Any,
    root: Any,
    doc: Document,
    wrinkled: WrinkledPrims,
    texture_dir: str,
    png_level: int = DEFAULT_PNG_LEVEL,
) -> tuple[dict[str, bytes], list[str]]:
    """Add ``doc``'s scene below ``root/Scene``, its wrinkled primitives bound to the wrinkle
    material (which lists their paths in ``wrinkle:meshes``, the package's order); return the
    image files it references ``{relative path: bytes}`` (a transcoded image: a PNG at zlib
    ``png_level``) and notes (see the module doc)."""
    from pxr import Sdf, UsdGeom, UsdSkel, Vt  # deferred: usd-core, USD only

    scene_path = root.AppendChild("Scene")
    if stage.GetPrimAtPath(root).IsA(UsdSkel.Root):
        UsdGeom.Xform.Define(stage, scene_path)
    else:
        UsdSkel.Root.Define(stage, scene_path)
    s = _Scene(stage, scene_path, doc, texture_dir, wrinkled, png_level)
    scenes = doc.array("scenes")
    which = doc.gltf.get("scene", 0)
    if scenes and isinstance(which, int) and 0 <= which < len(scenes):
        roots = [int(r) for r in scenes[which].get("nodes", [])]
    else:
        children = {c for n in doc.array("nodes") for c in n.get("children", [])}
        roots = [i for i in range(len(doc.array("nodes"))) if i not in children]
    seen: set[int] = set()
    for r in roots:
        s.node(scene_path, r, seen)
    s.unplaced()
    for info in s.skel_info.values():  # the animation source is a variant's choice
        UsdSkel.BindingAPI.Apply(info.skel.GetPrim())
    s.notes += add_animations(
        stage,
        scene_path,
        doc,
        list(s.skel_info.values()),
        s.worlds,
        s.xform_paths,
        s.wrinkle_morphs(),
    )
    order = stage.GetPrimAtPath(wrinkled.material).CreateAttribute(
        SCENE_MESHES, Sdf.ValueTypeNames.StringArray
    )
    order.SetCustom(True)
    order.Set(Vt.StringArray([str(s.wrinkled_paths[k]) for k in range(len(wrinkled.refs))]))
    if wrinkled.mesh_name:
        named = stage.GetPrimAtPath(wrinkled.material).CreateAttribute(
            SCENE_MESH_NAME, Sdf.ValueTypeNames.String
        )
        named.SetCustom(True)
        named.Set(wrinkled.mesh_name)
    return s.looks.files, s.looks.notes + s.notes
