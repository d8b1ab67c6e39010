"""The ``capture`` job as a plain function: read the session -> capture -> the output files.

:func:`run_capture` reads and checks every input, runs :func:`wrinklepipe.capture.capture`, and
returns the files of the output folder (images as arrays with their bit depth, text as bytes)
and the JSON-ready report; it writes nothing. :meth:`CaptureOutput.write` puts the files into a
folder (the command writes them through :func:`wrinklepipe.atomic.staged_folder`).
:class:`CaptureJobOptions` holds every option with the command line's defaults.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.atomic import dumps_json, write_bytes
from wrinklepipe.capture import landmarks as L
from wrinklepipe.capture.evaluate import errors as truth_errors
from wrinklepipe.capture.orientation import OrientationOptions
from wrinklepipe.capture.pipeline import CaptureOptions, CaptureResult, capture, sigma_scale
from wrinklepipe.capture.ratio import RatioOptions
from wrinklepipe.capture.report import (
    UNOBSERVABLE,
    build_report,
    picture_images,
    render_html,
)
from wrinklepipe.capture.synthetic import dome_height, make_scene, normal_of
from wrinklepipe.errors import InputError, Problem, input_error
from wrinklepipe.io.images import read_image, write_image
from wrinklepipe.jobs.capture_inputs import (
    neutral_normals_from_mesh,
    parse_light,
    parse_size,
    read_mask,
    read_neutral_normals,
    read_photo,
)
from wrinklepipe.model import normalize


@dataclass(frozen=True)
class CaptureJobOptions:
    """Every option of ``wrinklepipe capture`` (the command's defaults come from here)."""

    orientation: str = "auto"
    state: str = "capture"
    colorspace: str = "auto"
    blur: float = 1.0
    dark: float = 0.02
    deadband: float | None = None
    normalize_exposure: bool = True
    furrow_sigma: float = 3.0
    scale: float | None = None
    nz: float = 1.0
    nz_regions: tuple[str, ...] = ()
    side_light: str | None = None  # "X,Y,Z": towards the side-lit photo's light, camera frame
    max_pixels: int | None = None


@dataclass(frozen=True)
class CaptureInputs:
    """The files of one session (paths as given; ``None``: not given)."""

    neutral: str
    expression: str
    neutral_landmarks: str
    expression_landmarks: str
    texture_landmarks: str | None = None
    photo_landmarks: str | None = None
    size: str | None = None
    roi: str | None = None
    neutral_normals: str | None = None
    neutral_mesh: str | None = None
    side_lit: str | None = None
    truth: str | None = None

    def given(self) -> dict[str, str]:
        """The inputs that were given, by name (for the report)."""
        names = (
            "neutral",
            "expression",
            "neutral_landmarks",
            "expression_landmarks",
            "texture_landmarks",
            "photo_landmarks",
            "roi",
            "neutral_normals",
            "neutral_mesh",
            "side_lit",
            "truth",
        )
        return {n: str(getattr(self, n)) for n in names if getattr(self, n)}


@dataclass
class CaptureOutput:
    """The output folder's files and the report."""

    images: dict[str, tuple[np.ndarray, int]]  # relative path -> (values 0..1, bits)
    texts: dict[str, bytes]  # relative path -> bytes
    report: dict[str, Any]
    result: CaptureResult | None = field(default=None, repr=False)
    truth: dict[str, dict] | None = None

    def summary(self, out: Path) -> list[str]:
        """The lines the command prints."""
        return _summary(self, out)

    def write(self, folder: Path) -> None:
        """Write every file under ``folder`` (which exists)."""
        for rel, (img, bits) in sorted(self.images.items()):
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            write_image(folder / rel, img, bits=bits)
        for rel, data in sorted(self.texts.items()):
            write_bytes(folder / rel, data)


def _nz_map(o: CaptureJobOptions, shape: tuple[int, int]) -> np.ndarray | float:
    nz: np.ndarray | float = o.nz
    for spec in o.nz_regions:
        if "=" not in spec:
            raise input_error("<arguments>", f"--nz-region expects MASK=VALUE, got {spec!r}")
        path, _, val = spec.rpartition("=")
        try:
            v = float(val)
        except ValueError:
            raise input_error(
                "<arguments>", f"--nz-region value is not a number: {val!r}"
            ) from None
        if not 0 < v <= 1:
            raise input_error("<arguments>", f"--nz-region value must lie in (0, 1], got {v}")
        m = read_mask(path, shape, "N_z region mask")
        nz = np.asarray(nz, np.float32) * (1.0 - m) + v * m
    return nz


def check_options(inputs: CaptureInputs, o: CaptureJobOptions) -> None:
    """Refuse bad options before any file is read."""
    if not re.fullmatch(r"[A-Za-z0-9_]+", o.state):
        raise input_error(
            "<arguments>", f"--state must be letters, digits and '_' (a manifest name): {o.state!r}"
        )
    missing = [
        flag
        for flag, val in (
            ("NEUTRAL", inputs.neutral),
            ("EXPRESSION", inputs.expression),
            ("--neutral-landmarks", inputs.neutral_landmarks),
            ("--expression-landmarks", inputs.expression_landmarks),
        )
        if not val
    ]
    if missing:
        raise InputError([Problem("<arguments>", f"missing {m}") for m in missing])
    checks = [("--blur", o.blur), ("--furrow-sigma", o.furrow_sigma), ("--dark", o.dark)]
    checks.append(("--nz", o.nz))
    if o.scale is not None:
        checks.append(("--scale", o.scale))
    for flag, val in checks:
        if not np.isfinite(val) or val < 0:
            raise input_error("<arguments>", f"{flag} must be a finite number >= 0, got {val}")
    if not 0 < o.nz <= 1:
        raise input_error("<arguments>", f"--nz must lie in (0, 1], got {o.nz}")
    if inputs.neutral_normals and inputs.neutral_mesh:
        raise input_error(
            "<arguments>", "give the neutral's shape once: --neutral-normals or --neutral-mesh"
        )
    for flag, given in (
        ("--neutral-normals", inputs.neutral_normals),
        ("--neutral-mesh", inputs.neutral_mesh),
    ):
        if given and (o.nz != 1.0 or o.nz_regions):
            raise input_error(
                "<arguments>",
                f"{flag} gives the neutral's shape per pixel; drop --nz / --nz-region",
            )
    if inputs.side_lit and not (inputs.neutral_normals or inputs.neutral_mesh):
        raise input_error(
            "<arguments>",
            "--side-lit needs the neutral's shape (--neutral-normals or --neutral-mesh): the "
            "side light's shading is measured against the neutral's normals",
        )
    if bool(inputs.side_lit) != bool(o.side_light):
        raise input_error("<arguments>", "--side-lit and --side-light go together")
    if o.side_light:
        parse_light(o.side_light)
    if inputs.neutral_mesh and not inputs.texture_landmarks:
        raise input_error(
            "<arguments>",
            "--neutral-mesh needs --texture-landmarks (the UVs that put the landmarks on the "
            "mesh and define the camera)",
        )


def _check_sigmas(copts: CaptureOptions, width: int, height: int) -> None:
    """Every blur the capture runs (its sigma times ``--scale``) at most as wide as the photo,
    before any runs: a wider one blurs nothing more and costs without bound (a 1e300-pixel
    sigma was an internal error, 'Maximum allowed size exceeded')."""
    k = sigma_scale(width, copts)
    side = max(width, height)
    for flag, sigma in (
        ("--blur", copts.ratio.blur_sigma),
        ("--furrow-sigma", copts.orientation.furrow_sigma),
        ("--scale", copts.orientation.structure_sigma),
        ("--scale", copts.ratio.exposure_ring),
    ):
        if sigma * k > side:
            what = f"{sigma:g} x {k:g} (--scale)" if flag != "--scale" else f"{k:g} x {sigma:g}"
            lower = flag if flag == "--scale" else f"{flag} or --scale"
            raise input_error(
                flag,
                f"{what} makes a blur of {sigma * k:g} pixels, wider than the photo "
                f"({width} x {height}); lower {lower}",
            )


def _snippet(state: str) -> bytes:
    return (
        "# wrinklepipe capture: merge into the character's manifest (copy the maps beside it).\n"
        "# The captured map holds the wrinkles alone (no base detail), so the manifest needs,\n"
        "# at its top level (above any [[table]]):\n"
        "#   states_include_base = false\n\n"
        f'[[states]]\nname = "{state}"\nmap = "{state}.png"\n\n'
        f'[[regions]]\nname = "{state}_roi"\nmask = "{state}_roi.png"\nstates = ["{state}"]\n'
    ).encode()


def run_capture(inputs: CaptureInputs, options: CaptureJobOptions | None = None) -> CaptureOutput:
    """Read, check and capture one session; returns the output files and the report.

    Raises :class:`InputError` (one message per problem, naming the file) for bad inputs.
    """
    o = options or CaptureJobOptions()
    check_options(inputs, o)
    parse_size(inputs.size, o.max_pixels)  # the texture costed before the photos are read
    i0, info0, i1, info1 = _photos(inputs, o)
    shape = (info0.height, info0.width)
    lm_n = L.read_landmarks(inputs.neutral_landmarks).to_pixels(info0.width, info0.height)
    lm_e = L.read_landmarks(inputs.expression_landmarks).to_pixels(info1.width, info1.height)
    pn, pe = L.pair(lm_n, lm_e)
    L.check_inside(lm_n, info0.width, info0.height, "neutral photo")
    L.check_inside(lm_e, info1.width, info1.height, "expression photo")

    tex_shape, pp, pt, lm_t_names = _photo_to_texture(inputs, info0, lm_n, o.max_pixels)

    roi = read_mask(inputs.roi, shape, "ROI mask") if inputs.roi else None
    nz = _nz_map(o, shape)
    n0 = (
        read_neutral_normals(inputs.neutral_normals, shape, roi) if inputs.neutral_normals else None
    )
    mesh_info = None
    if inputs.neutral_mesh:
        uv = pt / np.array([tex_shape[1], tex_shape[0]], np.float64)
        n0, mesh_info = neutral_normals_from_mesh(
            inputs.neutral_mesh, uv, pp, lm_t_names, shape, roi
        )
    truth = _read_truth(inputs.truth, tex_shape) if inputs.truth else None

    copts = CaptureOptions(
        ratio=RatioOptions(
            dark_threshold=o.dark,
            normalize_exposure=o.normalize_exposure,
            blur_sigma=o.blur,
            deadband=o.deadband,
        ),
        orientation=OrientationOptions(method=o.orientation, furrow_sigma=o.furrow_sigma),
        scale=o.scale,
    )
    _check_sigmas(copts, info0.width, info0.height)
    side_img = _side_photo(inputs, o, info1) if inputs.side_lit else None
    res = capture(
        i0,
        i1,
        pn,
        pe,
        pp,
        pt,
        tuple(tex_shape),
        roi,
        nz,
        copts,
        neutral_normals=n0,
        side_lit=side_img,
        side_light=parse_light(o.side_light) if side_img is not None else None,
    )

    te = None
    if truth is not None:
        te = {m: truth_errors(n, truth, res.roi_texture) for m, n in res.normal_texture.items()}
    state = o.state
    outputs = {
        "normal_map": f"{state}.png",
        "roi_map": f"{state}_roi.png",
        "manifest_snippet": "manifest_snippet.toml",
        "texture_size": [int(tex_shape[1]), int(tex_shape[0])],
        "space": "texture" if inputs.texture_landmarks else "photo",
    }
    shape_from = "mesh" if mesh_info else "normal map" if n0 is not None else "N_z constant/regions"
    report = build_report(res, inputs.given(), _options_json(o, shape_from), outputs, te)
    if mesh_info is not None:
        report["neutral_shape"] = "mesh"
        report["neutral_mesh"] = mesh_info
    for key, names in (("expression_to_neutral", lm_n.names), ("photo_to_texture", lm_t_names)):
        worst = report["warps"][key]["leave_one_out_worst_index"]
        if names is not None and worst is not None:
            report["warps"][key]["leave_one_out_worst_name"] = names[worst]

    images: dict[str, tuple[np.ndarray, int]] = {
        f"{state}.png": (0.5 + 0.5 * res.normal, 16),
        f"{state}_roi.png": (res.roi_texture, 16),
    }
    pics = picture_images(res, i0, i1, roi if roi is not None else np.ones(shape))
    for rel, img in pics.values():
        images[rel] = (img, 8)
    texts = {
        "manifest_snippet.toml": _snippet(state),
        "report.json": dumps_json(report).encode("utf-8"),
        "report.html": render_html(report, {c: rel for c, (rel, _) in pics.items()}).encode(),
    }
    return CaptureOutput(images, texts, report, res, te)


def _photos(inputs: CaptureInputs, o: CaptureJobOptions) -> tuple[np.ndarray, Any, np.ndarray, Any]:
    """The neutral and expression photos (linear luminance) and their headers: one size, and
    neither all black."""
    i0, info0 = read_photo(inputs.neutral, o.colorspace, o.max_pixels)
    i1, info1 = read_photo(inputs.expression, o.colorspace, o.max_pixels)
    if (info0.width, info0.height) != (info1.width, info1.height):
        raise input_error(
            inputs.expression,
            f"photo is {info1.width} x {info1.height} but the neutral photo {inputs.neutral} is "
            f"{info0.width} x {info0.height}; take both with the same camera settings (or crop "
            "them to one size)",
        )
    for path, lum in ((inputs.neutral, i0), (inputs.expression, i1)):
        top = float(np.nanmax(lum)) if lum.size else 0.0
        if not np.isfinite(top) or top < o.dark:
            raise input_error(
                path,
                f"photo is all black (brightest linear luminance {top:.4f} is below --dark "
                f"{o.dark}); nothing to divide",
            )
    return i0, info0, i1, info1


def _photo_to_texture(
    inputs: CaptureInputs, info0: Any, lm_n: L.Landmarks, max_pixels: int | None
) -> tuple[tuple[int, int], np.ndarray, np.ndarray, list[str] | None]:
    """The texture's shape ``(h, w)``, the paired photo and texture points of the warp between
    them, and the texture landmarks' names; without ``--texture-landmarks`` the map stays in
    photo space (the identity: the photo's corners)."""
    tex_shape = parse_size(inputs.size, max_pixels)
    if not inputs.texture_landmarks:
        w, h = info0.width, info0.height
        corners = np.array([[0, 0], [w, 0], [0, h], [w, h]], float)
        return (info0.height, info0.width), corners, corners, None
    if tex_shape is None:
        raise input_error("<arguments>", "--size is required with --texture-landmarks")
    th, tw = tex_shape
    lm_t = L.read_landmarks(inputs.texture_landmarks).to_pixels(tw, th)
    lm_p = (
        L.read_landmarks(inputs.photo_landmarks).to_pixels(info0.width, info0.height)
        if inputs.photo_landmarks
        else lm_n
    )
    pp, pt = L.pair(lm_p, lm_t)
    lm_t_names = lm_p.names if lm_p.names is not None and lm_t.names is not None else None
    L.check_inside(lm_p, info0.width, info0.height, "neutral photo")
    L.check_inside(lm_t, tw, th, "texture")
    return tex_shape, pp, pt, lm_t_names


def _read_truth(path: str, tex_shape: tuple[int, int]) -> np.ndarray:
    """The true texture-space normal map (unit normals), of the texture's size."""
    t, tinfo = read_image(path)
    if (tinfo.height, tinfo.width) != tuple(tex_shape) or t.shape[2] < 3:
        raise input_error(
            path,
            f"truth map must be an RGB {tex_shape[1]} x {tex_shape[0]} normal map",
        )
    return normalize(2.0 * t[..., :3] - 1.0)


def _side_photo(inputs: CaptureInputs, o: CaptureJobOptions, info1: Any) -> np.ndarray:
    """The side-lit photo (linear luminance): the expression again, its size, not all black."""
    side_img, info_s = read_photo(inputs.side_lit, o.colorspace, o.max_pixels)
    if (info_s.width, info_s.height) != (info1.width, info1.height):
        raise input_error(
            inputs.side_lit,
            f"photo is {info_s.width} x {info_s.height} but the expression photo "
            f"{inputs.expression} is {info1.width} x {info1.height}; the side-lit photo is "
            "the expression again, same pose and camera",
        )
    if not float(np.nanmax(side_img)) >= o.dark:
        raise input_error(inputs.side_lit, "photo is all black; nothing to divide")
    return side_img


def _options_json(o: CaptureJobOptions, neutral_shape: str) -> dict[str, Any]:
    """The options as the report records them."""
    return {
        "orientation": o.orientation,
        "blur_sigma": o.blur,
        "dark_threshold": o.dark,
        "deadband": o.deadband,
        "normalize_exposure": o.normalize_exposure,
        "furrow_sigma": o.furrow_sigma,
        "nz": o.nz,
        "nz_regions": list(o.nz_regions),
        "neutral_shape": neutral_shape,
        "colorspace": o.colorspace,
        "scale": o.scale,
        "side_light": o.side_light,
    }


def _summary(self: CaptureOutput, out: Path) -> list[str]:
    """The lines the command prints (the chosen method, residuals, truth errors if known)."""
    r = self.report
    w1 = r["warps"]["expression_to_neutral"]
    state_png = r["outputs"]["normal_map"]
    size = r["outputs"]["texture_size"]
    lines = [
        f"captured {state_png[:-4]} ({r['method']}) -> {out / state_png} [{size[0]} x {size[1]}]"
        f"; neutral: {r['neutral_shape']}; leave-one-out landmark residual max "
        f"{w1['leave_one_out_max_px']} px; clipped {r['ratio']['fraction_clipped']:.3f}, dark "
        f"{r['ratio']['fraction_dark']:.3f}"
    ]
    for m, e in r["orientation"].items():
        line = f"  {m:<10} ratio residual {e['ratio_residual']:.5f}"
        t = e.get("truth")
        if t is not None:
            line += (
                f"; angular mean {t['angular']['mean']:.2f} deg, tilt mean {t['tilt']['mean']:.2f}"
                f" deg, orientation correct {t['orientation_correct']:.3f} (flat map "
                f"{t['flat']['mean']:.2f} deg)"
            )
        lines.append(line)
    amb = r.get("sfs", {}).get("sign_ambiguous_fraction")
    if amb:
        lines.append(
            f"  sfs: the photos leave the sign of {100 * amb:.0f} % of its crease pixels open "
            "(another height explains R as well): see pictures/sfs_ambiguous.png"
        )
    if r.get("sfs", {}).get("sign_observable") is False:
        lines.append(f"  warning: {UNOBSERVABLE}")
    return lines


def example_session() -> CaptureOutput:
    """The synthetic session of :mod:`.synthetic` as files (photos, landmarks as JSON, CSV and
    UV JSON, ROI, the neutral's normal map, the true texture-space map); ``report["hint"]``
    is the command to run on it (``DIR`` standing for the folder)."""

    sc = make_scene()
    s = float(sc.neutral.shape[0])
    idx = np.arange(sc.neutral.shape[0]) + 0.5
    yy, xx = np.meshgrid(idx, idx, indexing="ij")
    n0 = normal_of(lambda x, y: dome_height(x, y, s), xx, yy)
    names = [f"p{i:02d}" for i in range(len(sc.lm_neutral))]
    t_size = sc.truth_texture.shape[0]
    neutral = {
        n: [round(float(x), 4), round(float(y), 4)] for n, (x, y) in zip(names, sc.lm_neutral)
    }
    lines = ["name,x,y"] + [f"{n},{x:.4f},{y:.4f}" for n, (x, y) in zip(names, sc.lm_expression)]
    uv = {
        n: [round(float(x) / t_size, 6), round(float(y) / t_size, 6)]
        for n, (x, y) in zip(names, sc.lm_texture)
    }
    images = {
        "neutral.png": (np.clip(sc.neutral, 0, 1), 16),
        "expression.png": (np.clip(sc.expression, 0, 1), 16),
        "roi.png": (sc.roi, 8),
        "neutral_normals.png": (0.5 + 0.5 * n0, 16),
        "truth_texture.png": (0.5 + 0.5 * sc.truth_texture, 16),
    }
    texts = {
        "neutral.json": dumps_json({"points": neutral}).encode(),
        "expression.csv": ("\n".join(lines) + "\n").encode(),
        "texture.json": dumps_json({"space": "uv", "points": uv}).encode(),
    }
    hint = (
        "wrote a synthetic session to DIR; try:\n  wrinklepipe capture DIR/neutral.png "
        "DIR/expression.png --neutral-landmarks DIR/neutral.json --expression-landmarks "
        f"DIR/expression.csv --texture-landmarks DIR/texture.json --size {t_size} --roi "
        "DIR/roi.png --neutral-normals DIR/neutral_normals.png --truth DIR/truth_texture.png "
        "-o captured/"
    )
    return CaptureOutput(images, texts, {"hint": hint})
