"""The capture stage as one pure function on arrays: two photos -> a wrinkle normal map.

Steps (Dutreve et al. section 3, with the guards and the orientation priors of this package):

1. thin-plate warp of the expression photo onto the neutral photo (landmarks ``expr -> neutral``);
2. ratio image ``R = I'_d / I`` on linear luminance, guarded, blurred (:mod:`.ratio`);
3. ``N'_z = R N_z`` and the orientation: the priors of :mod:`.orientation` and the shape from
   shading of :mod:`.sfs` (which uses the neutral's normals ``n0`` when they are given), every
   method for the report, each with its ratio residual (how well it explains R);
4. ROI masking (outside: the flat normal ``(0, 0, 1)``; a soft mask scales the in-plane part);
5. thin-plate warp from photo space into the character's texture space, with the normals'
   in-plane part rotated into the texture's tangent frame.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from wrinklepipe.capture import sfs as S
from wrinklepipe.capture import slopes
from wrinklepipe.capture import warp as W
from wrinklepipe.capture.orientation import (
    METHODS,
    PRIORS,
    OrientationOptions,
    integrability_residual,
    orient,
)
from wrinklepipe.capture.ratio import (
    RatioOptions,
    RatioResult,
    blurred_noise,
    masked_blur,
    pixel_noise,
    ratio_image,
)
from wrinklepipe.model import normalize


@dataclass(frozen=True)
class CaptureOptions:
    """All parameters of the capture stage, with the defaults ``wrinklepipe capture`` uses."""

    ratio: RatioOptions = field(default_factory=RatioOptions)
    orientation: OrientationOptions = field(default_factory=OrientationOptions)
    sfs: S.SfsOptions = field(default_factory=S.SfsOptions)
    #: Grid step (pixels) at which the thin-plate splines are evaluated: 1 = every pixel (exact),
    #: 0 = every pixel up to 4 Mpx and every second pixel above (cubic refinement between).
    warp_step: int = 0
    #: Spline order of the resampling through the warps (the expression photo onto the neutral,
    #: the normals into texture space): 3 = cubic (measured: R's error against the true ratio
    #: 0.0065 -> 0.0054 RMS, the texture warp's own tilt loss 1.1 % -> 0.1 % of a flat map's
    #: error), 1 = bilinear.
    sample_order: int = 3
    #: Rotate normals into the texture's tangent frame (the photo -> texture map may rotate).
    rotate_normals: bool = True
    #: Also compute the other orientation methods (for the report's side-by-side comparison;
    #: ``sfs`` only when the neutral's normals are given).
    compare_methods: bool = True
    #: Factor applied to every Gaussian sigma (ratio blur, structure tensor, furrow scale), which
    #: are given for a photo up to ``SCALE_REFERENCE_PX`` wide; ``None``: ``max(1, width / 256)``
    #: (wrinkles are wider in pixels in a larger photo of the same face).
    scale: float | None = None
    #: Flat skin in the ``sfs`` map: where R stays at 1 within this many times its noise over
    #: a window (``flat_window`` px before the sigma scale), the wrinkle normal is blended
    #: to flat (the neutral itself), by ``exp(-m / 2 (level noise)^2)``, ``m`` the window's mean
    #: of ``(R - 1)^2``. Why: R = 1 where the skin keeps the neutral's shape but also wherever
    #: the expression's slope has the neutral's magnitude in another direction; near the
    #: dome's apex the solve tilts flat skin that way at no cost in R (a "bow tie" between the
    #: creases and the apex, measured on mixed N_z 0.9). 0 turns it off; not used with a
    #: side-lit photo (which fixes those slopes).
    flat_level: float = 3.0
    flat_window: float = 3.0


def flat_skin(
    ratio: np.ndarray, valid: np.ndarray, roi: np.ndarray, noise: float, level: float, window: float
) -> np.ndarray:
    """How flat the skin looks per pixel, 0..1: ``exp(-m / 2 (level noise)^2)`` with ``m`` the
    Gaussian-window (``window`` px) mean of ``(R - 1)^2`` over valid ROI pixels; 0 where
    ``noise`` is 0."""
    if noise <= 0 or level <= 0:
        return np.zeros(np.shape(ratio))
    wgt = (np.asarray(valid, bool) & (np.asarray(roi) > 0.5)).astype(np.float64)
    dev = (np.asarray(ratio, np.float64) - 1.0) ** 2 * wgt
    m = masked_blur(dev, wgt, window) if window > 0 else dev
    return np.exp(-0.5 * m / (level * noise) ** 2)


#: Photo width (pixels) at which the sigmas apply unscaled (session 7: 384 -> 256). Measured
#: with the sessions' faces photographed larger (creases wider in pixels in proportion):
#: forehead N_z 0.99 at 384 px 1.13x / 0.46x / 39 % (scale 1, `auto` kept the prior) -> 0.30x /
#: 0.18x / 93 % (1.5); forehead 0.9 at 384 px 0.70x -> 0.38x; the 512 px forehead 0.555x ->
#: 0.33x (2); mixed 0.9 at 384 px 0.39x -> 0.41x; the flat-facing synthetic scene's
#: `integrable` at 384 / 512 / 768 / 1024 px 3.74 / 3.41 / 3.27 / 3.39 -> 2.56 / 2.56 / 3.52 /
#: 2.70 degrees. At 256 px and below nothing changes.
SCALE_REFERENCE_PX = 256.0


def sigma_scale(width: int, options: CaptureOptions) -> float:
    """The factor applied to the sigmas for a photo ``width`` pixels wide."""
    if options.scale is not None:
        return float(options.scale)
    return max(1.0, width / SCALE_REFERENCE_PX)


@dataclass(frozen=True)
class WarpStats:
    """Landmark residuals (pixels of the image sampled from) of one warp."""

    fit: np.ndarray  # dense map at each landmark vs its target (grid approximation error)
    leave_one_out: np.ndarray  # spline fitted without the landmark vs the landmark

    def summary(self) -> dict:
        loo = self.leave_one_out[np.isfinite(self.leave_one_out)]
        return {
            "count": len(self.fit),
            "fit_max_px": float(self.fit.max()) if len(self.fit) else 0.0,
            "fit_mean_px": float(self.fit.mean()) if len(self.fit) else 0.0,
            "leave_one_out_max_px": float(loo.max()) if len(loo) else None,
            "leave_one_out_mean_px": float(loo.mean()) if len(loo) else None,
            "leave_one_out_worst_index": int(np.nanargmax(self.leave_one_out))
            if len(loo)
            else None,
        }


@dataclass(frozen=True)
class SideRatio:
    """The side-lit photo over the flash-lit expression photo, both registered onto the
    neutral photo: ``S = k n1 . l / N1_z`` (albedo cancels), divided by ``k``."""

    ratio: np.ndarray  # [H, W] S / k, blurred as R; 1 where not valid
    light: np.ndarray  # [3] unit direction towards the side light (camera frame)
    exposure: float  # k: the side light's level over the flash's (median over the ROI)


def side_ratio(
    side_warped: np.ndarray,
    expression_warped: np.ndarray,
    valid: np.ndarray,
    roi: np.ndarray,
    n0: np.ndarray,
    light: np.ndarray | None,
    blur: float,
) -> SideRatio:
    """``S = I_side / I'`` on the neutral photo's pixels, blurred as R (``blur`` px), divided
    by its level ``k``: the median over the ROI of ``S`` over the neutral's own
    ``n0 . l / N0_z`` (the model at the neutral's slopes; the neutral's normals are only known
    inside the ROI)."""
    if light is None:
        raise ValueError("a side-lit photo needs its light direction (side_light)")
    l_vec = np.asarray(light, np.float64)
    if l_vec.shape != (3,) or not np.all(np.isfinite(l_vec)) or np.linalg.norm(l_vec) == 0:
        raise ValueError(f"side_light must be a 3-vector, got {light!r}")
    l_vec = l_vec / np.linalg.norm(l_vec)
    if l_vec[2] <= 0.2:
        raise ValueError("side_light must point towards the camera's side (z > 0.2)")
    ie = np.asarray(expression_warped, np.float64)
    ok = np.asarray(valid, bool) & (ie > 1e-6)
    raw = np.where(ok, np.asarray(side_warped, np.float64) / np.where(ok, ie, 1.0), 1.0)
    s_img = masked_blur(raw, ok.astype(np.float64), blur)
    g0 = slopes.neutral_slopes(n0)
    base = l_vec[2] - l_vec[0] * g0[..., 0] + l_vec[1] * g0[..., 1]
    ref = ok & (np.asarray(roi, np.float64) > 0.5)
    # the median over the ROI: a crease adds l . q, of both signs across it (its two flanks)
    k = float(np.median(s_img[ref] / base[ref])) if ref.any() else 1.0
    k = k if k > 1e-6 else 1.0
    return SideRatio(np.where(ok, s_img / k, base).astype(np.float64), l_vec, k)


@dataclass
class CaptureResult:
    """Everything the stage computed; ``normal_texture`` is the product."""

    expression_warped: np.ndarray  # [H, W] luminance of I'_d
    ratio: RatioResult
    method: str
    normal_photo: dict[str, np.ndarray]  # method -> [H, W, 3], ROI applied
    normal_texture: dict[str, np.ndarray]  # method -> [T, Tw, 3]
    roi_texture: np.ndarray  # [T, Tw]
    inside_texture: np.ndarray  # [T, Tw] bool: texel maps into the photo
    warp_expression: WarpStats
    warp_texture: WarpStats
    integrability: dict[str, float]  # method -> residual in the ROI (photo space)
    sigma_scale: float = 1.0  # factor the sigmas were multiplied by
    #: method -> RMS of (ratio of the method's integrated height - R) over the ROI
    ratio_residual: dict[str, float] = field(default_factory=dict)
    sfs: S.SfsResult | None = None  # the shape-from-shading solve (starts, exposure)
    side: SideRatio | None = None  # the side-lit photo's ratio (when one was given)
    neutral_shape: str = "facing the camera"  # where n0 came from

    @property
    def normal(self) -> np.ndarray:
        """The wrinkle normal map of the chosen method, texture space."""
        return self.normal_texture[self.method]


#: ``auto`` solves (``sfs``) when the neutral turns from the camera beyond this N_z somewhere
#: in the ROI (1st percentile). Measured (docs/capture.md): where the neutral's N_z stays above
#: 0.99 the sign of a crease is barely in the data and the integrable prior's angular error is
#: lower; at N_z 0.9 and 0.8 the solve is better in angle, tilt and orientation.
AUTO_SFS_BELOW_NZ = 0.97


#: ``auto`` on a nearly flat neutral takes the solve only where the photos fixed most crease
#: signs: at most this share of its crease pixels ambiguous (``SfsResult.ambiguous_fraction``).
AUTO_MAX_AMBIGUOUS = 0.5


def solve_explains_better(result: S.SfsResult) -> bool:
    """Whether the solve's winning start is not its first (the integrable prior): another start
    ended with a residual lower by more than ``SfsOptions.tie``, so the photos, not the prior,
    decided the sign; and no other solution explaining R as well disagrees on most crease signs
    (``AUTO_MAX_AMBIGUOUS``). ``auto`` takes ``sfs`` then even on a nearly flat neutral.
    Measured: nearly flat foreheads with ridges and furrows (the prior's mirror or the coarse
    solve wins, 10-16 % ambiguous; the solve orients 77-91 % right against the prior's 8-53 %);
    the nearly flat mixed session (80 % ambiguous: equally good heights disagree, the prior is
    kept); the example session (all dents: the prior's height without its broad part ends 22 %
    lower than the prior, and the solve is the better map there, 3.15 against 3.36 degrees)."""
    first = next(iter(result.starts), None)
    return (
        first is not None
        and result.start != first
        and result.ambiguous_fraction <= AUTO_MAX_AMBIGUOUS
    )


def resolve_method(method: str, neutral_nz: np.ndarray | None) -> str:
    """``auto``: ``sfs`` when the neutral's normals are known and turn from the camera (N_z
    below ``AUTO_SFS_BELOW_NZ`` on 1 % of the ROI), ``integrable`` otherwise; other names are
    themselves. ``neutral_nz``: the neutral's N_z over the ROI (``None``: not known)."""
    if method == "auto":
        if neutral_nz is None or np.size(neutral_nz) == 0:
            return "integrable"
        turned = float(np.percentile(neutral_nz, 1.0)) < AUTO_SFS_BELOW_NZ
        return "sfs" if turned else "integrable"
    if method not in METHODS:
        raise ValueError(f"unknown orientation {method!r}; expected auto or {', '.join(METHODS)}")
    return method


