"""MetaHuman's animated wrinkle-map regions: 37 masks named ``head_wm<k>_<region>``.

MetaHuman blends three wrinkle normal maps (``wm1``, ``wm2``, ``wm3``) over the base inside 37
region masks whose weights RigLogic computes (the shader parameters are named
``head_wm<k>_normal_head_wm<k>_<region>``). ``wm13`` regions (the lips) drive both wm1 and wm3.

The region names are MetaHuman's. **The channel table is ours, not Epic's**: the engine's own mask
textures are not public, so we pack the regions grouped by wrinkle map, in the order below, four per
RGBA texture: wm1 in textures 0-3 (15 regions), wm2 in 4-6 (10), wm3 in 7-8 (8), wm13 in 9 (4),
10 textures in all (37 of 40 channels used), plus a texture array with one layer per region.
"""

from __future__ import annotations

_WM1 = (
    "blink_L",
    "blink_R",
    "browsRaiseInner_L",
    "browsRaiseInner_R",
    "browsRaiseOuter_L",
    "browsRaiseOuter_R",
    "chinRaise_L",
    "chinRaise_R",
    "jawOpen",
    "purse_DL",
    "purse_DR",
    "purse_UL",
    "purse_UR",
    "squintInner_L",
    "squintInner_R",
)
_WM2 = (
    "browsDown_L",
    "browsDown_R",
    "browsLateral_L",
    "browsLateral_R",
    "mouthStretch_L",
    "mouthStretch_R",
    "neckStretch_L",
    "neckStretch_R",
    "noseWrinkler_L",
    "noseWrinkler_R",
)
_WM3 = (
    "cheekRaiseInner_L",
    "cheekRaiseInner_R",
    "cheekRaiseOuter_L",
    "cheekRaiseOuter_R",
    "cheekRaiseUpper_L",
    "cheekRaiseUpper_R",
    "smile_L",
    "smile_R",
)
_WM13 = ("lips_DL", "lips_DR", "lips_UL", "lips_UR")

#: The wrinkle states (normal maps) MetaHuman blends.
STATES: tuple[str, ...] = ("wm1", "wm2", "wm3")

_GROUPS: tuple[tuple[str, tuple[str, ...], tuple[str, ...], int], ...] = (
    # (prefix, regions, states driven, first texture)
    ("head_wm1_", _WM1, ("wm1",), 0),
    ("head_wm2_", _WM2, ("wm2",), 4),
    ("head_wm3_", _WM3, ("wm3",), 7),
    ("head_wm13_", _WM13, ("wm1", "wm3"), 9),
)

#: The 37 region names, in packing order.
REGIONS: tuple[str, ...] = tuple(p + r for p, regs, _, _ in _GROUPS for r in regs)

#: Number of RGBA mask textures.
TEXTURES = 10

#: Region -> the states it drives.
REGION_STATES: dict[str, tuple[str, ...]] = {p + r: st for p, regs, st, _ in _GROUPS for r in regs}

_CH = "rgba"

#: The channel table (see docs/regions.md): ``{"region", "texture", "channel"}`` per region.
CHANNEL_TABLE: tuple[dict[str, object], ...] = tuple(
    {"region": p + r, "texture": t0 + i // 4, "channel": _CH[i % 4]}
    for p, regs, _, t0 in _GROUPS
    for i, r in enumerate(regs)
)


def side_of(region: str) -> str:
    """``left`` / ``right`` / ``center`` from MetaHuman's suffixes (``_L``, ``_DL``, ``_UR``...)."""
    tail = region.rsplit("_", 1)[-1]
    if tail in ("L", "DL", "UL"):
        return "left"
    if tail in ("R", "DR", "UR"):
        return "right"
    return "center"


def shader_parameter(region: str, state: str) -> str:
    """The MetaHuman material parameter name: ``head_wm1_normal_head_wm1_browsRaiseInner_L``."""
    return f"head_{state}_normal_{region}"
