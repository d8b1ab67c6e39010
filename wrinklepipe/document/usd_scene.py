"""The whole glTF source scene in the USD output: every part the wrinkle layer does not hold.

The USD layer convert writes keeps its wrinkle prims as they are (``/NAME/MESH`` with the
wrinkled primitives at their rest pose, ``/NAME/Looks/skin`` with ``WrinkleMapsAPI``:
:mod:`wrinklepipe.io.usd_write`); for a glTF source, :func:`add_scene` adds the rest of the
character below ``/NAME/Scene``::

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
      Looks/<material>           UsdPreviewSurface per glTF material: base colour (factor,
                                 texture, alpha), metallic / roughness, normal, occlusion,
                                 emissive; the images copied byte for byte (PNG, JPEG)

What USD's preview surface cannot hold is said in a note (KTX2 / WebP images, texture
transforms, node animations); the glTF output beside it keeps everything.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wrinklepipe.document.model import Document, PrimitiveRef
from wrinklepipe.document.scene import node_world_matrices, primitive_triangles
from wrinklepipe.document.write import mime_type
from wrinklepipe.io.mesh_gltf import _node_matrix  # the one glTF TRS -> matrix

_EXT = {"image/png": "png", "image/jpeg": "jpg"}


class _Names:
    """Valid, unique USD identifiers per parent path."""

    def __init__(self) -> None:
        self.taken: dict[str, set[str]] = {}

    def __call__(self, parent: Any, name: str) -> str:
        from pxr import Tf  # deferred: usd-core, USD only

        base = Tf.MakeValidIdentifier(name or "unnamed")
        used = self.taken.setdefault(str(parent), set())
        tok, k = base, 1
        while tok in used:
            k += 1
            tok = f"{base}_{k}"
        used.add(tok)
        return tok


def _gf(m: np.ndarray) -> Any:
    from pxr import Gf  # deferred: usd-core, USD only

    return Gf.Matrix4d(np.asarray(m, np.float64).T.tolist())  # Gf: row vectors


class _Scene:
    def __init__(self, stage: Any, root: Any, doc: Document, texture_dir: str) -> None:
        self.stage, self.root, self.doc = stage, root, doc
        self.names = _Names()
        self.tdir = texture_dir
        self.files: dict[str, bytes] = {}
        self.notes: list[str] = []
        self.materials: dict[int, Any] = {}
        self.images: dict[int, str | None] = {}
        self.skeletons: dict[int, Any] = {}
        self.worlds = node_world_matrices(doc)

    # -- materials ---------------------------------------------------------------------------
    def image_path(self, texture: int) -> str | None:
        doc = self.doc
        tex = doc.array("textures")[texture] if 0 <= texture < len(doc.array("textures")) else {}
        src = tex.get("source")
        if not isinstance(src, int):
            self.notes.append(f"USD: texture {texture} has no PNG/JPEG source; left out")
            return None
        if src not in self.images:
            data = doc.image_bytes(src)
            img = doc.array("images")[src]
            ext = _EXT.get(mime_type(data, str(img.get("uri", ""))))
            if ext is None:
                self.notes.append(
                    f"USD: image {src} ({img.get('name', '')!r}) is not PNG or JPEG; "
                    "UsdPreviewSurface cannot read it: left out of the USD (kept in the glTF)"
                )
                self.images[src] = None
            else:
                stem = self.names("images", str(img.get("name") or f"image_{src}"))
                rel = f"{self.tdir}/source/{stem}.{ext}" if self.tdir else f"source/{stem}.{ext}"
                self.files[rel] = data
                self.images[src] = rel
        return self.images[src]

    def material(self, index: int | None) -> Any:
        from pxr import Gf, Sdf, UsdGeom, UsdShade  # deferred: usd-core, USD only

        if index is None:
            return None
        if index in self.materials:
            return self.materials[index]
        doc = self.doc
        m = doc.array("materials")[index]
        looks = self.root.AppendChild("Looks")
        if not self.stage.GetPrimAtPath(looks):
            UsdGeom.Scope.Define(self.stage, looks)
        mat = UsdShade.Material.Define(
            self.stage, looks.AppendChild(self.names(looks, doc.material_name(index)))
        )
        surf = UsdShade.Shader.Define(self.stage, mat.GetPath().AppendChild("Surface"))
        surf.CreateIdAttr("UsdPreviewSurface")
        mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
        readers: dict[int, Any] = {}

        def reader(tc: int) -> Any:
            if tc not in readers:
                r = UsdShade.Shader.Define(self.stage, mat.GetPath().AppendChild(f"StReader{tc}"))
                r.CreateIdAttr("UsdPrimvarReader_float2")
                r.CreateInput("varname", Sdf.ValueTypeNames.String).Set(
                    "st" if tc == 0 else f"st{tc}"
                )
                r.CreateOutput("result", Sdf.ValueTypeNames.Float2)
                readers[tc] = r
            return readers[tc]

        def texture(key: str, info: Any, color_space: str, scale: tuple, bias: tuple) -> Any:
            if not isinstance(info, dict) or not isinstance(info.get("index"), int):
                return None
            path = self.image_path(info["index"])
            if path is None:
                return None
            if "KHR_texture_transform" in (info.get("extensions") or {}):
                self.notes.append(
                    f"USD: /materials/{index}/{key} has KHR_texture_transform; not carried "
                    "into the USD preview surface (kept in the glTF)"
                )
            tex = UsdShade.Shader.Define(self.stage, mat.GetPath().AppendChild(key))
            tex.CreateIdAttr("UsdUVTexture")
            tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(f"./{path}"))
            tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
                reader(int(info.get("texCoord", 0))).ConnectableAPI(), "result"
            )
            tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(color_space)
            tex.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*scale))
            tex.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*bias))
            for out, kind in (("rgb", "Float3"), ("r", "Float"), ("g", "Float"), ("b", "Float")):
                tex.CreateOutput(out, getattr(Sdf.ValueTypeNames, kind))
            tex.CreateOutput("a", Sdf.ValueTypeNames.Float)
            return tex

        pbr = m.get("pbrMetallicRoughness") or {}
        f = [float(x) for x in pbr.get("baseColorFactor", [1, 1, 1, 1])]
        base = texture("baseColorTexture", pbr.get("baseColorTexture"), "sRGB", tuple(f), (0,) * 4)
        mode = m.get("alphaMode", "OPAQUE")
        if base is not None:
            surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(
                base.ConnectableAPI(), "rgb"
            )
            if mode != "OPAQUE":
                surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(
                    base.ConnectableAPI(), "a"
                )
        else:
            surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*f[:3]))
            if mode != "OPAQUE":
                surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(f[3])
        if mode == "MASK":
            surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(
                float(m.get("alphaCutoff", 0.5))
            )
        metal, rough = float(pbr.get("metallicFactor", 1.0)), float(pbr.get("roughnessFactor", 1.0))
        mr = texture(
            "metallicRoughnessTexture",
            pbr.get("metallicRoughnessTexture"),
            "raw",
            (1, rough, metal, 1),
            (0,) * 4,
        )
        for name, value, channel in (("metallic", metal, "b"), ("roughness", rough, "g")):
            inp = surf.CreateInput(name, Sdf.ValueTypeNames.Float)
            if mr is not None:
                inp.ConnectToSource(mr.ConnectableAPI(), channel)
            else:
                inp.Set(value)
        nt = m.get("normalTexture")
        s = float(nt.get("scale", 1.0)) if isinstance(nt, dict) else 1.0
        normal = texture("normalTexture", nt, "raw", (2 * s, 2 * s, 2, 1), (-s, -s, -1, 0))
        if normal is not None:
            surf.CreateInput("normal", Sdf.ValueTypeNames.Normal3f).ConnectToSource(
                normal.ConnectableAPI(), "rgb"
            )
        occ = texture("occlusionTexture", m.get("occlusionTexture"), "raw", (1,) * 4, (0,) * 4)
        if occ is not None:
            surf.CreateInput("occlusion", Sdf.ValueTypeNames.Float).ConnectToSource(
                occ.ConnectableAPI(), "r"
            )
        e = [float(x) for x in m.get("emissiveFactor", [0, 0, 0])]
        strength = (m.get("extensions") or {}).get("KHR_materials_emissive_strength", {})
        k = float(strength.get("emissiveStrength", 1.0)) if isinstance(strength, dict) else 1.0
        e = [x * k for x in e]
        em = texture("emissiveTexture", m.get("emissiveTexture"), "sRGB", (*e, 1), (0,) * 4)
        emissive = surf.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f)
        if em is not None:
            emissive.ConnectToSource(em.ConnectableAPI(), "rgb")
        elif any(e):
            emissive.Set(Gf.Vec3f(*e))
        self.materials[index] = mat
        return mat

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
        names = _Names()
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
            world = self.worlds.get(j, _node_matrix(nodes[j]))
            rest.append(world if p is None else np.linalg.inv(self.worlds[p]) @ world)
        if "inverseBindMatrices" in s:
            ibm = doc.accessor(s["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
        else:
            ibm = np.tile(np.eye(4), (len(joints), 1, 1))
        holder = self.root.AppendChild("Skeletons")
        if not self.stage.GetPrimAtPath(holder):
            UsdGeom.Scope.Define(self.stage, holder)
        name = str(s.get("name") or f"skin_{skin}")
        skel = UsdSkel.Skeleton.Define(self.stage, holder.AppendChild(self.names(holder, name)))
        skel.CreateJointsAttr(Vt.TokenArray([token(j) for j in joints]))
        skel.CreateRestTransformsAttr(Vt.Matrix4dArray([_gf(r) for r in rest]))
        bind = np.linalg.inv(np.asarray(ibm, np.float64))
        skel.CreateBindTransformsAttr(Vt.Matrix4dArray([_gf(b) for b in bind]))
        a = skel.GetPrim().CreateAttribute("wrinkle:jointNames", Sdf.ValueTypeNames.StringArray)
        a.SetCustom(True)
        a.Set(Vt.StringArray([doc.node_name(j) for j in joints]))
        self.skeletons[skin] = skel
        return skel

    # -- meshes ------------------------------------------------------------------------------
    def mesh(self, parent: Any, name: str, ref: PrimitiveRef, node: int) -> None:
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
        bound = self.material(material if isinstance(material, int) else None)
        if bound is not None:
            UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(bound)
        skin = doc.array("nodes")[node].get("skin")
        targets = prim.get("targets") or []
        if not isinstance(skin, int) and not targets:
            return
        binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
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
            shape_names = _Names()
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

    # -- nodes -------------------------------------------------------------------------------
    def node(self, parent: Any, i: int, skip: set[tuple[int, int]], seen: set[int]) -> None:
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
        xf.AddTransformOp().Set(_gf(_node_matrix(n)))
        if isinstance(n.get("mesh"), int):
            mi = int(n["mesh"])
            prims = doc.array("meshes")[mi].get("primitives", [])
            skinned = isinstance(n.get("skin"), int)
            holder = self.root.AppendChild("Skinned") if skinned else path
            if skinned and not self.stage.GetPrimAtPath(holder):
                UsdGeom.Xform.Define(self.stage, holder)
            for k in range(len(prims)):
                if (mi, k) in skip:
                    continue
                ref = PrimitiveRef(mi, k, prims[k].get("material"))
                label = doc.mesh_name(mi) if not skinned else name
                self.mesh(holder, label if len(prims) == 1 else f"{label}_{k}", ref, i)
        for c in n.get("children", []):
            self.node(path, int(c), skip, seen)


def add_scene(
    stage: Any, root: Any, doc: Document, skip: set[tuple[int, int]], texture_dir: str
) -> tuple[dict[str, bytes], list[str]]:
    """Add ``doc``'s scene, less the primitives ``skip`` (``(mesh, primitive)``: the wrinkled
    ones, which the wrinkle layer holds), below ``root/Scene``; return the image files it
    references ``{relative path: bytes}`` and notes (see the module doc)."""
    from pxr import UsdGeom, UsdSkel  # deferred: usd-core, USD only

    scene_path = root.AppendChild("Scene")
    if stage.GetPrimAtPath(root).IsA(UsdSkel.Root):
        UsdGeom.Xform.Define(stage, scene_path)
    else:
        UsdSkel.Root.Define(stage, scene_path)
    s = _Scene(stage, scene_path, doc, texture_dir)
    scenes = doc.array("scenes")
    which = doc.gltf.get("scene", 0)
    if scenes and isinstance(which, int) and 0 <= which < len(scenes):
        roots = [int(r) for r in scenes[which].get("nodes", [])]
    else:
        children = {c for n in doc.array("nodes") for c in n.get("children", [])}
        roots = [i for i in range(len(doc.array("nodes"))) if i not in children]
    seen: set[int] = set()
    for r in roots:
        s.node(scene_path, r, skip, seen)
    if doc.array("animations"):
        s.notes.append(
            f"USD: the {len(doc.array('animations'))} glTF animation(s) of the source are not "
            "carried into the USD scene (kept in the glTF); the wrinkle weights are"
        )
    return s.files, s.notes
