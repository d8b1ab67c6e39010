"""A deterministic, seeded head-like demo character with known ground truth.

Everything is generated from a seed with numpy (no files needed): a closed lat-long head mesh whose
UVs have a seam at the back of the head (split vertices) and poles closed by fans; vertex normals;
named morph targets; a base height field with pores and a scar; two wrinkle *height fields*
(stretch: horizontal forehead lines; compress: glabella lines, crow's feet, nose lines, nasolabial
creases, chin dimpling); the 8 Jimenez zones as soft masks; and Jimenez Table 1.1.

Heights are in texel units of the map, so the true tangent-space normal of any combination is
``height_to_normal(h_base + sum_k a_k h_k)``: the model's ``pd`` encoding reproduces it exactly
where the activations are constant.

Texture space: u along columns, v along rows with v = 0 at the top (glTF). The face looks along
+Z; the character's left is +X, which lands at u > 0.5 (the right half of the image, as when
looking at the face).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from wrinklepipe.geometry.normals import vertex_normals
from wrinklepipe.model import height_to_normal
from wrinklepipe.presets import jimenez

DEMO_SEED = 20111
DEMO_VERSION = 6  # 6: colour states (base_color, color_<state>)
STATE_NAMES: tuple[str, ...] = ("stretch", "compress")
MORPH_NAMES: tuple[str, ...] = (
    "brow_raise",
    "brow_furrow",
    "smile_L",
    "smile_R",
    "squint_L",
    "squint_R",
    "nose_wrinkle",
    "chin_raise",
)

# Face frame in UV: fx in [-1, 1] across the face (character's left positive), fy positive down.
_FACE_U0, _FACE_UW = 0.5, 0.216
_FACE_V0, _FACE_VH = 0.52, 0.22


@dataclass
class DemoMesh:
    """Render mesh: split vertices (seam twins share positions), triangles, named morph deltas."""

    positions: np.ndarray  # [V, 3] float32, metres
    normals: np.ndarray  # [V, 3] float32
    uvs: np.ndarray  # [V, 2] float32, glTF convention (v down)
    indices: np.ndarray  # [T, 3] uint32
    morph_names: tuple[str, ...]
    morph_deltas: np.ndarray  # [M, V, 3] float32 position deltas


@dataclass
class DemoCharacter:
    """The demo character's mesh, height fields, normal maps, masks and expression table."""

    mesh: DemoMesh
    base_height: np.ndarray  # [H, W] float64, texel units
    wrinkle_heights: np.ndarray  # [K, H, W] float64
    state_names: tuple[str, ...]
    region_names: tuple[str, ...]
    region_sides: tuple[str, ...]
    masks: np.ndarray  # [R, H, W] float32 in [0, 1]
    expressions: dict[str, dict[str, float]] = field(default_factory=dict)
    seed: int = DEMO_SEED

    @property
    def base_normal(self) -> np.ndarray:
        """True base normal map ``[H, W, 3]``."""
        return height_to_normal(self.base_height)

    def wrinkled_normal(self, k: int, amount: float = 1.0) -> np.ndarray:
        """True normal of the face in wrinkle state k everywhere: ``base + amount * h_k``."""
        return height_to_normal(self.base_height + amount * self.wrinkle_heights[k])

    def wrinkle_only_normal(self, k: int) -> np.ndarray:
        """Normal of the wrinkle height alone (what a PD wrinkle map stores)."""
        return height_to_normal(self.wrinkle_heights[k])


# --------------------------------------------------------------------------------------------
# texture-space helpers


def _uv_grid(size: int) -> tuple[np.ndarray, np.ndarray]:
    c = (np.arange(size, dtype=np.float64) + 0.5) / size
    u, v = np.meshgrid(c, c, indexing="xy")
    return u, v


def u_of_longitude(phi: np.ndarray) -> np.ndarray:
    """UV u of a longitude (phi = 0 at the face, +-pi at the seam behind the head).

    Not uniform: the face gets about 1.4x the texels of a plain lat-long map, the back of the
    head fewer, as an artist would lay it out. Monotonic, with u(-pi) = 0 and u(pi) = 1.
    """
    return 0.5 + 0.5 * (0.3 * phi / np.pi + 0.7 * np.sin(phi / 2.0))


