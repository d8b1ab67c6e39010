"""The region colours are told apart by colour-blind readers: under Machado et al. (2009)'s
simulation of full protanomaly, deuteranomaly and tritanomaly (colour-science's matrices), every
two of the first nine (Tol's muted scheme) still differ by CIEDE2000 >= 10, where the random
pale colours used before had two 1.5 apart; the viewer's table is the same as the validator's."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from wrinklepipe.palette import LIGHT, MUTED, REGION_COLOURS, region_colours_linear
from wrinklepipe.paths import ROOT

CVD = ("Protanomaly", "Deuteranomaly", "Tritanomaly")


def _min_delta_e(srgb: np.ndarray, cvd: str) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour  # the test extra (colour-science); imported here: it warns on import

        matrix = colour.blindness.matrix_cvd_Machado2009(cvd, 1.0)
        linear = colour.cctf_decoding(srgb, "sRGB")
        seen = colour.cctf_encoding(np.clip(linear @ matrix.T, 0, 1), "sRGB")
        lab = colour.XYZ_to_Lab(colour.sRGB_to_XYZ(seen))
    i, j = np.triu_indices(len(srgb), 1)
    return float(colour.delta_E(lab[i], lab[j], method="CIE 2000").min())


def _srgb(hexes: tuple[str, ...]) -> np.ndarray:
    return np.array([[int(h[k : k + 2], 16) for k in (1, 3, 5)] for h in hexes]) / 255.0


@pytest.mark.parametrize("cvd", CVD)
def test_muted_colours_stay_apart_for_colour_blind_readers(cvd: str) -> None:
    assert _min_delta_e(_srgb(MUTED), cvd) >= 10.0
    assert _min_delta_e(_srgb(LIGHT), cvd) >= 7.0
    old = np.random.default_rng(7).uniform(0.2, 1.0, (8, 3))  # the palette before (linear)
    if cvd == "Deuteranomaly":
        srgb = np.where(old <= 0.0031308, 12.92 * old, 1.055 * old ** (1 / 2.4) - 0.055)
        assert _min_delta_e(srgb, cvd) < 3.0


def test_linear_colours_decode_the_table() -> None:
    lin = region_colours_linear(20)
    assert lin.shape == (20, 3)
    np.testing.assert_array_equal(lin[18], lin[0])  # past 18 the list repeats
    # #CC6677: sRGB 0.8 -> linear 0.6038 (IEC 61966-2-1)
    np.testing.assert_allclose(lin[0, 0], ((0.8 + 0.055) / 1.055) ** 2.4, rtol=1e-6)


def test_viewer_uses_the_same_table() -> None:
    js = (ROOT / "wrinklepipe" / "data" / "threejs" / "wrinkle_setup.js").read_text()
    table = re.search(r"REGION_COLOURS = \[(.*?)\];", js, re.S).group(1)
    assert tuple(re.findall(r"'(#[0-9A-F]{6})'", table)) == REGION_COLOURS