def apply_roi(normals: np.ndarray, roi: np.ndarray) -> np.ndarray:
    """Scale the in-plane part by the ROI weight (0..1) and recompute z: flat outside."""
    n = np.asarray(normals, np.float32)
    m = np.clip(np.asarray(roi, np.float32), 0.0, 1.0)[..., None]
    xy = n[..., :2] * m
    z = np.sqrt(np.clip(1.0 - np.sum(xy * xy, axis=-1), 0.0, 1.0))
    return np.concatenate([xy, z[..., None]], axis=-1).astype(np.float32)


def _stats(field_: np.ndarray, dst: np.ndarray, src: np.ndarray) -> WarpStats:
    return WarpStats(W.landmark_residuals(field_, dst, src), W.leave_one_out(dst, src))


def capture(
    neutral: np.ndarray,
    expression: np.ndarray,
    lm_neutral: np.ndarray,
    lm_expression: np.ndarray,
    lm_photo: np.ndarray,
    lm_texture: np.ndarray,
    texture_shape: tuple[int, int],
    roi: np.ndarray | None = None,
    nz_neutral: np.ndarray | float = 1.0,
    options: CaptureOptions | None = None,
    neutral_normals: np.ndarray | None = None,
    side_lit: np.ndarray | None = None,
    side_light: np.ndarray | None = None,
) -> CaptureResult:
    """Run the capture on linear luminance photos ``[H, W]`` (and ``[H', W']``).

    Landmarks are ``[N, 2]`` pixel positions (x, y; origin at the top-left corner): neutral and
    expression photo pairs for the first warp; ``lm_photo`` (neutral photo) and ``lm_texture``
    (texture pixels) for the second. ``texture_shape`` is ``(height, width)`` of the output.
    ``neutral_normals`` ``[H, W, 3]`` is the neutral face's shape seen from the camera (+Y up,
    +Z towards the camera); it replaces ``nz_neutral`` (its z is the per-pixel N_z).
    ``side_lit`` ``[H', W']``: a photo of the expression (same pose and camera as
    ``expression``, so the same landmarks) lit from the direction ``side_light`` (towards the
    light, camera frame) instead of the flash; with it the solve sees every crease's sign
    (:func:`side_ratio`), and ``auto`` takes ``sfs``. Needs ``neutral_normals``.
    """
    o = options or CaptureOptions()
    i0 = np.asarray(neutral, np.float32)
    i1 = np.asarray(expression, np.float32)
    h, w = i0.shape
    k = sigma_scale(w, o)
    ratio_opts = dataclasses.replace(
        o.ratio, blur_sigma=o.ratio.blur_sigma * k, exposure_ring=o.ratio.exposure_ring * k
    )
    orient_opts = dataclasses.replace(
        o.orientation,
        structure_sigma=o.orientation.structure_sigma * k,
        furrow_sigma=o.orientation.furrow_sigma * k,
    )
    roi_m = np.ones((h, w), np.float32) if roi is None else np.asarray(roi, np.float32)

    # 1. expression -> neutral.
    warp1 = W.fit_tps(lm_neutral, lm_expression)
    map1 = W.dense_map(warp1, (h, w), o.warp_step)
    warped, inside = W.sample(i1, map1, o.sample_order)
    if side_lit is not None and neutral_normals is None:
        raise ValueError("a side-lit photo needs the neutral's normals (neutral_normals)")

    # 2-3. ratio, tilt, orientation.
    n0, nz_neutral, shape_src = _neutral_shape(neutral_normals, nz_neutral, (h, w))
    rr = ratio_image(i0, warped, inside, roi_m, nz_neutral, ratio_opts)
    chosen = resolve_method(
        o.orientation.method, n0[..., 2][roi_m > 0.5] if neutral_normals is not None else None
    )
    side_args = None
    if side_lit is not None:
        if o.orientation.method == "auto":
            chosen = "sfs"  # the side light shows every crease's sign
        s_img, _ = W.sample(np.asarray(side_lit, np.float32), map1, o.sample_order)
        side_args = (s_img, warped, inside & rr.valid, roi_m, n0, side_light)
    # The comparison runs every prior; the solve only when it can add something (the neutral's
    # normals are known) or when it was asked for: on a neutral facing the camera it is
    # measured worse than the integrable prior it starts from, and it is the slow step.
    compared = METHODS if neutral_normals is not None else PRIORS
    # auto with the neutral's normals on a nearly flat neutral: the solve decides (below)
    auto_solve = o.orientation.method == "auto" and neutral_normals is not None
    methods = tuple(m for m in METHODS if m in compared or m == chosen)
    if not o.compare_methods:
        methods = (chosen, "sfs") if auto_solve and chosen != "sfs" else (chosen,)
    photo: dict[str, np.ndarray] = {}
    for m in PRIORS:  # the priors (the integrable one also starts the solve)
        if m in methods or (m == "integrable" and "sfs" in methods):
            opts = dataclasses.replace(orient_opts, method=m)
            photo[m] = apply_roi(orient(rr.ratio, rr.nz, opts, roi_m), roi_m)
    r_model, r_blur = _ratio_model(rr, nz_neutral, neutral_normals is not None, o, k, ratio_opts)
    side = None
    if side_args is not None:
        side = side_ratio(*side_args, r_blur)
    sfs_res = None
    if "sfs" in methods:
        sfs_res, n_sfs = _solve(photo["integrable"], r_model, r_blur, n0, roi_m, rr, side, o, k)
        photo["sfs"] = apply_roi(n_sfs.astype(np.float32), roi_m)
        if auto_solve and chosen != "sfs" and solve_explains_better(sfs_res):
            chosen = "sfs"
    if not o.compare_methods:
        methods = (chosen,)
    photo = {m: photo[m] for m in methods}
    integrability = {m: integrability_residual(n, roi_m) for m, n in photo.items()}
    exposure = sfs_res.exposure if sfs_res is not None else 1.0
    explained = {
        m: S.ratio_residual(n, n0, r_model, roi_m, rr.valid, exposure, o.sfs.max_side, r_blur)
        for m, n in photo.items()
    }

    # 5. photo -> texture.
    map2, texture, inside2, roi_t = _to_texture(
        photo, roi_m, lm_photo, lm_texture, texture_shape, o
    )
    return CaptureResult(
        expression_warped=warped,
        ratio=rr,
        method=chosen,
        normal_photo=photo,
        normal_texture=texture,
        roi_texture=np.where(inside2, roi_t, 0.0).astype(np.float32),
        inside_texture=inside2,
        warp_expression=_stats(map1, lm_neutral, lm_expression),
        warp_texture=_stats(map2, lm_texture, lm_photo),
        integrability=integrability,
        sigma_scale=k,
        ratio_residual=explained,
        sfs=sfs_res,
        neutral_shape=shape_src,
        side=side,
    )


