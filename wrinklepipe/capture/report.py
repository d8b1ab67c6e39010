"""The capture report: JSON (machine) and an HTML picture sheet with its images as files beside it.

No network, no inline data: ``report.html`` references ``pictures/*.png`` by relative path, so
the folder can be zipped or served as is. Every number in the sheet is also in ``report.json``.
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.atomic import dumps_json, write_bytes
from wrinklepipe.capture.pipeline import AUTO_MAX_AMBIGUOUS, CaptureResult


def _r(x: float | None, nd: int = 4) -> float | None:
    return None if x is None else round(float(x), nd)


def _round_tree(obj: Any, nd: int = 4) -> Any:
    if isinstance(obj, dict):
        return {k: _round_tree(v, nd) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_round_tree(v, nd) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return round(float(obj), nd)
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def _tilt_stats(n: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    t = np.degrees(np.arccos(np.clip(n[..., 2][mask > 0.5], -1, 1)))
    if t.size == 0:
        return {"mean_deg": 0.0, "p95_deg": 0.0, "max_deg": 0.0}
    return {
        "mean_deg": float(t.mean()),
        "p95_deg": float(np.percentile(t, 95)),
        "max_deg": float(t.max()),
    }


def build_report(
    result: CaptureResult,
    inputs: dict[str, str],
    options: dict[str, Any],
    outputs: dict[str, str],
    truth_errors: dict[str, dict] | None = None,
) -> dict[str, Any]:
    """The JSON report: inputs, options, warp residuals, clipping, per-method diagnostics."""
    rr = result.ratio
    methods: dict[str, Any] = {}
    chosen = result.normal_photo[result.method]
    roi_photo = result.ratio.valid.astype(np.float32)  # diagnostics over divided pixels
    for m, n in result.normal_photo.items():
        dot = np.einsum("...c,...c->...", n[..., :2], chosen[..., :2])
        leaning = (np.hypot(n[..., 0], n[..., 1]) > 1e-3) & (roi_photo > 0.5)
        methods[m] = {
            "ratio_residual": result.ratio_residual.get(m),
            "ratio_residual_over_noise": (
                result.ratio_residual[m] / rr.noise
                if m in result.ratio_residual and rr.noise > 0
                else None
            ),
            "integrability_residual": result.integrability[m],
            "agrees_with_chosen": float((dot[leaning] > 0).mean()) if leaning.any() else 1.0,
            "tilt_texture": _tilt_stats(result.normal_texture[m], result.roi_texture),
        }
        if truth_errors and m in truth_errors:
            methods[m]["truth"] = truth_errors[m]
    report = {
        "tool": "wrinklepipe capture",
        "method": result.method,
        "inputs": inputs,
        "outputs": outputs,
        "options": options,
        "warps": {
            "expression_to_neutral": result.warp_expression.summary(),
            "photo_to_texture": result.warp_texture.summary(),
            "expression_to_neutral_leave_one_out_px": [
                _r(v, 3) for v in result.warp_expression.leave_one_out.tolist()
            ],
            "photo_to_texture_leave_one_out_px": [
                _r(v, 3) for v in result.warp_texture.leave_one_out.tolist()
            ],
        },
        "ratio": {
            "exposure_factor": rr.exposure,
            "exposure_reference": rr.exposure_reference,
            "noise_sigma": rr.noise,
            "deadband": rr.deadband,
            "fraction_dark": rr.frac_dark,
            "fraction_outside_expression": rr.frac_outside,
            "fraction_clipped_raw": rr.frac_clipped_raw,
            "fraction_clipped": rr.frac_clipped,
            "min": float(rr.ratio[rr.valid].min()) if rr.valid.any() else 1.0,
        },
        "texture": {
            "fraction_outside_photo": float(1.0 - result.inside_texture.mean()),
        },
        "orientation": methods,
        "neutral_shape": result.neutral_shape,
        "sigma_scale": result.sigma_scale,
    }
    if result.sfs is not None:
        report["sfs"] = {
            "start": result.sfs.start,
            "starts_ratio_residual": result.sfs.starts,
            "exposure_refit": result.sfs.exposure,
            "grid_factor": result.sfs.factor,
            # crease pixels whose sign the photos do not fix (another height explains R as
            # well and leans the other way): do not trust the orientation there
            "sign_ambiguous_fraction": result.sfs.ambiguous_fraction,
            # False: most crease signs are not in these photos (see UNOBSERVABLE)
            "sign_observable": bool(result.sfs.ambiguous_fraction <= AUTO_MAX_AMBIGUOUS),
        }
    if result.side is not None:
        report["side_lit"] = {
            "light": [float(v) for v in result.side.light],
            # the side light's level over the flash's (median over the ROI)
            "exposure": result.side.exposure,
        }
    return _round_tree(report)


#: What the command and report.html say when most crease signs are ambiguous (docs/capture.md,
#: "the sign: observable or not"): why, and which photos would make the sign observable.
UNOBSERVABLE = (
    "most crease signs are not in these photos: with one light at the camera a crease's sign "
    "shows only through the neutral's own slope (first order in it), and here the neutral "
    "faces the camera too squarely for that, so a ridge and a valley give the same photos. "
    "The orientation there is the prior's guess (creases are dents). To make it observable, "
    "photograph the region turned from the camera and flash (its N_z down to 0.9 or lower over "
    "the region, e.g. the head turned about 25 degrees; measured 94-100 % of crease texels "
    "oriented right) with its --neutral-normals, or add the expression photographed again lit "
    "from one side: --side-lit PHOTO --side-light X,Y,Z (measured 100 % oriented on a neutral "
    "facing the camera)."
)


def _grey(v: np.ndarray, lo: float, hi: float) -> np.ndarray:
    return np.clip((np.asarray(v, np.float64) - lo) / max(hi - lo, 1e-9), 0.0, 1.0)


def picture_images(
    result: CaptureResult,
    neutral: np.ndarray,
    expression: np.ndarray,
    roi: np.ndarray,
) -> dict[str, tuple[str, np.ndarray]]:
    """The sheet's pictures: caption -> (relative path, image 0..1)."""
    top = float(max(np.percentile(neutral, 99.5), 1e-6))
    rr = result.ratio
    r_lo = float(min(np.percentile(rr.ratio[rr.valid], 0.5), 0.99)) if rr.valid.any() else 0.5
    ratio_rgb = np.repeat(_grey(rr.ratio, r_lo, 1.0)[..., None], 3, axis=-1)
    ratio_rgb[~rr.valid] = (0.0, 0.0, 0.6)  # dark or outside: blue
    ratio_rgb[rr.valid & (rr.nz >= 1.0) & (rr.ratio > 1.0 + rr.deadband)] = (0.9, 0.5, 0.0)
    items: list[tuple[str, str, np.ndarray]] = [
        ("neutral photo I", "neutral.png", _grey(neutral, 0.0, top)),
        ("expression photo I'", "expression.png", _grey(expression, 0.0, top)),
        (
            "expression warped onto neutral I'_d",
            "expression_warped.png",
            _grey(result.expression_warped, 0.0, top),
        ),
        ("region of interest", "roi.png", np.clip(roi, 0, 1)),
        (
            f"ratio R = I'_d / I ({r_lo:.3f} black .. 1 white; blue: dark/outside; "
            "orange: clipped)",
            "ratio.png",
            ratio_rgb,
        ),
    ]
    if result.sfs is not None and result.sfs.ambiguous is not None:
        amb = np.repeat(_grey(rr.ratio, r_lo, 1.0)[..., None], 3, axis=-1) * 0.6
        amb[result.sfs.ambiguous] = (0.9, 0.1, 0.1)
        items.append(
            (
                "sfs: crease sign not fixed by the photos (red: another height explains R as "
                "well and leans the other way)",
                "sfs_ambiguous.png",
                amb,
            )
        )
    for m in result.normal_photo:
        items.append(
            (
                f"normals, photo space ({m})",
                f"normal_photo_{m}.png",
                0.5 + 0.5 * result.normal_photo[m],
            )
        )
    for m in result.normal_texture:
        items.append(
            (
                f"wrinkle normal map, texture space ({m})",
                f"normal_texture_{m}.png",
                0.5 + 0.5 * result.normal_texture[m],
            )
        )
    return {caption: (f"pictures/{name}", img) for caption, name, img in items}


