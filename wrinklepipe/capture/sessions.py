"""Capture sessions of a curved face, built apart from the capture stage's own assumptions.

:mod:`.synthetic` renders the session the stage was first tuned on (flat-facing furrows). This
module renders harder ones, from first principles and without any of the stage's code, with
the truth known exactly:

- **neutral shape**: a paraboloid dome (stronger across than along, apex off the ROI centre)
  scaled so that the smallest ``N_z`` over the ROI is ``nz_min`` (1: flat; 0.8: a cheek turned
  37 degrees away), optionally turned as a whole (``tilt_deg``);
- **creases** added to the expression's height (pixels, along the view axis): Gaussian
  **valleys** and **ridges**, **asymmetric** folds (steep on one side, gentle on the other),
  and **cosine** bands whose height rises and falls like a cosine (ridges *and* furrows, a
  forehead's horizontal lines), each faded smoothly at its ends;
- **camera**: orthographic along -Z, light at the camera (so ``I = E a N_z``, Lambertian), each
  pixel the mean of ``supersample^2`` point samples (a box-filtered sensor), albedo with
  freckles and fine texture, shot + read noise, quantised to 16 bits, linear;
- **registration**: the expression photo is seen through a smooth *non-rigid* warp ``psi``
  (affine + random low-frequency bending); landmarks on a jittered grid, exact in both photos;
- **texture space** through a known bent similarity ``tau`` (texel -> neutral photo pixel).

Truth: the wrinkle alone, relative to the neutral surface: the expression's normal ``n1``
rotated by the smallest rotation taking the neutral's normal ``n0`` to +Z (so the map, applied
on the neutral surface, gives back ``n1``; its tilt is the angle between ``n1`` and ``n0``). In
texture space its in-plane part is rotated by ``tau``'s Jacobian rotation. Normals are +Y up
(against the rows); slopes are central differences of the analytic heights (step 1e-4 px).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wrinklepipe.asset import Mesh

PROFILES = ("valley", "ridge", "asymmetric", "cosine")


@dataclass(frozen=True)
class Fold:
    """One crease, in units of the photo size S (positions, lengths, widths).

    ``width`` is the Gaussian sigma of a valley/ridge (the narrow side of an asymmetric fold,
    whose other side is ``asymmetry`` times wider) or the wavelength of a cosine band, whose
    extent across its lines is ``band`` (half-width). ``slope`` is the steepest slope of the
    profile (tan of its steepest tilt) before the end fades.
    """

    profile: str
    x: float
    y: float
    angle_deg: float = 0.0  # direction of the crease lines, degrees from +x towards +y (down)
    half_length: float = 0.2
    width: float = 0.015
    slope: float = 0.3
    bend: float = 0.0  # curvature of the centre line, 1/S
    asymmetry: float = 3.0
    band: float = 0.1


@dataclass(frozen=True)
class SessionOptions:
    """A session; the defaults are the issue-like forehead (cosine lines, N_z down to 0.99)."""

    size: int = 512
    texture_size: int = 256
    nz_min: float = 0.99
    dome_aspect: float = 0.5  # curvature along y relative to along x
    apex: tuple[float, float] = (0.52, 0.45)  # dome apex, fractions of S
    tilt_deg: float = 0.0  # the whole surface turned about the x axis (top away from camera)
    folds: tuple[Fold, ...] = ()  # () = FOREHEAD
    roi_radii: tuple[float, float] = (0.4, 0.36)  # ROI ellipse, fractions of S
    exposure: float = 0.85
    exposure_expression: float = 0.88
    read_noise: float = 0.0008
    shot_noise: float = 0.002  # sigma at luminance 1 (scales with sqrt(I))
    bits: int = 16
    supersample: int = 2
    warp_amplitude: float = 0.008  # non-rigid bending, fraction of S
    landmarks: int = 6  # landmarks: n x n jittered grid over the ROI
    texture_rotation_deg: float = -5.0
    seed: int = 3
    #: Also photograph the expression lit from one side (the direction towards that light in
    #: the camera frame, +X right, +Y up, +Z to the camera; ``None``: no side-lit photo). Same
    #: pose and camera as the expression photo (registered to it), exposure
    #: ``exposure_side``, its own noise (drawn from a separate generator: the other photos are
    #: the same with or without it).
    side_light: tuple[float, float, float] | None = None
    exposure_side: float = 0.7


#: Horizontal forehead lines that rise and fall like a cosine (the issue's independent case).
FOREHEAD: tuple[Fold, ...] = (
    Fold("cosine", 0.5, 0.46, angle_deg=2.0, half_length=0.42, width=0.07, slope=0.36,
         bend=0.4, band=0.3),
)  # fmt: skip

#: Separate creases of every profile, some near the dome's apex and some far out on its side.
MIXED: tuple[Fold, ...] = (
    Fold("valley", 0.50, 0.26, 0.0, 0.22, 0.016, 0.35, bend=0.8),
    Fold("ridge", 0.48, 0.36, 4.0, 0.24, 0.018, 0.3, bend=0.6),
    Fold("asymmetric", 0.30, 0.56, 70.0, 0.1, 0.012, 0.4, asymmetry=3.0),
    Fold("ridge", 0.70, 0.58, 105.0, 0.1, 0.02, 0.3),
    Fold("valley", 0.52, 0.72, -8.0, 0.18, 0.014, 0.35, bend=-0.6),
    Fold("asymmetric", 0.72, 0.34, 30.0, 0.09, 0.012, 0.35, asymmetry=0.35),
)

FAMILIES: dict[str, tuple[Fold, ...]] = {"forehead": FOREHEAD, "mixed": MIXED}


@dataclass
class Session:
    """Photos, landmarks, masks, neutral shape and truth (float32 images; float64 points)."""

    options: SessionOptions
    neutral: np.ndarray  # [S, S] linear luminance, quantised
    expression: np.ndarray  # [S, S]
    lm_neutral: np.ndarray  # [N, 2] neutral-photo pixels
    lm_expression: np.ndarray  # [N, 2] expression-photo pixels
    lm_texture: np.ndarray  # [N, 2] texture pixels
    roi: np.ndarray  # [S, S] in {0, 1}
    roi_texture: np.ndarray  # [T, T]
    neutral_normals: np.ndarray  # [S, S, 3] n0 in the camera frame (+Y up, +Z to the camera)
    expression_normals: np.ndarray  # [S, S, 3] n1
    truth_photo: np.ndarray  # [S, S, 3] the wrinkle alone (n1 relative to n0)
    truth_texture: np.ndarray  # [T, T, 3]
    height0: Callable[[np.ndarray, np.ndarray], np.ndarray] = field(repr=False)
    crease: Callable[[np.ndarray, np.ndarray], np.ndarray] = field(repr=False)
    psi: Callable = field(repr=False)  # expression px -> neutral px
    tau: Callable = field(repr=False)  # texture px -> neutral px
    side_lit: np.ndarray | None = None  # [S, S] the expression lit from ``side_light``


def _fold_height(x: np.ndarray, y: np.ndarray, s: float, f: Fold) -> np.ndarray:
    a = np.radians(f.angle_deg)
    dx, dy = x - f.x * s, y - f.y * s
    u = dx * np.cos(a) + dy * np.sin(a)  # along the lines
    v = -dx * np.sin(a) + dy * np.cos(a)  # across
    k = f.bend / s
    d = (v - k * u * u) / np.sqrt(1.0 + (2.0 * k * u) ** 2)  # distance to the bent centre line
    ends = np.exp(-((u / (f.half_length * s)) ** 6))
    w = f.width * s
    if f.profile == "cosine":
        # slope of A cos(2 pi d / w) peaks at 2 pi A / w
        amp = f.slope * w / (2.0 * np.pi)
        across = np.exp(-((d / (f.band * s)) ** 6))
        return amp * np.cos(2.0 * np.pi * d / w) * across * ends
    if f.profile in ("valley", "ridge"):
        # slope of A exp(-d^2 / 2 w^2) peaks at A / (w sqrt(e))
        amp = f.slope * w * np.sqrt(np.e)
        sign = -1.0 if f.profile == "valley" else 1.0
        return sign * amp * np.exp(-0.5 * (d / w) ** 2) * ends
    if f.profile == "asymmetric":
        # a valley whose two sides have different widths (C1 at the floor); depth set by the
        # narrow side's steepest slope
        w2 = w * f.asymmetry
        ws = np.where(d < 0, w, w2)
        amp = f.slope * min(w, w2) * np.sqrt(np.e)
        return -amp * np.exp(-0.5 * (d / ws) ** 2) * ends
    raise ValueError(f"unknown fold profile {f.profile!r}; expected one of {PROFILES}")


def _unit_normals(fn: Callable, x: np.ndarray, y: np.ndarray, eps: float = 1e-4) -> np.ndarray:
    """Camera-frame unit normals (+Y up) of the height ``fn(x, y)`` (pixels, towards camera)."""
    hx = (fn(x + eps, y) - fn(x - eps, y)) / (2 * eps)
    hr = (fn(x, y + eps) - fn(x, y - eps)) / (2 * eps)
    n = np.stack([-hx, hr, np.ones_like(hx)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def relative_to(n1: np.ndarray, n0: np.ndarray) -> np.ndarray:
    """``n1`` turned by the smallest rotation taking ``n0`` to +Z (Rodrigues), ``[..., 3]``."""
    n1 = np.asarray(n1, np.float64)
    n0 = np.asarray(n0, np.float64)
    # axis v = n0 x z = (n0y, -n0x, 0); cos = n0z; R x = x + v x x + v x (v x x) / (1 + cos)
    v = np.stack([n0[..., 1], -n0[..., 0], np.zeros_like(n0[..., 0])], axis=-1)
    vx = np.cross(v, n1)
    return n1 + vx + np.cross(v, vx) / (1.0 + n0[..., 2])[..., None]


def _albedo(s: float, rng: np.random.Generator) -> Callable:
    spots = rng.uniform(0.08, 0.92, (24, 2)) * s
    spot_r = rng.uniform(0.004, 0.012, 24) * s
    k = rng.uniform(2 * np.pi / (0.06 * s), 2 * np.pi / (0.015 * s), 40)
    th = rng.uniform(0, 2 * np.pi, 40)
    ph = rng.uniform(0, 2 * np.pi, 40)

    def albedo(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        a = 0.5 + 0.07 * np.sin(2 * np.pi * x / (0.8 * s) + 0.3) * np.cos(2 * np.pi * y / s)
        for (sx, sy), r in zip(spots, spot_r):  # 24 freckles, each vectorised
            a = a - 0.06 * np.exp(-((x - sx) ** 2 + (y - sy) ** 2) / (2 * r * r))
        for kk, t, p in zip(k, th, ph):  # fine skin texture: 40 plane waves
            a = a + 0.004 * np.sin(kk * (np.cos(t) * x + np.sin(t) * y) + p)
        return a

    return albedo


def _photo(
    shade: Callable, albedo: Callable, coords: Callable, n: int, ss: int, e: float
) -> np.ndarray:
    """Mean of ``ss^2`` point samples per pixel of ``e * albedo * N_z`` at ``coords(x, y)``."""
    out = np.zeros((n, n))
    for i in range(ss):  # ss^2 sub-pixel offsets, each over the whole image
        for j in range(ss):
            c = np.arange(n) + (j + 0.5) / ss
            r = np.arange(n) + (i + 0.5) / ss
            yy, xx = np.meshgrid(r, c, indexing="ij")
            px, py = coords(xx, yy)
            out += e * albedo(px, py) * shade(px, py)
    return out / (ss * ss)


def _invert(fn: Callable, tx: np.ndarray, ty: np.ndarray, iters: int = 80) -> tuple:
    """Positions ``q`` with ``fn(q) = t`` (fixed point; ``fn`` is near the identity up to an
    affine part, so the iteration uses its affine part's inverse)."""
    e = 1e-3
    x0, y0 = np.asarray(tx, np.float64).mean(), np.asarray(ty, np.float64).mean()
    fx, fy = fn(np.array([x0, x0 + e, x0]), np.array([y0, y0, y0 + e]))
    jac = np.array([[fx[1] - fx[0], fx[2] - fx[0]], [fy[1] - fy[0], fy[2] - fy[0]]]) / e
    inv = np.linalg.inv(jac)
    qx, qy = np.array(tx, np.float64), np.array(ty, np.float64)
    qx, qy = (
        x0 + inv[0, 0] * (qx - fx[0]) + inv[0, 1] * (qy - fy[0]),
        y0 + inv[1, 0] * (qx - fx[0]) + inv[1, 1] * (qy - fy[0]),
    )
    for _ in range(iters):  # a contraction: converges to ~1e-12 px
        px, py = fn(qx, qy)
        rx, ry = px - tx, py - ty
        qx = qx - (inv[0, 0] * rx + inv[0, 1] * ry)
        qy = qy - (inv[1, 0] * rx + inv[1, 1] * ry)
    return qx, qy


def make_session(options: SessionOptions | None = None) -> Session:
    """Render the session (deterministic for given options)."""
    o = options or SessionOptions()
    s = float(o.size)
    t_size = float(o.texture_size)
    rng = np.random.default_rng(o.seed)
    folds = o.folds or FOREHEAD
    idx = np.arange(o.size) + 0.5
    yy, xx = np.meshgrid(idx, idx, indexing="ij")

    def roi_at(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        rx, ry = o.roi_radii
        return ((x - 0.5 * s) / (rx * s)) ** 2 + ((y - 0.5 * s) / (ry * s)) ** 2 <= 1.0

    roi = roi_at(xx, yy)
    # Dome: h0 = -kappa (dx^2 + q dy^2) / 2, steepest slope kappa sqrt(dx^2 + q^2 dy^2) on the
    # ROI; kappa is set so the steepest slope over the ROI is tan(acos(nz_min)).
    ax, ay = o.apex[0] * s, o.apex[1] * s
    q = o.dome_aspect
    reach = float(np.sqrt((xx - ax) ** 2 + (q * (yy - ay)) ** 2)[roi].max())
    kappa = np.tan(np.arccos(np.clip(o.nz_min, 0.0, 1.0))) / reach
    tilt = np.tan(np.radians(o.tilt_deg))

    def height0(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return -0.5 * kappa * ((x - ax) ** 2 + q * (y - ay) ** 2) + tilt * (y - 0.5 * s)

    def crease(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        out = np.zeros(np.broadcast(x, y).shape)
        for f in folds:  # a handful of folds, each vectorised
            out = out + _fold_height(x, y, s, f)
        return out

    def height1(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return height0(x, y) + crease(x, y)

    psi = _expression_warp(o.warp_amplitude * s, s, rng)

    theta = np.radians(o.texture_rotation_deg)
    scale = 0.85 * s / t_size

    def tau(tx: np.ndarray, ty: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ux, uy = tx - 0.5 * t_size, ty - 0.5 * t_size
        px = 0.5 * s + scale * (np.cos(theta) * ux - np.sin(theta) * uy)
        py = 0.5 * s + scale * (np.sin(theta) * ux + np.cos(theta) * uy)
        return px + 0.01 * s * np.sin(np.pi * ty / t_size), py

    albedo = _albedo(s, np.random.default_rng(int(rng.integers(1 << 30))))

    def shade0(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return _unit_normals(height0, x, y)[..., 2]

    def shade1(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return _unit_normals(height1, x, y)[..., 2]

    ss = max(int(o.supersample), 1)
    neutral = _photo(shade0, albedo, lambda x, y: (x, y), o.size, ss, o.exposure)
    expression = _photo(shade1, albedo, psi, o.size, ss, o.exposure_expression)
    levels = float(2**o.bits - 1)

    def develop(img: np.ndarray, gen: np.random.Generator) -> np.ndarray:
        sigma = np.sqrt(o.read_noise**2 + o.shot_noise**2 * np.maximum(img, 0.0))
        noisy = img + gen.normal(0.0, 1.0, img.shape) * sigma
        return np.round(np.clip(noisy, 0.0, 1.0) * levels) / levels

    photos = [develop(img, rng) for img in (neutral, expression)]
    side_lit = None
    if o.side_light is not None:
        light = np.asarray(o.side_light, np.float64)
        light = light / np.linalg.norm(light)

        def shade_side(x: np.ndarray, y: np.ndarray) -> np.ndarray:
            return np.maximum(_unit_normals(height1, x, y) @ light, 0.0)  # Lambert, attached

        side = _photo(shade_side, albedo, psi, o.size, ss, o.exposure_side)
        side_lit = develop(side, np.random.default_rng([o.seed, 1])).astype(np.float32)

    lx, ly = _landmarks(o, s, rng)
    qx, qy = _invert(psi, lx, ly)
    tx, ty = _invert(tau, lx, ly)

    n0 = _unit_normals(height0, xx, yy)
    n1 = _unit_normals(height1, xx, yy)
    truth_photo = relative_to(n1, n0)
    truth_texture, tpx, tpy = _truth_texture(tau, height0, height1, o.texture_size)

    return Session(
        options=o,
        neutral=photos[0].astype(np.float32),
        expression=photos[1].astype(np.float32),
        lm_neutral=np.stack([lx, ly], axis=-1),
        lm_expression=np.stack([qx, qy], axis=-1),
        lm_texture=np.stack([tx, ty], axis=-1),
        roi=roi.astype(np.float32),
        roi_texture=roi_at(tpx, tpy).astype(np.float32),
        neutral_normals=n0.astype(np.float32),
        expression_normals=n1.astype(np.float32),
        truth_photo=truth_photo.astype(np.float32),
        truth_texture=truth_texture.astype(np.float32),
        side_lit=side_lit,
        height0=height0,
        crease=crease,
        psi=psi,
        tau=tau,
    )


def _expression_warp(amp: float, s: float, rng: np.random.Generator) -> Callable:
    """The non-rigid warp psi: expression pixel -> neutral pixel (an affine map and four
    smooth bends of amplitude ``amp`` pixels, drawn from ``rng``)."""
    freq = rng.uniform(0.6, 1.8, (4, 2)) * 2 * np.pi / s
    phase = rng.uniform(0, 2 * np.pi, (4, 2))
    coef = rng.normal(0, 1, (4, 2))
    coef = coef / np.abs(coef).sum(axis=0)
    aff = np.array([[1.02, 0.015], [-0.01, 0.985]])
    shift = np.array([0.006, -0.004]) * s

    def psi(qx: np.ndarray, qy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cx, cy = qx - 0.5 * s, qy - 0.5 * s
        px = 0.5 * s + aff[0, 0] * cx + aff[0, 1] * cy + shift[0]
        py = 0.5 * s + aff[1, 0] * cx + aff[1, 1] * cy + shift[1]
        for k in range(4):  # four smooth bends
            arg = freq[k, 0] * qx + freq[k, 1] * qy
            px = px + amp * coef[k, 0] * np.sin(arg + phase[k, 0])
            py = py + amp * coef[k, 1] * np.sin(arg + phase[k, 1])
        return px, py

    return psi


def _landmarks(
    o: SessionOptions, s: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """The landmarks in the neutral photo: a jittered grid over the ROI's box."""
    rx, ry = o.roi_radii
    gx = np.linspace(0.5 - 1.05 * rx, 0.5 + 1.05 * rx, o.landmarks) * s
    gy = np.linspace(0.5 - 1.05 * ry, 0.5 + 1.05 * ry, o.landmarks) * s
    my, mx = np.meshgrid(gy, gx, indexing="ij")
    jit = rng.uniform(-0.015, 0.015, (2,) + mx.shape) * s
    lx = np.clip((mx + jit[0]).ravel(), 1.0, s - 1.0)
    ly = np.clip((my + jit[1]).ravel(), 1.0, s - 1.0)
    return lx, ly


def _truth_texture(
    tau: Callable, height0: Callable, height1: Callable, size: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The true wrinkle normals in texture space (relative to the neutral, turned by the
    texture warp ``tau``'s rotation) and the photo pixels ``tau`` puts each texel at."""
    tidx = np.arange(size) + 0.5
    tyy, txx = np.meshgrid(tidx, tidx, indexing="ij")
    tpx, tpy = tau(txx, tyy)
    tn = relative_to(_unit_normals(height1, tpx, tpy), _unit_normals(height0, tpx, tpy))
    e = 1e-3
    ax1, ay1 = tau(txx + e, tyy)
    ax0, ay0 = tau(txx - e, tyy)
    bx1, by1 = tau(txx, tyy + e)
    bx0, by0 = tau(txx, tyy - e)
    ang = np.arctan2((ay1 - ay0) - (bx1 - bx0), (ax1 - ax0) + (by1 - by0))
    vx, vy = tn[..., 0], -tn[..., 1]  # photo pixel frame (y down)
    rxx = np.cos(ang) * vx + np.sin(ang) * vy
    ryy = -np.sin(ang) * vx + np.cos(ang) * vy
    truth_texture = np.stack([rxx, -ryy, tn[..., 2]], axis=-1)
    truth_texture /= np.linalg.norm(truth_texture, axis=-1, keepdims=True)
    return truth_texture, tpx, tpy


def neutral_mesh(session: Session, step: float = 8.0, world_scale: float = 0.01) -> Mesh:
    """The neutral surface as a mesh a character artist would hand over: a grid every ``step``
    photo pixels over the ROI's box, positions in world units (Y up, the face looking down +Z,
    then turned 20 degrees about Y and moved, so the camera must be found from the landmarks),
    UVs from ``tau`` (glTF convention) and analytic vertex normals."""
    o = session.options
    s = float(o.size)
    t = float(o.texture_size)
    rx, ry = o.roi_radii
    xs = np.arange((0.5 - 1.2 * rx) * s, (0.5 + 1.2 * rx) * s + step, step)
    ys = np.arange((0.5 - 1.2 * ry) * s, (0.5 + 1.2 * ry) * s + step, step)
    gy, gx = np.meshgrid(ys, xs, indexing="ij")
    px, py = gx.ravel(), gy.ravel()
    h = session.height0(px, py)
    local = np.stack([px, -py, h], axis=-1) * world_scale
    n = _unit_normals(session.height0, px, py)
    a = np.radians(20.0)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    pos = local @ rot.T + np.array([0.3, 1.6, -0.2])
    tu, tv = _invert(session.tau, px, py)
    uv = np.stack([tu / t, tv / t], axis=-1)
    nx, ny = len(xs), len(ys)
    k = np.arange(nx * ny).reshape(ny, nx)
    a0, b0, c0, d0 = k[:-1, :-1], k[:-1, 1:], k[1:, :-1], k[1:, 1:]
    # counter-clockwise seen from +Z (rows run down in the photo, so (a, c, b) is CCW)
    tris = np.concatenate(
        [np.stack([a0, c0, b0], -1).reshape(-1, 3), np.stack([b0, c0, d0], -1).reshape(-1, 3)]
    )
    return Mesh(
        positions=pos.astype(np.float32),
        indices=tris.astype(np.uint32),
        uvs=uv.astype(np.float32),
        normals=(n @ rot.T).astype(np.float32),
        name="neutral_face",
    )
