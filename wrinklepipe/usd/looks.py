"""The glTF source's materials in its USD: a UsdPreviewSurface per glTF material.

:class:`Looks` writes ``Looks/<material>`` below the scene (see
:mod:`wrinklepipe.usd.scene`): base colour (factor, texture, alpha, cutoff), metallic /
roughness, normal (with its scale), occlusion, emissive (with
``KHR_materials_emissive_strength``), ``KHR_materials_clearcoat`` (clearcoat and its roughness,
factors and textures) and ``KHR_materials_ior``; other material extensions are named in a
note. Images: a PNG / JPEG ``source`` copied byte for byte into ``textures/source/``; a KTX2
(Basis Universal, ``KHR_texture_basisu``) or WebP (``EXT_texture_webp``) image, which
UsdPreviewSurface cannot read, transcoded to PNG (noted). A ``KHR_texture_transform`` becomes
a ``UsdTransform2d`` between the primvar reader and the texture (:func:`usd_texture_transform`;
its ``texCoord`` honoured).
"""

from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np

from wrinklepipe.errors import InputError, plain_reason
from wrinklepipe.gltf.document import Document
from wrinklepipe.gltf.images import image_pixels, texture_source
from wrinklepipe.gltf.write import mime_type
from wrinklepipe.io.png import DEFAULT_PNG_LEVEL, png_bytes
from wrinklepipe.names import unique_name

_EXT = {"image/png": "png", "image/jpeg": "jpg"}

#: Material extensions the preview surface carries (the others are named in a note).
CARRIED_EXTENSIONS = {
    "KHR_materials_emissive_strength",
    "KHR_materials_clearcoat",
    "KHR_materials_ior",
}


def usd_texture_transform(xf: dict[str, Any]) -> tuple[tuple[float, float], float, tuple]:
    """A glTF ``KHR_texture_transform`` (``uv' = offset + R(rotation) scale uv``, v down, R
    turning ``(u, v)`` to ``(c u + s v, -s u + c v)``) as ``UsdTransform2d`` inputs on USD's
    ``st = (u, 1 - v)``: (scale, rotation in degrees counter-clockwise, translation); USD
    applies scale, then the rotation, then the translation. Flipping v conjugates R into the
    ordinary counter-clockwise rotation by the same angle and moves the origin:
    ``translation = (ox + s sy, 1 - oy - c sy)``."""
    ox, oy = (float(x) for x in xf.get("offset", [0.0, 0.0]))
    sx, sy = (float(x) for x in xf.get("scale", [1.0, 1.0]))
    r = float(xf.get("rotation", 0.0))
    c, s = float(np.cos(r)), float(np.sin(r))
    return (sx, sy), float(np.degrees(r)), (ox + s * sy, 1.0 - oy - c * sy)


class Names:
    """Valid, unique USD identifiers per parent path."""

    def __init__(self) -> None:
        self.taken: dict[str, set[str]] = {}

    def __call__(self, parent: Any, name: str) -> str:
        from pxr import Tf  # deferred: usd-core, USD only

        base = Tf.MakeValidIdentifier(name or "unnamed")
        return unique_name(base, self.taken.setdefault(str(parent), set()))


def gf_matrix(m: np.ndarray) -> Any:
    """A 4x4 (column vectors) as a ``Gf.Matrix4d`` (USD: row vectors, so transposed)."""
    from pxr import Gf  # deferred: usd-core, USD only

    return Gf.Matrix4d(np.asarray(m, np.float64).T.tolist())  # Gf: row vectors


