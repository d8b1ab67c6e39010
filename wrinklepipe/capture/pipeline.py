"""The capture stage as one pure function on arrays: two photos -> a wrinkle normal map.

Steps (Dutreve et al. section 3, with the guards and the orientation priors of this package):

1. thin-plate warp of the expression photo onto the neutral photo (landmarks ``expr -> neutral``);
2. ratio image ``R = I'_d / I`` on linear luminance, guarded, blurred (:mod:`.ratio`);
3. ``N'_z = R N_z`` and the orientation (:mod:`.orientation`), every method for the report;
4. ROI masking (outside: the flat normal ``(0, 0, 1)``; a soft mask scales the in-plane part);
5. thin-plate warp from photo space into the character's texture space, with the normals'
   in-plane part rotated into the texture's tangent frame.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from wrinklepipe.capture import warp as W
from wrinklepipe.capture.orientation import (
    METHODS,
    OrientationOptions,
    integrability_residual,
    orient,
)
from wrinklepipe.capture.ratio import RatioOptions, RatioResult, ratio_image
from wrinklepipe.model import normalize


@dataclass(frozen=True)
class CaptureOptions:
    """All parameters of the capture stage, with the defaults ``wrinklepipe capture`` uses."""

    ratio: RatioOptions = field(default_factory=RatioOptions)
    orientation: OrientationOptions = field(default_factory=OrientationOptions)
    #: Grid step (pixels) at which the thin-plate splines are evaluated: 1 = every pixel (exact),
    #: 0 = every pixel up to 4 Mpx and every second pixel above (cubic refinement between).
    warp_step: int = 0
    #: Rotate normals into the texture's tangent frame (the photo -> texture map may rotate).
    rotate_normals: bool = True
    #: Also compute the other orientation methods (for the report's side-by-side comparison).
    compare_methods: bool = True
    #: Factor applied to every Gaussian sigma (ratio blur, structure tensor, furrow scale), which
    #: are given for a photo up to ``SCALE_REFERENCE_PX`` wide; ``None``: ``max(1, width / 384)``
    #: (wrinkles are wider in pixels in a larger photo of the same face).
    scale: float | None = None


#: Photo width (pixels) at which the sigmas apply unscaled.
SCALE_REFERENCE_PX = 384.0


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

    @property
    def normal(self) -> np.ndarray:
        """The wrinkle normal map of the chosen method, texture space."""
        return self.normal_texture[self.method]


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
) -> CaptureResult:
    """Run the capture on linear luminance photos ``[H, W]`` (and ``[H', W']``).

    Landmarks are ``[N, 2]`` pixel positions (x, y; origin at the top-left corner): neutral and
    expression photo pairs for the first warp; ``lm_photo`` (neutral photo) and ``lm_texture``
    (texture pixels) for the second. ``texture_shape`` is ``(height, width)`` of the output.
    """
    o = options or CaptureOptions()
    i0 = np.asarray(neutral, np.float32)
    i1 = np.asarray(expression, np.float32)
    h, w = i0.shape
    k = sigma_scale(w, o)
    ratio_opts = dataclasses.replace(o.ratio, blur_sigma=o.ratio.blur_sigma * k)
    orient_opts = dataclasses.replace(
        o.orientation,
        structure_sigma=o.orientation.structure_sigma * k,
        furrow_sigma=o.orientation.furrow_sigma * k,
    )
    roi_m = np.ones((h, w), np.float32) if roi is None else np.asarray(roi, np.float32)

    # 1. expression -> neutral.
    warp1 = W.fit_tps(lm_neutral, lm_expression)
    map1 = W.dense_map(warp1, (h, w), o.warp_step)
    warped, inside = W.sample(i1, map1)

    # 2-3. ratio, tilt, orientation.
    rr = ratio_image(i0, warped, inside, roi_m, nz_neutral, ratio_opts)
    methods = METHODS if o.compare_methods else (o.orientation.method,)
    photo: dict[str, np.ndarray] = {}
    integrability: dict[str, float] = {}
    for m in methods:  # up to three methods, each vectorised over the image
        opts = dataclasses.replace(orient_opts, method=m)
        n = apply_roi(orient(rr.ratio, rr.nz, opts, roi_m), roi_m)
        photo[m] = n
        integrability[m] = integrability_residual(n, roi_m)

    # 5. photo -> texture.
    th, tw = texture_shape
    warp2 = W.fit_tps(lm_texture, lm_photo)
    map2 = W.dense_map(warp2, (th, tw), o.warp_step)
    rot = W.jacobian_rotation(map2) if o.rotate_normals else None
    texture: dict[str, np.ndarray] = {}
    inside2 = np.zeros((th, tw), bool)
    for m, n in photo.items():
        s, inside2 = W.sample(n, map2)
        s = np.where(inside2[..., None], s, np.array([0.0, 0.0, 1.0], np.float32))
        s = normalize(s)
        if rot is not None:
            s = W.rotate_normals(s, rot)
        texture[m] = s
    roi_t, _ = W.sample(roi_m, map2)
    return CaptureResult(
        expression_warped=warped,
        ratio=rr,
        method=o.orientation.method,
        normal_photo=photo,
        normal_texture=texture,
        roi_texture=np.where(inside2, roi_t, 0.0).astype(np.float32),
        inside_texture=inside2,
        warp_expression=_stats(map1, lm_neutral, lm_expression),
        warp_texture=_stats(map2, lm_texture, lm_photo),
        integrability=integrability,
        sigma_scale=k,
    )