def _neutral_shape(
    neutral_normals: np.ndarray | None, nz_neutral: np.ndarray | float, shape: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray | float, str]:
    """The neutral's normals ``[H, W, 3]`` (float64; +Z where only N_z is known), its N_z, and
    where its shape came from (for the report)."""
    if neutral_normals is not None:
        n0 = normalize(np.asarray(neutral_normals, np.float32)).astype(np.float64)
        return n0, n0[..., 2], "normal map"
    n0 = np.zeros((*shape, 3))
    n0[..., 2] = 1.0
    given = "N_z given" if np.any(np.asarray(nz_neutral) != 1.0) else "facing the camera"
    return n0, nz_neutral, given


def _ratio_model(
    rr: RatioResult,
    nz_neutral: np.ndarray | float,
    have_normals: bool,
    o: CaptureOptions,
    k: float,
    ratio_opts: RatioOptions,
) -> tuple[np.ndarray, float]:
    """What the solve explains, and R's blur in all (sigma, pixels): R against the neutral's
    normals; without them (a neutral facing the camera, or a constant N_z) the neutral is
    flat and R the cosine of the extra tilt. Blurred by the solve's own blur on top of the
    ratio's (Gaussians compose in quadrature)."""
    if have_normals:
        r_model = rr.plain.astype(np.float64)
    else:
        nzn = np.broadcast_to(np.asarray(nz_neutral, np.float64), rr.plain.shape)
        extra = np.arccos(np.clip(rr.plain * nzn, 0.0, 1.0)) - np.arccos(np.clip(nzn, 0.0, 1.0))
        r_model = np.where(nzn < 1.0, np.cos(np.clip(extra, 0.0, np.pi / 2)), rr.plain)
    more = float(np.sqrt(max((o.sfs.blur * k) ** 2 - ratio_opts.blur_sigma**2, 0.0)))
    if more > 0:
        r_model = masked_blur(r_model, rr.valid.astype(np.float64), more)
    return r_model, float(np.hypot(ratio_opts.blur_sigma, more))


