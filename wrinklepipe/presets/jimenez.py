"""Jimenez et al., "Practical and Realistic Facial Wrinkles Animation": zones and Table 1.1.

Our reading of the zone colours of their Figure 1.3 (two RGBA masks, 8 zones), in channel order.
``_l`` / ``_r`` are the character's left and right.
"""

from __future__ import annotations

#: (zone colour in the paper, region name, side, mask texture, channel)
ZONES: tuple[tuple[str, str, str, int, str], ...] = (
    ("red", "forehead_outer_l", "left", 0, "r"),
    ("green", "forehead_outer_r", "right", 0, "g"),
    ("blue", "forehead_inner_l", "left", 0, "b"),
    ("brown", "forehead_inner_r", "right", 0, "a"),
    ("cyan", "nose_l", "left", 1, "r"),
    ("magenta", "nose_r", "right", 1, "g"),
    ("orange", "glabella", "center", 1, "b"),
    ("gray", "chin", "center", 1, "a"),
)

REGION_NAMES: tuple[str, ...] = tuple(z[1] for z in ZONES)

#: Table 1.1, rows in the paper's order; columns in :data:`ZONES` order
#: (Red, Green, Blue, Brown, Cyan, Magenta, Orange, Gray).
TABLE_1_1: dict[str, tuple[float, ...]] = {
    "joy": (1.0, 1.0, 0.2, 0.2, 0.0, 0.0, 0.0, 0.0),
    "surprise": (0.8, 0.8, 0.8, 0.8, 0.0, 0.0, 0.0, 0.0),
    "fear": (0.2, 0.2, 0.75, 0.75, 0.3, 0.3, 0.0, 0.6),
    "anger": (-0.6, -0.6, -0.8, -0.8, 0.8, 0.8, 1.0, 0.0),
    "disgust": (0.0, 0.0, -0.1, -0.1, 1.0, 1.0, 1.0, 0.5),
    "sad": (0.2, 0.2, 0.75, 0.75, 0.0, 0.0, 0.1, 1.0),
}

EXPRESSIONS: tuple[str, ...] = tuple(TABLE_1_1)


def expression_table() -> dict[str, dict[str, float]]:
    """Table 1.1 as ``{expression: {region: weight}}``."""
    return {e: dict(zip(REGION_NAMES, row)) for e, row in TABLE_1_1.items()}
