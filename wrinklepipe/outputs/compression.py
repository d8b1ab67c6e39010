"""The block-format choice: DDS + KTX2 copies of the base and the states within the budget.

The copies themselves (layouts, encoders, mips, containers) are
:mod:`wrinklepipe.normals.copies`; this module is what the folder and the engine exports call.
"""

from __future__ import annotations

from typing import Any

from wrinklepipe.normals import copies as nc
from wrinklepipe.options import BudgetOptions, FormatOptions
from wrinklepipe.package import WrinklePackage

#: Block formats ``auto`` tries (smallest blocks first; ``bc7xy`` only when asked for).
AUTO_FORMATS: tuple[str, ...] = nc.AUTO_FORMATS


def compressed_copies(
    pkg: WrinklePackage,
    budget: BudgetOptions | None = None,
    formats: FormatOptions | None = None,
) -> tuple[list[nc.Copy], list[str], dict[str, Any]]:
    """The copies of the base and every state (:func:`wrinklepipe.normals.copies.compressed_copies`:
    the manifest's ``formats.base`` / ``formats.wrinkle``, ``auto`` = the smallest format whose
    every map of the group meets the budget; all states share one format), notes, and the
    per-group choices for the report."""
    return nc.compressed_copies(pkg, budget, formats)


def compressed_files(
    pkg: WrinklePackage,
    budget: BudgetOptions | None = None,
    formats: FormatOptions | None = None,
) -> tuple[dict[str, bytes], list[str], dict[str, Any]]:
    """Like :func:`compressed_copies`, as ``{relative path: bytes}`` (``compressed/NAME.dds``
    and ``compressed/NAME.ktx2``, full mip chains), notes and choices."""
    made, notes, choices = compressed_copies(pkg, budget, formats)
    return nc.files(made), notes, choices
