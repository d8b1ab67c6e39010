"""Region masks: read, check, resample, pack into RGBA / texture arrays / left-right split, unpack.

See docs/regions.md for the channel table format and the layouts.
"""

from __future__ import annotations

from wrinklepipe.masks.check import CheckOptions, MaskReport, RegionCoverage, check_masks
from wrinklepipe.masks.files import CHANNELS_FILE, read_packed, write_packed
from wrinklepipe.masks.layouts import (
    CAPACITY,
    CHANNELS,
    LAYOUTS,
    PackedMasks,
    check_table,
    infer_side,
    pack,
    unpack,
)
from wrinklepipe.masks.read import MaskSet, mask_from_pixels, read_mask, read_masks, stack_masks
from wrinklepipe.masks.resample import resample_masks

__all__ = [
    "CAPACITY",
    "CHANNELS",
    "CHANNELS_FILE",
    "LAYOUTS",
    "CheckOptions",
    "MaskReport",
    "MaskSet",
    "PackedMasks",
    "RegionCoverage",
    "check_masks",
    "check_table",
    "infer_side",
    "mask_from_pixels",
    "pack",
    "read_mask",
    "read_masks",
    "read_packed",
    "resample_masks",
    "stack_masks",
    "unpack",
    "write_packed",
]
