"""report.json and report.html: what convert read (hashes), did, wrote, what validation found."""

from __future__ import annotations

import hashlib
import html
import json
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import __version__
from wrinklepipe.asset import WrinkleAsset
from wrinklepipe.atomic import dumps_json, write_bytes
from wrinklepipe.metrics import angle_deg, weighted_stats
from wrinklepipe.names import file_stems
from wrinklepipe.package import WrinklePackage
from wrinklepipe.pipeline.package import decode_state, decoded_base_at, mapping_version

#: The validator's own page, written beside report.html (with ``validation_files/``).
VALIDATION_HTML = "validation.html"


def sha256(data: bytes) -> str:
    """Hex SHA-256 of ``data``."""
    return hashlib.sha256(data).hexdigest()


def input_rows(root: Path, files: list[Path]) -> list[dict[str, Any]]:
    """``{file, bytes, sha256}`` per input (paths relative to ``root`` when under it)."""
    rows = []
    for p in files:
        data = p.read_bytes()
        rel = p.relative_to(root).as_posix() if root in p.parents else p.name
        rows.append({"file": rel, "bytes": len(data), "sha256": sha256(data)})
    return rows


def output_rows(folder: Path) -> list[dict[str, Any]]:
    """``{file, bytes, sha256}`` for every file under ``folder``, sorted by path."""
    rows = []
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            data = p.read_bytes()
            rel = p.relative_to(folder).as_posix()
            rows.append({"file": rel, "bytes": len(data), "sha256": sha256(data)})
    return rows


def decode_errors(asset: WrinkleAsset, pkg: WrinklePackage) -> dict[str, dict[str, float]]:
    """Angular error (degrees) between each state as given and as decoded from what is stored.

    Each state is decoded on its own over the base at its size, resampled band by band from
    the base's texels (:func:`~wrinklepipe.pipeline.package.decoded_base_at`): the values
    :func:`~wrinklepipe.pipeline.package.asset_from_package` decodes, bit for bit, without
    the whole package decoded (the base's normals at full size, every state, the masks)."""
    meta = pkg.meta
    enc, scale = meta.encoding, float(meta.scale)
    version = mapping_version(meta)
    texels = pkg.texture(pkg.base_name).pixels
    bases: dict[tuple[int, ...], np.ndarray] = {}
    out = {}
    for k, name in enumerate(asset.state_names):
        stored = pkg.texture(meta.states[k].texture).pixels
        shape = tuple(stored.shape[:2])
        if shape not in bases:
            bases[shape] = decoded_base_at(texels, shape)
        back = decode_state(bases[shape], stored, enc, scale, version)
        st = weighted_stats(angle_deg(asset.states[k], back))
        del back
        out[name] = {k: v for k, v in st.to_json().items() if k.endswith("_deg")}
    return out


def asset_summary(pkg: WrinklePackage) -> dict[str, Any]:
    """The report's ``asset`` section: the wrinkle setup, texture sizes, mesh and curves."""
    m = pkg.mesh
    return {
        "encoding": pkg.meta.encoding,
        "scale": pkg.meta.scale,
        "policy": pkg.meta.policy,
        "states": pkg.meta.state_names,
        "regions": [
            {**r.to_json(), "mask": e.to_json()}
            for r, e in zip(pkg.meta.regions, pkg.meta.masks.table)
        ],
        "mask_layout": pkg.meta.masks.layout,
        "sizes": {t.name: list(t.pixels.shape) for t in pkg.textures},
        "vertices": m.vertex_count,
        "triangles": m.triangle_count,
        "morph_targets": list(m.morph_names),
        "curves": [
            {
                "name": c.name,
                "keys": int(c.times.size),
                "duration_s": float(c.times[-1] - c.times[0]),
            }
            for c in pkg.curves
        ],
    }


def write_report(folder: Path, report: dict[str, Any]) -> None:
    """``report.json`` and ``report.html`` into ``folder``."""
    write_bytes(folder / "report.json", dumps_json(report).encode("utf-8"))
    write_bytes(folder / "report.html", report_html(report).encode("utf-8"))


