"""Fidelity in colour: CIEDE2000 per pose inside the active region, against hand-computed
texels and a brute-force recomputation with colour-science and a bilinear sampler written here;
the colour size choice."""

from __future__ import annotations

import os

import numpy as np
import pytest

from wrinklepipe.asset import ColorMaps, Region, WrinkleAsset
from wrinklepipe.codec import srgb
from wrinklepipe.fidelity import Pose
from wrinklepipe.fidelity import color as fc
from wrinklepipe.metrics import Budget
from wrinklepipe.pipeline import color as pc

os.environ.setdefault("COLOUR_SCIENCE__FILTER_USAGE_WARNINGS", "True")
colour = pytest.importorskip("colour")
_SRGB = colour.RGB_COLOURSPACES["sRGB"]


def _de(a, b):
    def lab(x):
        xyz = colour.RGB_to_XYZ(np.asarray(x, np.float64), _SRGB, apply_cctf_decoding=False)
        return colour.XYZ_to_Lab(xyz, _SRGB.whitepoint)

    return colour.delta_E(lab(a), lab(b), method="CIE 2000")


def _tex(rgb, shape):
    return np.broadcast_to(np.asarray(rgb, np.uint8), (*shape, 3)).copy()


def test_the_default_budget_is_one_and_one_jnd():
    assert fc.color_budget({}) == Budget(1.0, 2.3, None)
    assert fc.color_budget({"max_mean_delta_e": 0.5, "max_p99_delta_e": 1.5}) == Budget(
        0.5, 1.5, None
    )


def test_a_changed_texel_costs_its_delta_e_weighted_by_its_activation():
    base = _tex((200, 150, 130), (4, 4))
    state = _tex((150, 40, 40), (4, 4))
    mask = np.zeros((1, 4, 4), np.float32)
    mask[0, 0, :3] = (1.0, 0.5, 0.5)
    mask[0, 1, 0] = 0.25
    pose = Pose("flush", np.ones((1, 1), np.float32))
    ref = fc.prepare_color(
        srgb.decode_texels(base), srgb.decode_texels(state)[None], mask, [pose], ["r"],
        "clamp01", (0,),
    )  # fmt: skip
    assert ref.union.tolist() == [0, 1, 2, 4]
    same = fc.measure_color(ref, base, [state], mask)
    assert same.poses[0].overall.mean == 0.0 and same.poses[0].overall.max == 0.0
    shipped = state.copy()
    shipped[0, 0] = (150, 40, 60)  # the fully active texel: shows the state as shipped
    fid = fc.measure_color(ref, base, [shipped], mask)
    want = float(_de(srgb.decode_texels(shipped[0, 0]), srgb.decode_texels(state[0, 0])))
    o = fid.poses[0].overall
    assert o.texels == 4 and o.weight == pytest.approx(2.25)
    assert o.mean == pytest.approx(want * 1.0 / 2.25, rel=1e-6)
    assert o.p99 == pytest.approx(want, rel=1e-6) and o.max == pytest.approx(want, rel=1e-6)
    assert fid.poses[0].regions["r"].mean == pytest.approx(o.mean, rel=1e-6)


def test_shipped_texels_are_decoded_before_they_are_filtered():
    """A black and a white texel magnified to four: linear light 0, 1/4, 3/4, 1 between
    them (an sRGB sampler), not the decode of interpolated sRGB values (1/4 -> 0.05)."""
    ref = fc.ColorReference((1, 4), "clamp01", ("r",), (0,), np.arange(4), [], np.zeros((1, 4, 3)))
    two = np.array([[[0, 0, 0], [255, 255, 255]]], np.uint8)
    b, s = fc.sample_colors(ref, two, [two])
    np.testing.assert_allclose(b[:, 0], [0.0, 0.25, 0.75, 1.0], atol=1e-7)
    np.testing.assert_allclose(s[0, :, 1], [0.0, 0.25, 0.75, 1.0], atol=1e-7)


def _bilinear(img, H, W):
    """Bilinear magnification between texel centres, clamped at the edges (written here, as
    a GPU samples: GL_LINEAR, CLAMP_TO_EDGE)."""
    h, w = img.shape[:2]
    y = np.clip((np.arange(H) + 0.5) * h / H - 0.5, 0, h - 1)
    x = np.clip((np.arange(W) + 0.5) * w / W - 0.5, 0, w - 1)
    y0, x0 = np.floor(y).astype(int), np.floor(x).astype(int)
    y1, x1 = np.minimum(y0 + 1, h - 1), np.minimum(x0 + 1, w - 1)
    fy, fx = (y - y0)[:, None, None], (x - x0)[None, :, None]
    top = img[y0][:, x0] * (1 - fx) + img[y0][:, x1] * fx
    bot = img[y1][:, x0] * (1 - fx) + img[y1][:, x1] * fx
    return top * (1 - fy) + bot * fy


