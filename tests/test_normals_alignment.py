"""The share of the base's detail a state keeps (wrinklepipe.normals.alignment), on fields
whose answer is known: the base itself (1), the base plus independent relief (1), another
field (0), the base mirrored or green-flipped (0, and 1 once undone), shifted (1 moved back)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe import model
from wrinklepipe.normals import alignment as al


def field(seed: int, n: int = 64, amp: float = 0.2) -> np.ndarray:
    """Unit normals of independent random PD slopes (white: no two texels alike)."""
    rng = np.random.default_rng(seed)
    return model.pd_to_normal(rng.normal(0, amp, (n, n, 2)).astype(np.float32))


def everywhere(n: int = 64):
    return al.lattice(np.ones((n, n), bool))


def test_the_base_and_the_base_with_relief_keep_all_of_it():
    b = field(1)
    r, c = everywhere()
    assert al.kept(b, b, r, c) == pytest.approx(1.0, abs=1e-6)
    # relief added everywhere (uncorrelated with the base) leaves the share at 1
    relief = field(2, amp=0.3)
    s = model.pd_to_normal(model.normal_to_pd(b) + model.normal_to_pd(relief))
    assert al.kept(b, s, r, c) == pytest.approx(1.0, abs=0.05)


def test_another_face_keeps_none_and_a_flat_base_gives_no_evidence():
    r, c = everywhere()
    assert abs(al.kept(field(1), field(3), r, c)) < 0.05
    flat = np.zeros((64, 64, 3), np.float32)
    flat[..., 2] = 1.0
    assert al.kept(flat, field(3), r, c) is None
    assert al.detail(flat, r, c) == 0.0


def test_mirrors_flips_and_shifts_are_found_when_undone():
    b = field(4)
    r, c = everywhere()
    green = b.copy()
    green[..., 1] *= -1
    cases = {
        "the base flipped vertically (V)": np.ascontiguousarray(b[::-1]),
        "the base flipped horizontally (U)": np.ascontiguousarray(b[:, ::-1]),
        "the base's green channel flipped": green,
    }
    for label, moved in cases.items():
        # the state is of the original; the given base is the moved one
        assert abs(al.kept(moved, b, r, c)) < 0.1, label
        assert al.kept(moved, b, r, c, al.TRANSFORMS[label]) == pytest.approx(1.0, abs=1e-6)
    rolled = np.roll(b, (5, -3), axis=(0, 1))  # rolled[r, c] = b[r - 5, c + 3]
    assert abs(al.kept(rolled, b, r, c)) < 0.1
    assert al.kept(rolled, b, r, c, shift=(5, -3)) == pytest.approx(1.0, abs=1e-6)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31), st.floats(0.0, 1.0), st.floats(0.05, 0.5))
def test_the_share_is_the_regression_slope(seed, share, amp):
    """A state holding ``share`` of the base's slopes plus independent relief keeps ``share``
    of its detail (to sampling noise)."""
    rng = np.random.default_rng(seed)
    pb = rng.normal(0, amp, (64, 64, 2))
    ps = share * pb + rng.normal(0, amp, (64, 64, 2))
    r, c = everywhere()
    got = al.kept(model.pd_to_normal(pb), model.pd_to_normal(ps), r, c)
    assert got == pytest.approx(share, abs=0.06)


def test_the_lattice_reads_at_most_the_sample():
    where = np.zeros((3000, 3000), bool)
    where[::2] = True
    r, c = al.lattice(where, max_texels=10_000)
    assert r.size <= 10_000 and where[r, c].all()