def _solve(
    integrable: np.ndarray,
    r_model: np.ndarray,
    r_blur: float,
    n0: np.ndarray,
    roi_m: np.ndarray,
    rr: RatioResult,
    side: SideRatio | None,
    o: CaptureOptions,
    k: float,
) -> tuple[S.SfsResult, np.ndarray]:
    """The crease solve started from the integrable prior's slopes, and its normals."""
    prior = integrable.astype(np.float64)
    z = np.maximum(prior[..., 2], 1e-3)
    q = np.stack([-prior[..., 0] / z, prior[..., 1] / z], axis=-1)  # the prior's slopes
    sfs_res = S.solve_crease(
        r_model,
        n0,
        roi_m,
        rr.valid,
        {"integrable": q, "mirror": -q},
        o.sfs,
        r_blur,
        side=(side.ratio, side.light) if side is not None else None,
    )
    # the tilt: R's own (the data's detail), or with a side-lit photo the solve's slopes
    # (fitted to both photos: measured on mixed N_z 0.995, tilt 0.33x -> 0.12x)
    n1z = None if side is not None else np.clip(r_model * n0[..., 2] / sfs_res.exposure, 0, 1)
    n_sfs = slopes.normals_from_slopes(sfs_res.slopes, n0, n1z)
    if side is None and o.flat_level > 0:  # flat skin stays flat (CaptureOptions.flat_level)
        noise = blurred_noise(pixel_noise(rr.raw, rr.valid), r_blur)
        flat = flat_skin(
            r_model / sfs_res.exposure,
            rr.valid,
            roi_m,
            noise,
            o.flat_level,
            o.flat_window * k,
        )[..., None]
        n_sfs = normalize((1.0 - flat) * n_sfs + flat * np.array([0.0, 0.0, 1.0]))
    return sfs_res, n_sfs


def _to_texture(
    photo: dict[str, np.ndarray],
    roi_m: np.ndarray,
    lm_photo: np.ndarray,
    lm_texture: np.ndarray,
    texture_shape: tuple[int, int],
    o: CaptureOptions,
) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """Photo -> texture: the dense map, each method's normals in texture space (+Z outside
    the photo, rotated with the warp), where the photo covers the texture, the ROI there."""
    th, tw = texture_shape
    warp2 = W.fit_tps(lm_texture, lm_photo)
    map2 = W.dense_map(warp2, (th, tw), o.warp_step)
    rot = W.jacobian_rotation(map2) if o.rotate_normals else None
    texture: dict[str, np.ndarray] = {}
    inside2 = np.zeros((th, tw), bool)
    for m, n in photo.items():
        s, inside2 = W.sample(n, map2, o.sample_order)
        s = np.where(inside2[..., None], s, np.array([0.0, 0.0, 1.0], np.float32))
        s = normalize(s)
        if rot is not None:
            s = W.rotate_normals(s, rot)
        texture[m] = s
    roi_t, _ = W.sample(roi_m, map2)
    return map2, texture, inside2, roi_t