#: The validator's report style (wrinklepipe.validate.report), plus a highlight for the best row.
_CSS = (
    "body{font:14px sans-serif;margin:24px;max-width:1400px}"
    "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 6px;"
    "vertical-align:top}th{background:#eee}figure{display:inline-block;margin:4px;"
    "text-align:center}figure img{width:240px;image-rendering:pixelated;border:1px solid #999}"
    "figcaption{font-size:12px;max-width:240px}.best{font-weight:bold;background:#efe}"
    ".muted{color:#666}td.l,th.l{text-align:left}"
)


def _table(header: list[str], rows: list[list[str]], best_row: int | None = None) -> str:
    h = "".join(
        f"<th{' class=l' if i == 0 else ''}>{html.escape(c)}</th>" for i, c in enumerate(header)
    )
    body = []
    for k, r in enumerate(rows):
        cls = " class=best" if k == best_row else ""
        cells = "".join(
            f"<td{' class=l' if i == 0 else ''}>{html.escape(str(c))}</td>" for i, c in enumerate(r)
        )
        body.append(f"<tr{cls}>{cells}</tr>")
    return f"<table><tr>{h}</tr>{''.join(body)}</table>"


def _f(x: Any, nd: int = 2) -> str:
    return "-" if x is None else f"{float(x):.{nd}f}"


