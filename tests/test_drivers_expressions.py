"""Expressions driver vs Jimenez et al. Table 1.1 (the independently transcribed fixture)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from wrinklepipe import drivers as wd
from wrinklepipe.model import activations
from wrinklepipe.presets import jimenez

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "jimenez_table_1_1.csv"
STATES = ("stretch", "compress")


def _fixture() -> tuple[list[str], dict[str, list[float]]]:
    lines = [ln for ln in FIXTURE.read_text().splitlines() if ln and not ln.startswith("#")]
    rows = list(csv.reader(lines))
    colours = [c.strip().lower() for c in rows[0][1:]]
    table = {r[0].strip().lower(): [float(v) for v in r[1:]] for r in rows[1:]}
    return colours, table


def _ctx(policy: str = "clamp01") -> wd.DriverContext:
    return wd.DriverContext(jimenez.REGION_NAMES, STATES, policy=policy)


def _mix(mix: dict[str, float], policy: str = "clamp01") -> np.ndarray:
    spec = {"preset": "jimenez", "morphs": mix}
    return wd.evaluate("expressions", _ctx(policy), spec).weights[0]


def test_each_expression_equals_table_1_1():
    colours, table = _fixture()
    region_of_colour = {z[0]: z[1] for z in jimenez.ZONES}
    assert set(table) == {"joy", "surprise", "fear", "anger", "disgust", "sad"}
    for expr, row in table.items():
        w = _mix({expr: 1.0})
        assert w.shape == (8, 2)
        for colour, expected in zip(colours, row):
            i = jimenez.REGION_NAMES.index(region_of_colour[colour])
            assert w[i, 0] == pytest.approx(expected, abs=1e-7), (expr, colour)
            assert w[i, 1] == pytest.approx(expected, abs=1e-7), (expr, colour)


def test_surprise_plus_anger_cancels_the_inner_forehead():
    """Fig. 1.5: surprise (+0.8) and anger (-0.8) leave the inner forehead without wrinkles."""
    w = _mix({"surprise": 1.0, "anger": 1.0})
    names = jimenez.REGION_NAMES
    for r in ("forehead_inner_l", "forehead_inner_r"):
        assert w[names.index(r), 0] == pytest.approx(0.0, abs=1e-7)
    for r in ("forehead_outer_l", "forehead_outer_r"):
        assert w[names.index(r), 0] == pytest.approx(0.8 - 0.6, abs=1e-6)
    # Per texel: a texel fully inside the inner forehead gets no activation at all.
    masks = np.eye(8, dtype=np.float32)[:, :, None]  # texel i lies in region i only
    a = activations(masks, w, "clamp01")
    assert a[0, names.index("forehead_inner_l"), 0] == 0.0
    assert a[0, names.index("glabella"), 0] == pytest.approx(1.0)


def test_sums_above_one_are_clamped_under_clamp01():
    w = _mix({"joy": 1.0, "surprise": 1.0})
    i = jimenez.REGION_NAMES.index("forehead_outer_l")
    assert w[i, 0] == pytest.approx(1.8)  # the driver's weights stay linear
    masks = np.zeros((8, 1, 3), np.float32)
    masks[i, 0, :] = (1.0, 0.5, 0.25)
    a = activations(masks, w, "clamp01")[0, 0]
    np.testing.assert_allclose(a, [1.0, 0.9, 0.45], rtol=1e-6)
    assert activations(masks, w, "additive")[0, 0, 0] == pytest.approx(1.8)
    np.testing.assert_allclose(wd.policy_weights(w, "clamp01")[i], [1.0, 1.0])


def test_expression_keys_interpolate_linearly_over_time():
    spec = {"preset": "jimenez", "keys": {"sad": [[0, 0], [2, 1]]}, "fps": 4}
    res = wd.evaluate("expressions", _ctx(), spec)
    assert res.times.tolist() == pytest.approx([0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0])
    chin = jimenez.REGION_NAMES.index("chin")
    np.testing.assert_allclose(res.weights[:, chin, 0], res.times / 2.0, atol=1e-6)


def test_region_states_limit_which_states_a_region_drives():
    rs = np.zeros((8, 2), np.float32)
    rs[:, 1] = 1.0  # every region drives only "compress"
    ctx = wd.DriverContext(jimenez.REGION_NAMES, STATES, region_states=rs)
    w = wd.evaluate("expressions", ctx, {"preset": "jimenez", "morphs": {"joy": 1}}).weights[0]
    assert np.all(w[:, 0] == 0) and w[0, 1] == pytest.approx(1.0)


def test_signed_policy_gives_one_weight_per_region():
    w = _mix({"anger": 1.0}, policy="signed")
    assert w.shape == (8, 1) and w[0, 0] == pytest.approx(-0.6)


def test_unknown_expression_is_refused():
    from wrinklepipe.errors import InputError

    with pytest.raises(InputError, match="unknown expression"):
        wd.evaluate("expressions", _ctx(), {"preset": "jimenez", "morphs": {"smirk": 1}})