class Looks:
    """The scene's UsdPreviewSurface materials and the image files they reference
    (``files``: ``{path relative to the layer: bytes}``; ``notes``: what was transcoded or left
    out)."""

    def __init__(
        self,
        stage: Any,
        root: Any,
        doc: Document,
        texture_dir: str,
        names: Names,
        png_level: int = DEFAULT_PNG_LEVEL,
    ):
        self.stage, self.root, self.doc = stage, root, doc
        self.png_level = png_level
        self.names = names
        self.tdir = texture_dir
        self.files: dict[str, bytes] = {}
        self.notes: list[str] = []
        self.materials: dict[int, Any] = {}
        self.images: dict[int, str | None] = {}

    def image_path(self, texture: int) -> str | None:
        """The file a texture's image is in for the USD (relative to the layer): its PNG/JPEG
        ``source`` byte for byte; else its KHR_texture_basisu / EXT_texture_webp image (or a
        source in another format) transcoded to PNG (noted); None when none decodes."""
        doc = self.doc
        tex = doc.array("textures")[texture] if 0 <= texture < len(doc.array("textures")) else {}
        plain = tex.get("source")
        if isinstance(plain, int) and self.mime(plain) in _EXT:
            src = plain
        else:
            try:
                src = texture_source(doc, texture)
            except InputError:
                self.notes.append(f"USD: texture {texture} has no source image; left out")
                return None
        if src not in self.images:
            data = doc.image_bytes(src)
            img = doc.array("images")[src]
            mime = self.mime(src)
            ext = _EXT.get(mime)
            if ext is None:
                try:
                    data, ext = png_bytes(image_pixels(doc, src), self.png_level), "png"
                except InputError as exc:
                    self.notes.append(
                        f"USD: image {src} ({img.get('name', '')!r}, {mime}) does not decode "
                        f"({plain_reason(exc)}): left out of the USD (kept in the glTF)"
                    )
                    self.images[src] = None
                    return None
                self.notes.append(
                    f"USD: image {src} ({img.get('name', '')!r}) is {mime}, which "
                    "UsdPreviewSurface cannot read: transcoded to PNG for the USD (the glTF "
                    "keeps it as it is)"
                )
            stem = self.names("images", str(img.get("name") or f"image_{src}"))
            rel = f"{self.tdir}/source/{stem}.{ext}" if self.tdir else f"source/{stem}.{ext}"
            self.files[rel] = data
            self.images[src] = rel
        return self.images[src]

    def mime(self, image: int) -> str:
        img = self.doc.array("images")[image]
        return mime_type(self.doc.image_bytes(image), str(img.get("uri", "")))

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
        texture = partial(self._texture, mat, {})  # one st reader per texCoord

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
        exts = m.get("extensions") or {}
        cc = exts.get("KHR_materials_clearcoat")
        if isinstance(cc, dict):  # UsdPreviewSurface's clearcoat layer (its normal: none)
            for key, inp, channel in (
                ("clearcoat", "clearcoat", "r"),
                ("clearcoatRoughness", "clearcoatRoughness", "g"),
            ):
                f = float(cc.get(f"{key}Factor", 0.0))
                tex = texture(f"{key}Texture", cc.get(f"{key}Texture"), "raw", (f,) * 4, (0,) * 4)
                value = surf.CreateInput(inp, Sdf.ValueTypeNames.Float)
                if tex is not None:
                    value.ConnectToSource(tex.ConnectableAPI(), channel)
                else:
                    value.Set(f)
            if "clearcoatNormalTexture" in cc:
                self.notes.append(
                    f"USD: /materials/{index} clearcoatNormalTexture has no UsdPreviewSurface "
                    "input; left out (kept in the glTF)"
                )
        ior = exts.get("KHR_materials_ior")
        if isinstance(ior, dict):
            surf.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(float(ior.get("ior", 1.5)))
        other = sorted(set(exts) - CARRIED_EXTENSIONS)
        if other:
            self.notes.append(
                f"USD: material {doc.material_name(index)!r} has {', '.join(other)}, which "
                "UsdPreviewSurface cannot hold: not carried (kept in the glTF)"
            )
        self.materials[index] = mat
        return mat

    def _reader(self, mat: Any, readers: dict[int, Any], tc: int) -> Any:
        """The material's primvar reader of texture coordinate set ``tc`` (made once)."""
        from pxr import Sdf, UsdShade  # deferred: usd-core, USD only

        if tc not in readers:
            r = UsdShade.Shader.Define(self.stage, mat.GetPath().AppendChild(f"StReader{tc}"))
            r.CreateIdAttr("UsdPrimvarReader_float2")
            r.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st" if tc == 0 else f"st{tc}")
            r.CreateOutput("result", Sdf.ValueTypeNames.Float2)
            readers[tc] = r
        return readers[tc]

    def _texture(
        self,
        mat: Any,
        readers: dict[int, Any],
        key: str,
        info: Any,
        color_space: str,
        scale: tuple,
        bias: tuple,
    ) -> Any:
        """A UsdUVTexture of the material for a glTF texture info (its texCoord and
        KHR_texture_transform through a UsdTransform2d), or None when there is none."""
        from pxr import Gf, Sdf, UsdShade  # deferred: usd-core, USD only

        if not isinstance(info, dict) or not isinstance(info.get("index"), int):
            return None
        path = self.image_path(info["index"])
        if path is None:
            return None
        tc = int(info.get("texCoord", 0))
        xf = (info.get("extensions") or {}).get("KHR_texture_transform")
        st = None
        if isinstance(xf, dict):
            tc = int(xf.get("texCoord", tc))
            st = UsdShade.Shader.Define(self.stage, mat.GetPath().AppendChild(f"{key}_uv"))
            st.CreateIdAttr("UsdTransform2d")
            st.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(
                self._reader(mat, readers, tc).ConnectableAPI(), "result"
            )
            uv_scale, degrees, uv_move = usd_texture_transform(xf)
            st.CreateInput("scale", Sdf.ValueTypeNames.Float2).Set(Gf.Vec2f(*uv_scale))
            st.CreateInput("rotation", Sdf.ValueTypeNames.Float).Set(degrees)
            st.CreateInput("translation", Sdf.ValueTypeNames.Float2).Set(Gf.Vec2f(*uv_move))
            st.CreateOutput("result", Sdf.ValueTypeNames.Float2)
        tex = UsdShade.Shader.Define(self.stage, mat.GetPath().AppendChild(key))
        tex.CreateIdAttr("UsdUVTexture")
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(f"./{path}"))
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
            (st or self._reader(mat, readers, tc)).ConnectableAPI(), "result"
        )
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(color_space)
        tex.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*scale))
        tex.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*bias))
        for out, kind in (("rgb", "Float3"), ("r", "Float"), ("g", "Float"), ("b", "Float")):
            tex.CreateOutput(out, getattr(Sdf.ValueTypeNames, kind))
        tex.CreateOutput("a", Sdf.ValueTypeNames.Float)
        return tex
