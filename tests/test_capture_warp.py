"""Thin-plate warps: landmarks reproduced exactly, affine maps reproduced everywhere."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.capture import warp as W


def _grid(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    yy, xx = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
    return xx, yy


def test_spline_passes_through_every_landmark():
    rng = np.random.default_rng(1)
    dst = rng.uniform(5, 120, (20, 2))
    src = dst + rng.normal(0, 2, (20, 2))
    warp = W.fit_tps(dst, src)
    assert np.abs(warp(dst) - src).max() < 1e-8
    exact = W.dense_map(warp, (128, 128))  # default: every pixel at this size
    assert W.landmark_residuals(exact, dst, src).max() < 0.02  # (cubic read-back of the map)
    # The coarse path (2-pixel grid + cubic refinement, used above 4 Mpx) stays well below a px.
    coarse = W.dense_map(warp, (128, 128), step=2)
    assert W.landmark_residuals(coarse, dst, src).max() < 0.1


def test_known_affine_within_half_a_pixel_everywhere():
    a = np.array([[1.05, 0.08], [-0.06, 0.97]])
    t = np.array([3.5, -2.25])
    rng = np.random.default_rng(3)
    dst = rng.uniform(10, 150, (8, 2))
    src = dst @ a.T + t
    field = W.dense_map(W.fit_tps(dst, src), (160, 160), step=4)
    xx, yy = _grid(160, 160)
    expect = np.stack([xx, yy], -1) @ a.T + t
    err = np.linalg.norm(field - expect, axis=-1)
    assert err.max() < 0.5
    assert err.max() < 1e-6  # in fact exact: the spline's polynomial part is affine


def test_warped_image_matches_the_analytic_image():
    # I'(q) = f(q); I'_d(p) = I'(A p + t) must equal f(A p + t) (an analytic pattern).
    a = np.array([[0.98, 0.05], [-0.04, 1.02]])
    t = np.array([2.0, -1.5])

    def f(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return 0.5 + 0.25 * np.sin(x / 7.0) * np.cos(y / 9.0)

    xx, yy = _grid(96, 96)
    src_img = f(xx, yy)
    dst = np.array([[10, 12], [80, 15], [20, 85], [85, 80], [50, 50]], float)
    field = W.dense_map(W.fit_tps(dst, dst @ a.T + t), (96, 96), step=4)
    warped, inside = W.sample(src_img, field)
    expect = f(field[..., 0], field[..., 1])
    # Away from the source's border half-pixel (clamped there, by design):
    core = inside & (field.min(axis=-1) > 1.0) & (field.max(axis=-1) < 95.0)
    assert np.abs(warped - expect)[core].max() < 2e-3  # bilinear error of a smooth pattern


@settings(max_examples=25, deadline=None)
@given(
    st.floats(0.8, 1.2),
    st.floats(-0.2, 0.2),
    st.floats(-0.2, 0.2),
    st.floats(0.8, 1.2),
    st.floats(-10, 10),
    st.floats(-10, 10),
    st.integers(0, 10_000),
)
def test_affine_property(a00, a01, a10, a11, tx, ty, seed):
    a = np.array([[a00, a01], [a10, a11]])
    t = np.array([tx, ty])
    dst = np.random.default_rng(seed).uniform(0, 64, (6, 2))
    if W.is_collinear(dst):
        return
    field = W.dense_map(W.fit_tps(dst, dst @ a.T + t), (48, 64), step=4)
    xx, yy = _grid(48, 64)
    expect = np.stack([xx, yy], -1) @ a.T + t
    assert np.linalg.norm(field - expect, axis=-1).max() < 0.5


def test_leave_one_out_flags_a_misplaced_landmark():
    g = np.linspace(10, 110, 4)
    dst = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    src = dst + np.array([2.0, -1.0])
    src[5] += np.array([9.0, 0.0])  # one landmark clicked 9 px off
    loo = W.leave_one_out(dst, src)
    assert int(np.argmax(loo)) == 5 and loo[5] > 5.0
    assert np.nanmax(np.delete(loo, 5)) < loo[5]


def test_collinear_landmarks_are_detected():
    assert W.is_collinear(np.array([[0, 0], [1, 1], [2, 2], [3, 3.0]]))
    assert not W.is_collinear(np.array([[0, 0], [1, 0], [0, 1.0]]))


def test_rotation_of_a_rotated_map_and_normals():
    theta = np.radians(30.0)
    c, s = np.cos(theta), np.sin(theta)
    xx, yy = _grid(16, 16)
    # texture -> photo: p = R(theta) t (pixel frame, y down).
    field = np.stack([c * xx - s * yy, s * xx + c * yy], -1)
    rot = W.jacobian_rotation(field)
    assert np.allclose(rot[..., 0], c) and np.allclose(rot[..., 1], s)
    # A photo normal leaning along the texture's u axis (seen in the photo: (c, s) in the
    # pixel frame, i.e. (c, -s) with +Y up) leans along +x in the texture.
    n = np.broadcast_to(np.array([0.6 * c, -0.6 * s, 0.8], np.float32), (16, 16, 3))
    out = W.rotate_normals(n, rot)
    assert np.allclose(out[0, 0], [0.6, 0.0, 0.8], atol=1e-6)