def render_html(report: dict[str, Any], pictures: dict[str, str]) -> str:
    """The picture sheet (self-contained HTML; images by relative path)."""
    parts = [
        "<!doctype html><html><head><meta charset=utf-8><title>wrinklepipe capture</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>wrinklepipe capture</h1>",
        f"<p class=muted>orientation: <b>{html.escape(report['method'])}</b> &middot; output: "
        f"{html.escape(str(report['outputs'].get('normal_map', '')))}</p>",
        *_warps_html(report),
        *_ratio_html(report),
        "<h2>Orientation methods</h2>",
        *_methods_html(report),
    ]
    parts.append("<h2>Pictures</h2><div>")
    for caption, rel in pictures.items():
        parts.append(
            f"<figure><a href='{html.escape(rel)}'><img src='{html.escape(rel)}' "
            f"alt='{html.escape(caption)}'></a><figcaption>{html.escape(caption)}"
            "</figcaption></figure>"
        )
    parts.append("</div></body></html>\n")
    return "\n".join(parts)


def _warps_html(report: dict[str, Any]) -> list[str]:
    """The landmark residuals of both warps."""
    w1 = report["warps"]["expression_to_neutral"]
    w2 = report["warps"]["photo_to_texture"]
    return [
        "<h2>Landmark residuals (pixels)</h2>",
        _table(
            [
                "warp",
                "landmarks",
                "fit max",
                "fit mean",
                "leave-one-out max",
                "leave-one-out mean",
                "worst landmark",
            ],
            [
                [
                    "expression -> neutral",
                    w1["count"],
                    _f(w1["fit_max_px"], 4),
                    _f(w1["fit_mean_px"], 4),
                    _f(w1["leave_one_out_max_px"]),
                    _f(w1["leave_one_out_mean_px"]),
                    w1.get("leave_one_out_worst_name", w1["leave_one_out_worst_index"]),
                ],
                [
                    "photo -> texture",
                    w2["count"],
                    _f(w2["fit_max_px"], 4),
                    _f(w2["fit_mean_px"], 4),
                    _f(w2["leave_one_out_max_px"]),
                    _f(w2["leave_one_out_mean_px"]),
                    w2.get("leave_one_out_worst_name", w2["leave_one_out_worst_index"]),
                ],
            ],
        ),
        "<p class=muted>fit: the evaluated warp at each landmark (0 up to the coarse-grid "
        "approximation); leave-one-out: the warp fitted without that landmark, predicting it "
        "(large values flag a misplaced landmark).</p>",
    ]


