"""UDIM setups for tests: a small USD face whose UV layout spans tiles 1001 and 1002, and
maps, masks and a manifest naming them with ``<UDIM>``.

The face is an N x N quad grid in the XY plane facing +Z, skinned to one joint (so the layer
over it keeps a SkelRoot); its left half is laid out on tile 1001 (u in [0, 1]), its right
half on tile 1002 (u in [1, 2]): the seam's corners carry two UVs (faceVarying ``st``). Each
tile's maps are drawn analytically in that tile's own [0, 1] square, so what a tile should
show is known without the code under test."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wrinklepipe.io.images import write_image

#: Regions as boxes in a tile's own UV square (u0, v0, u1, v1; v down, as images) and the
#: tile they are painted on.
REGIONS = {
    "brow_L": (1002, (0.1, 0.1, 0.9, 0.45), "left"),
    "brow_R": (1001, (0.1, 0.1, 0.9, 0.45), "right"),
    "mouth": (1001, (0.2, 0.55, 0.8, 0.9), "center"),
    "cheek": (1002, (0.2, 0.55, 0.8, 0.9), "left"),
}


def face_usda(n: int = 8) -> str:
    """The face's USD text (``/Face`` SkelRoot, ``/Face/Mesh``, ``/Face/Looks/Skin``)."""
    xs = np.linspace(0.0, 1.0, n + 1)
    pts = [(x, 1.3 + 0.6 * y, 0.1) for y in xs for x in xs]
    faces, st = [], []
    half = n // 2
    for r in range(n):
        for c in range(n):
            quad = [
                r * (n + 1) + c,
                r * (n + 1) + c + 1,
                (r + 1) * (n + 1) + c + 1,
                (r + 1) * (n + 1) + c,
            ]
            faces += quad
            for q in quad:
                qc, qr = q % (n + 1), q // (n + 1)
                if c < half:  # tile 1001: columns 0 .. half over u 0 .. 1
                    u = qc / half
                else:  # tile 1002: columns half .. n over u 1 .. 2
                    u = 1.0 + (qc - half) / (n - half)
                st.append((u, qr / n))
    fmt = ", ".join
    count = (n + 1) ** 2
    eye = "( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1) )"
    return f"""#usda 1.0
(
    defaultPrim = "Face"
    metersPerUnit = 1
    upAxis = "Y"
)

def SkelRoot "Face" (
    kind = "component"
)
{{
    def Skeleton "Skel" (
        prepend apiSchemas = ["SkelBindingAPI"]
    )
    {{
        uniform token[] joints = ["root"]
        uniform matrix4d[] bindTransforms = [{eye}]
        uniform matrix4d[] restTransforms = [{eye}]
    }}

    def Mesh "Mesh" (
        prepend apiSchemas = ["SkelBindingAPI", "MaterialBindingAPI"]
    )
    {{
        float3[] extent = [(0, 1.3, 0.1), (1, 1.9, 0.1)]
        int[] faceVertexCounts = [{fmt(["4"] * (n * n))}]
        int[] faceVertexIndices = [{fmt(map(str, faces))}]
        point3f[] points = [{fmt(f"({a:g}, {b:g}, {z:g})" for a, b, z in pts)}]
        normal3f[] normals = [{fmt(["(0, 0, 1)"] * count)}] (
            interpolation = "vertex"
        )
        texCoord2f[] primvars:st = [{fmt(f"({u:.6g}, {v:.6g})" for u, v in st)}] (
            interpolation = "faceVarying"
        )
        int[] primvars:skel:jointIndices = [{fmt(["0"] * count)}] (
            elementSize = 1
            interpolation = "vertex"
        )
        float[] primvars:skel:jointWeights = [{fmt(["1"] * count)}] (
            elementSize = 1
            interpolation = "vertex"
        )
        matrix4d primvars:skel:geomBindTransform = {eye}
        uniform token subdivisionScheme = "none"
        rel material:binding = </Face/Looks/Skin>
        rel skel:skeleton = </Face/Skel>
    }}

    def Scope "Looks"
    {{
        def Material "Skin"
        {{
            token outputs:surface.connect = </Face/Looks/Skin/Surface.outputs:surface>

            def Shader "Surface"
            {{
                uniform token info:id = "UsdPreviewSurface"
                float inputs:roughness = 0.6
                token outputs:surface
            }}
        }}
    }}
}}
"""