def convert_report(
    *,
    manifest: str,
    inputs: list[dict[str, Any]],
    pkg: WrinklePackage,
    pd_scale: dict[str, Any],
    decode_error: dict[str, dict[str, float]],
    compression: dict[str, Any],
    notes: list[str],
    outputs: list[dict[str, Any]],
    validation: dict[str, Any],
    key_notes: list[str] | None = None,
    fidelity: dict[str, Any] | None = None,
    warnings: list[str] | None = None,
    color: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """report.json: tool and version, what was read, the asset, what the stages did and chose,
    what was written (hashes) and what validation found; ``color``: the colour states' choice
    and its CIEDE2000 fidelity (only with colour states)."""
    out = {
        "tool": "wrinklepipe",
        "version": __version__,
        "name": pkg.name,
        "manifest": manifest,
        "inputs": inputs,
        "asset": asset_summary(pkg),
        "pd_scale": pd_scale,
        "fidelity": fidelity,
        "warnings": list(warnings or []),
        "decode_error": decode_error,
        "compression": compression,
        "notes": notes,
        "key_notes": list(key_notes or []),
        "outputs": outputs,
        "validation": validation,
    }
    if color is not None:
        out["color"] = color
    return out


def _validation_html(validation: dict[str, Any], table: Any) -> str:
    if validation.get("status") != "ran":
        return f"<p>{html.escape(str(validation.get('reason', 'skipped')))}</p>"
    counts = validation.get("counts", {})
    head = ", ".join(f"{v} {k}(s)" for k, v in sorted(counts.items()))
    rows = [
        [i.get("severity", ""), i.get("code", ""), i.get("message", ""), i.get("pointer", "")]
        for i in validation.get("issues", [])
    ]
    link = f"<p>The validator's page: <a href='{VALIDATION_HTML}'>{VALIDATION_HTML}</a></p>"
    return (
        f"<p>{html.escape(head)}</p>" + link + table(rows, ["severity", "code", "message", "where"])
    )


def _regions_html(report: dict[str, Any], table: Any) -> str:
    """The regions table; with the validator's page, each region's shipped mask beside it as
    grey levels (its thumbnail there: a mask packed in a channel, alpha above all, would show
    black or transparent as the texture itself)."""
    a = report["asset"]
    files = {o["file"] for o in report["outputs"]}
    stems = file_stems([f"region_mask/{r['name']}" for r in a["regions"]])  # as the page names them
    thumbs = {
        r["name"]: f"{Path(VALIDATION_HTML).stem}_files/{stems['region_mask/' + r['name']]}.png"
        for r in a["regions"]
    }
    if not all(t in files for t in thumbs.values()):
        return table(
            [[r["name"], r["side"], json.dumps(r["mask"])] for r in a["regions"]],
            ["region", "side", "channel table"],
        )
    esc = html.escape
    rows = "".join(
        f"<tr><td>{esc(r['name'])}</td><td>{esc(str(r['side']))}</td>"
        f"<td>{esc(json.dumps(r['mask']))}</td><td><img src='{esc(thumbs[r['name']])}' "
        f"style='width:96px;image-rendering:pixelated' alt='{esc(r['name'])} mask'></td></tr>"
        for r in a["regions"]
    )
    head = "<tr><th>region</th><th>side</th><th>channel table</th><th>mask (0 black, 1 white)</th>"
    return f"<table><thead>{head}</tr></thead><tbody>{rows}</tbody></table>"


def _color_html(color: dict[str, Any] | None, table: Any) -> str:
    """The colour fidelity table (CIEDE2000 per pose inside its active region), with colour
    states only."""
    if not color:
        return ""
    b = color["budget"]
    h, w = color["size"]
    rows = [
        [p["pose"], p["mean_delta_e"], p["p99_delta_e"], p["max_delta_e"], p["texels"]]
        for p in sorted(color["fidelity"]["poses"], key=lambda p: -p["p99_delta_e"])
    ]
    return (
        f"<h2>Colour fidelity</h2><p>colour states {w} x {h} ({html.escape(color['how'])}); "
        f"CIEDE2000 between the shipped and the full-resolution source colour blend inside each "
        f"pose's active region, weighted by activation; budget mean {b['max_mean_delta_e']:g}, "
        f"p99 {b['max_p99_delta_e']:g}</p>"
        + table(rows, ["pose", "mean ΔE00", "p99 ΔE00", "max ΔE00", "texels"])
    )


#: A checkerboard behind transparent texels (CSS, 16 px squares).
CHECKERBOARD = "repeating-conic-gradient(#c8c8c8 0% 25%, #f4f4f4 0% 50%) 0 0 / 16px 16px"

#: An SVG filter showing a texture's alpha channel as grey levels (in sRGB: the stored values).
#: (Its RGB under alpha 0 cannot be shown from the file: browsers decode PNGs premultiplied;
#: the regions table shows each region's mask whatever channel holds it.)
ALPHA_FILTERS = (
    "<svg width='0' height='0' style='position:absolute' aria-hidden='true'>"
    "<filter id='alpha' color-interpolation-filters='sRGB'><feColorMatrix type='matrix' "
    "values='0 0 0 1 0  0 0 0 1 0  0 0 0 1 0  0 0 0 0 1'/></filter></svg>"
)


def _alpha_textures(report: dict[str, Any]) -> set[str]:
    """The files of the mask textures whose alpha channel holds a region (``channel: "a"`` in a
    region's channel table; its ``texture`` is the mask texture's index, written as
    ``textures/mask_<index>.png``)."""
    out = set()
    for r in report["asset"]["regions"]:
        mask = r.get("mask")
        if isinstance(mask, dict) and mask.get("channel") == "a":
            t = mask.get("texture")
            out.add(f"textures/mask_{t}.png" if isinstance(t, int) else str(t))
    return out


def _texture_figures(file: str, alpha: bool) -> str:
    """A texture's thumbnail on a checkerboard; with ``alpha``, its alpha channel as grey."""
    esc = html.escape
    views = [("", "checker", file)]
    if alpha:
        views += [("filter:url(#alpha)", "", "alpha")]
    return "".join(
        f"<figure class='tex'><img src='{esc(file)}' class='{cls}' style='{style}' "
        f"alt='{esc(file)} {esc(label)}'><figcaption>{esc(label)}</figcaption></figure>"
        for style, cls, label in views
    )


def report_html(report: dict[str, Any]) -> str:
    """A static, self-contained HTML summary of report.json (textures linked, not embedded)."""
    esc = html.escape

    def table(rows: list[list[Any]], head: list[str]) -> str:
        th = "".join(f"<th>{esc(h)}</th>" for h in head)
        body = "".join(
            "<tr>" + "".join(f"<td>{esc(str(c))}</td>" for c in r) + "</tr>" for r in rows
        )
        return f"<table><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>"

    a = report["asset"]
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>wrinklepipe convert: {esc(report['name'])}</title>",
        "<style>body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}"
        "td,th{border:1px solid #ccc;padding:2px 6px;text-align:left}"
        "img{width:128px;image-rendering:pixelated;margin:2px}"
        # transparent texels show a checkerboard, never black
        f".checker{{background:{CHECKERBOARD}}}"
        "figure.tex{display:inline-block;margin:4px;vertical-align:top}"
        "figure.tex img{width:160px}</style></head><body>",
        ALPHA_FILTERS,
        f"<h1>{esc(report['name'])}</h1>",
        f"<p>encoding <b>{esc(a['encoding'])}</b>, scale {a['scale']}, policy "
        f"<b>{esc(a['policy'])}</b>; {a['vertices']} vertices, {a['triangles']} triangles, "
        f"{len(a['morph_targets'])} morph targets.</p>",
        "".join(f"<p class='note'><b>Note:</b> {esc(n)}</p>" for n in report.get("key_notes", [])),
        "<h2>Textures</h2><p>On a checkerboard where they are transparent; a mask texture "
        "with a region in alpha also as that channel (0 black, 1 white). Each region's mask "
        "alone, whatever channel holds it: the regions table below.</p><div>",
        "".join(
            _texture_figures(o["file"], o["file"] in _alpha_textures(report))
            for o in report["outputs"]
            if o["file"].startswith("textures/")
        ),
        "</div><h2>Regions</h2>",
        _regions_html(report, table),
        "<h2>Decode error of the stored states</h2>",
        table(
            [
                [k, v["mean_deg"], v["p99_deg"], v["max_deg"]]
                for k, v in report["decode_error"].items()
            ],
            ["state", "mean deg", "p99 deg", "max deg"],
        ),
        _color_html(report.get("color"), table),
        "<h2>Stages</h2><ul>",
        "".join(f"<li>{esc(n)}</li>" for n in report["notes"]),
        "</ul><h2>Block compression</h2>",
        table(
            [[g, c["requested"], c["chosen"]] for g, c in sorted(report["compression"].items())],
            ["maps", "requested", "chosen"],
        ),
        "<h2>Validation</h2>",
        _validation_html(report["validation"], table),
        "<h2>Outputs</h2>",
        table(
            [[o["file"], o["bytes"], o["sha256"][:16]] for o in report["outputs"]],
            ["file", "bytes", "sha256"],
        ),
        "<h2>Inputs</h2>",
        table(
            [[i["file"], i["bytes"], i["sha256"][:16]] for i in report["inputs"]],
            ["file", "bytes", "sha256"],
        ),
        "</body></html>\n",
    ]
    return "".join(parts)
