"""CIEDE2000 colour differences of linear sRGB colours, by colour-science: the colour half of
the one measure (the colour states' automatic choices, the validator's colour rules, the
reports and the render comparisons all call it; its statistics are :mod:`.stats`').

A colour error is judged where people see it: in CIELAB, by CIEDE2000 (Sharma, Wu and Dalal's
formulation, ``colour.difference.delta_E_CIE2000``). Linear sRGB (the wrinkle model's colours)
goes to CIE XYZ by the sRGB primaries and D65 white (``colour.RGB_to_XYZ``, no transfer
function: the values are linear already), then to CIELAB relative to D65
(``colour.XYZ_to_Lab``). A difference of 1 is about the smallest a trained eye sees side by
side; 2.3 is the just-noticeable difference usually quoted for CIELAB.

colour-science takes about half a second to import, so it is loaded on first use (an asset
without colour states never pays for it).
"""

from __future__ import annotations

import functools
import os
import warnings
from typing import Any

import numpy as np


@functools.cache
def _colour() -> Any:
    # colour-science: ~0.6 s to import (its whole library loads); only colour measures need it
    os.environ.setdefault("COLOUR_SCIENCE__FILTER_USAGE_WARNINGS", "True")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "Matplotlib related API features are not available"
        import colour
    return colour


def linear_to_lab(lin: np.ndarray) -> np.ndarray:
    """Linear sRGB ``[..., 3]`` (D65) -> CIELAB ``[..., 3]`` (float64, L in 0..100)."""
    colour = _colour()
    space = colour.RGB_COLOURSPACES["sRGB"]
    with colour.utilities.domain_range_scale("reference"):
        xyz = colour.RGB_to_XYZ(np.asarray(lin, np.float64), space, apply_cctf_decoding=False)
        return colour.XYZ_to_Lab(xyz, space.whitepoint)


def delta_e_lab(lab_a: np.ndarray, lab_b: np.ndarray) -> np.ndarray:
    """CIEDE2000 between CIELAB colours ``[..., 3]`` (float64)."""
    colour = _colour()
    with colour.utilities.domain_range_scale("reference"):
        return np.asarray(colour.difference.delta_E_CIE2000(lab_a, lab_b), np.float64)


def delta_e(lin_a: np.ndarray, lin_b: np.ndarray) -> np.ndarray:
    """CIEDE2000 between linear sRGB colours ``[..., 3]``."""
    return delta_e_lab(linear_to_lab(lin_a), linear_to_lab(lin_b))
