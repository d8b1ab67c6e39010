"""Reports of ``validate-asset``: JSON (``schemas/report.schema.json``), a terminal summary
through rich, and ``report.html`` with its images written as files beside it (no network).
"""

from __future__ import annotations

import html
import re
from pathlib import Path
from typing import Any

import numpy as np
from rich.markup import escape
from rich.table import Table

from wrinklepipe import __version__
from wrinklepipe.atomic import dumps_json, output_files, staged_folder, write_bytes
from wrinklepipe.console import info, issue_counts, plural, problem, verbosity
from wrinklepipe.errors import input_error
from wrinklepipe.io.png import png_bytes
from wrinklepipe.names import unique_name
from wrinklepipe.reuse import map_threads
from wrinklepipe.validate.catalogue import RULES_BY_CODE
from wrinklepipe.validate.run import Report

SCHEMA_ID = "wrinklepipe/validate-report@1"
#: Fields that change between machines or runs; dropped by :func:`normalized`.
VOLATILE = ("tool.version", "timings", "render", "input.path", "metrics.gpu_vs_reference_deg")


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return round(v, 6) if np.isfinite(v) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    return x


def report_json(report: Report, fail_on: str = "error") -> dict[str, Any]:
    """The JSON document (see ``schemas/report.schema.json``)."""
    return _jsonable(
        {
            "schema": SCHEMA_ID,
            "tool": {"name": "wrinklepipe validate-asset", "version": __version__},
            "input": report.input,
            "counts": report.counts,
            "ignored": report.ignored,
            "fail_on": fail_on,
            "exit_code": report.exit_code(fail_on),
            "issues": [i.to_json() for i in report.issues],
            "metrics": report.metrics,
            "timings": report.timings,
            "render": report.render,
        }
    )


_NUM = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")


def normalized(doc: dict[str, Any]) -> dict[str, Any]:
    """A report without volatile fields, for golden comparisons.

    Drops timings, the tool version, render details (GPU-dependent) and the input path; in the
    messages of render-pass issues (``WP-RND-*``) every number becomes ``#``; other messages
    keep their numbers but floats are rounded to 1 decimal (8-bit/BC decoding is exact, but
    float sums differ in the last digits between numpy builds).
    """
    out = {k: v for k, v in doc.items() if k not in ("timings", "render", "metrics")}
    out["tool"] = {"name": doc["tool"]["name"]}
    out["input"] = {k: v for k, v in doc["input"].items() if k != "path"}
    out["input"]["textures"] = [
        {k: v for k, v in t.items() if k != "pointer"} for t in doc["input"].get("textures", [])
    ]
    issues = []
    for i in doc["issues"]:
        j = {k: v for k, v in i.items() if k not in ("data", "pointer")}
        if i["code"].startswith("WP-RND"):
            j["message"] = _NUM.sub("#", i["message"])
        else:
            j["message"] = re.sub(r"\d+\.\d+", lambda m: f"{float(m.group()):.1f}", i["message"])
        j["pointer"] = Path(i["pointer"].split("#")[0].split(" ")[0]).name + (
            "#" + i["pointer"].split("#", 1)[1] if "#" in i["pointer"] else ""
        )
        issues.append(j)
    out["issues"] = issues
    return out


# ------------------------------------------------------------------------------------------------
# terminal


