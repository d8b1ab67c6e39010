"""Write packed masks to a folder (textures + ``channels.json``) and read them back.

RGBA layouts write one PNG per texture (``<stem>_<t>.png``). A texture array is written as one
grey PNG strip (``<stem>_array.png``): layer ``i`` occupies rows ``i*H .. (i+1)*H - 1``, the form
engines import as a flipbook / Texture2DArray. Masks are linear data (no sRGB). Deterministic.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.atomic import write_json
from wrinklepipe.errors import InputError, input_error
from wrinklepipe.io.images import read_image, write_image
from wrinklepipe.io.json_safe import loads_json
from wrinklepipe.masks.layouts import LAYOUTS, PackedMasks, check_table

CHANNELS_FILE = "channels.json"
FORMAT_VERSION = 1


def _write_one(
    folder: Path, p: PackedMasks, bits: int, stem: str, inputs: Iterable[str | Path]
) -> dict[str, Any]:
    inputs = tuple(inputs)
    if p.layout == "array":
        layers, h, w = p.textures.shape
        name = f"{stem}_array.png"
        write_image(folder / name, p.textures.reshape(layers * h, w), bits, inputs)
        files = [name]
    else:
        files = []
        for t in range(p.textures.shape[0]):
            name = f"{stem}_{t}.png"
            write_image(folder / name, p.textures[t], bits, inputs)
            files.append(name)
    h, w = p.size
    return {
        "layout": p.layout,
        "preset": p.preset,
        "size": [h, w],
        "bits": int(bits),
        "textures": files,
        "layers": int(p.textures.shape[0]) if p.layout == "array" else None,
        "entries": p.table,
    }


def write_packed(
    folder: str | Path,
    packed: PackedMasks,
    bits: int = 8,
    stem: str = "masks",
    invert: bool = False,
    inputs: Iterable[str | Path] = (),
) -> Path:
    """Write ``packed`` into ``folder``; returns the path of ``channels.json``.

    ``invert`` only records that the sources were painted white = none (Reis); the stored masks
    are always 1 = full wrinkle.
    """
    folder = Path(folder)
    inputs = tuple(inputs)
    doc = _write_one(folder, packed, bits, stem, inputs)
    doc["array"] = (
        _write_one(folder, packed.array, bits, stem, inputs) if packed.array is not None else None
    )
    doc["invert"] = bool(invert)
    doc["version"] = FORMAT_VERSION
    return write_json(folder / CHANNELS_FILE, doc, inputs)


def _read_one(folder: Path, doc: dict[str, Any], where: str) -> PackedMasks:
    layout = doc.get("layout")
    if layout not in LAYOUTS:
        raise input_error(where, f"unknown layout {layout!r}", "layout")
    files = doc.get("textures")
    if not isinstance(files, list) or not files:
        raise input_error(where, "'textures' must list the texture files", "textures")
    imgs = [read_image(folder / f)[0] for f in files]
    if layout == "array":
        strip = imgs[0][..., 0]
        layers = int(doc.get("layers") or 0)
        if layers <= 0 or strip.shape[0] % layers:
            raise input_error(where, f"array strip of {strip.shape[0]} rows is not {layers} layers")
        tex = strip.reshape(layers, strip.shape[0] // layers, strip.shape[1])
    else:
        shapes = {i.shape for i in imgs}
        if len(shapes) != 1 or imgs[0].shape[-1] != 4:
            raise input_error(
                where, f"mask textures must be RGBA of one size, got {sorted(shapes)}"
            )
        tex = np.stack(imgs)
    table = doc.get("entries")
    if not isinstance(table, list):
        raise input_error(where, "'entries' must be the channel table (a list)", "entries")
    try:
        check_table(table, tex.shape)
    except InputError as exc:
        raise InputError(
            [type(p)(where, p.message, f"entries{p.key}") for p in exc.problems]
        ) from None
    return PackedMasks(str(layout), tex, table, str(doc.get("preset", "")))


def read_packed(folder: str | Path) -> PackedMasks:
    """Read ``channels.json`` and its textures from ``folder`` (or a path to the JSON itself)."""
    path = Path(folder)
    if path.is_dir():
        path = path / CHANNELS_FILE
    if not path.exists():
        raise input_error(path, "file not found")
    if path.is_dir():
        raise input_error(path, "is a folder, expected the channel table (channels.json)")
    doc = loads_json(path.read_bytes(), path, "channel table JSON")
    if not isinstance(doc, dict):
        raise input_error(path, "expected a JSON object")
    packed = _read_one(path.parent, doc, str(path))
    if isinstance(doc.get("array"), dict):
        packed.array = _read_one(path.parent, doc["array"], str(path))
    return packed
