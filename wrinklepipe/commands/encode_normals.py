"""``wrinklepipe encode-normals``: encode one normal map as PD / diff / full, resize, compress,
check the angular error, write DDS / KTX2 / PNG / EXR."""

from __future__ import annotations

import argparse
from pathlib import Path

from wrinklepipe.atomic import output_files, write_bytes, write_json
from wrinklepipe.commands._options import add_json, add_output, add_report, finite_float
from wrinklepipe.console import emit_json, err, status
from wrinklepipe.normals.job import OUTPUT_FORMATS, EncodeOptions, encode_normals

NAME = "encode-normals"
HELP = "encode a normal map (pd/diff/full), resize, block-compress, and measure the error"
DESCRIPTION = """\
Read a normal map (PNG 8/16, TIFF, EXR, JPEG, DDS BC1/BC3/BC5/BC7), bring it to +Y (OpenGL)
tangent space (--convention, detected when auto), encode it and write OUT:

  --encoding pd    slopes (x/z, y/z) in R, G, scaled by s (--scale S|auto); with --base, the
                   wrinkle-only slopes (map minus base), as Jimenez et al. store them
  --encoding diff  0.5 + 0.5 gain (W - B) (needs --base; --gain G|auto)
  --encoding full  the normal map itself (x, y in R, G; z rebuilt for BC formats)

--format bc5|bc1|bc3nm|bc7 writes a .dds or .ktx2 (mip chain unless --no-mips); uastc a .ktx2
(Basis Universal, needs the alktx2 package); png8/png16 a .png/.tif; exr a half-float .exr;
auto picks the smallest block format whose error stays within the budget (--max-p99 /
--max-mean degrees). Every block format is decoded independently (texture2ddecoder) and
measured: angular error mean / p99 / max, PSNR per channel, the error of
the blended result at weights 0.5 and 1 (with --base), bytes, verdict.

Exit codes: 0 written and within budget, 1 written but over budget, 2 bad input (nothing
written).

examples:
  wrinklepipe encode-normals compress.png --base base.png -o compress_pd.dds --encoding pd
  wrinklepipe encode-normals stretch.png -o w.ktx2 --format auto --size 32 --report r.json
  wrinklepipe encode-normals unreal_normal.png --convention directx -o n.png --encoding full
"""


def _scale(text: str) -> float | str:
    if text == "auto":
        return "auto"
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or auto, got {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text}")
    return v


def _size(text: str) -> int | str:
    if text == "auto":
        return "auto"
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer or auto, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {text}")
    return v


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = EncodeOptions()  # the defaults: one place
    p.add_argument("input", metavar="IN", help="normal map to encode")
    add_output(p, "output file (.dds, .ktx2, .png, .tif or .exr)")
    p.add_argument(
        "--encoding",
        choices=("pd", "diff", "full"),
        default=d.encoding,
        metavar="ENCODING",
        help="pd (slopes), diff (the difference to --base) or full (the normals)",
    )
    p.add_argument(
        "--base", metavar="FILE", help="neutral-face normal map (diff; pd: wrinkle-only slopes)"
    )
    p.add_argument(
        "--scale", type=_scale, default=d.scale, metavar="S", help="PD slope scale, or auto"
    )
    p.add_argument("--gain", type=_scale, default=d.gain, metavar="G", help="diff gain, or auto")
    p.add_argument(
        "--format",
        dest="fmt",
        choices=OUTPUT_FORMATS,
        default=None,
        metavar="FORMAT",
        help=", ".join(OUTPUT_FORMATS) + " (default: from OUT's suffix; .dds/.ktx2 -> bc5)",
    )
    p.add_argument(
        "--convention",
        choices=("auto", "opengl", "directx"),
        default=d.convention,
        metavar="GREEN",
        help="the input's green channel: opengl (+Y), directx (-Y) or auto (detected)",
    )
    p.add_argument(
        "--size", type=_size, default=None, metavar="N", help="target side in texels, or auto"
    )
    p.add_argument("--no-mips", dest="mips", action="store_false", help="level 0 only")
    p.add_argument(
        "--no-pad",
        dest="pad",
        action="store_false",
        help="refuse sizes that are not multiples of 4 instead of padding",
    )
    p.add_argument(
        "--dds-legacy",
        dest="dx10",
        action="store_const",
        const=False,
        default=None,
        help="BC5 as FourCC ATI2 instead of the DX10 header",
    )
    p.add_argument(
        "--dds-dx10",
        dest="dx10",
        action="store_const",
        const=True,
        help="DX10 header for every format (also BC1/BC3)",
    )
    p.add_argument(
        "--max-p99",
        type=finite_float,
        default=d.max_p99_deg,
        metavar="DEG",
        help="budget: p99 error in degrees",
    )
    p.add_argument(
        "--max-mean",
        type=finite_float,
        default=d.max_mean_deg,
        metavar="DEG",
        help="budget: mean error in degrees",
    )
    p.add_argument("--repair", action="store_true", help="repair NaN / zero / z<0 texels")
    p.add_argument(
        "--max-pixels",
        type=int,
        default=d.max_pixels,
        metavar="N",
        help="refuse images of more pixels",
    )
    add_report(p, "the report")
    add_json(p)


def run(args: argparse.Namespace) -> int:
    opts = EncodeOptions(
        encoding=args.encoding,
        scale=args.scale,
        gain=args.gain,
        fmt=args.fmt,
        size=args.size,
        convention=args.convention,
        repair=args.repair,
        max_pixels=args.max_pixels,
        mips=args.mips,
        pad=args.pad,
        dx10=args.dx10,
        max_p99_deg=args.max_p99,
        max_mean_deg=args.max_mean,
    )
    inputs = [args.input] + ([args.base] if args.base else [])
    with output_files(args.output, args.report):  # a second run into the same files is refused
        with status(f"encoding {args.input}"):
            res = encode_normals(args.input, args.output, opts, args.base)
        res.report["output"] = {"path": str(Path(args.output)), "bytes": len(res.data)}
        write_bytes(args.output, res.data, inputs=inputs)
        if args.report:
            write_json(args.report, res.report, inputs=inputs)
    if args.json:
        emit_json(res.report)
    else:
        fmt = res.report["format"]
        checks = [c for c in res.report.get("checks", []) if c["format"] == fmt["name"]]
        e0 = checks[0]["error"] if checks else fmt["error"]
        err.print(
            f"wrote {args.output} ({fmt['name']}, {len(res.data)} bytes): error mean "
            f"{e0['mean_deg']:.3f} deg, p99 {e0['p99_deg']:.3f}, max {e0['max_deg']:.3f} -> "
            f"{res.report['verdict']}"
        )
        for note in res.notes:
            err.print(f"  note: {note}")
    return 0 if res.ok else 1
