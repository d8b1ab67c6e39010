"""A synthetic capture session with known truth: two flash photos of a creased face patch.

Everything is an analytic function of continuous pixel position (x right, y down, origin at the
top-left corner; pixel centres at half integers), evaluated in float64, so the photos need no
resampling and the truth needs no finite differences of sampled data (slopes are central
differences of the analytic height with a 1e-4 px step, exact to ~1e-8).

- neutral height ``h0``: a gentle dome (the face, tilts up to ~8 degrees);
- crease height ``c``: curved furrows of several widths, depths and orientations, each with
  optional raised shoulders (skin pushed up beside a fold), faded smoothly at their ends;
- albedo: a low-frequency variation plus freckles (cancelled by the ratio only if registered);
- photos under a light at the camera (Lambertian, ``I = E a N_z``), with a small exposure
  difference and Gaussian noise; the expression photo is seen through a known smooth warp
  ``psi`` (expression pixel -> neutral pixel: an affine part plus sinusoidal bending);
- texture space: a known map ``tau`` (texel -> neutral photo pixel: similarity with a 6 degree
  rotation plus a bend); truth normals in texture space are the crease normals at ``tau(t)``
  with their in-plane part rotated into the texture frame (the rotation of ``tau``'s Jacobian).

Landmarks: a jittered grid of texels ``t_i``; ``p_i = tau(t_i)`` in the neutral photo and
``q_i = psi^-1(p_i)`` in the expression photo (fixed-point iteration).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wrinklepipe.model import normalize


@dataclass(frozen=True)
class Crease:
    """One furrow, in units of the photo size S (positions, lengths) and of its width (depth)."""

    x: float
    y: float
    angle_deg: float  # direction of the crease line, degrees from +x towards +y (down)
    half_length: float
    width: float  # Gaussian sigma of the cross profile
    depth: float  # in widths: 1.0 gives a steepest slope of ~31 degrees
    bend: float = 0.0  # curvature of the centre line, 1/S
    shoulder: float = 0.3  # raised shoulders, as a fraction of the depth


DEFAULT_CREASES: tuple[Crease, ...] = (
    Crease(0.50, 0.22, 0.0, 0.26, 0.012, 0.9, bend=0.9),
    Crease(0.50, 0.31, 0.0, 0.30, 0.014, 1.0, bend=0.7),
    Crease(0.44, 0.47, 98.0, 0.08, 0.012, 1.1),
    Crease(0.57, 0.47, 82.0, 0.08, 0.011, 1.0),
    Crease(0.20, 0.62, 20.0, 0.10, 0.010, 0.8),
    Crease(0.21, 0.72, -15.0, 0.10, 0.010, 0.9),
    Crease(0.72, 0.72, 60.0, 0.14, 0.028, 0.8, bend=-0.5),
)


@dataclass(frozen=True)
class SceneOptions:
    """Parameters of the synthetic session (defaults used by the tests and the benchmark)."""

    size: int = 192  # photo width and height, px
    texture_size: int = 128  # texture width and height, px
    creases: tuple[Crease, ...] = DEFAULT_CREASES
    exposure: float = 0.9
    exposure_expression: float = 0.93  # the second flash is a little brighter
    noise: float = 0.002
    grid: int = 6  # landmarks: grid x grid
    seed: int = 7
    texture_rotation_deg: float = 6.0


@dataclass
class Scene:
    """Photos, landmarks, masks and truth of a synthetic session (float32 images)."""

    neutral: np.ndarray  # [S, S] linear luminance
    expression: np.ndarray  # [S, S]
    lm_neutral: np.ndarray  # [N, 2] pixels
    lm_expression: np.ndarray  # [N, 2]
    lm_texture: np.ndarray  # [N, 2] texture pixels
    roi: np.ndarray  # [S, S] in {0, 1}
    truth_photo: np.ndarray  # [S, S, 3] crease normals, neutral photo space
    truth_texture: np.ndarray  # [T, T, 3] crease normals, texture space
    roi_texture: np.ndarray  # [T, T] in {0, 1}
    psi: object = field(repr=False, default=None)  # expression px -> neutral px
    tau: object = field(repr=False, default=None)  # texture px -> neutral px


def _crease_height(x: np.ndarray, y: np.ndarray, s: float, cr: Crease) -> np.ndarray:
    dx = x - cr.x * s
    dy = y - cr.y * s
    a = np.radians(cr.angle_deg)
    u = dx * np.cos(a) + dy * np.sin(a)
    v = -dx * np.sin(a) + dy * np.cos(a)
    k = cr.bend / s
    d = (v - k * u * u) / np.sqrt(1.0 + (2.0 * k * u) ** 2)
    w = cr.width * s
    env = np.exp(-((u / (cr.half_length * s)) ** 6))
    depth = cr.depth * w
    prof = -np.exp(-0.5 * (d / w) ** 2)
    prof = prof + cr.shoulder * np.exp(-0.5 * ((np.abs(d) - 2.2 * w) / w) ** 2)
    return depth * env * prof


def crease_height(
    x: np.ndarray, y: np.ndarray, s: float, creases: tuple[Crease, ...]
) -> np.ndarray:
    """Sum of the creases' heights (pixels) at positions (float64 arrays)."""
    out = np.zeros(np.broadcast(x, y).shape)
    for cr in creases:  # a handful of creases, each vectorised over all positions
        out += _crease_height(x, y, s, cr)
    return out


