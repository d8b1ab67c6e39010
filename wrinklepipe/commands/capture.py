"""``wrinklepipe capture``: a wrinkle normal map from two flash-lit photographs (ratio image)."""

from __future__ import annotations

import argparse
from pathlib import Path

from wrinklepipe.atomic import staged_folder
from wrinklepipe.capture.orientation import METHODS
from wrinklepipe.commands._options import add_force, add_json, add_output, finite_float
from wrinklepipe.console import emit_json, err, status
from wrinklepipe.errors import input_error
from wrinklepipe.jobs.capture import CaptureInputs, CaptureJobOptions, example_session, run_capture

NAME = "capture"
HELP = "capture a wrinkle normal map from a neutral and an expression photo (ratio image)"
DESCRIPTION = """\
Dutreve et al.'s mono-camera capture: two frontal photos of the same face under the camera's
flash, one neutral (I) and one with the expression (I'). The expression photo is warped onto the
neutral one with a thin-plate spline through the landmarks; the ratio R = I'_d / I of their
linear luminance cancels the skin colour and gives the wrinkled normal's tilt from the camera
(N'_z = R N_z); the orientation comes from --orientation; the map is masked by --roi and warped
into the character's texture space through the texture landmarks.

The neutral's shape: --neutral-normals is the neutral face's normal map seen from the photo's
camera (camera frame: +X right, +Y up, +Z towards the camera; 0.5 + 0.5 n, or raw n in EXR),
the same size as the neutral photo; or --neutral-mesh, the character's neutral mesh (glTF, USD
or OBJ with the UVs the texture landmarks are given in): the landmarks define a scaled
orthographic camera and the mesh's normals are rendered from it. With either, ratios above 1
(skin turned towards the flash) are used, the wrinkle is measured relative to the neutral
surface, and ridges are told from valleys where the neutral turns from the camera. Without them
the neutral faces the camera (--nz, --nz-region give constants).

A light at the camera shows a crease's sign only through the neutral's own slope: on a region
facing the camera ridges and valleys look alike. --side-lit PHOTO (the expression again, same
pose and camera, lit from --side-light X,Y,Z instead of the flash) shows it everywhere: the
solve fits both photos.

orientation (which way each wrinkle normal leans; the ratio only gives how much):
  auto        sfs with --neutral-normals on a neutral turned from the camera (N_z < 0.97
              somewhere in the ROI) or with --side-lit, integrable otherwise (default;
              measured, docs/capture.md)
  sfs         the crease height whose Lambertian ratio image matches R (integrable, zero at
              the ROI border; tells ridges from valleys where the neutral is tilted)
  integrable  a smooth surface's slope flips sign only where R peaks (one dent per crease)
  furrow      lean towards the crease's centre line, per pixel
  gradient    the paper: along grad R

Writes OUT/<state>.png (16-bit, +Y OpenGL, wrinkles alone), OUT/<state>_roi.png (the ROI in
texture space), OUT/manifest_snippet.toml, OUT/report.json and OUT/report.html with pictures/.

examples:
  wrinklepipe capture --example session/
  wrinklepipe capture session/neutral.png session/expression.png \\
      --neutral-landmarks session/neutral.json --expression-landmarks session/expression.csv \\
      --texture-landmarks session/texture.json --size 128 --roi session/roi.png \\
      --neutral-normals session/neutral_normals.png -o captured/
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = CaptureJobOptions()
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
    p.add_argument(
        "--size",
        metavar="SIZE",
        help="texture size: N (square) or WxH (required with --texture-landmarks)",
    )
    p.add_argument("--roi", metavar="MASK", help="region of interest on the neutral photo (0..1)")
    p.add_argument(
        "--neutral-normals",
        metavar="MAP",
        help="the neutral face's normals seen from the photo's camera (the neutral's shape)",
    )
    p.add_argument(
        "--neutral-mesh",
        metavar="MESH",
        help="the character's neutral mesh (glTF/USD/OBJ with UVs): its normals are rendered "
        "from the camera the texture landmarks define (instead of --neutral-normals)",
    )
    p.add_argument(
        "--side-lit",
        metavar="PHOTO",
        help="the expression photographed again lit from one side (same pose and camera as "
        "EXPRESSION, so its landmarks): every crease's sign becomes observable; needs "
        "--side-light and the neutral's shape",
    )
    p.add_argument(
        "--side-light",
        metavar="X,Y,Z",
        help="direction towards the side light in the camera frame (+X right, +Y up, +Z "
        "towards the camera), e.g. 0.4,0.3,0.87",
    )
    _add_solver_options(p, d)


def _add_solver_options(p: argparse.ArgumentParser, d: CaptureJobOptions) -> None:
    """The ratio, orientation and output options."""
    p.add_argument(
        "--nz",
        type=finite_float,
        default=d.nz,
        metavar="NZ",
        help="N_z of the neutral surface (1: facing the camera)",
    )
    p.add_argument(
        "--nz-region",
        action="append",
        default=[],
        metavar="MASK=VALUE",
        help="N_z for a painted region of the neutral photo (repeatable)",
    )
    p.add_argument(
        "--orientation",
        choices=("auto",) + METHODS,
        default=d.orientation,
        metavar="METHOD",
        help="orientation method: auto, " + ", ".join(METHODS),
    )
    p.add_argument("--state", default=d.state, metavar="NAME", help="name of the wrinkle state")
    p.add_argument(
        "--colorspace",
        choices=("auto", "srgb", "linear"),
        default=d.colorspace,
        metavar="SPACE",
        help="how photo values are encoded: auto (sRGB unless tagged linear or float), srgb, "
        "linear",
    )
    p.add_argument(
        "--blur",
        type=finite_float,
        default=d.blur,
        metavar="PX",
        help="Gaussian blur of R, in pixels before --scale",
    )
    p.add_argument(
        "--dark",
        type=finite_float,
        default=d.dark,
        metavar="L",
        help="neutral luminance below which R is not taken",
    )
    p.add_argument(
        "--deadband",
        type=finite_float,
        default=d.deadband,
        metavar="D",
        help="noise floor of 1 - R (default: measured)",
    )
    p.add_argument(
        "--no-exposure", action="store_true", help="do not normalise the flash/exposure ratio"
    )
    p.add_argument(
        "--furrow-sigma",
        type=finite_float,
        default=d.furrow_sigma,
        metavar="PX",
        help="crease half-width, in pixels before --scale",
    )
    p.add_argument(
        "--scale",
        type=finite_float,
        default=d.scale,
        metavar="K",
        help="multiply the blur/furrow sigmas (default: max(1, photo width / 256))",
    )
    p.add_argument("--truth", metavar="MAP", help="a true normal map (texture space) to score")
    p.add_argument("--example", metavar="DIR", help="write a synthetic session into DIR and stop")
    add_output(p, "output folder (required unless --example)", required=False)
    p.add_argument(
        "--max-pixels",
        type=int,
        default=d.max_pixels,
        metavar="N",
        help="refuse photos of more pixels",
    )
    add_force(p)
    add_json(p)


def run(args: argparse.Namespace) -> int:
    if args.example:
        out = example_session()
        with staged_folder(args.example, force=args.force) as tmp:
            out.write(tmp)
        err.print(out.report["hint"].replace("DIR", args.example))
        return 0
    if not args.output:
        raise input_error("<arguments>", "missing -o/--output")
    inputs = CaptureInputs(
        neutral=args.neutral,
        expression=args.expression,
        neutral_landmarks=args.neutral_landmarks,
        expression_landmarks=args.expression_landmarks,
        texture_landmarks=args.texture_landmarks,
        photo_landmarks=args.photo_landmarks,
        size=args.size,
        roi=args.roi,
        neutral_normals=args.neutral_normals,
        neutral_mesh=args.neutral_mesh,
        side_lit=args.side_lit,
        truth=args.truth,
    )
    options = CaptureJobOptions(
        orientation=args.orientation,
        state=args.state,
        colorspace=args.colorspace,
        blur=args.blur,
        dark=args.dark,
        deadband=args.deadband,
        normalize_exposure=not args.no_exposure,
        furrow_sigma=args.furrow_sigma,
        scale=args.scale,
        nz=args.nz,
        nz_regions=tuple(args.nz_region),
        side_light=args.side_light,
        max_pixels=args.max_pixels,
    )
    with status("capturing"):
        out = run_capture(inputs, options)
    with staged_folder(args.output, force=args.force, inputs=list(inputs.given().values())) as tmp:
        out.write(tmp)
    if args.json:
        emit_json(out.report)
    else:
        for line in out.summary(Path(args.output)):
            err.print(line)
    return 0
