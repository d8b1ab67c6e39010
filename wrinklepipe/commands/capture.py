"""``wrinklepipe capture``: a wrinkle normal map from two flash-lit photographs (ratio image)."""

from __future__ import annotations

import argparse
import re
from pathlib import Path
from typing import Any

import numpy as np

NAME = "capture"
HELP = "capture a wrinkle normal map from a neutral and an expression photo (ratio image)"
DESCRIPTION = """\
Dutreve et al.'s mono-camera capture: two frontal photos of the same face under the camera's
flash, one neutral (I) and one with the expression (I'). The expression photo is warped onto the
neutral one with a thin-plate spline through the landmarks; the ratio R = I'_d / I of their
linear luminance cancels the skin colour and gives the wrinkled normal's tilt (N'_z = R N_z);
the orientation comes from --orientation; the map is masked by --roi and warped into the
character's texture space through the texture landmarks.

orientation (which way each wrinkle normal leans; the ratio only gives how much):
  integrable  a smooth surface's slope flips sign only where R peaks (default; one sign
              per crease: the one that makes the integrated crease a dent)
  furrow      lean towards the crease's centre line, per pixel
  gradient    the paper: along grad R (right on only part of each crease)

Landmarks: JSON or CSV, pixels (origin top-left corner, y down) or UV (glTF, v down); named
landmarks are paired by name, unnamed ones by order. Photos: PNG/TIFF/EXR/JPEG; 8/16-bit files
are decoded from sRGB unless tagged linear (--colorspace).

Writes OUT/<state>.png (16-bit, +Y OpenGL, wrinkles alone), OUT/<state>_roi.png (the ROI in
texture space), OUT/manifest_snippet.toml, OUT/report.json and OUT/report.html with pictures/.

examples:
  wrinklepipe capture --example session/
  wrinklepipe capture session/neutral.png session/expression.png \\
      --neutral-landmarks session/neutral.json --expression-landmarks session/expression.csv \\
      --texture-landmarks session/texture.json --size 128 --roi session/roi.png -o captured/
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("neutral", nargs="?", metavar="NEUTRAL", help="neutral photo I")
    p.add_argument("expression", nargs="?", metavar="EXPRESSION", help="expression photo I'")
    p.add_argument("--neutral-landmarks", metavar="FILE", help="landmarks on the neutral photo")
    p.add_argument(
        "--expression-landmarks", metavar="FILE", help="the same landmarks on the expression photo"
    )
    p.add_argument(
        "--texture-landmarks",
        metavar="FILE",
        help="landmarks in the character's texture (default: output stays in photo space)",
    )
    p.add_argument(
        "--photo-landmarks",
        metavar="FILE",
        help="neutral-photo landmarks paired with --texture-landmarks (default: the neutral set)",
    )
    p.add_argument("--size", metavar="N|WxH", help="texture size (required with texture landmarks)")
    p.add_argument("--roi", metavar="MASK", help="region of interest on the neutral photo (0..1)")
    p.add_argument(
        "--nz",
        type=float,
        default=1.0,
        help="N_z of the neutral surface (default 1: facing camera)",
    )
    p.add_argument(
        "--nz-region",
        action="append",
        default=[],
        metavar="MASK=VALUE",
        help="N_z for a painted region of the neutral photo (repeatable)",
    )
    from wrinklepipe.capture.orientation import METHODS

    p.add_argument(
        "--orientation",
        choices=METHODS,
        default="integrable",
        help="orientation prior (integrable)",
    )
    p.add_argument("--state", default="capture", help="name of the wrinkle state (capture)")
    p.add_argument(
        "--colorspace",
        choices=("auto", "srgb", "linear"),
        default="auto",
        help="how photo values are encoded (auto: sRGB unless tagged linear or float)",
    )
    p.add_argument(
        "--blur", type=float, default=1.0, help="Gaussian blur of R, pixels before --scale (1.0)"
    )
    p.add_argument(
        "--dark", type=float, default=0.02, help="neutral luminance below which R is not taken"
    )
    p.add_argument("--deadband", type=float, default=None, help="noise floor of 1 - R (auto)")
    p.add_argument(
        "--no-exposure", action="store_true", help="do not normalise the flash/exposure ratio"
    )
    p.add_argument(
        "--furrow-sigma",
        type=float,
        default=3.0,
        help="crease half-width, pixels before --scale (3.0)",
    )
    p.add_argument(
        "--scale",
        type=float,
        default=None,
        help="multiply the blur/furrow sigmas (default: max(1, photo width / 384))",
    )
    p.add_argument("--truth", metavar="MAP", help="a true normal map (texture space) to score")
    p.add_argument("--example", metavar="DIR", help="write a synthetic session into DIR and stop")
    p.add_argument("-o", "--output", metavar="OUT", help="output folder")
    p.add_argument("--max-pixels", type=int, default=None, help="cap on photo size (pixels)")
    p.add_argument("--force", action="store_true", help="replace a non-empty output folder")
    p.add_argument("--json", action="store_true", help="print the report as JSON")


def _size(text: str | None) -> tuple[int, int] | None:
    from wrinklepipe.errors import input_error

    if text is None:
        return None
    try:
        if "x" in text.lower():
            w, h = (int(v) for v in text.lower().split("x"))
        else:
            w = h = int(text)
    except ValueError:
        raise input_error("<arguments>", f"--size must be N or WxH, got {text!r}") from None
    if w <= 0 or h <= 0 or w * h > 16384 * 16384:
        raise input_error("<arguments>", f"--size out of range: {text!r}")
    return h, w


def _read_photo(path: str, colorspace: str, max_pixels: int | None) -> tuple[np.ndarray, Any]:
    from wrinklepipe.capture.ratio import luminance, srgb_to_linear
    from wrinklepipe.io.images import DEFAULT_MAX_PIXELS, read_image

    img, info = read_image(path, max_pixels or DEFAULT_MAX_PIXELS)
    linear = colorspace == "linear"
    if colorspace == "auto":
        tag = info.colorspace.lower()
        linear = info.format in ("half", "float", "double") or "lin" in tag or tag == "raw"
    if not linear:
        img = srgb_to_linear(np.clip(img, 0.0, 1.0))
    return luminance(img), info


def _read_mask(path: str, shape: tuple[int, int], what: str) -> np.ndarray:
    from wrinklepipe.errors import input_error
    from wrinklepipe.io.images import read_image

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


def _write_example(folder: str, force: bool) -> int:
    from wrinklepipe.atomic import dumps_json, staged_folder, write_bytes
    from wrinklepipe.capture.synthetic import make_scene
    from wrinklepipe.console import err
    from wrinklepipe.io.images import write_image

    sc = make_scene()
    names = [f"p{i:02d}" for i in range(len(sc.lm_neutral))]
    t_size = sc.truth_texture.shape[0]
    with staged_folder(folder, force=force) as tmp:
        write_image(tmp / "neutral.png", np.clip(sc.neutral, 0, 1), bits=16)
        write_image(tmp / "expression.png", np.clip(sc.expression, 0, 1), bits=16)
        write_image(tmp / "roi.png", sc.roi, bits=8)
        write_image(tmp / "truth_texture.png", 0.5 + 0.5 * sc.truth_texture, bits=16)
        neutral = {
            n: [round(float(x), 4), round(float(y), 4)] for n, (x, y) in zip(names, sc.lm_neutral)
        }
        write_bytes(tmp / "neutral.json", dumps_json({"points": neutral}).encode())
        lines = ["name,x,y"] + [
            f"{n},{x:.4f},{y:.4f}" for n, (x, y) in zip(names, sc.lm_expression)
        ]
        write_bytes(tmp / "expression.csv", ("\n".join(lines) + "\n").encode())
        uv = {
            n: [round(float(x) / t_size, 6), round(float(y) / t_size, 6)]
            for n, (x, y) in zip(names, sc.lm_texture)
        }
        write_bytes(tmp / "texture.json", dumps_json({"space": "uv", "points": uv}).encode())
    err.print(
        f"wrote a synthetic session to {folder}; try:\n  wrinklepipe capture {folder}/neutral.png "
        f"{folder}/expression.png --neutral-landmarks {folder}/neutral.json "
        f"--expression-landmarks {folder}/expression.csv --texture-landmarks "
        f"{folder}/texture.json --size {t_size} --roi {folder}/roi.png "
        f"--truth {folder}/truth_texture.png -o captured/"
    )
    return 0


def run(args: argparse.Namespace) -> int:
    from wrinklepipe.atomic import staged_folder, write_bytes
    from wrinklepipe.capture import CaptureOptions, OrientationOptions, RatioOptions, capture
    from wrinklepipe.capture import landmarks as L
    from wrinklepipe.capture.evaluate import errors as truth_errors
    from wrinklepipe.capture.report import build_report, write_pictures, write_report
    from wrinklepipe.console import emit_json, err, status
    from wrinklepipe.errors import InputError, Problem, input_error
    from wrinklepipe.io.images import read_image, write_image
    from wrinklepipe.model import normalize

    if args.example:
        return _write_example(args.example, args.force)
    if not re.fullmatch(r"[A-Za-z0-9_]+", args.state):
        raise input_error(
            "<arguments>",
            f"--state must be letters, digits and '_' (a manifest name): {args.state!r}",
        )
    missing = [
        flag
        for flag, val in (
            ("NEUTRAL", args.neutral),
            ("EXPRESSION", args.expression),
            ("--neutral-landmarks", args.neutral_landmarks),
            ("--expression-landmarks", args.expression_landmarks),
            ("-o/--output", args.output),
        )
        if not val
    ]
    if missing:
        raise InputError([Problem("<arguments>", f"missing {m}") for m in missing])
    checks = [("--blur", args.blur), ("--dark", args.dark), ("--nz", args.nz)]
    if args.scale is not None:
        checks.append(("--scale", args.scale))
    for flag, val in checks:
        if not np.isfinite(val) or val < 0:
            raise input_error("<arguments>", f"{flag} must be a finite number >= 0, got {val}")
    if not 0 < args.nz <= 1:
        raise input_error("<arguments>", f"--nz must lie in (0, 1], got {args.nz}")

    i0, info0 = _read_photo(args.neutral, args.colorspace, args.max_pixels)
    i1, info1 = _read_photo(args.expression, args.colorspace, args.max_pixels)
    if (info0.width, info0.height) != (info1.width, info1.height):
        raise input_error(
            args.expression,
            f"photo is {info1.width} x {info1.height} but the neutral photo {args.neutral} is "
            f"{info0.width} x {info0.height}; take both with the same camera settings (or crop "
            "them to one size)",
        )
    for path, lum in ((args.neutral, i0), (args.expression, i1)):
        top = float(np.nanmax(lum)) if lum.size else 0.0
        if not np.isfinite(top) or top < args.dark:
            raise input_error(
                path,
                f"photo is all black (brightest linear luminance {top:.4f} is below --dark "
                f"{args.dark}); nothing to divide",
            )
    shape = (info0.height, info0.width)

    lm_n = L.read_landmarks(args.neutral_landmarks).to_pixels(info0.width, info0.height)
    lm_e = L.read_landmarks(args.expression_landmarks).to_pixels(info1.width, info1.height)
    pn, pe = L.pair(lm_n, lm_e)
    L.check_inside(lm_n, info0.width, info0.height, "neutral photo")
    L.check_inside(lm_e, info1.width, info1.height, "expression photo")

    tex_shape = _size(args.size)
    if args.texture_landmarks:
        if tex_shape is None:
            raise input_error("<arguments>", "--size is required with --texture-landmarks")
        th, tw = tex_shape
        lm_t = L.read_landmarks(args.texture_landmarks).to_pixels(tw, th)
        lm_p = (
            L.read_landmarks(args.photo_landmarks).to_pixels(info0.width, info0.height)
            if args.photo_landmarks
            else lm_n
        )
        pp, pt = L.pair(lm_p, lm_t)
        lm_t_names = lm_p.names if lm_p.names is not None and lm_t.names is not None else None
        L.check_inside(lm_p, info0.width, info0.height, "neutral photo")
        L.check_inside(lm_t, tw, th, "texture")
    else:  # identity: the map stays in photo space
        lm_t_names = None
        tex_shape = shape
        corners = np.array(
            [[0, 0], [info0.width, 0], [0, info0.height], [info0.width, info0.height]], float
        )
        pp = pt = corners

    roi = _read_mask(args.roi, shape, "ROI mask") if args.roi else None
    nz: np.ndarray | float = args.nz
    for spec in args.nz_region:
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
        m = _read_mask(path, shape, "N_z region mask")
        nz = np.asarray(nz, np.float32) * (1.0 - m) + v * m
    truth = None
    if args.truth:
        t, tinfo = read_image(args.truth)
        if (tinfo.height, tinfo.width) != tuple(tex_shape) or t.shape[2] < 3:
            raise input_error(
                args.truth, f"truth map must be an RGB {tex_shape[1]} x {tex_shape[0]} normal map"
            )
        truth = normalize(2.0 * t[..., :3] - 1.0)

    options = CaptureOptions(
        ratio=RatioOptions(
            dark_threshold=args.dark,
            normalize_exposure=not args.no_exposure,
            blur_sigma=args.blur,
            deadband=args.deadband,
        ),
        orientation=OrientationOptions(method=args.orientation, furrow_sigma=args.furrow_sigma),
        scale=args.scale,
    )
    with status("capturing"):
        res = capture(i0, i1, pn, pe, pp, pt, tuple(tex_shape), roi, nz, options)

    te = None
    if truth is not None:
        te = {m: truth_errors(n, truth, res.roi_texture) for m, n in res.normal_texture.items()}
    inputs = {
        k: str(v)
        for k, v in (
            ("neutral", args.neutral),
            ("expression", args.expression),
            ("neutral_landmarks", args.neutral_landmarks),
            ("expression_landmarks", args.expression_landmarks),
            ("texture_landmarks", args.texture_landmarks),
            ("photo_landmarks", args.photo_landmarks),
            ("roi", args.roi),
            ("truth", args.truth),
        )
        if v
    }
    state = args.state
    outputs = {
        "normal_map": f"{state}.png",
        "roi_map": f"{state}_roi.png",
        "manifest_snippet": "manifest_snippet.toml",
        "texture_size": [int(tex_shape[1]), int(tex_shape[0])],
        "space": "texture" if args.texture_landmarks else "photo",
    }
    opts = {
        "orientation": args.orientation,
        "blur_sigma": args.blur,
        "dark_threshold": args.dark,
        "deadband": args.deadband,
        "normalize_exposure": not args.no_exposure,
        "furrow_sigma": args.furrow_sigma,
        "nz": args.nz,
        "nz_regions": list(args.nz_region),
        "colorspace": args.colorspace,
        "scale": args.scale,
    }
    report = build_report(res, inputs, opts, outputs, te)
    for key, names in (("expression_to_neutral", lm_n.names), ("photo_to_texture", lm_t_names)):
        worst = report["warps"][key]["leave_one_out_worst_index"]
        if names is not None and worst is not None:
            report["warps"][key]["leave_one_out_worst_name"] = names[worst]
    input_files = [v for k, v in inputs.items()]
    snippet = (
        "# wrinklepipe capture: merge into the character's manifest (copy the maps beside it).\n"
        "# The captured map holds the wrinkles alone (no base detail), so the manifest needs,\n"
        "# at its top level (above any [[table]]):\n"
        "#   states_include_base = false\n\n"
        f'[[states]]\nname = "{state}"\nmap = "{state}.png"\n\n'
        f'[[regions]]\nname = "{state}_roi"\nmask = "{state}_roi.png"\nstates = ["{state}"]\n'
    )
    with staged_folder(args.output, force=args.force, inputs=input_files) as tmp:
        write_image(tmp / f"{state}.png", 0.5 + 0.5 * res.normal, bits=16)
        write_image(tmp / f"{state}_roi.png", res.roi_texture, bits=16)
        write_bytes(tmp / "manifest_snippet.toml", snippet.encode("utf-8"))
        pics = write_pictures(tmp, res, i0, i1, roi if roi is not None else np.ones(shape))
        write_report(tmp, report, pics)
    if args.json:
        emit_json(report)
    else:
        w1 = report["warps"]["expression_to_neutral"]
        err.print(
            f"captured {state} ({args.orientation}) -> {Path(args.output) / (state + '.png')} "
            f"[{tex_shape[1]} x {tex_shape[0]}]; leave-one-out landmark residual max "
            f"{w1['leave_one_out_max_px']} px; clipped {report['ratio']['fraction_clipped']:.3f}"
            f", dark {report['ratio']['fraction_dark']:.3f}"
        )
        if te is not None:
            for m, e in te.items():
                err.print(
                    f"  {m:<10} angular mean {e['angular']['mean']:.2f} deg, tilt mean "
                    f"{e['tilt']['mean']:.2f} deg, orientation correct "
                    f"{e['orientation_correct']:.3f} (flat map {e['flat']['mean']:.2f} deg)"
                )
    return 0
