"""validate-asset's colour rules on the demo with colour states: each fires on the defect it is
built for and stays silent on the clean asset (a pale / flushed recolour of the whole face)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wrinklepipe.demo import demo_asset
from wrinklepipe.validate import ValidateOptions, validate
from wrinklepipe.validate.ship import ShipOptions, ship_asset

COLOR_CODES = ("WP-COL-001", "WP-COL-002", "WP-COL-003", "WP-COL-004", "WP-FID-008")


@pytest.fixture(scope="module")
def asset():
    return demo_asset(64, color=True, mesh_resolution=(48, 32))


def _codes(inp) -> list[str]:
    rep = validate(inp, ValidateOptions(render=False))
    return sorted({i.code for i in rep.issues if i.code in COLOR_CODES}), rep


def test_the_clean_demo_has_no_colour_issue_and_reports_its_colour_fidelity(asset):
    codes, rep = _codes(ship_asset(asset, ShipOptions(compress=False)))
    assert codes == []
    fid = rep.metrics["color_fidelity"]
    assert [p["pose"] for p in fid["poses"]]  # every pose measured
    # the colour maps ship as painted; only the masks' 8-bit quantisation costs a little
    assert 0.0 < max(p["p99_delta_e"] for p in fid["poses"]) < 0.05
    assert rep.metrics["color_outside_misfit"] == {"stretch": 0.0, "compress": 0.0}


def test_bc7_copies_stay_inside_the_colour_budget(asset):
    codes, rep = _codes(ship_asset(asset, ShipOptions(compress=True)))
    assert codes == []
    worst = max(p["p99_delta_e"] for p in rep.metrics["color_fidelity"]["poses"])
    assert 0.0 < worst < 2.3


def _with_state(asset, j: int, texels: np.ndarray):
    states = asset.color.states.copy()
    states[j] = texels
    return replace(asset, color=replace(asset.color, states=states))


def test_a_flipped_colour_map_is_an_error(asset):
    # the flushed map painted upside down (V flipped): its colour lands on the wrong features
    flipped = _with_state(asset, 1, asset.color.states[1][::-1])
    codes, _ = _codes(ship_asset(flipped, ShipOptions(compress=False)))
    assert "WP-COL-002" in codes and "WP-FID-008" not in codes  # the source is flipped too


def test_a_map_of_another_layout_is_a_warning(asset):
    rng = np.random.default_rng(3)
    noise = rng.integers(40, 220, asset.color.states[0].shape).astype(np.uint8)
    codes, _ = _codes(ship_asset(_with_state(asset, 0, noise), ShipOptions(compress=False)))
    assert "WP-COL-003" in codes


def test_a_state_equal_to_the_base_colour_never_changes_the_colour(asset):
    same = _with_state(asset, 0, asset.color.base[..., :3])
    codes, _ = _codes(ship_asset(same, ShipOptions(compress=False)))
    assert codes == ["WP-COL-004"]


def test_a_colour_map_of_another_aspect_is_an_error(asset):
    inp = ship_asset(asset, ShipOptions(compress=False))
    t = next(t for t in inp.by_role("state_color") if t.state == "compress")
    px = np.frombuffer(t.data, np.uint8).reshape(t.height, t.width, 3)
    wide = np.ascontiguousarray(px[: t.height // 2])  # 64 x 32: another aspect
    t.data, t.height = wide.tobytes(), wide.shape[0]
    codes, _ = _codes(inp)
    assert "WP-COL-001" in codes


def test_a_degraded_shipped_colour_is_over_the_colour_budget(asset):
    inp = ship_asset(asset, ShipOptions(compress=False))
    t = next(t for t in inp.by_role("state_color") if t.state == "compress")
    px = np.frombuffer(t.data, np.uint8).reshape(t.height, t.width, 3).astype(np.int64)
    px[..., 1] += 40  # the flush shipped far less red than painted
    t.data = np.clip(px, 0, 255).astype(np.uint8).tobytes()
    codes, rep = _codes(inp)
    assert "WP-FID-008" in codes
    issue = next(i for i in rep.issues if i.code == "WP-FID-008")
    assert issue.data["p99_delta_e"] > 2.3
