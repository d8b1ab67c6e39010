"""A generated multi-mesh avatar: what a studio's character looks like to the pipeline.

Deterministic (no randomness, fixed float32 data), small, and built here rather than committed:
:func:`avatar_glb_bytes` returns the GLB, :func:`write_avatar_source` writes it with a wrinkle
setup for its head material, :func:`avatar_source_dir` caches that folder
(``$WRINKLEPIPE_CACHE/avatar-vN-HASH``) and returns the manifest path.

The character (glTF +Y up, facing +Z, metres):

- 4 meshes, each its own skinned root node: ``Head`` (a lat-long ellipsoid with a front-centred
  cylindrical UV layout: its left, +X, at u > 0.5; morph targets ``browInnerUp``, ``jawOpen``,
  ``mouthSmile``), ``Eyes`` (two spheres), ``Teeth`` (an arc; morph target ``jawOpen``), ``Body``
  (torso and arms);
- 4 materials, each with a base-colour texture: ``Skin`` (also a normalTexture: the face's
  pore-scale base map, the wrinkle base when the manifest names none), ``Eye`` (emissive, with
  ``KHR_materials_emissive_strength``), ``Teeth``, ``Body`` (double-sided); 5 PNG images;
- one skin of 20 joints (Hips .. Head, eyes, jaw, arms, legs) bound in a T-pose, whose *rest*
  pose (the node TRS) is not the bind pose: arms lowered 40 degrees, head turned 10 degrees;
- an ``Idle`` animation (head rotation, brow morph weights), node extras, mesh target names.

The wrinkle setup (``manifest.toml``): ``material = "Skin"``, no ``base`` (the material's own
normalTexture), states ``stretch`` / ``compress`` (the base plus analytic ridges, whole-face
maps), masks ``brow_L`` / ``brow_R`` / ``mouth`` in the head's UV layout, an expression table and
a ``blendshapes`` driver reading ``browInnerUp`` and ``jawOpen``.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.atomic import write_files
from wrinklepipe.demo.source import cache_root
from wrinklepipe.gltf.package_write import glb_bytes
from wrinklepipe.io.png import png_bytes
from wrinklepipe.staging import output_lock

AVATAR_VERSION = 1
MAP_SIZE = 64
MASK_SIZE = 16

#: Joint name, parent, bind-pose world position (T-pose; bind rotations are the identity).
JOINTS: tuple[tuple[str, str | None, tuple[float, float, float]], ...] = (
    ("Hips", None, (0.0, 1.0, 0.0)),
    ("Spine", "Hips", (0.0, 1.1, 0.0)),
    ("Spine1", "Spine", (0.0, 1.25, 0.0)),
    ("Spine2", "Spine1", (0.0, 1.4, 0.0)),
    ("Neck", "Spine2", (0.0, 1.52, 0.0)),
    ("Head", "Neck", (0.0, 1.6, 0.0)),
    ("HeadTop", "Head", (0.0, 1.78, 0.0)),
    ("LeftEye", "Head", (0.032, 1.66, 0.075)),
    ("RightEye", "Head", (-0.032, 1.66, 0.075)),
    ("Jaw", "Head", (0.0, 1.6, 0.02)),
    ("LeftShoulder", "Spine2", (0.05, 1.45, 0.0)),
    ("LeftArm", "LeftShoulder", (0.18, 1.45, 0.0)),
    ("LeftForeArm", "LeftArm", (0.45, 1.45, 0.0)),
    ("LeftHand", "LeftForeArm", (0.7, 1.45, 0.0)),
    ("RightShoulder", "Spine2", (-0.05, 1.45, 0.0)),
    ("RightArm", "RightShoulder", (-0.18, 1.45, 0.0)),
    ("RightForeArm", "RightArm", (-0.45, 1.45, 0.0)),
    ("RightHand", "RightForeArm", (-0.7, 1.45, 0.0)),
    ("LeftUpLeg", "Hips", (0.1, 0.95, 0.0)),
    ("RightUpLeg", "Hips", (-0.1, 0.95, 0.0)),
)
JOINT_NAMES = tuple(j[0] for j in JOINTS)
#: Rest-pose rotations (axis, degrees) that make the rest pose differ from the bind pose.
REST_ROTATIONS = {
    "LeftArm": ((0.0, 0.0, 1.0), -40.0),
    "RightArm": ((0.0, 0.0, 1.0), 40.0),
    "Head": ((0.0, 1.0, 0.0), 10.0),
}
HEAD_CENTRE = (0.0, 1.66, 0.0)
HEAD_RADII = (0.08, 0.11, 0.09)
REGIONS = {  # UV boxes (u0, v0, u1, v1) on the head's layout, and sides
    "brow_L": ((0.5, 0.22, 0.62, 0.36), "left"),
    "brow_R": ((0.38, 0.22, 0.5, 0.36), "right"),
    "mouth": ((0.42, 0.58, 0.58, 0.7), "center"),
}


def _quat(axis: tuple[float, float, float], degrees: float) -> list[float]:
    a = math.radians(degrees) / 2
    x, y, z = (float(c) * math.sin(a) for c in axis)
    return [x, y, z, math.cos(a)]


# ------------------------------------------------------------------------------------------------
# geometry (numpy, no loops over vertices)


def _grid(nu: int, nv: int) -> np.ndarray:
    """Triangles of an (nv + 1) x (nu + 1) vertex grid, counter-clockwise seen from outside."""
    r, c = np.meshgrid(np.arange(nv), np.arange(nu), indexing="ij")
    a = r * (nu + 1) + c
    b, d = a + 1, a + nu + 1
    e = d + 1
    return np.concatenate([np.stack([a, d, b], -1), np.stack([b, d, e], -1)]).reshape(-1, 3)


def head_geometry(nu: int = 32, nv: int = 24) -> dict[str, np.ndarray]:
    """The head ellipsoid: positions, normals, UVs (front-centred), triangles, morph deltas."""
    u = np.linspace(0.0, 1.0, nu + 1)
    v = np.linspace(0.04, 0.96, nv + 1)
    uu, vv = np.meshgrid(u, v)
    phi = (uu - 0.5) * 2 * np.pi  # 0 at the front (+Z), +pi/2 at the character's left (+X)
    theta = vv * np.pi
    unit = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), np.sin(theta) * np.cos(phi)], -1)
    radii = np.asarray(HEAD_RADII)
    pos = unit * radii + np.asarray(HEAD_CENTRE)
    nrm = unit / radii
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    front = np.clip(np.cos(phi), 0.0, None)
    brow = np.exp(-(((vv - 0.29) / 0.06) ** 2)) * front
    jaw = np.clip((vv - 0.55) / 0.4, 0.0, 1.0) * front
    smile = np.exp(-(((vv - 0.64) / 0.05) ** 2)) * np.abs(np.sin(phi)) * front
    zero = np.zeros_like(pos)
    deltas = np.stack(
        [
            zero + np.stack([0 * brow, 0.006 * brow, 0 * brow], -1),
            zero + np.stack([0 * jaw, -0.02 * jaw, 0.004 * jaw], -1),
            zero + np.stack([0.004 * smile * np.sign(np.sin(phi)), 0.004 * smile, 0 * smile], -1),
        ]
    )
    return {
        "positions": pos.reshape(-1, 3),
        "normals": nrm.reshape(-1, 3),
        "uvs": np.stack([uu, vv], -1).reshape(-1, 2),
        "triangles": _grid(nu, nv),
        "deltas": deltas.reshape(3, -1, 3),
    }


def _sphere(centre: tuple[float, float, float], radius: float, n: int = 8) -> dict[str, Any]:
    u = np.linspace(0.0, 1.0, n + 1)
    v = np.linspace(0.05, 0.95, n + 1)
    uu, vv = np.meshgrid(u, v)
    phi, theta = (uu - 0.5) * 2 * np.pi, vv * np.pi
    unit = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), np.sin(theta) * np.cos(phi)], -1)
    return {
        "positions": (unit * radius + np.asarray(centre)).reshape(-1, 3),
        "normals": unit.reshape(-1, 3),
        "uvs": np.stack([uu, vv], -1).reshape(-1, 2),
        "triangles": _grid(n, n),
    }


def _cylinder(
    a: tuple[float, float, float], b: tuple[float, float, float], radius: float, n: int = 12
) -> dict[str, Any]:
    """An open cylinder from ``a`` to ``b`` (2 rings of ``n + 1`` vertices)."""
    a_, b_ = np.asarray(a), np.asarray(b)
    axis = (b_ - a_) / np.linalg.norm(b_ - a_)
    side = np.cross(axis, [0.0, 0.0, 1.0])
    if np.linalg.norm(side) < 1e-6:
        side = np.cross(axis, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    up = np.cross(side, axis)
    t = np.linspace(0.0, 1.0, n + 1) * 2 * np.pi
    ring = np.cos(t)[:, None] * side + np.sin(t)[:, None] * up  # [n + 1, 3]
    pos = np.concatenate([a_ + radius * ring, b_ + radius * ring])
    uvs = np.stack([np.tile(t / (2 * np.pi), 2), np.repeat([1.0, 0.0], n + 1)], -1)
    return {
        "positions": pos,
        "normals": np.concatenate([ring, ring]),
        "uvs": uvs,
        "triangles": _grid(n, 1)[:, [0, 2, 1]],
    }


def _join(parts: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    offsets = np.cumsum([0] + [len(p["positions"]) for p in parts[:-1]])
    out["triangles"] = np.concatenate([p["triangles"] + o for p, o in zip(parts, offsets)])
    return out


def _skin_to(pos: np.ndarray, joints: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """JOINTS_0 / WEIGHTS_0 binding each vertex to its two nearest of ``joints`` (inverse
    distance weights; rows sum to 1 exactly in float32 terms of the sum check)."""
    centres = np.array([JOINTS[JOINT_NAMES.index(j)][2] for j in joints])
    d = np.linalg.norm(pos[:, None, :] - centres[None], axis=-1)
    order = np.argsort(d, axis=1, kind="stable")[:, :2]
    near = np.take_along_axis(d, order, axis=1)
    w = 1.0 / np.maximum(near, 1e-4)
    w = (w / w.sum(axis=1, keepdims=True)).astype(np.float32)
    w[:, 1] = np.float32(1.0) - w[:, 0]
    idx = np.array([JOINT_NAMES.index(j) for j in joints])[order]
    jw = np.zeros((len(pos), 4), np.uint8)
    jw[:, :2] = idx
    ww = np.zeros((len(pos), 4), np.float32)
    ww[:, :2] = w
    return jw, ww


def _texture(rgb: tuple[int, int, int], size: int = 16) -> bytes:
    """A small deterministic texture: a colour with a checker modulation."""
    y, x = np.mgrid[0:size, 0:size]
    check = ((x // 4 + y // 4) % 2).astype(np.float64)
    px = np.asarray(rgb, np.float64)[None, None] * (0.85 + 0.15 * check[..., None])
    return png_bytes(np.clip(np.rint(px), 0, 255).astype(np.uint8))


def skin_normals(size: int = MAP_SIZE) -> np.ndarray:
    """The Skin material's normal map as unit normals (OpenGL: +Y is up the image, -v): the
    bumps of ``h = A sin(2 pi 11 u) sin(2 pi 7 v)``, n ~ (-dh/du, +dh/dv, 1), slopes <= 0.15."""
    c = (np.arange(size) + 0.5) / size
    uu, vv = np.meshgrid(c, c)
    a, b, amp = 2 * np.pi * 11, 2 * np.pi * 7, 0.15 / (2 * np.pi * 11)
    dx = -amp * a * np.cos(a * uu) * np.sin(b * vv)
    dy = amp * b * np.sin(a * uu) * np.cos(b * vv)
    n = np.stack([dx, dy, np.ones_like(dx)], -1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def _encode(normals: np.ndarray) -> np.ndarray:
    return np.clip(np.rint((0.5 + 0.5 * normals) * 255), 0, 255).astype(np.uint8)


# ------------------------------------------------------------------------------------------------
# the document


class _Buffer:
    def __init__(self) -> None:
        self.chunks: list[bytes] = []
        self.views: list[dict[str, Any]] = []
        self.accessors: list[dict[str, Any]] = []
        self.length = 0

    def view(self, data: bytes, target: int | None = None) -> int:
        pad = (-self.length) % 4
        self.chunks.append(b"\0" * pad + data)
        self.length += pad
        v: dict[str, Any] = {"buffer": 0, "byteLength": len(data)}
        if self.length:
            v["byteOffset"] = self.length
        if target is not None:
            v["target"] = target
        self.length += len(data)
        self.views.append(v)
        return len(self.views) - 1

    def accessor(
        self, a: np.ndarray, type_: str, target: int | None = None, minmax: bool = False
    ) -> int:
        comp = {np.float32: 5126, np.uint8: 5121, np.uint16: 5123, np.uint32: 5125}[a.dtype.type]
        acc: dict[str, Any] = {
            "bufferView": self.view(np.ascontiguousarray(a).tobytes(), target),
            "componentType": comp,
            "count": int(a.shape[0]),
            "type": type_,
        }
        if minmax:
            flat = a.reshape(a.shape[0], -1)
            acc["min"] = [float(x) for x in flat.min(axis=0)]
            acc["max"] = [float(x) for x in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def _primitive(
    buf: _Buffer, g: dict[str, Any], material: int, joints: list[str], targets: Any = None
) -> dict[str, Any]:
    f32 = np.float32
    pos = g["positions"].astype(f32)
    jw, ww = _skin_to(g["positions"], joints)
    attrs = {
        "POSITION": buf.accessor(pos, "VEC3", 34962, minmax=True),
        "NORMAL": buf.accessor(g["normals"].astype(f32), "VEC3", 34962),
        "TEXCOORD_0": buf.accessor(g["uvs"].astype(f32), "VEC2", 34962),
        "JOINTS_0": buf.accessor(jw, "VEC4", 34962),
        "WEIGHTS_0": buf.accessor(ww, "VEC4", 34962),
    }
    idx = g["triangles"].reshape(-1).astype(np.uint16)
    prim: dict[str, Any] = {
        "attributes": attrs,
        "indices": buf.accessor(idx, "SCALAR", 34963),
        "material": material,
    }
    if targets is not None:
        prim["targets"] = [
            {"POSITION": buf.accessor(d.astype(f32), "VEC3", 34962, minmax=True)} for d in targets
        ]
    return prim


def avatar_document() -> tuple[dict[str, Any], bytes]:
    """The avatar's glTF JSON and binary buffer (images embedded)."""
    buf = _Buffer()
    head = head_geometry()
    eyes = _join([_sphere(JOINTS[7][2], 0.012), _sphere(JOINTS[8][2], 0.012)])
    t = np.linspace(-0.6, 0.6, 9)
    arc = [(0.03 * math.sin(a), 1.615, 0.02 + 0.055 * math.cos(a)) for a in t]
    teeth_parts = [_sphere(c, 0.006, 4) for c in arc]
    teeth = _join(teeth_parts)
    lower = (teeth["positions"][:, 1] < 1.615)[None, :, None]
    teeth_jaw = np.where(lower, [0.0, -0.012, 0.002], 0.0)[0]
    body = _join(
        [
            _cylinder((0, 0.95, 0), (0, 1.5, 0), 0.15),
            _cylinder((0.15, 1.45, 0), (0.7, 1.45, 0), 0.04),
            _cylinder((-0.15, 1.45, 0), (-0.7, 1.45, 0), 0.04),
        ]
    )
    meshes = [
        {
            "name": "Head",
            "primitives": [_primitive(buf, head, 0, ["Head", "Neck", "Jaw"], head["deltas"])],
            "weights": [0.0, 0.0, 0.0],
            "extras": {"targetNames": ["browInnerUp", "jawOpen", "mouthSmile"]},
        },
        {"name": "Eyes", "primitives": [_primitive(buf, eyes, 1, ["LeftEye", "RightEye"])]},
        {
            "name": "Teeth",
            "primitives": [_primitive(buf, teeth, 2, ["Head", "Jaw"], [teeth_jaw])],
            "weights": [0.0],
            "extras": {"targetNames": ["jawOpen"]},
        },
        {
            "name": "Body",
            "primitives": [
                _primitive(
                    buf,
                    body,
                    3,
                    ["Spine", "Spine1", "Spine2", "LeftArm", "LeftForeArm", "RightArm"],
                )
            ],
        },
    ]
    nodes = _nodes([m["name"] for m in meshes])
    ibm = np.zeros((len(JOINTS), 16), np.float32)
    for i, (_, _, p) in enumerate(JOINTS):
        m = np.eye(4)
        m[:3, 3] = -np.asarray(p)
        ibm[i] = m.T.reshape(-1)  # column-major
    skin = {
        "name": "AvatarSkin",
        "joints": list(range(len(JOINTS))),
        "skeleton": 0,
        "inverseBindMatrices": buf.accessor(ibm, "MAT4"),
    }
    images_data = [
        _texture((214, 160, 140)),
        png_bytes(_encode(skin_normals())),
        _texture((240, 240, 235)),
        _texture((250, 245, 220)),
        _texture((60, 80, 120)),
    ]
    names = ["skin_color", "skin_normal", "eye_color", "teeth_color", "body_color"]
    images = [
        {"name": n, "mimeType": "image/png", "bufferView": buf.view(d)}
        for n, d in zip(names, images_data)
    ]
    textures = [{"sampler": 0, "source": i, "name": n} for i, n in enumerate(names)]
    # Idle: the head turns and the brows rise, 0..2 s
    times = np.array([0.0, 1.0, 2.0], np.float32)
    rot = np.array([_quat((0, 1, 0), a) for a in (10.0, -10.0, 10.0)], np.float32)
    brow = np.array([0, 0, 0, 1, 0, 0, 0, 0, 0], np.float32)  # browInnerUp 0 -> 1 -> 0
    t_acc = buf.accessor(times, "SCALAR", minmax=True)
    animation = {
        "name": "Idle",
        "samplers": [
            {"input": t_acc, "output": buf.accessor(rot, "VEC4"), "interpolation": "LINEAR"},
            {"input": t_acc, "output": buf.accessor(brow, "SCALAR"), "interpolation": "LINEAR"},
        ],
        "channels": [
            {"sampler": 0, "target": {"node": 5, "path": "rotation"}},
            {"sampler": 1, "target": {"node": 20, "path": "weights"}},
        ],
    }
    data = b"".join(buf.chunks)
    data += b"\0" * ((-len(data)) % 4)
    doc = {
        "asset": {"version": "2.0", "generator": f"wrinklepipe avatar fixture v{AVATAR_VERSION}"},
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "scene": 0,
        "scenes": [{"name": "AvatarScene", "nodes": [24, 20, 21, 22, 23]}],
        "nodes": nodes,
        "meshes": meshes,
        "skins": [skin],
        "materials": _materials(),
        "textures": textures,
        "images": images,
        "samplers": [{"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497}],
        "animations": [animation],
        "accessors": buf.accessors,
        "bufferViews": buf.views,
        "buffers": [{"byteLength": len(data)}],
    }
    return doc, data


def _nodes(mesh_names: list[str]) -> list[dict[str, Any]]:
    """The avatar's nodes: the joints 0..19 in JOINTS order (rest TRS), a node per mesh
    (20..23, skinned), the root 24."""
    nodes: list[dict[str, Any]] = []
    for name, parent, p in JOINTS:
        base = JOINTS[JOINT_NAMES.index(parent)][2] if parent else (0.0, 0.0, 0.0)
        node: dict[str, Any] = {
            "name": name,
            "translation": [float(np.float32(a - b)) for a, b in zip(p, base)],
        }
        if name in REST_ROTATIONS:
            node["rotation"] = _quat(*REST_ROTATIONS[name])
        kids = [i for i, j in enumerate(JOINTS) if j[1] == name]
        if kids:
            node["children"] = kids
        nodes.append(node)
    for i, m in enumerate(mesh_names):
        nodes.append({"name": m, "mesh": i, "skin": 0})
    nodes.append({"name": "Avatar", "children": [0], "extras": {"rig": "wrinklepipe avatar"}})
    return nodes


def _materials() -> list[dict[str, Any]]:
    """Skin (its colour and normal maps), eyes (emissive), teeth, body."""
    return [
        {
            "name": "Skin",
            "pbrMetallicRoughness": {
                "baseColorTexture": {"index": 0},
                "metallicFactor": 0.0,
                "roughnessFactor": 0.6,
            },
            "normalTexture": {"index": 1},
        },
        {
            "name": "Eye",
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 2}, "roughnessFactor": 0.1},
            "emissiveFactor": [0.1, 0.1, 0.1],
            "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 2.0}},
        },
        {
            "name": "Teeth",
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 3}, "metallicFactor": 0.0},
        },
        {
            "name": "Body",
            "pbrMetallicRoughness": {"baseColorTexture": {"index": 4}},
            "doubleSided": True,
        },
    ]


