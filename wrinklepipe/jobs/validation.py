"""Convert's validation step: :mod:`wrinklepipe.validate` on the folder just written."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from wrinklepipe.asset import WrinkleAsset
from wrinklepipe.atomic import write_bytes
from wrinklepipe.outputs.report import VALIDATION_HTML
from wrinklepipe.sources.validation import LoadOptions, attach_source, load_input
from wrinklepipe.validate import ValidateOptions, validate
from wrinklepipe.validate.report import html_images
from wrinklepipe.validate.report import report_html as validation_page


def _scrub(obj: Any, replacements: dict[str, str]) -> Any:
    """Replace machine-specific path prefixes in every string of a JSON-able value."""
    if isinstance(obj, str):
        for old, new in replacements.items():
            obj = obj.replace(old, new)
        return obj
    if isinstance(obj, dict):
        return {k: _scrub(v, replacements) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_scrub(v, replacements) for v in obj]
    return obj


def validate_output(
    folder: Path,
    manifest_path: Path | None = None,
    render: bool = True,
    html_page: bool = False,
    source: WrinkleAsset | dict[int, WrinkleAsset] | None = None,
) -> dict[str, Any]:
    """Run :mod:`wrinklepipe.validate` on a written folder.

    With ``manifest_path`` the shipped textures are compared with the source maps. Only
    deterministic parts go into the report (counts and issues, no timings); paths are written
    relative to the output folder (``.``) and the manifest's folder (``<source>``). With
    ``html_page`` the validator's own page (contact sheet of renders, error heat maps, mask
    overlay, metrics) is written into the folder as ``validation.html`` + ``validation_files/``.
    ``source``: the asset ``convert`` ingested from the manifest (its maps at source resolution),
    used instead of reading and decoding the manifest's files again; the written folder itself
    is always read back, so the validator judges the bytes that were written. A UDIM asset:
    ``source`` one asset per tile, and the result also holds the fidelity per tile and over
    the whole face (``fidelity``: the validator's ``fidelity_by_tile``).
    """
    if source is not None and manifest_path is not None:
        shipped = load_input(folder, LoadOptions(shipped_maps=False))  # the source's replace them
        inp = attach_source(shipped, source, manifest_path)
    else:
        src = str(manifest_path) if manifest_path is not None else None
        inp = load_input(folder, LoadOptions(source=src))
    report = validate(inp, ValidateOptions(render=render))
    issues = [i.to_json() for i in report.issues]
    replacements = {str(folder): "."}
    if manifest_path is not None:
        replacements[str(manifest_path.parent)] = "<source>"
    if html_page:
        files_dir = Path(VALIDATION_HTML).stem + "_files"
        for image, data in html_images(report).items():
            write_bytes(folder / files_dir / image, data)
        page = _scrub(validation_page(report, files_dir), replacements)
        write_bytes(folder / VALIDATION_HTML, page.encode("utf-8"))
    counts = {k: int(v) for k, v in report.counts.items()}
    out: dict[str, Any] = {"status": "ran", "counts": counts, "issues": issues}
    if inp.tiles and "fidelity_by_tile" in report.metrics:
        out["fidelity"] = report.metrics["fidelity_by_tile"]
    return _scrub(out, replacements)
