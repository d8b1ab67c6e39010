"""``pack-masks`` as a job: grey mask files -> checked, packed masks written to a folder.

:func:`pack_mask_files` reads the masks (:func:`~wrinklepipe.masks.read.read_masks`), resamples
them when asked, checks them (:func:`~wrinklepipe.masks.check.check_masks`: coverage, overlap,
empty regions), packs them in a layout (:func:`~wrinklepipe.masks.layouts.pack`) and writes the
textures and ``channels.json`` into the output folder, staged (all or none; a non-empty folder
only with ``force``). Its :class:`PackMasksOptions` give the command's defaults.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wrinklepipe.atomic import staged_folder
from wrinklepipe.errors import InputError, input_error
from wrinklepipe.io.images import DEFAULT_MAX_PIXELS
from wrinklepipe.masks.check import MaskReport, check_masks
from wrinklepipe.masks.files import write_packed
from wrinklepipe.masks.layouts import PackedMasks, pack
from wrinklepipe.masks.read import read_masks
from wrinklepipe.masks.resample import resample_masks


@dataclass(frozen=True)
class PackMasksOptions:
    """Options of :func:`pack_mask_files`.

    layout: packing layout (``rgba``, ``array``, ``lr-split``, ``jimenez8``, ``metahuman``).
    size: resample to ``size`` x ``size`` first (None: keep the inputs' size).
    invert: inputs are painted white = no wrinkle, black = full (Reis et al.).
    names: region names, one per file (None: the file stems).
    bits: bits per channel of the textures (None: the deepest input's).
    lr_conflict: lr-split: texels both sides cover are an ``error`` or go to the ``dominant``.
    force: replace a non-empty output folder.
    """

    layout: str = "rgba"
    size: int | None = None
    invert: bool = False
    names: tuple[str, ...] | None = None
    bits: int | None = None
    lr_conflict: str = "error"
    force: bool = False


@dataclass
class PackMasksResult:
    """What was written: the folder (as given), the layout asked for, the packed masks, the
    check report, the bits and the region names."""

    output: str
    layout: str
    packed: PackedMasks
    report: MaskReport
    bits: int
    names: tuple[str, ...]

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the packed textures."""
        return int(self.packed.textures.shape[2]), int(self.packed.textures.shape[1])

    def to_json(self) -> dict[str, Any]:
        return {
            "output": self.output,
            "layout": self.layout,
            "bits": self.bits,
            "table": self.packed.table,
            "report": self.report.to_json(),
            "notes": self.packed.notes,
        }


def pack_mask_files(
    paths: Sequence[str | Path], output: str | Path, options: PackMasksOptions | None = None
) -> PackMasksResult:
    """Read, check, pack and write ``paths`` into the folder ``output`` (see the module doc)."""
    o = options or PackMasksOptions()
    if o.size is not None and o.size <= 0:
        raise InputError(f"--size must be positive, got {o.size}", "<arguments>")
    if o.size is not None and o.size * o.size > DEFAULT_MAX_PIXELS:  # costed before any read
        raise input_error(
            "--size",
            f"{o.size} makes masks of {o.size} x {o.size} = {o.size * o.size} pixels, over the "
            f"cap of {DEFAULT_MAX_PIXELS} pixels",
        )
    ms = read_masks(paths, list(o.names) if o.names else None, invert=o.invert)
    masks = ms.masks if o.size is None else resample_masks(ms.masks, o.size)
    report = check_masks(masks, ms.names)
    packed = pack(masks, ms.names, o.layout, lr_conflict=o.lr_conflict)
    bits = o.bits or ms.bits
    with staged_folder(output, force=o.force, inputs=ms.files) as tmp:
        write_packed(tmp, packed, bits=bits, invert=o.invert, inputs=ms.files)
    return PackMasksResult(str(output), o.layout, packed, report, bits, ms.names)