def avatar_glb_bytes() -> bytes:
    """The avatar as a GLB (deterministic bytes)."""
    doc, data = avatar_document()
    return glb_bytes(doc, data)


# ------------------------------------------------------------------------------------------------
# the wrinkle setup


def _ridged(base: np.ndarray, freq: float, amp: float) -> np.ndarray:
    """``base`` plus ridges along u (PD-space addition), as unit normals."""
    size = base.shape[0]
    v = (np.arange(size) + 0.5) / size
    slope = amp * 2 * np.pi * freq * np.cos(2 * np.pi * freq * v)
    pd = base[..., :2] / base[..., 2:3]
    pd[..., 1] += slope[:, None]
    n = np.concatenate([pd, np.ones_like(pd[..., :1])], -1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def manifest_text() -> str:
    lines = [
        "# wrinklepipe avatar fixture (generated): the head material of a multi-mesh character",
        'schema = "wrinklepipe/manifest@1"',
        'name = "avatar"',
        'mesh = "avatar.glb"',
        'material = "Skin"  # base omitted: the material\'s own normalTexture',
        'convention = "opengl"',
        "pd_scale = 1",
        "",
    ]
    for s in ("stretch", "compress"):
        lines += ["[[states]]", f'name = "{s}"', f'map = "wrinkle_{s}.png"', ""]
    for r, (_, side) in REGIONS.items():
        lines += ["[[regions]]", f'name = "{r}"', f'mask = "masks/{r}.png"', f'side = "{side}"', ""]
    lines += [
        "[expressions]",
        "surprise = { brow_L = 1.0, brow_R = 1.0 }",
        "open = { mouth = 1.0 }",
        "",
        "[[drivers]]",
        'kind = "blendshapes"',
        'rows = [["browInnerUp", "brow_L", 0, 1, 1, 0], ["browInnerUp", "brow_R", 0, 1, 1, 0],',
        '        ["jawOpen", "mouth", 0, 1, 1, 0]]',
        "[drivers.keys]",
        "browInnerUp = [[0, 0], [1, 1], [2, 0]]",
        "jawOpen = [[0, 0], [2, 0], [3, 1], [4, 0]]",
        "",
    ]
    return "\n".join(lines)


def avatar_source_files() -> dict[str, bytes]:
    """Every file of the avatar's source folder as ``{relative path: bytes}``."""
    base = skin_normals()
    files = {
        "avatar.glb": avatar_glb_bytes(),
        "manifest.toml": manifest_text().encode("utf-8"),
        "wrinkle_stretch.png": png_bytes(_encode(_ridged(base, 4, 0.004))),
        "wrinkle_compress.png": png_bytes(_encode(_ridged(base, 8, 0.002))),
    }
    c = (np.arange(MASK_SIZE) + 0.5) / MASK_SIZE
    for r, ((u0, v0, u1, v1), _) in REGIONS.items():
        m = (c[None, :] >= u0) & (c[None, :] <= u1) & (c[:, None] >= v0) & (c[:, None] <= v1)
        files[f"masks/{r}.png"] = png_bytes((m * 255).astype(np.uint8)[..., None])
    return files


def write_avatar_source(folder: str | Path) -> Path:
    """Write the avatar's source folder (see the module doc); return the manifest path."""
    folder = Path(folder)
    write_files(folder, avatar_source_files(), what="the avatar source")
    return folder / "manifest.toml"


def avatar_source_dir() -> Path:
    """The avatar source folder, generated into the cache; returns the manifest path.

    The folder is named by a hash of its files (generating them takes a fraction of a second),
    so a change in the fixture or its encoders never reuses stale bytes."""
    files = avatar_source_files()
    digest = hashlib.sha256()
    for rel, data in sorted(files.items()):
        digest.update(rel.encode("utf-8") + b"\0" + hashlib.sha256(data).digest())
    folder = cache_root() / f"avatar-v{AVATAR_VERSION}-{digest.hexdigest()[:12]}"
    manifest = folder / "manifest.toml"
    if manifest.is_file():
        return manifest
    folder.parent.mkdir(parents=True, exist_ok=True)
    with output_lock(folder, wait=True):  # parallel workers: one writes, the others wait
        if not manifest.is_file():
            write_files(folder, files, force=True, what="the avatar source")
    return manifest
