"""The inputs of a capture session read and checked: the options given as text (``--size``,
``--side-light``), the photos (linear luminance), masks, the neutral's normal map, and the
neutral's normals rendered from its mesh with the camera the landmarks define. Each refuses a
bad file with one message naming it. :mod:`wrinklepipe.jobs.capture` runs the session on them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wrinklepipe.capture import mesh_view as MV
from wrinklepipe.capture.ratio import luminance, srgb_to_linear
from wrinklepipe.errors import input_error
from wrinklepipe.io.images import DEFAULT_MAX_PIXELS, read_image
from wrinklepipe.model import normalize
from wrinklepipe.names import noun, plural
from wrinklepipe.readers.meshes import LoadOptions, load_mesh
from wrinklepipe.validate.gl import GLUnavailable, create_context


def parse_size(
    text: str | None, max_pixels: int | None = DEFAULT_MAX_PIXELS
) -> tuple[int, int] | None:
    """``N`` or ``WxH`` -> ``(height, width)``; at most ``max_pixels`` texels (the photos'
    cap, ``--max-pixels``), checked before anything of that size is made."""
    if text is None:
        return None
    try:
        if "x" in text.lower():
            w, h = (int(v) for v in text.lower().split("x"))
        else:
            w = h = int(text)
    except ValueError:
        raise input_error("<arguments>", f"--size must be N or WxH, got {text!r}") from None
    if w <= 0 or h <= 0:
        raise input_error("<arguments>", f"--size out of range: {text!r}")
    cap = max_pixels or DEFAULT_MAX_PIXELS
    if w * h > cap:
        raise input_error(
            "--size",
            f"{text} makes a texture of {w} x {h} = {w * h} pixels, over the cap of {cap} "
            "pixels (--max-pixels N raises it)",
        )
    return h, w


def parse_light(text: str) -> np.ndarray:
    """``X,Y,Z`` -> the unit direction towards the side light (camera frame)."""
    try:
        v = np.array([float(t) for t in text.split(",")], np.float64)
    except ValueError:
        v = np.zeros(0)
    if v.shape != (3,) or not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0:
        raise input_error(
            "<arguments>", f"--side-light must be X,Y,Z (three numbers), got {text!r}"
        )
    v = v / np.linalg.norm(v)
    if v[2] <= 0.2:
        raise input_error(
            "<arguments>",
            f"--side-light {text}: the light must be in front of the face, within about 78 "
            "degrees of the camera (z > 0.2 of the unit direction)",
        )
    return v


def read_photo(path: str, colorspace: str, max_pixels: int | None) -> tuple[np.ndarray, Any]:
    """Linear luminance of a photo (decoded from sRGB unless linear or tagged so)."""
    img, info = read_image(path, max_pixels or DEFAULT_MAX_PIXELS)
    linear = colorspace == "linear"
    if colorspace == "auto":
        tag = info.colorspace.lower()
        linear = info.format in ("half", "float", "double") or "lin" in tag or tag == "raw"
    if not linear:
        img = srgb_to_linear(np.clip(img, 0.0, 1.0))
    return luminance(img), info


def read_mask(path: str, shape: tuple[int, int], what: str) -> np.ndarray:
    """A 0..1 mask of the neutral photo's size (alpha times red when there is alpha)."""
    m, info = read_image(path)
    if (info.height, info.width) != shape:
        raise input_error(
            path,
            f"{what} is {info.width} x {info.height} but the neutral photo is "
            f"{shape[1]} x {shape[0]}",
        )
    m = m[..., 0] if m.shape[2] < 4 else m[..., 3] * m[..., 0]
    if not np.all(np.isfinite(m)):
        raise input_error(path, f"{what} has non-finite values")
    return np.clip(m, 0.0, 1.0)


def read_neutral_normals(path: str, shape: tuple[int, int], roi: np.ndarray | None) -> np.ndarray:
    """The neutral face's normals in the neutral photo's view: camera frame, +X right, +Y up,
    +Z towards the camera; stored ``0.5 + 0.5 n`` (8/16-bit) or as raw ``n`` (float files)."""
    img, info = read_image(path)
    if (info.height, info.width) != shape:
        raise input_error(
            path,
            f"neutral normal map is {info.width} x {info.height} but the neutral photo is "
            f"{shape[1]} x {shape[0]}; render it from the photo's camera at the photo's size",
        )
    if img.shape[2] < 3:
        raise input_error(path, "neutral normal map needs three channels (x, y, z)")
    v = np.asarray(img[..., :3], np.float64)
    if not np.all(np.isfinite(v)):
        raise input_error(path, "neutral normal map has non-finite values")
    if info.format not in ("half", "float", "double"):
        v = 2.0 * v - 1.0
    return _facing(path, v, shape, roi, "expected +Z towards the camera")