def test_smaller_states_against_a_brute_force_recomputation():
    rng = np.random.default_rng(7)
    base = rng.integers(60, 230, (8, 8, 3)).astype(np.uint8)
    states = rng.integers(60, 230, (2, 8, 8, 3)).astype(np.uint8)
    masks = np.clip(rng.random((2, 8, 8)) * 1.6 - 0.3, 0, 1).astype(np.float32)
    weights = np.array([[0.9, 0.0], [0.3, 0.8]], np.float32)
    pose = Pose("p", weights)
    ref = fc.prepare_color(
        srgb.decode_texels(base), srgb.decode_texels(states), masks, [pose], ["a", "b"],
        "clamp01", (0, 1),
    )  # fmt: skip
    small = states[:, ::2, ::2]  # shipped at 4 x 4
    fid = fc.measure_color(ref, base, list(small), masks)
    # by hand: activations, the two blends, CIEDE2000 by colour-science, weighted mean
    act = np.clip(np.einsum("rk,rhw->khw", weights, masks), 0, 1)
    b = srgb.decode_texels(base).astype(np.float64)
    src = srgb.decode_texels(states).astype(np.float64)
    ship = np.stack([_bilinear(srgb.decode_texels(s).astype(np.float64), 8, 8) for s in small])
    c_src = np.clip(b + np.einsum("khw,khwc->hwc", act, src - b), 0, 1)
    c_ship = np.clip(b + np.einsum("khw,khwc->hwc", act, ship - b), 0, 1)
    w = act.sum(axis=0)
    on = w > 0
    err = _de(c_ship[on], c_src[on])
    o = fid.poses[0].overall
    assert o.texels == int(on.sum())
    assert o.mean == pytest.approx(float((err * w[on]).sum() / w[on].sum()), rel=1e-5)
    assert o.max == pytest.approx(float(err.max()), rel=1e-5)
    assert o.mean > 1.0  # random texels lose a lot at half size


# ------------------------------------------------------------------------------------------------
# the size choice


def _asset(state_texels: np.ndarray, base: np.ndarray, auto: bool = True) -> WrinkleAsset:
    H = base.shape[0]
    masks = np.zeros((1, H, H), np.float32)
    masks[0, H // 4 : 3 * H // 4, H // 4 : 3 * H // 4] = 1.0
    flat = np.zeros((H, H, 3), np.float32)
    flat[..., 2] = 1.0
    return WrinkleAsset(
        name="t",
        base=flat,
        states=flat[None],
        state_names=("flush",),
        masks=masks,
        regions=(Region("cheek"),),
        expressions={"smile": {"cheek": 1.0}},
        color=ColorMaps(base, state_texels[None], (0,)),
        provenance={"auto_resolution": ["color"] if auto else []},
    )


def test_a_smooth_flush_ships_small_and_a_detailed_one_at_full_size():
    H = 64
    yy, xx = np.mgrid[0:H, 0:H] / H
    base = _tex((200, 150, 130), (H, H))
    smooth_lin = srgb.decode_texels(base) * np.stack(
        [np.ones_like(xx), 0.6 + 0.2 * xx, 0.6 + 0.2 * yy], -1
    )
    smooth = srgb.encode_texels(smooth_lin)
    pose = [Pose("smile", np.ones((1, 1), np.float32))]
    a = _asset(smooth, base)
    shipped, choice = pc.choose_color_size(a, a, pose)
    assert choice.how == "auto" and choice.size[0] < H
    assert choice.fidelity.meets(choice.budget)
    assert shipped.color.states.shape[1:3] == choice.size
    checker = smooth.copy()
    checker[(np.add.outer(np.arange(H), np.arange(H)) % 2) == 1] = (120, 40, 40)
    b = _asset(checker, base)
    _, choice = pc.choose_color_size(b, b, pose)
    assert choice.size == (H, H) and choice.tried[1]["within"] is False
    # not asked: the size it was painted at
    c = _asset(smooth, base, auto=False)
    _, choice = pc.choose_color_size(c, c, pose)
    assert choice.how == "source" and choice.size == (H, H)
