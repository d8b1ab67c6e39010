"""The ``encode-normals`` job as a plain function: read -> encode -> resize -> store -> check.

:func:`encode_normals` returns the output bytes and a JSON-ready report; it writes nothing
(the command writes atomically), so ``convert`` can reuse it.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import codec
from wrinklepipe.errors import input_error
from wrinklepipe.io.images import DEFAULT_MAX_PIXELS, write_image
from wrinklepipe.metrics import Budget, Stats
from wrinklepipe.model import normal_to_pd, normalize, pd_to_normal
from wrinklepipe.normals import compress as cmp
from wrinklepipe.normals import dds as dds_mod
from wrinklepipe.normals import encode as enc
from wrinklepipe.normals import footprint as fp
from wrinklepipe.normals import ktx2 as ktx2_mod
from wrinklepipe.normals import mips, resample, uastc
from wrinklepipe.normals.encode import MAX_PD_SCALE, MIN_PD_SCALE
from wrinklepipe.normals.read import NormalMap, ReadOptions, read_normal_map
from wrinklepipe.options import DEFAULT_MAX_P99_DEG

_F = np.float32

ENCODINGS = ("pd", "diff", "full")
OUTPUT_FORMATS = ("bc5", "bc1", "bc3nm", "bc7", "bc7xy", "uastc", "png8", "png16", "exr", "auto")
#: BC7 (bc7enc) is slow: above this many texels ``--format auto`` leaves it out.
AUTO_BC7_MAX_TEXELS = 1 << 20


@dataclass(frozen=True)
class EncodeOptions:
    """What ``encode-normals`` does; defaults match the command line.

    encoding: "pd" (two channels, slopes), "diff" (three, needs ``base``), "full".
    scale: PD slope scale s (float) or "auto" (smallest power of two >= p99.9 slope).
    gain: diff gain (float) or "auto".
    fmt: output format; None derives it from the output suffix (.dds/.ktx2 -> bc5,
        .png -> png8, .exr -> exr); "auto" picks the smallest BC format within budget.
    size: target side (int), None (keep) or "auto" (smallest power of two within budget).
    mips: write a full mip chain into DDS/KTX2.
    pad: pad BC inputs whose size is not a multiple of 4 (edge texels repeated) instead of
        refusing them.
    dx10: DDS header choice (None: DX10 for bc5/bc7, FourCC for bc1/bc3).
    max_p99_deg / max_mean_deg: the error budget (None: no limit; the p99 default is the
    manifest's, :data:`wrinklepipe.options.DEFAULT_MAX_P99_DEG`).
    """

    encoding: str = "pd"
    scale: float | str = "auto"
    gain: float | str = 1.0
    fmt: str | None = None
    size: int | str | None = None
    convention: str = "auto"
    repair: bool = False
    max_pixels: int = DEFAULT_MAX_PIXELS
    mips: bool = True
    pad: bool = True
    dx10: bool | None = None
    max_p99_deg: float | None = DEFAULT_MAX_P99_DEG
    max_mean_deg: float | None = None  # a whole map, not a manifest's regions: p99 only


@dataclass
class EncodeResult:
    """The output file's bytes, the report, and whether the budget held."""

    data: bytes
    report: dict[str, Any]
    ok: bool = True
    notes: list[str] = field(default_factory=list)


def _container_for(path: Path) -> str:
    suf = path.suffix.lower()
    if suf in (".dds", ".ktx2", ".png", ".exr", ".tif", ".tiff"):
        return suf[1:].replace("tiff", "tif")
    raise input_error(path, f"unknown output type {suf!r} (use .dds, .ktx2, .png, .tif or .exr)")


def _resolve_format(out: Path, fmt: str | None) -> tuple[str, str]:
    container = _container_for(out)
    if fmt is None:
        fmt = {"dds": "bc5", "ktx2": "bc5", "png": "png8", "tif": "png16", "exr": "exr"}[container]
    if fmt not in OUTPUT_FORMATS:
        raise input_error(
            out, f"unknown format {fmt!r}; expected one of {', '.join(OUTPUT_FORMATS)}"
        )
    if fmt == "uastc" and container != "ktx2":
        raise input_error(out, "format uastc is written as KTX2: use a .ktx2 output")
    block = fmt in cmp.FORMATS or fmt in ("auto", "uastc")
    if block and container not in ("dds", "ktx2"):
        raise input_error(
            out, f"format {fmt} is block-compressed: write it to a .dds or .ktx2 file"
        )
    if not block and container in ("dds", "ktx2"):
        raise input_error(out, f"format {fmt} is not block-compressed: write it to .png/.tif/.exr")
    if fmt == "exr" and container != "exr":
        raise input_error(out, "format exr needs a .exr output")
    if fmt in ("png8", "png16") and container not in ("png", "tif"):
        raise input_error(out, f"format {fmt} needs a .png or .tif output")
    return fmt, container


def _stored(
    encoding: str, wrinkle: np.ndarray, base: np.ndarray | None, scale: float, gain: float | str
) -> tuple[np.ndarray, dict[str, Any], np.ndarray]:
    """The map's quantity (:mod:`wrinklepipe.codec.encodings`: pd slopes, diff deltas, unit
    normals), the encoding parameters, and the normals that the stored map must decode to (pd
    with a base: the wrinkle-only normal; else the map)."""
    if encoding == "pd":
        slopes = enc.normal_slopes(wrinkle)
        if base is not None:
            slopes = slopes - enc.normal_slopes(base)  # wrinkle-only slopes (PD is linear)
        slopes = np.nan_to_num(slopes, posinf=1e6, neginf=-1e6)
        n_store = pd_to_normal(slopes)
        s = float(scale)
        params = {
            "scale": s,
            "clipped": enc.pd_clipped_count(n_store, s),
            "cone_deg": round(enc.cone_deg(s), 6),
            "mapping": codec.CURRENT_VERSION,
        }
        return slopes, params, n_store
    if encoding == "diff":
        g = enc.auto_diff_gain(wrinkle, base) if gain == "auto" else float(gain)
        if not g > 0 or not math.isfinite(g):
            raise ValueError(f"diff gain must be a positive number, got {gain!r}")
        delta = np.asarray(wrinkle, _F) - np.asarray(base, _F)
        _, clipped = codec.DIFF.to_signed(delta, g)
        params = {"gain": g, "clipped": clipped, "mapping": codec.CURRENT_VERSION}
        return delta, params, wrinkle
    return normalize(wrinkle), {}, wrinkle


def _param(encoding: str, params: dict[str, Any]) -> float:
    return float(params.get("scale" if encoding == "pd" else "gain", 1.0))


def _components(
    encoding: str, x: np.ndarray, fmt: str, params: dict[str, Any], bits: int = 8
) -> np.ndarray:
    """Texel components [H, W, 2 or 3] of the quantity in ``fmt``'s layout (codec)."""
    lay = codec.storage_format(fmt).layout_for(encoding)
    packed, _ = codec.encode(encoding, x, lay, param=_param(encoding, params), bits=bits)
    return codec.layouts.unpack(packed, lay)


def _read(path: Path, o: EncodeOptions) -> NormalMap:
    return read_normal_map(
        path, ReadOptions(convention=o.convention, repair=o.repair, max_pixels=o.max_pixels)
    )


def encode_normals(
    src: str | Path, out: str | Path, options: EncodeOptions, base_path: str | Path | None = None
) -> EncodeResult:
    """Run the whole job in memory. Raises :class:`InputError` for bad inputs or options."""
    o = options
    src, out = Path(src), Path(out)
    fmt, container = _checked_format(src, out, o, base_path)
    if isinstance(o.size, int) and o.size * o.size > o.max_pixels:  # costed before any read
        raise input_error(
            "--size",
            f"{o.size} makes maps of up to {o.size} x {o.size} = {o.size * o.size} pixels, over "
            f"the cap of {o.max_pixels} pixels (--max-pixels N raises it)",
        )
    nm = _read(src, o)
    base_nm = _read(Path(base_path), o) if base_path is not None else None
    w_n = nm.normals
    b_n = base_nm.normals if base_nm is not None else None
    if b_n is not None and b_n.shape != w_n.shape:
        raise input_error(
            base_path,
            f"base is {b_n.shape[1]} x {b_n.shape[0]}, the map {w_n.shape[1]} x {w_n.shape[0]}",
        )
    notes: list[str] = list(nm.notes)
    budget = Budget(o.max_mean_deg, o.max_p99_deg)
    w_n, b_n, size_report = _resized(w_n, b_n, o, budget)
    h, w = w_n.shape[:2]

    scale = o.scale
    if o.encoding == "pd" and scale == "auto":
        slopes = enc.normal_slopes(w_n) - (enc.normal_slopes(b_n) if b_n is not None else 0)
        scale = enc.auto_pd_scale(np.nan_to_num(slopes, posinf=1e6, neginf=-1e6))
    try:
        x, params, truth = _stored(
            o.encoding, w_n, b_n, float(scale) if scale != "auto" else 1.0, o.gain
        )
    except ValueError as exc:
        raise input_error(src, str(exc)) from None
    report: dict[str, Any] = {
        "input": nm.to_json(),
        "base": base_nm.to_json() if base_nm else None,
        "encoding": {"name": o.encoding, **params},
        "size": size_report,
        "budget": {"max_p99_deg": o.max_p99_deg, "max_mean_deg": o.max_mean_deg},
    }
    if params.get("clipped"):
        notes.append(
            f"{params['clipped']} texels were outside the encodable range and were clipped"
        )

    if fmt in ("png8", "png16", "exr"):
        data, err = _plain(x, fmt, container, o.encoding, params, b_n, truth)
        report["format"] = {"name": fmt, "error": err.to_json(), "bytes": len(data)}
        ok = budget.inside(err)
        report["verdict"] = "pass" if ok else "fail"
        report["footprint"] = fp.footprint(
            [(out.name, "rgb16" if fmt != "png8" else "rgb8", w, h, False)]
        ).to_json()
        report["notes"] = notes
        return EncodeResult(data, report, ok, notes)

    # --- block formats: each format stores the quantity in its own layout (codec)
    padded = bool(h % 4 or w % 4)
    if padded and not o.pad:
        raise input_error(
            src,
            f"{w} x {h} is not a multiple of 4, which {fmt if fmt != 'auto' else 'BC formats'} "
            "need; resize (--size) or allow padding (drop --no-pad)",
        )
    if padded:
        notes.append(f"{w} x {h} padded to multiples of 4 by repeating the edge texels")
    dec = cmp.decoder_for(o.encoding, params.get("scale", 1.0), params.get("gain", 1.0), b_n)
    blend = _blend_fn(o.encoding, params, b_n, truth)
    if fmt == "uastc":
        return _uastc(out, o, x, params, truth, dec, budget, report, notes)
    if fmt != "auto" and not codec.storage_format(fmt).holds(o.encoding):
        raise input_error(out, f"a {o.encoding} map has three channels; {fmt} holds two")
    candidates = (
        [fmt]
        if fmt != "auto"
        else [f for f in cmp.AUTO_FORMATS if codec.storage_format(f).holds(o.encoding)]
    )
    if fmt == "auto" and h * w > AUTO_BC7_MAX_TEXELS and "bc7" in candidates:
        candidates.remove("bc7")
        notes.append("bc7 left out of --format auto: too slow above 1 Mpx")
    checks = []
    for f in candidates:
        q = _components(o.encoding, x, f, params)
        checks.append(
            cmp.compress_and_check(
                q, truth, f, dec, budget=budget, pad=True, blend=blend, keep_decoded=False
            )
        )
    chosen = cmp.choose_format(checks, budget) if fmt == "auto" else checks[0]
    if chosen is None:
        chosen = min(checks, key=lambda c: c.error.p99)
        notes.append(f"no format meets the budget; wrote the best one ({chosen.format})")
    levels = [chosen.data]
    if o.mips:
        levels += mips.block_levels(o.encoding, x, chosen.format, _param(o.encoding, params))
    layout = codec.storage_format(chosen.format).layout_for(o.encoding).name
    if container == "dds":
        data = dds_mod.dds_bytes(chosen.format, w, h, levels, dx10=o.dx10)
    else:
        data = ktx2_mod.ktx2_bytes(chosen.format, w, h, levels, layout=layout)
    ok = chosen.verdict == "pass"
    report["format"] = {
        "name": chosen.format,
        "container": container,
        "layout": layout,
        "levels": len(levels),
        "bytes": len(data),
    }
    report["checks"] = [c.to_json() for c in checks]
    report["verdict"] = "pass" if ok else "fail"
    report["footprint"] = fp.footprint([(out.name, chosen.format, w, h, o.mips)]).to_json()
    report["notes"] = notes
    return EncodeResult(data, report, ok, notes)


def _checked_format(
    src: Path, out: Path, o: EncodeOptions, base_path: str | Path | None
) -> tuple[str, str]:
    """The output's format and container, once the encoding, the base and ``--scale`` that
    the options give are known to fit together."""
    if o.encoding not in ENCODINGS:
        raise input_error(out, f"unknown encoding {o.encoding!r}; expected pd, diff or full")
    fmt, container = _resolve_format(out, o.fmt)
    if o.encoding == "diff" and base_path is None:
        raise input_error(src, "encoding diff needs --base (the neutral face's normal map)")
    if o.encoding == "diff" and fmt in ("bc5", "bc3nm"):
        raise input_error(out, f"a diff map has three channels; {fmt} holds two (use bc1 or bc7)")
    # the range a manifest's pd_scale has (an auto scale or gain stays inside it too): beyond
    # it the slopes overflow float32 (numpy's RuntimeWarnings, 180-degree errors)
    for flag, value in (("--scale", o.scale), ("--gain", o.gain)):
        if isinstance(value, (int, float)) and not MIN_PD_SCALE <= value <= MAX_PD_SCALE:
            raise input_error(
                flag,
                f"{value:g} is out of range; expected auto or a number >= {MIN_PD_SCALE:g} and "
                f"<= {MAX_PD_SCALE:g}",
            )
    return fmt, container


def _resized(
    w_n: np.ndarray, b_n: np.ndarray | None, o: EncodeOptions, budget: Budget
) -> tuple[np.ndarray, np.ndarray | None, dict[str, Any]]:
    """The map (and the base) at ``--size`` (``auto``: the smallest within the budget),
    resampled in PD space for pd, renormalised otherwise; and the size report."""
    h0, w0 = w_n.shape[:2]
    size_report: dict[str, Any] = {"source": [w0, h0]}
    target = o.size
    if target == "auto":
        target, tried = _auto_size(w_n, b_n, o.encoding, budget)
        size_report["auto"] = {str(k): v.to_json() for k, v in sorted(tried.items())}
    if target is not None and int(target) != max(h0, w0):
        t = int(target)
        th, tw = (t, max(1, round(w0 * t / h0))) if h0 >= w0 else (max(1, round(h0 * t / w0)), t)
        space = "pd" if o.encoding == "pd" else "normal"
        w_n = resample.resize_normals(w_n, (th, tw), space=space)
        if b_n is not None:
            b_n = resample.resize_normals(b_n, (th, tw), space=space)
    h, w = w_n.shape[:2]
    size_report["output"] = [w, h]
    return w_n, b_n, size_report


def _uastc(
    out: Path,
    o: EncodeOptions,
    x: np.ndarray,
    params: dict[str, Any],
    truth: np.ndarray,
    dec: Any,
    budget: Budget,
    report: dict[str, Any],
    notes: list[str],
) -> EncodeResult:
    """The map as Basis Universal UASTC in KTX2, checked against the budget."""
    h, w = x.shape[:2]
    q = _components(o.encoding, x, "uastc", params)
    try:
        check, data = uastc.uastc_check(q, truth, dec, budget, mips=o.mips)
    except ValueError as exc:
        raise input_error(out, str(exc)) from None
    ok = check.verdict == "pass"
    report["format"] = {"name": "uastc", "container": "ktx2", "bytes": len(data)}
    report["checks"] = [check.to_json()]
    report["verdict"] = "pass" if ok else "fail"
    report["footprint"] = fp.footprint([(out.name, "bc5", w, h, o.mips)]).to_json()
    report["notes"] = notes + ["uastc: GPU footprint as 8 bpp (transcoded to BC7/ASTC)"]
    return EncodeResult(data, report, ok, report["notes"])


def _blend_fn(encoding: str, params: dict[str, Any], base: np.ndarray | None, truth: np.ndarray):  # noqa: ANN202
    """``f(decoded, weight) -> (blended, reference)`` at a uniform activation, or None."""
    if base is None:
        return None
    if encoding == "pd":
        bd = normal_to_pd(base)
        wd = normal_to_pd(truth)  # exact wrinkle-only slopes

        def f(decoded: np.ndarray, a: float) -> tuple[np.ndarray, np.ndarray]:
            # decoded is the wrinkle-only normal: N = normalize(B_d + a W_d, 1)
            return pd_to_normal(bd + _F(a) * normal_to_pd(decoded)), pd_to_normal(bd + _F(a) * wd)

        return f

    def g(decoded: np.ndarray, a: float) -> tuple[np.ndarray, np.ndarray]:
        return normalize(base + _F(a) * (decoded - base)), normalize(base + _F(a) * (truth - base))

    return g


def _plain(
    x: np.ndarray,
    fmt: str,
    container: str,
    encoding: str,
    params: dict[str, Any],
    base: np.ndarray | None,
    truth: np.ndarray,
) -> tuple[bytes, Stats]:
    """Bytes of a PNG/TIFF/EXR file of the map (RGB: pd keeps B = 0) and the error of its
    stored texels."""

    f = codec.storage_format(fmt)
    texels, _ = codec.encode(encoding, x, f, param=_param(encoding, params), channels=3)
    bits: int | str = {"png8": 8, "png16": 16, "exr": "half"}[fmt]
    if fmt == "exr":
        texels = texels.astype(np.float16).astype(_F)  # what the half-float file holds
        values = texels
    else:
        values = codec.dequantize_unorm(texels)  # re-quantised exactly by the writer
    e = codec.encoding(encoding)
    decoded = e.to_normal(
        codec.decode(e, texels, f, param=_param(encoding, params)),
        base if encoding == "diff" else None,
    )
    err = cmp.angular_error_stats(decoded, truth)
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / f"out.{container}"
        write_image(p, values, bits=bits)
        return p.read_bytes(), err


def _auto_size(
    w_n: np.ndarray, b_n: np.ndarray | None, encoding: str, budget: Budget
) -> tuple[int, dict[int, Stats]]:
    """Smallest power-of-two side whose reduce-then-magnify error fits the budget."""
    h, w = w_n.shape[:2]
    full = max(h, w)
    tried: dict[int, Stats] = {}
    s = 16
    while s < full:
        th, tw = (s, max(1, round(w * s / h))) if h >= w else (max(1, round(h * s / w)), s)
        space = "pd" if encoding == "pd" else "normal"
        small = resample.resize_normals(w_n, (th, tw), space=space)
        back = resample.resize_normals(small, (h, w), space=space, filter="triangle")
        e = cmp.angular_error_stats(back, w_n)
        tried[s] = e
        if budget.inside(e):
            return s, tried
        s *= 2
    return full, tried
