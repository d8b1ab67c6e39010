"""The block-format choice: DDS + KTX2 copies of the base and PD state maps within the budget."""

from __future__ import annotations

from typing import Any

import numpy as np

from wrinklepipe.io.package import WrinklePackage
from wrinklepipe.normals import compress as nc
from wrinklepipe.normals.dds import dds_bytes
from wrinklepipe.normals.ktx2 import ktx2_bytes

#: Block formats tried for a two-channel normal map when the manifest says ``auto``.
AUTO_FORMATS: tuple[str, ...] = ("bc5", "bc3nm", "bc7", "bc1")
_BLOCK = ("bc5", "bc1", "bc3nm", "bc7")


def compressed_files(
    pkg: WrinklePackage,
    budget: dict[str, float] | None = None,
    formats: dict[str, str] | None = None,
) -> tuple[dict[str, bytes], list[str], dict[str, Any]]:
    """Block-compressed copies (DDS + KTX2) of the base and the PD state maps.

    For each map the format is the manifest's ``formats.base`` / ``formats.wrinkle``; ``auto``
    (default) tries :data:`AUTO_FORMATS` and keeps the smallest that meets the budget for every
    map of the group (error of the decoded map against the stored 8-bit map, measured by
    :func:`wrinklepipe.normals.compress.compress_and_check`); all states share one format. When
    no format passes, the group ships as PNG only and a note says why.
    Returns (files, notes, per-map choices for the report).
    """
    files: dict[str, bytes] = {}
    notes: list[str] = []
    choices: dict[str, Any] = {}
    budget = budget or {}
    limits = nc.Budget(budget.get("max_mean_deg"), budget.get("max_p99_deg", 2.0))
    formats = formats or {}
    meta = pkg.meta
    lut = np.arange(256, dtype=np.float32) / np.float32(255.0)
    groups: list[tuple[str, str, Any, list[Any]]] = [
        (
            "base",
            formats.get("base", "auto"),
            nc.decoder_for("full"),
            [t for t in pkg.textures if t.role == "base_normal"],
        ),
    ]
    if meta["encoding"] == "pd":  # every state ships in one format (shaders sample them alike)
        groups.append(
            (
                "wrinkle",
                formats.get("wrinkle", "auto"),
                nc.decoder_for("pd", scale=float(meta["scale"])),
                [t for t in pkg.textures if t.role == "state"],
            )
        )
    else:
        notes.append(f"{meta['encoding']} states ship as PNG only (block copies are for pd)")
    for group, want, decode, maps in groups:
        if any(t.bits != 8 for t in maps):
            notes.append(f"{group}: 16-bit maps ship as PNG only (block formats are 8-bit)")
        maps = [t for t in maps if t.bits == 8]
        if not maps or (want not in _BLOCK and want != "auto"):
            continue
        # Smallest blocks first (BC1: 8 bytes; then BC5, BC3nm, BC7: 16), stop at the first
        # format every map of the group passes with: that is the smallest that meets the budget.
        candidates = (
            tuple(
                sorted(
                    AUTO_FORMATS, key=lambda f: (nc.block_data_size(f, 4, 4), AUTO_FORMATS.index(f))
                )
            )
            if want == "auto"
            else (want,)
        )
        references = []
        for t in maps:
            stored = t.pixels[..., :2]
            references.append((stored, decode(lut[stored], slice(0, stored.shape[0]))))
        checks: dict[str, list[Any]] = {}
        for f in candidates:
            checks[f] = [
                nc.compress_and_check(st, ref, f, decode, limits, keep_decoded=False)
                for st, ref in references
            ]
            if all(c.verdict == "pass" for c in checks[f]):
                break
        candidates = tuple(checks)
        passing = [f for f in candidates if all(c.verdict == "pass" for c in checks[f])]
        if want != "auto":
            pick = want
            if not passing:
                notes.append(f"{group}: {want} as requested, over the error budget")
        elif passing:
            pick = passing[0]
        else:
            pick = None
            best = min(candidates, key=lambda f: max(c.error.mean_deg for c in checks[f]))
            worst = max(checks[best], key=lambda c: c.error.mean_deg)
            notes.append(
                f"{group}: no block format meets the budget (best {best}: mean "
                f"{worst.error.mean_deg:.2f}, p99 {worst.error.p99_deg:.2f} deg); PNG only"
            )
        choices[group] = {
            "requested": want,
            "chosen": pick or "png",
            "checks": {
                f: {t.name: c.to_json() for t, c in zip(maps, cs)} for f, cs in checks.items()
            },
        }
        if pick is None:
            continue
        for t, c in zip(maps, checks[pick]):
            h, w = t.pixels.shape[:2]
            files[f"compressed/{t.name}.dds"] = dds_bytes(pick, w, h, [c.data])
            files[f"compressed/{t.name}.ktx2"] = ktx2_bytes(pick, w, h, [c.data])
    return files, notes, choices