def _facing(
    path: str, v: np.ndarray, shape: tuple[int, int], roi: np.ndarray | None, hint: str
) -> np.ndarray:
    """Unit normals where every ROI pixel faces the camera (else one message naming the
    first pixel that does not); +Z outside the ROI."""
    length = np.linalg.norm(v, axis=-1)
    inside = np.ones(shape, bool) if roi is None else np.asarray(roi) > 0.5
    bad = inside & ((length < 0.5) | (v[..., 2] <= 0.0))
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise input_error(
            path,
            f"{plural(int(bad.sum()), 'pixel')} of the ROI {noun(int(bad.sum()), 'is', 'are')} not "
            f"normals facing the camera (first at x={c}, y={r}: "
            f"{np.round(v[r, c], 3).tolist()}); {hint}",
        )
    return np.where(inside[..., None], normalize(v), np.array([0.0, 0.0, 1.0], np.float32))


#: A camera fit worse than this (RMS pixels) means the landmarks do not match the mesh.
MAX_CAMERA_RESIDUAL_PX = 3.0


def neutral_normals_from_mesh(
    path: str,
    uv: np.ndarray,
    photo: np.ndarray,
    names: list[str] | None,
    shape: tuple[int, int],
    roi: np.ndarray | None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """The neutral's normals in the photo's view, rendered from the mesh at ``path`` with the
    camera that the landmark pairs define (``uv`` on the mesh's layout, ``photo`` pixels); and
    what the fit found (for the report). See :mod:`.mesh_view`."""
    mesh = load_mesh(path, LoadOptions(generate_uvs=False))
    if mesh.uvs is None:
        raise input_error(path, "mesh has no texture coordinates; the landmarks are UVs on it")
    world, found = MV.points_at_uv(mesh, uv)
    if not found.all():
        off = [names[i] if names else str(i) for i in np.flatnonzero(~found)[:5]]
        raise input_error(
            path,
            f"{plural(int((~found).sum()), 'texture landmark')} "
            f"{noun(int((~found).sum()), 'falls', 'fall')} outside the mesh's UV layout (first: "
            f"{', '.join(off)}); the texture landmarks must lie on this mesh",
        )
    cam = MV.fit_camera(world, photo)
    if cam.residual_px > MAX_CAMERA_RESIDUAL_PX:
        raise input_error(
            path,
            f"no camera projects the mesh's landmark points onto the photo's (RMS error "
            f"{cam.residual_px:.2f} px, worst {cam.max_residual_px:.2f} px > "
            f"{MAX_CAMERA_RESIDUAL_PX} px): is this the character's neutral mesh, and do the "
            "texture landmarks pair with the photo landmarks?",
        )
    try:
        ctx = create_context()
    except GLUnavailable as exc:
        raise input_error(
            path, f"{exc}; render the neutral's normal pass elsewhere and give --neutral-normals"
        ) from None
    try:
        n0, covered = MV.render_normals(mesh, cam, shape, ctx)
    finally:
        ctx.release()
    inside = np.ones(shape, bool) if roi is None else np.asarray(roi) > 0.5
    if not covered[inside].all():
        share = float(covered[inside].mean())
        raise input_error(
            path,
            f"seen from the landmarks' camera the mesh covers {100 * share:.1f} % of the ROI; "
            "the ROI must lie on the mesh",
        )
    n0 = _facing(path, n0, shape, roi, "the mesh turns away from the landmarks' camera there")
    info = {
        "file": str(path),
        "vertices": mesh.vertex_count,
        "triangles": mesh.triangle_count,
        "camera": "scaled orthographic",
        "view_from_mesh_z_deg": round(cam.view_deg, 4),
        "scale_px_per_unit": round(cam.scale, 6),
        "landmark_residual_rms_px": round(cam.residual_px, 4),
        "landmark_residual_max_px": round(cam.max_residual_px, 4),
        "roi_min_nz": round(float(n0[..., 2][inside].min()), 4),
    }
    return n0, info
