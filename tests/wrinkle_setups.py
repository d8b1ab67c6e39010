"""Wrinkle setups for whole characters in tests: a base, two states and masks drawn analytically
in a UV layout, and a manifest naming the wrinkled material (and meshes) of a source document."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from wrinklepipe import model
from wrinklepipe.asset import WrinkleAsset
from wrinklepipe.demo import avatar, demo_asset
from wrinklepipe.gltf.package_write import glb_bytes
from wrinklepipe.io.images import write_image

#: Regions as UV boxes (u0, v0, u1, v1) with their side; glTF characters face +Z, so their
#: left is +X, which a front projection (and a mirrored face layout) puts at u > 0.5.
REGIONS = {
    "brow_L": ((0.55, 0.05, 0.95, 0.45), "left"),
    "brow_R": ((0.05, 0.05, 0.45, 0.45), "right"),
    "mouth": ((0.2, 0.55, 0.8, 0.95), "center"),
}


def _ridges(size: int, freq: float, amp: float) -> np.ndarray:
    """Unit normals of a height field ``amp sin(2 pi freq v)`` (ridges along u), encoded."""
    v = (np.arange(size) + 0.5) / size
    dh = amp * 2 * np.pi * freq * np.cos(2 * np.pi * freq * v)  # dh/dv per texel row
    n = np.zeros((size, size, 3))
    n[..., 1] = dh[:, None]
    n[..., 2] = 1.0
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return 0.5 + 0.5 * n


def write_setup(
    folder: Path,
    mesh: Path,
    name: str,
    material: str | list[str] | None = None,
    meshes: list[str] | None = None,
    base: bool = True,
    size: int = 64,
    mask_size: int = 16,
    regions: dict | None = None,
    drivers: str = "",
    link_mesh: bool = False,
) -> Path:
    """Write maps, masks and ``manifest.toml`` into ``folder``; return the manifest path.

    ``mesh`` may be absolute (the tests allow its folder with ``allowed_roots``). With
    ``link_mesh`` the manifest names a symbolic link beside it instead, so its bytes (and the
    report's sha256 of it) do not depend on where the checkout and ``../shared`` are."""
    folder.mkdir(parents=True, exist_ok=True)
    if link_mesh:
        (folder / mesh.name).symlink_to(mesh)
        mesh_line = mesh.name
    else:
        mesh_line = mesh.as_posix()
    regions = REGIONS if regions is None else regions
    flat = np.zeros((size, size, 3))
    flat[..., :] = (0.5, 0.5, 1.0)
    if base:
        write_image(folder / "base.png", flat, 8)
    write_image(folder / "stretch.png", _ridges(size, 4, 0.01), 8)
    write_image(folder / "compress.png", _ridges(size, 8, 0.01), 8)
    (folder / "masks").mkdir(exist_ok=True)
    c = (np.arange(mask_size) + 0.5) / mask_size
    for r, ((u0, v0, u1, v1), _) in regions.items():
        m = (c[None, :] >= u0) & (c[None, :] <= u1) & (c[:, None] >= v0) & (c[:, None] <= v1)
        write_image(folder / "masks" / f"{r}.png", m.astype(np.float64), 8)
    lines = [
        f'name = "{name}"',
        f'mesh = "{mesh_line}"',
        'convention = "opengl"',
        "pd_scale = 1",
    ]
    if base:
        lines.append('base = "base.png"')
    if material is not None:
        lines.append(f"material = {_toml(material)}")
    if meshes is not None:
        lines.append(f"meshes = {_toml(meshes)}")
    lines += [
        "",
        "[[states]]",
        'name = "stretch"',
        'map = "stretch.png"',
        "",
        "[[states]]",
        'name = "compress"',
        'map = "compress.png"',
    ]
    for r, (_, side) in regions.items():
        lines += ["", "[[regions]]", f'name = "{r}"', f'mask = "masks/{r}.png"', f'side = "{side}"']
    names = list(regions)
    lines += ["", "[expressions]"]
    lines.append("raise = {" + ", ".join(f"{r} = 1.0" for r in names[:2]) + "}")
    lines.append("smile = {" + f"{names[-1]} = 1.0" + "}")
    (folder / "manifest.toml").write_text("\n".join(lines) + "\n" + drivers, encoding="utf-8")
    return folder / "manifest.toml"


def _toml(value: str | list[str]) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    return "[" + ", ".join(f'"{v}"' for v in value) + "]"


#: RobotExpressive (CC0, 14 meshes, 3 materials, 2 skins, 14 animations) from ../shared/data.
ROBOT = (
    Path(__file__).resolve().parents[2]
    / "shared"
    / "data"
    / "gltf-samples"
    / "RobotExpressive"
    / "RobotExpressive.glb"
)
#: The blendshapes driver the RobotExpressive setups use: its Angry / Surprised morphs drive
#: the brows and the mouth.
ROBOT_DRIVERS = """
[[drivers]]
kind = "blendshapes"
rows = [["Angry", "brow_L", 0, 1, 1, 0], ["Angry", "brow_R", 0, 1, 1, 0],
        ["Surprised", "mouth", 0, 1, 1, 0]]
[drivers.keys]
Angry = [[0, 0], [1, 1], [2, 0]]
Surprised = [[0, 0], [2, 0], [3, 1]]
"""


def write_robot_setup(folder: Path) -> Path:
    """RobotExpressive's wrinkle setup: ``material = "Main"`` on ``meshes = ["Head"]`` (Main
    is shared with the body, so it is cloned for the head), driven by :data:`ROBOT_DRIVERS`."""
    return write_setup(
        folder, ROBOT, "robot", "Main", ["Head"], drivers=ROBOT_DRIVERS, link_mesh=True
    )


def overlapping_demo(encoding: str, policy: str) -> WrinkleAsset:
    """The 128 demo with overlapping masks (glabella over forehead_inner: sums reach 2) and
    strong / negative expressions clipped to the policy's weight range: every policy's edge."""
    a = demo_asset(128, encoding=encoding, policy=policy)
    masks = a.masks.copy()
    masks[2] = np.maximum(masks[2], masks[6])  # overlap: sums reach 2 over the glabella
    ex = dict(a.expressions)
    ex["all_strong"] = {r: 0.9 for r in a.region_names}
    ex["negative"] = {r: -0.7 for r in a.region_names}
    lo = model.POLICY_WEIGHT_RANGE[policy].low
    ex = {e: {r: max(w, lo) for r, w in row.items()} for e, row in ex.items()}
    return replace(a, masks=masks, expressions=ex)


def avatar_variant(tmp_path: Path, change) -> Path:
    """The generated avatar's source folder under ``tmp_path/src`` with its GLB changed by
    ``change(doc, data, folder)`` (which edits ``doc`` in place and may return new binary
    data); the manifest's path."""
    folder = tmp_path / "src"
    for rel, data in avatar.avatar_source_files().items():
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        (folder / rel).write_bytes(data)
    doc, data = avatar.avatar_document()
    data = change(doc, data, folder) or data
    (folder / "avatar.glb").write_bytes(glb_bytes(doc, data))
    return folder / "manifest.toml"


#: LittlestTokyo (CC-BY-4.0, Draco: 71 meshes, 15 materials, 1 skin) from ../shared/data.
TOKYO = ROBOT.parents[1] / "LittlestTokyo" / "LittlestTokyo.glb"


def write_tokyo_setup(folder: Path) -> Path:
    """LittlestTokyo's wrinkle setup: ``material = "normal"`` (shared by 35 meshes) on its
    skinned character's body, ``meshes = ["body_normal_0"]``, whose UVs take a small corner of
    the atlas (u 0.53-0.56, v 0.07-0.12): the regions are boxes around it, masks at 64²."""
    regions = {
        "brow_L": ((0.545, 0.0, 0.6, 0.09), "left"),
        "brow_R": ((0.5, 0.0, 0.545, 0.09), "right"),
        "mouth": ((0.5, 0.09, 0.6, 0.2), "center"),
    }
    return write_setup(
        folder,
        TOKYO,
        "tokyo",
        "normal",
        ["body_normal_0"],
        mask_size=64,
        regions=regions,
        link_mesh=True,
    )


#: RobotExpressive's blendshapes rows read from a glTF file's animation (``file``): its Angry /
#: Surprised morphs drive the brows and the mouth. ``{file}`` and ``{clip}`` are filled in.
ROBOT_CLIP_DRIVERS = """
[[drivers]]
kind = "blendshapes"
file = "{file}"{clip}
rows = [["Angry", "brow_L", 0, 1, 1, 0], ["Angry", "brow_R", 0, 1, 1, 0],
        ["Surprised", "mouth", 0, 1, 1, 0]]
"""


def write_robot_clip_setup(folder: Path, file: str = "RobotExpressive.glb", clip=None) -> Path:
    """RobotExpressive's wrinkle setup driven by the morph-weight animation of ``file`` (beside
    the manifest; ``RobotExpressive.glb`` is the mesh's link, whose 14 clips all keep every
    morph weight at 0), reading ``clip`` (None: not named)."""
    named = "" if clip is None else f"\nclip = {clip!r}".replace("'", '"')
    drivers = ROBOT_CLIP_DRIVERS.format(file=file, clip=named)
    return write_setup(folder, ROBOT, "robot", "Main", ["Head"], drivers=drivers, link_mesh=True)


def write_face_clips(path: Path, names=("Angry", "Surprised", "Sad")) -> Path:
    """A small glTF (GLB) whose only mesh has the morph targets ``names`` and two animations
    of their weights: ``Idle`` (every weight 0) and ``Talk`` (Angry up at 1 s, Surprised at
    3 s): a performance file a blendshapes driver reads with ``clip``."""
    import pygltflib as g  # deferred: only the rig tests write glTF by hand

    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    delta = np.array([[0, 0, 0.1]] * 3, np.float32)
    times = np.array([0, 1, 2, 3, 4], np.float32)
    talk = np.zeros((5, len(names)), np.float32)
    talk[1, 0] = 1.0
    talk[3, 1] = 1.0
    idle = np.zeros((5, len(names)), np.float32)
    blobs = [pos, *([delta] * len(names)), times, talk, idle]
    data = b"".join(b.tobytes() for b in blobs)
    views, accessors, at = [], [], 0
    for b in blobs:
        views.append(g.BufferView(buffer=0, byteOffset=at, byteLength=b.nbytes))
        at += b.nbytes
    for i, b in enumerate(blobs):
        kind = "VEC3" if b.ndim == 2 and b.shape[1] == 3 and i <= len(names) else "SCALAR"
        count = b.shape[0] if kind == "VEC3" else b.size
        acc = g.Accessor(bufferView=i, componentType=g.FLOAT, count=count, type=kind)
        if i == 0 or kind == "VEC3":
            acc.min = b.min(axis=0).tolist()
            acc.max = b.max(axis=0).tolist()
        if i == len(names) + 1:
            acc.min, acc.max = [float(times.min())], [float(times.max())]
        accessors.append(acc)
    n = len(names)
    prim = g.Primitive(
        attributes=g.Attributes(POSITION=0), targets=[{"POSITION": 1 + k} for k in range(n)]
    )
    mesh = g.Mesh(primitives=[prim], weights=[0.0] * n, extras={"targetNames": list(names)})

    def anim(name: str, values: int) -> g.Animation:
        return g.Animation(
            name=name,
            samplers=[g.AnimationSampler(input=n + 1, output=values, interpolation="LINEAR")],
            channels=[
                g.AnimationChannel(
                    sampler=0, target=g.AnimationChannelTarget(node=0, path="weights")
                )
            ],
        )

    doc = g.GLTF2(
        asset=g.Asset(version="2.0"),
        scenes=[g.Scene(nodes=[0])],
        scene=0,
        nodes=[g.Node(mesh=0, name="Face")],
        meshes=[mesh],
        buffers=[g.Buffer(byteLength=len(data))],
        bufferViews=views,
        accessors=accessors,
        animations=[anim("Idle", n + 3), anim("Talk", n + 2)],
    )
    doc.set_binary_blob(data)
    path.write_bytes(b"".join(doc.save_to_bytes()))
    return path
