"""The validator's shortcuts give what the long way gives (issue 17: convert's validation
without repeated work)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe import fidelity as fd
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.sources.validation import load_input
from wrinklepipe.validate import rules_fidelity
from wrinklepipe.validate.context import Context
from wrinklepipe.validate.rules_fidelity import _outside


def _outside_by_every_mask(masks: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Every mask sampled on the grid, then 'no mask > 0' (the definition)."""
    H, W = shape
    m = fd.sample_masks_at(masks, shape, np.arange(H * W)).reshape(-1, H, W)
    return ~(m > 0).any(axis=0)


def test_outside_of_a_hand_made_mask():
    # one mask texel of a 2x2 map on at (0, 1): magnified to 4x4, bilinear between texel
    # centres (clamped) reaches it from columns 1..3 of rows 0..2; nothing else is inside
    m = np.zeros((2, 2, 2), np.float32)
    m[1, 0, 1] = 1 / 255
    want = np.ones((4, 4), bool)
    want[0:3, 1:4] = False
    assert (_outside(m, (4, 4), None) == want).all()
    fp = np.zeros((4, 4), bool)
    fp[0] = True
    assert (_outside(m, (4, 4), fp) == (want & fp)).all()


@settings(max_examples=60, deadline=None)
@given(
    st.integers(1, 4),
    st.integers(1, 24),
    st.integers(1, 24),
    st.integers(1, 40),
    st.integers(1, 40),
    st.floats(0.0, 0.3),
    st.integers(0, 2**32 - 1),
)
def test_outside_equals_sampling_every_mask(R, h, w, H, W, density, seed):
    rng = np.random.default_rng(seed)
    m = rng.random((R, h, w)).astype(np.float32)
    m *= rng.random((R, h, w)) < density
    m[m > 0.9] = 1 / 255  # the smallest 8-bit value: a faint edge still counts
    assert (_outside(m, (H, W), None) == _outside_by_every_mask(m, (H, W))).all()


@pytest.fixture(scope="module")
def ctx(tmp_path_factory) -> Context:
    manifest = write_demo_source(tmp_path_factory.mktemp("src") / "demo", size=64)
    c = Context(load_input(manifest))
    assert c.inp.has_source and rules_fidelity.reference(c) is not None
    return c


def _poses(fid: fd.Fidelity) -> list[dict]:
    return [p.to_json() for p in fid.poses]


def test_shipped_fidelity_is_the_one_measure(ctx):
    """Base and masks gathered once and shared: the same numbers as fd.measure in one call."""
    ref = rules_fidelity.reference(ctx)
    base, states, masks = ctx.shipped_base, np.stack(ctx.shipped_states), ctx.shipped_masks
    want = fd.measure(ref, base, states, masks, error_maps=True)
    got = rules_fidelity.shipped_fidelity(ctx)
    assert got.to_json() == want.to_json() and got.base is not None
    assert sorted(got.errors) == sorted(want.errors)
    for k in want.errors:
        assert np.array_equal(got.errors[k].flat, want.errors[k].flat)
        assert np.array_equal(
            got.errors[k].values.view(np.uint32), want.errors[k].values.view(np.uint32)
        )
    # other states against the same shipped base and masks (the half-size check's question)
    halves = states.reshape(states.shape[0], 32, 2, 32, 2, -1).mean(axis=(2, 4))
    other = fd.evaluate(ref, rules_fidelity.shipped_samples(ctx, halves), regions=False)
    assert _poses(other) == _poses(fd.measure(ref, base, halves, masks, False))
    assert _poses(other) != _poses(want)