def dome_height(x: np.ndarray, y: np.ndarray, s: float) -> np.ndarray:
    """The neutral face patch: a gentle dome (pixels)."""
    return 0.12 * s * np.exp(-((x - 0.5 * s) ** 2 + (y - 0.5 * s) ** 2) / (2 * (0.55 * s) ** 2))


def normal_of(fn: object, x: np.ndarray, y: np.ndarray, eps: float = 1e-4) -> np.ndarray:
    """Unit normal (+Y up) of a height function ``fn(x, y)`` by central differences."""
    hx = (fn(x + eps, y) - fn(x - eps, y)) / (2 * eps)  # type: ignore[operator]
    hy_row = (fn(x, y + eps) - fn(x, y - eps)) / (2 * eps)  # type: ignore[operator]
    # N = normalize(-dh/dx, -dh/dy_up, 1) and dh/dy_up = -dh/drow.
    n = np.stack([-hx, hy_row, np.ones_like(hx)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def _albedo(x: np.ndarray, y: np.ndarray, s: float, rng: np.random.Generator) -> np.ndarray:
    a = 0.5 + 0.08 * np.sin(2 * np.pi * x / (0.7 * s)) * np.cos(2 * np.pi * y / (0.9 * s))
    spots = rng.uniform(0.05, 0.95, size=(14, 2)) * s
    for sx, sy in spots:  # 14 freckles
        a = a - 0.08 * np.exp(-((x - sx) ** 2 + (y - sy) ** 2) / (2 * (0.015 * s) ** 2))
    return a


def make_scene(options: SceneOptions | None = None) -> Scene:
    """Render the session; deterministic for given options."""
    o = options or SceneOptions()
    s = float(o.size)
    t_size = float(o.texture_size)
    rng = np.random.default_rng(o.seed)
    spot_seed = int(rng.integers(1 << 30))

    def psi(qx: np.ndarray, qy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        f = s / 192.0
        cx = qx - 0.5 * s
        cy = qy - 0.5 * s
        px = qx + f * 3.0 + 0.03 * cx + 0.01 * cy + f * 2.0 * np.sin(2 * np.pi * qy / s)
        py = qy - f * 2.0 + 0.02 * cy - 0.01 * cx + f * 1.5 * np.sin(2 * np.pi * qx / s)
        return px, py

    theta = np.radians(o.texture_rotation_deg)
    scale = 0.8 * s / t_size

    def tau(tx: np.ndarray, ty: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ux = tx - 0.5 * t_size
        uy = ty - 0.5 * t_size
        px = 0.5 * s + scale * (np.cos(theta) * ux - np.sin(theta) * uy)
        py = 0.5 * s + scale * (np.sin(theta) * ux + np.cos(theta) * uy)
        px = px + 0.015 * s * np.sin(np.pi * ty / t_size)
        return px, py

    def height1(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return dome_height(x, y, s) + crease_height(x, y, s, o.creases)

    def height0(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return dome_height(x, y, s)

    def crease(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return crease_height(x, y, s, o.creases)

    idx = np.arange(o.size) + 0.5
    yy, xx = np.meshgrid(idx, idx, indexing="ij")

    neutral = o.exposure * _albedo(xx, yy, s, np.random.default_rng(spot_seed))
    neutral = neutral * normal_of(height0, xx, yy)[..., 2]
    px, py = psi(xx, yy)
    expression = o.exposure_expression * _albedo(px, py, s, np.random.default_rng(spot_seed))
    expression = expression * normal_of(height1, px, py)[..., 2]
    neutral = neutral + rng.normal(0.0, o.noise, neutral.shape)
    expression = expression + rng.normal(0.0, o.noise, expression.shape)

    # Landmarks: a jittered grid of texels.
    g = np.linspace(0.1, 0.9, o.grid) * t_size
    gy, gx = np.meshgrid(g, g, indexing="ij")
    jit = rng.uniform(-0.02, 0.02, size=(2,) + gx.shape) * t_size
    tx = (gx + jit[0]).ravel()
    ty = (gy + jit[1]).ravel()
    npx, npy = tau(tx, ty)
    qx, qy = npx.copy(), npy.copy()
    for _ in range(60):  # invert psi by fixed-point iteration (a contraction here)
        fx, fy = psi(qx, qy)
        qx, qy = qx - (fx - npx), qy - (fy - npy)

    # ROI: an ellipse around the creased area, in the neutral photo.
    def roi_at(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return ((x - 0.5 * s) / (0.42 * s)) ** 2 + ((y - 0.5 * s) / (0.40 * s)) ** 2 <= 1.0

    truth_photo = normal_of(crease, xx, yy)
    tidx = np.arange(o.texture_size) + 0.5
    tyy, txx = np.meshgrid(tidx, tidx, indexing="ij")
    tpx, tpy = tau(txx, tyy)
    tn = normal_of(crease, tpx, tpy)
    # Rotation of tau's Jacobian at each texel (polar decomposition angle).
    e = 1e-3
    ax1, ay1 = tau(txx + e, tyy)
    ax0, ay0 = tau(txx - e, tyy)
    bx1, by1 = tau(txx, tyy + e)
    bx0, by0 = tau(txx, tyy - e)
    j00 = (ax1 - ax0) / (2 * e)
    j10 = (ay1 - ay0) / (2 * e)
    j01 = (bx1 - bx0) / (2 * e)
    j11 = (by1 - by0) / (2 * e)
    ang = np.arctan2(j10 - j01, j00 + j11)
    vx, vy = tn[..., 0], -tn[..., 1]  # pixel frame, y down
    rx = np.cos(ang) * vx + np.sin(ang) * vy
    ry = -np.sin(ang) * vx + np.cos(ang) * vy
    truth_texture = normalize(np.stack([rx, -ry, tn[..., 2]], axis=-1))

    return Scene(
        neutral=neutral.astype(np.float32),
        expression=expression.astype(np.float32),
        lm_neutral=np.stack([npx, npy], axis=-1),
        lm_expression=np.stack([qx, qy], axis=-1),
        lm_texture=np.stack([tx, ty], axis=-1),
        roi=roi_at(xx, yy).astype(np.float32),
        truth_photo=truth_photo.astype(np.float32),
        truth_texture=truth_texture,
        roi_texture=roi_at(tpx, tpy).astype(np.float32),
        psi=psi,
        tau=tau,
    )
