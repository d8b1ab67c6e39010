"""``export``: read a written asset, build one engine's files, write them atomically."""

from __future__ import annotations

from pathlib import Path

from wrinklepipe.atomic import write_files
from wrinklepipe.errors import input_error
from wrinklepipe.export.files import export_files
from wrinklepipe.export.presets import ENGINE_PRESETS
from wrinklepipe.gltf.document import read_document
from wrinklepipe.readers.registry import format_of
from wrinklepipe.sources.package import read_package, written_file


def export(
    source: str | Path, output: str | Path, engine: str, force: bool = False
) -> tuple[dict[str, bytes], list[str]]:
    """Export a written asset for one engine into ``output`` (atomically)."""
    if engine not in ENGINE_PRESETS:
        raise input_error(engine, f"unknown engine; expected one of {', '.join(ENGINE_PRESETS)}")
    source = Path(source)
    pkg = read_package(source)
    written = written_file(source)
    # a glTF output is exported whole (every part of a character converted in place)
    fmt = format_of(written)
    document = read_document(written) if fmt is not None and fmt.name == "gltf" else None
    files, notes = export_files(pkg, engine, document)
    inputs = [source] if source.is_dir() else [source, source.parent]
    write_files(output, files, force=force, inputs=inputs, what="the export")
    return files, notes