def print_summary(report: Report, fail_on: str = "error", limit: int = 40) -> None:
    """A short summary on stderr: the input, the issues (first ``limit``), the render pass's
    agreement and the verdict. With --quiet only the warnings, errors and a failing verdict."""

    style = {"error": "bold red", "warning": "yellow", "info": "cyan"}
    c = report.counts
    inp = report.input
    info(
        f"[bold]{escape(str(inp.get('name')))}[/] ({escape(str(inp.get('kind')))}: "
        f"{escape(str(inp.get('path')))}) encoding {inp.get('encoding')}, policy "
        f"{inp.get('policy')}, {plural(len(inp.get('states', [])), 'state')}, "
        f"{plural(len(inp.get('regions', [])), 'region')}",
        markup=True,
    )
    shown = (
        report.issues
        if verbosity() >= 0
        else [i for i in report.issues if i.severity in ("error", "warning")]
    )
    if shown:
        t = Table(show_header=True, header_style="bold", box=None, pad_edge=False)
        t.add_column("severity")
        t.add_column("code")
        t.add_column("message", overflow="fold")
        t.add_column("where", overflow="fold")
        for i in shown[:limit]:
            t.add_row(
                f"[{style[i.severity]}]{i.severity}[/]",
                i.code,
                escape(i.message),
                escape(i.pointer),
            )
        problem(t)
        if len(shown) > limit:
            problem(f"... and {len(shown) - limit} more (see the JSON report)")
    gpu = report.metrics.get("gpu_vs_reference_deg")
    if gpu:
        worst = max(gpu.values(), key=lambda s: s["p99"])
        info(
            f"render pass ({report.render.get('renderer', '')}): GPU vs numpy "
            f"reference worst mean {max(s['mean'] for s in gpu.values()):.3f} deg, "
            f"p99 {worst['p99']:.3f} deg over {plural(len(gpu), 'pose')}"
        )
    elif report.render.get("skipped"):
        info(f"render pass skipped: {report.render['skipped']}")
    failed = bool(report.exit_code(fail_on))
    verdict = "[bold red]FAILED[/]" if failed else "[bold green]passed[/]"
    (problem if failed else info)(
        f"{verdict}: {escape(issue_counts(c))}"
        + (f", {report.ignored} ignored" if report.ignored else "")
        + (f" (failing on {fail_on})" if fail_on != "error" else ""),
        markup=True,
    )


# ------------------------------------------------------------------------------------------------
# HTML

_RAMP = np.array(
    [[0.05, 0.03, 0.2], [0.3, 0.1, 0.55], [0.75, 0.2, 0.4], [0.98, 0.55, 0.1], [1.0, 1.0, 0.6]],
    np.float32,
)


def heat(values: np.ndarray, vmax: float) -> np.ndarray:
    """A heat map ``[H, W, 3]`` of ``values`` in [0, vmax] (dark -> bright)."""
    t = np.clip(np.nan_to_num(values) / max(vmax, 1e-9), 0.0, 1.0) * (len(_RAMP) - 1)
    i = np.minimum(t.astype(np.int64), len(_RAMP) - 2)
    f = (t - i)[..., None]
    # np.take: the same ramp rows as _RAMP[i], without fancy indexing's overhead (~1.5x faster)
    lo, hi = np.take(_RAMP, i, axis=0), np.take(_RAMP, i + 1, axis=0)
    return (lo * (1 - f) + hi * f).astype(np.float32)


#: zlib level of the page's pictures, whatever the run's PNG level (which is the shipped
#: textures'): the fastest level. Measured on the 72 pictures of the 64, 256 and 1024 demos'
#: pages: 3-5x less CPU than level 6 (0.30 / 0.45 / 0.63 s against 1.38 / 0.94 / 1.93 s) for
#: files 12 % larger, 1 % smaller and 4 % larger (5.5 / 9.5 / 14.2 MB); the same bytes on a rerun.
PICTURE_PNG_LEVEL = 1


def _png(img: np.ndarray) -> bytes:
    arr = np.clip(np.rint(np.asarray(img, np.float64) * 255.0), 0, 255).astype(np.uint8)
    # a picture: no other part of a run encodes it, so not through the run's memo
    return png_bytes(arr, PICTURE_PNG_LEVEL, shared=False)


