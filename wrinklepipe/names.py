"""Unique names: the one ``stem, stem_2, stem_3 ...`` rule.

File stems (:func:`wrinklepipe.package.safe_name`), USD prim and variant names and HLSL
identifiers (:func:`wrinklepipe.shading.hlsl.identifier`) are all kept apart with it, so two
regions, textures or prims whose names clash get the same suffixes wherever they are written.
"""

from __future__ import annotations


def unique_name(stem: str, taken: set[str]) -> str:
    """``stem``, or ``stem_2``, ``stem_3`` ... the first not in ``taken`` (which it updates)."""
    out, i = stem, 1
    while out in taken:
        i += 1
        out = f"{stem}_{i}"
    taken.add(out)
    return out
