"""Region colours that colour-blind readers can tell apart: Paul Tol's qualitative schemes.

Paul Tol, *Colour Schemes*, SRON technical note SRON/EPS/TN/09-002, issue 3.2 (2021),
https://personal.sron.nl/~pault/ : the **muted** scheme (9 colours, "for 9 or fewer
categories"; distinct for the common forms of colour blindness and in print) and, for a 10th to
18th region, the **light** scheme (9 colours, lighter, meant to carry labels). Regions past 18
repeat the list; the legend beside every overlay names each colour. The validator's mask
overlay (``validation.html``) and the three.js viewer's region overlay
(``wrinklepipe/data/threejs/wrinkle_setup.js``, the same table; a test keeps them equal) use it.
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.codec.srgb import srgb_to_linear

#: Tol's muted scheme, in his order: rose, indigo, sand, green, cyan, wine, teal, olive, purple.
MUTED = (
    "#CC6677",
    "#332288",
    "#DDCC77",
    "#117733",
    "#88CCEE",
    "#882255",
    "#44AA99",
    "#999933",
    "#AA4499",
)

#: Tol's light scheme: light blue, orange, light yellow, pink, light cyan, mint, pear, olive,
#: pale grey.
LIGHT = (
    "#77AADD",
    "#EE8866",
    "#EEDD88",
    "#FFAABB",
    "#99DDFF",
    "#44BB99",
    "#BBCC33",
    "#AAAA00",
    "#DDDDDD",
)

#: The region colours, in order (sRGB hex).
REGION_COLOURS = MUTED + LIGHT


def region_colours_hex(n: int) -> list[str]:
    """The sRGB colours of ``n`` regions, as ``#rrggbb``."""
    return [REGION_COLOURS[i % len(REGION_COLOURS)] for i in range(n)]


def region_colours_linear(n: int) -> np.ndarray:
    """``[n, 3]`` float32 linear-light RGB of ``n`` regions (for blending with renders)."""
    codes = np.array(
        [[int(h[i : i + 2], 16) for i in (1, 3, 5)] for h in region_colours_hex(n)], np.float64
    ).reshape(n, 3)
    return srgb_to_linear(codes / 255.0).astype(np.float32)