def _ratio_html(report: dict[str, Any]) -> list[str]:
    """The ratio image's quantities."""
    rt = report["ratio"]
    return [
        "<h2>Ratio image</h2>",
        _table(
            ["quantity", "value"],
            [
                ["exposure factor (R divided by)", _f(rt["exposure_factor"], 4)],
                ["exposure measured on", rt["exposure_reference"]],
                ["noise sigma of blurred R", _f(rt["noise_sigma"], 5)],
                ["deadband", _f(rt["deadband"], 5)],
                ["dark pixels (ROI share)", _f(rt["fraction_dark"], 4)],
                [
                    "outside the expression photo (ROI share)",
                    _f(rt["fraction_outside_expression"], 4),
                ],
                ["R > 1 before the blur (ROI share)", _f(rt["fraction_clipped_raw"], 4)],
                ["R N_z > 1 + deadband, clipped (ROI share)", _f(rt["fraction_clipped"], 4)],
                ["texels outside the photo", _f(report["texture"]["fraction_outside_photo"], 4)],
            ],
        ),
    ]


def _methods_html(report: dict[str, Any]) -> list[str]:
    """The orientation methods: against the truth (when given), the residuals, the solve's
    ambiguous share."""
    parts: list[str] = []
    methods = report["orientation"]
    names = list(methods)
    has_truth = all("truth" in methods[m] for m in names)
    if has_truth:
        rows = []
        for m in names:
            t = methods[m]["truth"]
            rows.append(
                [
                    m,
                    _f(t["tilt"]["mean"]),
                    _f(t["angular"]["mean"]),
                    _f(t["angular"]["median"]),
                    _f(t["angular"]["p95"]),
                    _f(t["crease_angular"]["mean"]),
                    _f(t["orientation_correct"], 3),
                    _f(t["flat"]["mean"]),
                ]
            )
        best = int(np.argmin([methods[m]["truth"]["angular"]["mean"] for m in names]))
        parts.append(
            _table(
                [
                    "method",
                    "tilt mean",
                    "angular mean",
                    "angular median",
                    "angular p95",
                    "crease angular mean",
                    "orientation correct",
                    "flat map error",
                ],
                rows,
                best,
            )
        )
        parts.append(
            "<p class=muted>degrees, against the given truth inside the ROI; "
            "crease: texels tilted more than 3 degrees.</p>"
        )
    rows = [
        [
            m,
            _f(methods[m].get("ratio_residual"), 5),
            _f(methods[m]["integrability_residual"], 3),
            _f(methods[m]["agrees_with_chosen"], 3),
            _f(methods[m]["tilt_texture"]["mean_deg"]),
            _f(methods[m]["tilt_texture"]["p95_deg"]),
        ]
        for m in names
    ]
    parts.append(
        _table(
            [
                "method",
                "ratio residual (lower: explains the photos better)",
                "integrability residual",
                "agrees with chosen",
                "tilt mean (ROI)",
                "tilt p95 (ROI)",
            ],
            rows,
            names.index(report["method"]) if report["method"] in names else None,
        )
    )
    amb = report.get("sfs", {}).get("sign_ambiguous_fraction")
    if amb is not None:
        parts.append(
            f"<p>sfs: the photos leave the sign of <b>{100 * amb:.0f} %</b> of its crease pixels "
            "open (another height explains R about as well and leans the other way; red in the "
            "picture below): do not trust the orientation there. A second photo lit from one "
            "side would fix it.</p>"
        )
        if amb > AUTO_MAX_AMBIGUOUS:
            parts.append(f"<p><b>Sign not observable.</b> {html.escape(UNOBSERVABLE)}</p>")
    return parts


def write_report(folder: Path, report: dict[str, Any], pictures: dict[str, str]) -> None:
    """``report.json`` and ``report.html`` into ``folder`` (atomic, deterministic)."""

    write_bytes(folder / "report.json", dumps_json(report).encode("utf-8"))
    write_bytes(folder / "report.html", render_html(report, pictures).encode("utf-8"))