def _unit(n: np.ndarray) -> np.ndarray:
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def tile_maps(tile: int, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A tile's base and two states (unit normals ``[size, size, 3]``): the base a gentle
    bump field of its own per tile (so tiles differ), each state the base plus ridges."""
    c = (np.arange(size) + 0.5) / size
    u, v = np.meshgrid(c, c)
    k = 2.0 + (tile - 1001)
    bx = 0.05 * np.cos(2 * np.pi * k * u) * np.sin(2 * np.pi * v)
    by = 0.05 * np.sin(2 * np.pi * u) * np.cos(2 * np.pi * k * v)

    def face(dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
        return _unit(np.stack([-(bx + dx), -(by + dy), np.ones_like(u)], -1))

    stretch = face(0 * u, 0.25 * np.cos(2 * np.pi * 4 * v))
    compress = face(0.25 * np.cos(2 * np.pi * 6 * u), 0 * v)
    return face(0 * u, 0 * v), stretch, compress


def tile_mask(tile: int, region: str, size: int) -> np.ndarray | None:
    """A region's mask on a tile (None: the region is not painted on that tile)."""
    where, (u0, v0, u1, v1), _ = REGIONS[region]
    if where != tile:
        return None
    c = (np.arange(size) + 0.5) / size
    return (
        (c[None, :] >= u0) & (c[None, :] <= u1) & (c[:, None] >= v0) & (c[:, None] <= v1)
    ).astype(np.float64)


def write_udim_setup(
    folder: Path,
    size: int = 64,
    mask_size: int = 16,
    grid: int = 8,
    extra: str = "",
    name: str = "face",
) -> Path:
    """``face.usda``, ``maps/{base,stretch,compress}.<UDIM>.png`` (tiles 1001, 1002, 16-bit),
    ``masks/<region>.<UDIM>.png`` (each region on one tile only) and ``manifest.toml`` into
    ``folder``; the manifest's path."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "face.usda").write_text(face_usda(grid), encoding="utf-8")
    (folder / "maps").mkdir(exist_ok=True)
    (folder / "masks").mkdir(exist_ok=True)
    for t in (1001, 1002):
        for label, n in zip(("base", "stretch", "compress"), tile_maps(t, size)):
            write_image(folder / "maps" / f"{label}.{t}.png", 0.5 + 0.5 * n, 16)
        for r in REGIONS:
            m = tile_mask(t, r, mask_size)
            if m is not None:
                write_image(folder / "masks" / f"{r}.{t}.png", m, 8)
    lines = [
        f'name = "{name}"',
        'mesh = "face.usda"',
        'convention = "opengl"',
        'base = "maps/base.<UDIM>.png"',
        "",
        "[[states]]",
        'name = "stretch"',
        'map = "maps/stretch.<UDIM>.png"',
        "",
        "[[states]]",
        'name = "compress"',
        'map = "maps/compress.<UDIM>.png"',
    ]
    for r, (_, _, side) in REGIONS.items():
        lines += [
            "",
            "[[regions]]",
            f'name = "{r}"',
            f'mask = "masks/{r}.<UDIM>.png"',
            f'side = "{side}"',
        ]
    lines += [
        "",
        "[expressions]",
        "raise = {brow_L = 1.0, brow_R = 1.0}",
        "smile = {mouth = 1.0, cheek = 0.8}",
    ]
    (folder / "manifest.toml").write_text("\n".join(lines) + "\n" + extra, encoding="utf-8")
    return folder / "manifest.toml"


# ------------------------------------------------------------------------------------------------
# a two-tile head made from a shared sample: CesiumMan's face split over tiles 1001 and 1002

#: CesiumMan (Khronos glTF sample) under ``../shared/data``.
CESIUM = (
    Path(__file__).resolve().parents[2]
    / "shared"
    / "data"
    / "gltf-samples"
    / "CesiumMan"
    / "glTF-Binary"
    / "CesiumMan.glb"
)


def _head_usda(positions: np.ndarray, normals: np.ndarray, tris: np.ndarray, st: np.ndarray) -> str:
    """A USD layer of one triangle mesh (``/Head/Mesh``, Y up, metres) with faceVarying
    ``st`` (one UV per triangle corner, USD's t up) and a material to wrinkle."""
    fmt = ", ".join
    lo, hi = (tuple(x.round(6).tolist()) for x in (positions.min(0), positions.max(0)))
    return f"""#usda 1.0
(
    defaultPrim = "Head"
    metersPerUnit = 1
    upAxis = "Y"
)

def Xform "Head" (
    kind = "component"
)
{{
    def Mesh "Mesh" (
        prepend apiSchemas = ["MaterialBindingAPI"]
    )
    {{
        float3[] extent = [{lo}, {hi}]
        int[] faceVertexCounts = [{fmt(["3"] * len(tris))}]
        int[] faceVertexIndices = [{fmt(map(str, tris.reshape(-1).tolist()))}]
        point3f[] points = [{fmt(f"({a:.7g}, {b:.7g}, {c:.7g})" for a, b, c in positions)}]
        normal3f[] normals = [{fmt(f"({a:.7g}, {b:.7g}, {c:.7g})" for a, b, c in normals)}] (
            interpolation = "vertex"
        )
        texCoord2f[] primvars:st = [{fmt(f"({u:.9g}, {t:.9g})" for u, t in st)}] (
            interpolation = "faceVarying"
        )
        uniform token orientation = "rightHanded"
        uniform token subdivisionScheme = "none"
        rel material:binding = </Head/Looks/Skin>
    }}

    def Scope "Looks"
    {{
        def Material "Skin"
        {{
            token outputs:surface.connect = </Head/Looks/Skin/Surface.outputs:surface>

            def Shader "Surface"
            {{
                uniform token info:id = "UsdPreviewSurface"
                float inputs:roughness = 0.6
                token outputs:surface
            }}
        }}
    }}
}}
"""


def _keep(boxes: np.ndarray, size: int, pad: int = 3) -> np.ndarray:
    """Texels ``[size, size]`` inside any UV box ``[N, 4]`` (u0, v0, u1, v1; v down), each
    grown by ``pad`` texels."""
    keep = np.zeros((size, size), bool)
    px = np.clip(
        np.stack(
            [
                np.floor(boxes[:, 0] * size) - pad,
                np.floor(boxes[:, 1] * size) - pad,
                np.ceil(boxes[:, 2] * size) + pad,
                np.ceil(boxes[:, 3] * size) + pad,
            ],
            1,
        ),
        0,
        size,
    ).astype(int)
    for x0, y0, x1, y1 in px:  # a few hundred boxes of a test setup
        keep[y0:y1, x0:x1] = True
    return keep


def write_cesium_udim(folder: Path, size: int = 512) -> tuple[Path, dict]:
    """CesiumMan made a two-tile UDIM head: the face fixture's analytic maps
    (:mod:`wrinklepipe.demo.face_fixture`: a real artist's UV layout, exact wrinkle slopes)
    on its mesh, the triangles of the face's +u half (the character's left) moved to tile
    1002 (u + 1: same texels), the maps and masks split: each tile keeps the texels its own
    triangles reach (boxes grown by 3 texels), flat elsewhere. Writes ``head.usda``,
    ``maps/{base,stretch,compress}.<UDIM>.png`` (16-bit), ``masks/<region>.<UDIM>.png``
    (8-bit; a region's tile left out where its mask is zero there) and ``manifest.toml``
    (every choice on auto, the fixture's budget). Returns the manifest and what the test
    compares with: ``{"fixture", "tiles" (triangle -> tile), "keep" {tile: texels},
    "moved" (triangles on 1002)}``."""
    from wrinklepipe.demo import face_fixture as ff

    fx = ff.build_fixture(CESIUM, size)
    mesh, disc = fx.mesh, fx.disc
    tris = np.asarray(mesh.indices, np.int64).reshape(-1, 3)
    uv = np.asarray(mesh.uvs, np.float64)[tris]  # [T, 3, 2], glTF (v down)
    in_face = (np.abs(uv[..., 0] - disc.cu) <= disc.ru * 1.05).all(1) & (
        np.abs(uv[..., 1] - disc.cv) <= disc.rv * 1.05
    ).all(1)
    moved = in_face & (uv[..., 0] > disc.cu).all(1)
    boxes = np.concatenate([uv.min(1), uv.max(1)], 1)  # [T, 4]
    keep = {1001: _keep(boxes[~moved], size), 1002: _keep(boxes[moved], size)}
    corner_uv = uv.reshape(-1, 2).copy()
    corner_uv[np.repeat(moved, 3), 0] += 1.0
    st = np.stack([corner_uv[:, 0], 1.0 - corner_uv[:, 1]], 1)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "head.usda").write_text(
        _head_usda(
            np.asarray(mesh.positions, np.float64),
            np.asarray(mesh.normals, np.float64),
            tris,
            st,
        ),
        encoding="utf-8",
    )
    flat = np.array([0.0, 0.0, 1.0])
    maps = {"base": fx.base_normal}
    maps.update({s: fx.wrinkled_normal(k) for k, s in enumerate(fx.state_names)})
    for t, k in keep.items():
        for label, n in maps.items():
            out = np.where(k[..., None], n, flat)
            write_image(folder / "maps" / f"{label}.{t}.png", 0.5 + 0.5 * out, 16)
        for r, m in zip(fx.regions, fx.masks):
            if (m * k).any():
                write_image(folder / "masks" / f"{r.name}.{t}.png", m * k, 8)
    text = ff.manifest_text(fx, folder / "head.usda")
    text = text.replace(f'mesh = "{(folder / "head.usda").as_posix()}"', 'mesh = "head.usda"')
    text = text.replace('base = "base_normal.png"', 'base = "maps/base.<UDIM>.png"')
    for s in fx.state_names:
        text = text.replace(f'map = "wrinkle_{s}.png"', f'map = "maps/{s}.<UDIM>.png"')
    for r in fx.regions:
        text = text.replace(f'mask = "masks/{r.name}.png"', f'mask = "masks/{r.name}.<UDIM>.png"')
    (folder / "manifest.toml").write_text(text, encoding="utf-8")
    tiles = np.where(moved, 1002, 1001)
    return folder / "manifest.toml", {"fixture": fx, "tiles": tiles, "keep": keep, "moved": moved}