def face_coords(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Face frame: ``fx`` across the face (character's left positive), ``fy`` down."""
    return (u - _FACE_U0) / _FACE_UW, (v - _FACE_V0) / _FACE_VH


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _box(x: np.ndarray, lo: float, hi: float, soft: float) -> np.ndarray:
    return _smoothstep(lo - soft, lo + soft, x) * (1.0 - _smoothstep(hi - soft, hi + soft, x))


def _groove(dist: np.ndarray, width: float) -> np.ndarray:
    """A furrow profile: 1 at the crease line, falling off as a Gaussian of ``dist`` (texels)."""
    return np.exp(-0.5 * (dist / width) ** 2)


def _base_height(size: int, rng: np.random.Generator) -> np.ndarray:
    # Pores: band-passed white noise (pore-scale: a couple of texels at 1024).
    noise = rng.standard_normal((size, size))
    fine = ndimage.gaussian_filter(noise, 1.2 * size / 1024, mode="wrap")
    coarse = ndimage.gaussian_filter(noise, 6.0 * size / 1024, mode="wrap")
    pores = (fine - coarse) * 0.9 * (1024 / size) ** 0
    # A small scar on the character's right cheek: a raised ridge.
    u, v = _uv_grid(size)
    fx, fy = face_coords(u, v)
    ridge = np.exp(-0.5 * ((fy - 0.25 - 0.3 * (fx + 0.55)) / 0.02) ** 2) * _box(
        fx, -0.75, -0.45, 0.03
    )
    return pores + 1.5 * ridge * (size / 1024)


def _wrinkle_heights(size: int, rng: np.random.Generator) -> np.ndarray:
    u, v = _uv_grid(size)
    fx, fy = face_coords(u, v)
    tex = size / 1024.0  # heights scale with texel size so slopes are resolution independent
    # Texel distances along the face frame.
    px_per_fx = _FACE_UW * size
    px_per_fy = _FACE_VH * size

    # --- stretch: horizontal forehead lines (furrows), slightly curved and of varying depth.
    line_period = 0.11  # in fy units
    curve = 0.06 * fx**2
    phase = (fy - curve) / line_period
    dist = (phase - np.round(phase)) * line_period * px_per_fy
    depth = 3.4 * (1.0 + 0.25 * np.sin(3.1 * fx + 0.7 * np.round(phase)))
    forehead = _box(fy, -1.02, -0.46, 0.05) * _box(fx, -0.92, 0.92, 0.08)
    stretch = -depth * _groove(dist, 4.5 * tex) * forehead * tex

    # --- compress
    # glabella: two vertical furrows between the brows.
    glab = np.zeros_like(fx)
    for x0 in (-0.07, 0.07):
        d = (fx - x0 - 0.15 * (fy + 0.34)) * px_per_fx
        glab += _groove(d, 4.0 * tex)
    glab *= _box(fy, -0.50, -0.22, 0.04) * 3.6 * tex
    # crow's feet: radial lines at the outer eye corners (fx = +-0.78, fy = -0.18).
    crow = np.zeros_like(fx)
    for side in (-1.0, 1.0):
        dx = (fx - side * 0.78) * px_per_fx
        dy = (fy + 0.18) * px_per_fy
        ang = np.arctan2(dy, side * dx)
        r = np.hypot(dx, dy)
        spokes = np.cos(7.0 * ang) * 0.5 + 0.5
        crow += (
            (spokes**6)
            * _smoothstep(24 * tex, 48 * tex, r)
            * (1.0 - _smoothstep(100 * tex, 136 * tex, r))
            * (1.0 - _smoothstep(0.8, 1.2, np.abs(ang)))
        )
    crow *= 2.2 * tex
    # nose: horizontal "bunny lines" across the upper nose.
    nphase = (fy + 0.02) / 0.09
    ndist = (nphase - np.round(nphase)) * 0.09 * px_per_fy
    nose = _groove(ndist, 3.5 * tex) * _box(fy, -0.16, 0.10, 0.03) * _box(fx, -0.22, 0.22, 0.05)
    nose *= 3.0 * tex
    # nasolabial creases: a curved groove from the nose wing to past the mouth corner.
    naso = np.zeros_like(fx)
    for side in (-1.0, 1.0):
        t = fy
        x_line = side * (0.30 + 0.16 * (t - 0.12) + 0.35 * (t - 0.12) ** 2)
        d = (fx - x_line) * px_per_fx
        naso += _groove(d, 5.0 * tex) * _box(t, 0.14, 0.62, 0.05)
    naso *= 3.0 * tex
    # chin dimpling: smooth bumps and pits on the chin (peau d'orange).
    bumps = ndimage.gaussian_filter(rng.standard_normal((size, size)), 7.0 * tex, mode="wrap")
    bumps /= max(float(np.abs(bumps).max()), 1e-9)
    chin_zone = _box(fy, 0.78, 1.02, 0.05) * _box(fx, -0.38, 0.38, 0.08)
    chin = bumps * chin_zone * 9.0 * tex
    compress = -(glab + crow + nose + naso) + chin
    return np.stack([stretch, compress])


def _masks(size: int) -> np.ndarray:
    u, v = _uv_grid(size)
    fx, fy = face_coords(u, v)
    soft = 0.05
    forehead_y = _box(fy, -1.08, -0.40, soft)
    left = _smoothstep(-0.03, 0.03, fx)  # character's left: fx > 0
    right = 1.0 - left
    outer = _box(np.abs(fx), 0.40, 1.05, soft)
    inner = _box(np.abs(fx), -0.2, 0.40, soft)
    # outer forehead zones run down the temples to the outer eye corners (crow's feet).
    temple = _box(np.abs(fx), 0.58, 1.05, soft) * _box(fy, -0.42, 0.02, soft)
    outer_zone = np.clip(outer * forehead_y + temple, 0.0, 1.0)
    inner_zone = (
        inner * forehead_y * (1.0 - _box(fy, -0.52, -0.20, soft) * _box(fx, -0.2, 0.2, soft))
    )
    nose_zone = _box(fy, -0.20, 0.66, soft) * _box(np.abs(fx), -0.3, 0.72, soft)
    glabella = _box(fy, -0.52, -0.20, soft) * _box(fx, -0.2, 0.2, soft)
    chin = _box(fy, 0.72, 1.08, soft) * _box(fx, -0.45, 0.45, soft)
    masks = np.stack(
        [
            outer_zone * left,
            outer_zone * right,
            inner_zone * left,
            inner_zone * right,
            nose_zone * left,
            nose_zone * right,
            glabella,
            chin,
        ]
    )
    # Where zones overlap a little at soft edges, scale so they sum to at most 1 (a partition).
    total = masks.sum(axis=0)
    masks = masks / np.maximum(total, 1.0)
    return masks.astype(np.float32)


# --------------------------------------------------------------------------------------------
# mesh


def _head_mesh(n_lon: int = 96, n_lat: int = 64) -> DemoMesh:
    """Lat-long ellipsoid head; one column of vertices is duplicated at u = 0 / u = 1 (the seam)."""
    # Ring vertices: latitudes strictly between the poles; longitudes with the seam duplicated.
    lat = np.linspace(0.0, np.pi, n_lat + 1)[1:-1]  # polar angle from the top
    lon = np.linspace(-np.pi, np.pi, n_lon + 1)  # n_lon + 1 columns: first and last coincide
    theta, phi = np.meshgrid(lat, lon, indexing="ij")  # [n_lat-1, n_lon+1]
    u = u_of_longitude(phi)
    v = theta / np.pi
    pos = _head_surface(theta, phi)
    pos[:, -1] = pos[:, 0]  # seam twins: bit-identical positions (sin(-pi) != -sin(pi) in floats)
    ring_pos = pos.reshape(-1, 3)
    ring_uv = np.stack([u, v], axis=-1).reshape(-1, 2)
    rows, cols = theta.shape
    # Poles: one vertex per column so each fan triangle gets its own UV (standard lat-long UVs).
    top_pos = np.repeat(_head_surface(np.array([0.0]), np.array([0.0])), n_lon, axis=0)
    bot_pos = np.repeat(_head_surface(np.array([np.pi]), np.array([0.0])), n_lon, axis=0)
    col_mid = (np.arange(n_lon) + 0.5) / n_lon
    top_uv = np.stack([col_mid, np.zeros(n_lon)], axis=-1)
    bot_uv = np.stack([col_mid, np.ones(n_lon)], axis=-1)
    positions = np.concatenate([ring_pos, top_pos, bot_pos]).astype(np.float32)
    uvs = np.concatenate([ring_uv, top_uv, bot_uv]).astype(np.float32)
    top0 = rows * cols
    bot0 = top0 + n_lon

    r, c = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = r * cols + c
    b = a + 1
    d = a + cols
    e = d + 1
    # Counter-clockwise seen from outside (outward normals): longitude grows towards +X at front.
    quads = np.concatenate(
        [np.stack([a, d, b], -1).reshape(-1, 3), np.stack([b, d, e], -1).reshape(-1, 3)]
    )
    cc = np.arange(n_lon)
    top_fan = np.stack([top0 + cc, cc, cc + 1], -1)
    last = (rows - 1) * cols
    bot_fan = np.stack([bot0 + cc, last + cc + 1, last + cc], -1)
    indices = np.concatenate([top_fan, quads, bot_fan]).astype(np.uint32)
    # Fix winding so that normals point outwards (checked against the radial direction).
    tri = positions[indices]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centroid = tri.mean(axis=1)
    flip = np.einsum("ij,ij->i", nrm, centroid) < 0
    indices[flip] = indices[flip][:, [0, 2, 1]]

    uv_face = face_coords(uvs[:, 0].astype(np.float64), uvs[:, 1].astype(np.float64))
    deltas = _morph_deltas(positions, *uv_face)
    normals = vertex_normals(positions, indices)
    return DemoMesh(positions, normals, uvs, indices, MORPH_NAMES, deltas)


def _head_surface(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Ellipsoid head with a nose bump and brow ridge; theta from the top, phi = 0 at the face."""
    st, ct = np.sin(theta), np.cos(theta)
    sp, cp = np.sin(phi), np.cos(phi)
    fx = (u_of_longitude(phi) - _FACE_U0) / _FACE_UW
    fy = (theta / np.pi - _FACE_V0) / _FACE_VH
    nose = 0.018 * np.exp(-0.5 * ((fx / 0.18) ** 2 + ((fy + 0.05) / 0.22) ** 2))
    brow = 0.004 * np.exp(-0.5 * ((fy + 0.42) / 0.08) ** 2) * np.exp(-0.5 * (fx / 0.9) ** 2)
    bulge = (nose + brow) * (cp > 0)
    rx, ry, rz = 0.078, 0.112, 0.094
    x = (rx + bulge) * st * sp
    y = ry * ct
    z = (rz + bulge) * st * cp
    return np.stack([x, y, z], axis=-1)


def _morph_deltas(positions: np.ndarray, fx: np.ndarray, fy: np.ndarray) -> np.ndarray:
    def bump(cx: float, cy: float, sx: float, sy: float) -> np.ndarray:
        return np.exp(-0.5 * (((fx - cx) / sx) ** 2 + ((fy - cy) / sy) ** 2))

    up = np.array([0.0, 1.0, 0.0])
    out = np.zeros((len(MORPH_NAMES), len(positions), 3))
    mm = 0.001
    front = (positions[:, 2] > 0).astype(np.float64)
    # brow_raise: forehead and brows move up.
    out[0] = (6 * mm * bump(0.0, -0.45, 0.9, 0.25) * front)[:, None] * up
    # brow_furrow: brows move down and towards the middle.
    w = bump(0.0, -0.38, 0.35, 0.15) * front
    out[1] = (w * 4 * mm)[:, None] * np.stack([-np.sign(fx) * 0.6, -np.ones_like(fx), 0 * fx], -1)
    # smiles: mouth corners up and out.
    for i, side in ((2, 1.0), (3, -1.0)):
        w = bump(side * 0.35, 0.55, 0.25, 0.2) * front * _smoothstep(0.0, 0.15, side * fx)
        out[i] = (w * 7 * mm)[:, None] * np.stack(
            [side * np.ones_like(fx), np.ones_like(fx) * 0.8, 0 * fx], -1
        )
    # squints: lower lids and cheeks up.
    for i, side in ((4, 1.0), (5, -1.0)):
        w = bump(side * 0.55, -0.05, 0.3, 0.15) * front * _smoothstep(0.0, 0.15, side * fx)
        out[i] = (w * 4 * mm)[:, None] * up
    # nose wrinkle: nose skin pulled up.
    out[6] = (3 * mm * bump(0.0, -0.05, 0.25, 0.2) * front)[:, None] * up
    # chin raise.
    out[7] = (5 * mm * bump(0.0, 0.9, 0.4, 0.15) * front)[:, None] * up
    return out.astype(np.float32)


# --------------------------------------------------------------------------------------------


def generate(
    size: int = 1024, seed: int = DEMO_SEED, mesh_resolution: tuple[int, int] = (96, 64)
) -> DemoCharacter:
    """Build the demo character (deterministic for a given ``size`` and ``seed``); the head mesh
    has ``mesh_resolution`` = (longitudes, latitudes) segments."""
    rng = np.random.default_rng(seed)
    base = _base_height(size, rng)
    wrinkles = _wrinkle_heights(size, rng)
    masks = _masks(size)
    return DemoCharacter(
        mesh=_head_mesh(*mesh_resolution),
        base_height=base,
        wrinkle_heights=wrinkles,
        state_names=STATE_NAMES,
        region_names=jimenez.REGION_NAMES,
        region_sides=tuple(z[2] for z in jimenez.ZONES),
        masks=masks,
        expressions=jimenez.expression_table(),
        seed=seed,
    )