def _to_srgb(img: np.ndarray) -> np.ndarray:
    c = np.clip(img, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


#: Heat-map range (degrees) of the fidelity pictures: shipped vs full-resolution source.
FIDELITY_HEAT_DEG = 5.0

#: Pictures of the HTML page: image key (or key prefix ending in /) -> heat-map range in
#: degrees (None: the image itself, linear, shown in sRGB; "unorm": values in 0..1 as they are,
#: e.g. a normal map's 0.5 + 0.5 n or a mask's grey levels).
_PICTURES: tuple[tuple[str, float | str | None], ...] = (
    ("render/", None),
    ("mask_overlay", None),
    ("gpu_error/", 2.0),
    ("change/", 10.0),
    ("shipping_error/", 5.0),
    ("render_source/", "unorm"),
    ("render_shipped/", "unorm"),
    ("fidelity_source/", "unorm"),
    ("fidelity_shipped/", "unorm"),
    ("fidelity_error/", FIDELITY_HEAT_DEG),
    ("fidelity_render/", FIDELITY_HEAT_DEG),
    ("region_mask/", "unorm"),
)


def _rgb_hex(c: np.ndarray) -> str:
    v = np.clip(np.rint(np.asarray(c, np.float64) * 255.0), 0, 255).astype(int)
    return "#" + "".join(f"{int(x):02x}" for x in v[:3])


def colour_bar(vmax: float, unit: str = "degrees") -> str:
    """HTML of a heat map's colour bar: the ramp of :func:`heat` left to right, ticks at 0,
    half and ``vmax`` (the unit beside the last)."""
    stops = ", ".join(
        f"{_rgb_hex(c)} {100.0 * i / (len(_RAMP) - 1):g}%" for i, c in enumerate(_RAMP)
    )
    return (
        f"<div class='cbar'><div style='background:linear-gradient(to right, {stops})'></div>"
        f"<span>0</span><span>{vmax / 2:g}</span><span>{vmax:g} {html.escape(unit)}</span></div>"
    )


def picture_file(name: str) -> str:
    """A picture's file name: a pose is named by what drives it (``Surprised @ 1.0 s``), a
    file by letters, digits, ``.``, ``-`` and ``_`` only."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name)


def _html_pictures(report: Report) -> dict[str, tuple[str, float | str | None]]:
    """File name -> (image key, heat-map range or None) of every picture the HTML shows. A
    key ``group/name`` is the file ``group_name.png``, unique case-insensitively within its
    group (:func:`~wrinklepipe.names.file_stems`: poses or regions ``Joy`` and ``joy`` are two
    files on every file system)."""
    chosen: dict[str, float | str | None] = {}
    for key in sorted(report.images):
        if key.startswith("_"):
            continue
        for prefix, vmax in _PICTURES:
            if key == prefix or (prefix.endswith("/") and key.startswith(prefix)):
                chosen[key] = vmax
                break
    groups: dict[str, list[str]] = {}
    for key in chosen:
        groups.setdefault(key.split("/", 1)[0] if "/" in key else "", []).append(key)
    stems: dict[str, str] = {}
    for keys in groups.values():
        taken: set[str] = set()
        for k in sorted(keys):  # as file_stems names them, in letters a file name may hold
            stems[k] = unique_name(picture_file(k.replace("/", "_")), taken, fold_case=True)
    return {stems[key] + ".png": (key, vmax) for key, vmax in chosen.items()}


def picture_names(report: Report) -> dict[str, str]:
    """Each picture's natural file name (``region_mask_joy.png``, the key with ``/`` as ``_``)
    -> the file it is written to (the same, or ``region_mask_joy_2.png`` after a case-only
    clash)."""
    pictures = _html_pictures(report).items()
    return {picture_file(key.replace("/", "_")) + ".png": f for f, (key, _) in pictures}


def html_images(report: Report) -> dict[str, bytes]:
    """File name -> PNG bytes of every picture the HTML shows."""
    pictures = _html_pictures(report)

    def picture(item: tuple[str, float | str | None]) -> bytes:
        arr = report.images[item[0]]
        if item[1] is None:
            return _png(_to_srgb(arr))
        if isinstance(item[1], str):
            return _png(arr)
        return _png(heat(arr, item[1]))

    # numpy and zlib release the GIL: the pictures encode on two cores, in order
    return dict(zip(pictures, map_threads(picture, pictures.values())))


def report_html(report: Report, files_dir: str, fail_on: str = "error") -> str:
    """The HTML page; images are ``files_dir/<name>.png`` relative to the page."""
    doc = report_json(report, fail_on)
    e = html.escape
    c = doc["counts"]
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>validate-asset: {e(str(doc['input']['name']))}</title>",
        "<style>body{font:14px sans-serif;margin:24px;max-width:1700px}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 6px;"
        "vertical-align:top}th{background:#eee}.error{color:#b00}.warning{color:#a60}"
        ".info{color:#067}figure{display:inline-block;margin:4px;text-align:center}"
        "figure img{width:240px;image-rendering:pixelated;border:1px solid #999}"
        "figcaption{font-size:12px}figure img.big{width:512px}"
        ".cbar{width:512px;font-size:12px;display:flex;flex-wrap:wrap;"
        "justify-content:space-between}.cbar div{width:100%;height:12px;border:1px solid #999}"
        ".swatch{display:inline-block;width:12px;height:12px;border:1px solid #666;"
        "margin:0 4px 0 12px;vertical-align:middle}</style></head><body>",
        f"<h1>validate-asset: {e(str(doc['input']['name']))}</h1>",
        f"<p>{e(str(doc['input']['kind']))} <code>{e(str(doc['input']['path']))}</code> - "
        f"encoding <b>{e(doc['input']['encoding'])}</b>, policy "
        f"<b>{e(doc['input']['policy'])}</b>, states {e(', '.join(doc['input']['states']))}</p>",
        f"<p><b class='{'error' if doc['exit_code'] else 'info'}'>"
        f"{'FAILED' if doc['exit_code'] else 'passed'}</b>: {c['error']} errors, "
        f"{c['warning']} warnings, {c['info']} info (exit code {doc['exit_code']}).</p>",
        "<h2>Issues</h2>",
    ]
    parts.extend(_issues_html(doc))
    images = picture_names(report)  # names only: the PNGs are encoded once, by html_images

    def fig(name: str, caption: str, big: bool = False) -> str:
        name = picture_file(name)
        if name not in images:
            return ""
        name = images[name]  # the file it is written to
        cls = " class='big'" if big else ""
        return (
            f"<figure><img{cls} src='{e(files_dir)}/{e(name)}' alt='{e(caption)}'>"
            f"<figcaption>{e(caption)}</figcaption></figure>"
        )

    parts.extend(_fidelity_html(doc, images, fig))

    poses = list(report.render.get("poses", {}))
    if poses:
        parts.append(
            "<h2>Contact sheet</h2><p>Neutral first; then each expression without and with "
            "wrinkles, its change from neutral (0..10 degrees), the GPU vs numpy-reference "
            "error (0..2 degrees) and, with a source, the shipped vs source error in texture "
            "space (0..5 degrees). Renders are cropped to the masked area; the mask overlay "
            "shows the whole view.</p><div>"
        )
        for p in poses:
            parts.append("<div>")
            if p != "neutral":
                parts.append(fig("render_neutral.png", f"{p}: without wrinkles"))
            parts.append(fig(f"render_{p}.png", f"{p}: with wrinkles" if p != "neutral" else p))
            parts.append(fig(f"change_{p}.png", f"{p}: change from neutral"))
            parts.append(fig(f"gpu_error_{p}.png", f"{p}: GPU vs reference"))
            parts.append(fig(f"shipping_error_{p}.png", f"{p}: shipped vs source (0..5 deg)"))
            parts.append(fig(f"render_source_{p}.png", f"{p}: source render (normals)"))
            parts.append(fig(f"render_shipped_{p}.png", f"{p}: shipped render (normals)"))
            parts.append(fig(f"fidelity_render_{p}.png", f"{p}: GPU vs source render (0..5 deg)"))
            parts.append("</div>")
        parts.append("</div>")
        parts.append(
            "<h2>Mask overlay</h2>" + fig("mask_overlay.png", "shipped masks over neutral")
        )
        colours = report.images.get("_region_colors")
        if colours is not None and "mask_overlay.png" in images:
            legend = "".join(
                f"<span class='swatch' style='background:{_rgb_hex(_to_srgb(c))}'></span>"
                f"{e(str(r))}"
                for r, c in zip(doc["input"].get("regions", []), np.asarray(colours))
            )
            parts.append(f"<p>{legend}</p>")
    elif any(k.startswith("shipping_error_") for k in images):
        parts.append("<h2>Shipped vs source (texture space, 0..5 degrees)</h2><div>")
        for k in sorted(images):
            if k.startswith("shipping_error_"):
                parts.append(fig(k, k[len("shipping_error_") : -4]))
        parts.append("</div>")
    masks = sorted(k for k in images if k.startswith("region_mask_"))
    if masks:
        parts.append("<h2>Masks as shipped</h2><p>Each region's mask, 0 black to 1 white.</p><div>")
        parts.extend(fig(k, k[len("region_mask_") : -4]) for k in masks)
        parts.append("</div>")
    parts.extend(_metrics_html(doc))
    if doc["render"]:
        # no timings in the page: the same input gives the same bytes (they are in the JSON)
        r = {k: v for k, v in doc["render"].items() if k not in ("poses", "render_s", "compare_s")}
        parts.append(f"<h2>Render pass</h2>{_raw_json(r)}")
    parts.append("</body></html>\n")
    return "\n".join(p for p in parts if p)


def _issues_html(doc: dict[str, Any]) -> list[str]:
    """The issues table (severity, code with its title, message, where, fix)."""
    e = html.escape
    parts: list[str] = []
    if doc["issues"]:
        parts.append(
            "<table><tr><th>severity</th><th>code</th><th>message</th><th>where</th>"
            "<th>suggested fix</th></tr>"
        )
        for i in doc["issues"]:
            title = RULES_BY_CODE[i["code"]].title
            parts.append(
                f"<tr><td class='{i['severity']}'>{i['severity']}</td>"
                f"<td title='{e(title)}'><code>{e(i['code'])}</code></td><td>{e(i['message'])}"
                f"</td><td><code>{e(i['pointer'])}</code></td><td>{e(i['fix'])}</td></tr>"
            )
        parts.append("</table>")
    else:
        parts.append("<p>No issues.</p>")
    return parts


def _metrics_html(doc: dict[str, Any]) -> list[str]:
    """The metrics: a table for a dict of dicts, else the value as JSON."""
    e = html.escape
    parts: list[str] = []
    parts.append("<h2>Metrics</h2>")
    for key, val in sorted(doc["metrics"].items()):
        parts.append(f"<h3>{e(key)}</h3>")
        if isinstance(val, dict) and val and all(isinstance(v, dict) for v in val.values()):
            cols = sorted({k for v in val.values() for k in v})
            parts.append(
                "<table><tr><th></th>" + "".join(f"<th>{e(c)}</th>" for c in cols) + "</tr>"
            )
            for row, v in val.items():
                parts.append(
                    f"<tr><th>{e(row)}</th>"
                    + "".join(f"<td>{e(str(v.get(c, '')))}</td>" for c in cols)
                    + "</tr>"
                )
            parts.append("</table>")
        else:
            parts.append(_raw_json(val))
    return parts


def _raw_json(value: Any) -> str:
    """Raw JSON folded away: a ``<details>`` whose summary says how long it is."""
    text = dumps_json(value)
    lines = text.count("\n") + 1
    return (
        f"<details><summary>raw JSON ({lines} lines)</summary>"
        f"<pre>{html.escape(text)}</pre></details>"
    )


def _stat_cells(st: dict[str, Any]) -> str:
    return "".join(
        f"<td>{st.get(k, '')}</td>" for k in ("mean_deg", "p99_deg", "max_deg", "texels")
    )


def _fidelity_html(doc: dict[str, Any], images: dict[str, Any], fig: Any) -> list[str]:
    """The fidelity section: the per-pose and per-region tables of the measure (the shipped
    asset against the full-resolution source, inside each pose's active region) and, per pose,
    the source's and the shipped blended normal maps beside the error heat map."""
    f = doc["metrics"].get("fidelity")
    if not isinstance(f, dict) or not f.get("poses"):
        return []
    e = html.escape
    budget = ", ".join(f"{k} {v:g}" for k, v in sorted(f.get("budget", {}).items()))
    head = "<tr><th></th><th>mean</th><th>p99</th><th>max</th><th>texels</th>"
    out = [
        "<h2>Fidelity against the full-resolution source</h2>",
        "<p>For each pose: the blend of the shipped textures (decoded, magnified as a GPU "
        "samples them) against the blend of the full-resolution source, on the texels the "
        "pose activates (in the source or in the shipped masks), weighted by the activation; "
        f"degrees. The {e(str(f.get('applies', 'budget')))}: {e(budget)}. "
        f"Wrinkled share of the UV area: {100.0 * float(f.get('active_fraction', 0)):.2f} %.</p>",
        f"<table>{head}<th>leak texels</th></tr>",
    ]
    for p in f["poses"]:
        out.append(
            f"<tr><th>{e(str(p['pose']))}</th>{_stat_cells(p)}<td>{p.get('leak_texels', 0)}</td>"
            "</tr>"
        )
    if f.get("base"):
        out.append(f"<tr><th>base alone (face)</th>{_stat_cells(f['base'])}<td></td></tr>")
    out.append("</table><h3>Per region</h3>")
    out.append(f"<table><tr><th>pose</th><th>region</th>{head[len('<tr><th></th>') :]}</tr>")
    for p in f["poses"]:
        for r, st in sorted(p.get("regions", {}).items()):
            out.append(f"<tr><td>{e(str(p['pose']))}</td><th>{e(r)}</th>{_stat_cells(st)}</tr>")
    out.append("</table>")
    if any(k.startswith("fidelity_error_") for k in images):
        out.append(
            "<h3>Source vs shipped, per pose</h3><p>Cropped to the pose's wrinkled area, on "
            "the source grid: the full-resolution source's blended normal map, the shipped "
            "one, and the error where the pose is active (0 elsewhere).</p>"
        )
        for p in f["poses"]:
            key = str(p["pose"]).replace("/", "_")
            out.append("<div>")
            out.append(fig(f"fidelity_source_{key}.png", f"{p['pose']}: source", True))
            out.append(fig(f"fidelity_shipped_{key}.png", f"{p['pose']}: shipped", True))
            out.append(fig(f"fidelity_error_{key}.png", f"{p['pose']}: error", True))
            out.append("</div>")
        out.append(colour_bar(FIDELITY_HEAT_DEG))
    return out


def _ours(folder: Path, html_path: Path) -> bool:
    """A report's images folder is the tool's when the HTML report beside it is a validate-asset
    page that references every file in it (nothing the user added, nothing foreign)."""
    try:
        text = html_path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return False
    if "<title>validate-asset: " not in text:
        return False
    for p in folder.rglob("*"):
        if p.is_symlink() or (p.is_file() and f"{folder.name}/{p.name}" not in text):
            return False
        if p.is_dir():
            return False  # the tool writes no subfolders there
    return True


def _check_files_folder(folder: Path, html_path: Path) -> None:
    """An existing images folder is replaced only when it is empty or provably the tool's
    (:func:`_ours`); anything else is the user's and is never touched."""
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise input_error(folder, "is in the way of the HTML report's images; nothing was written")
    if folder.is_dir() and any(folder.iterdir()) and not _ours(folder, html_path):
        raise input_error(
            folder,
            f"exists and was not written by wrinklepipe for {html_path.name} (it holds files that "
            "report does not show), so the HTML report's images cannot go there; nothing was "
            "written. Choose another --html name or move that folder",
        )


def write_reports(
    report: Report,
    json_path: str | Path | None = None,
    html_path: str | Path | None = None,
    fail_on: str = "error",
    inputs: tuple[str | Path, ...] = (),
) -> list[Path]:
    """Write report.json and/or report.html (+ ``<stem>_files/`` images) atomically, under the
    outputs' locks; every check runs before anything is written."""
    written = []
    files_dir = None
    if html_path is not None:
        html_path = Path(html_path)
        files_dir = html_path.parent / f"{html_path.stem}_files"
        _check_files_folder(files_dir, html_path)
    with output_files(json_path, html_path):
        if json_path is not None:
            written.append(
                write_bytes(json_path, dumps_json(report_json(report, fail_on)).encode(), inputs)
            )
        if html_path is not None and files_dir is not None:
            images = html_images(report)
            _check_files_folder(files_dir, html_path)
            with staged_folder(files_dir, force=True, inputs=inputs) as tmp:
                for name, data in images.items():
                    (tmp / name).write_bytes(data)
            written.append(
                write_bytes(
                    html_path, report_html(report, files_dir.name, fail_on).encode(), inputs
                )
            )
    return written
