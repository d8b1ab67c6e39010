"""Mask packing: every layout gives back every mask exactly (8 bit) / within 1/65535 (16 bit)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.io.images import quantize
from wrinklepipe.masks import CAPACITY, check_table, infer_side, pack, unpack
from wrinklepipe.presets import jimenez, metahuman


def _quantised_masks(rng: np.random.Generator, r: int, h: int, w: int, bits: int) -> np.ndarray:
    top = (1 << bits) - 1
    q = rng.integers(0, top + 1, size=(r, h, w))
    # Make sure the extremes and exact zeros appear.
    q.reshape(-1)[:: max(1, q.size // 7)] = 0
    q.reshape(-1)[1 :: max(1, q.size // 5)] = top
    return (q / top).astype(np.float32)


def _through_file_precision(textures: np.ndarray, bits: int) -> np.ndarray:
    """What an 8/16-bit texture file stores and gives back."""
    top = (1 << bits) - 1
    return (quantize(textures, bits).astype(np.float64) / top).astype(np.float32)


def _names_for(layout: str, r: int, rng: np.random.Generator) -> list[str]:
    if layout == "jimenez8":
        return list(jimenez.REGION_NAMES[:r])
    if layout == "metahuman":
        return [str(n) for n in rng.permutation(np.array(metahuman.REGIONS))[:r]]
    return [f"region{i:03d}" for i in range(r)]


def _check_roundtrip(masks: np.ndarray, names: list[str], layout: str, bits: int) -> None:
    p = pack(masks, names, layout)
    check_table(p.table, p.textures.shape)
    stored = _through_file_precision(p.textures, bits)
    got_names, got = unpack(stored, p.table)
    assert list(got_names) == names
    tol = 0.0 if bits == 8 else 1.0 / 65535
    np.testing.assert_allclose(got, masks, rtol=0, atol=tol)
    if bits == 8:
        # exact at 8 bits: identical integer codes
        np.testing.assert_array_equal(quantize(got, 8), quantize(masks, 8))
    else:
        np.testing.assert_array_equal(quantize(got, 16), quantize(masks, 16))
    if p.array is not None:
        _, got_arr = unpack(_through_file_precision(p.array.textures, bits), p.array.table)
        np.testing.assert_allclose(got_arr, masks, rtol=0, atol=tol)


@settings(max_examples=60, deadline=None)
@given(
    layout=st.sampled_from(["rgba", "array", "jimenez8", "metahuman"]),
    r=st.integers(1, 256),
    h=st.integers(1, 9),
    w=st.integers(1, 9),
    bits=st.sampled_from([8, 16]),
    seed=st.integers(0, 2**32 - 1),
)
def test_unpack_gives_back_every_mask(layout, r, h, w, bits, seed):
    r = min(r, CAPACITY[layout])
    rng = np.random.default_rng(seed)
    masks = _quantised_masks(rng, r, h, w, bits)
    _check_roundtrip(masks, _names_for(layout, r, rng), layout, bits)


@settings(max_examples=60, deadline=None)
@given(
    r=st.integers(1, 256),
    h=st.integers(1, 9),
    w=st.integers(1, 9),
    bits=st.sampled_from([8, 16]),
    seed=st.integers(0, 2**32 - 1),
)
def test_lr_split_gives_back_every_mask(r, h, w, bits, seed):
    """The blog's layout: pairs share a channel, a split channel says left or right."""
    rng = np.random.default_rng(seed)
    masks = _quantised_masks(rng, r, h, w, bits)
    # Region i: a pair member (x_l / x_r) or a centre region, chosen at random.
    names, sides = [], []
    i = 0
    while len(names) < r:
        if rng.random() < 0.6 and len(names) + 2 <= r:
            names += [f"area{i}_l", f"area{i}_r"]
            sides += ["left", "right"]
        elif rng.random() < 0.5:
            names.append(f"area{i}_{'l' if rng.random() < 0.5 else 'r'}")
            sides.append(infer_side(names[-1]))
        else:
            names.append(f"centre{i}")
            sides.append("center")
        i += 1
    # Each texel belongs to one side: zero the other side's masks there.
    left_texel = rng.random((h, w)) < 0.5
    s = np.array(sides)
    masks[s == "left"] *= left_texel
    masks[s == "right"] *= ~left_texel
    _check_roundtrip(masks, names, "lr-split", bits)
    p = pack(masks, names, "lr-split")
    # one shared channel per pair: fewer channels than regions when pairs exist
    slots = {(e["texture"], e["channel"]) for e in p.table}
    assert len(slots) == len({n[:-2] if sd != "center" else n for n, sd in zip(names, sides)})


def test_jimenez8_puts_zones_at_the_papers_channels():
    masks = np.arange(8, dtype=np.float32)[:, None, None] / 8 * np.ones((8, 2, 3), np.float32)
    p = pack(masks, list(jimenez.REGION_NAMES), "jimenez8")
    assert p.textures.shape == (2, 2, 3, 4)
    for z in jimenez.ZONES:
        i = jimenez.REGION_NAMES.index(z[1])
        assert p.textures[z[3], 0, 0, "rgba".index(z[4])] == pytest.approx(i / 8)
    assert {"region": "glabella", "texture": 1, "channel": "b"} in p.table


def test_metahuman_has_37_regions_in_10_textures_and_an_array():
    assert len(metahuman.REGIONS) == 37 and len(set(metahuman.REGIONS)) == 37
    assert all(n.startswith("head_wm") for n in metahuman.REGIONS)
    masks = np.random.default_rng(1).random((37, 4, 4)).astype(np.float32)
    p = pack(masks, list(metahuman.REGIONS), "metahuman")
    assert p.textures.shape == (10, 4, 4, 4)
    assert p.array is not None and p.array.textures.shape == (37, 4, 4)
    assert p.array.table[5] == {"region": metahuman.REGIONS[5], "layer": 5}


def test_lr_split_blog_layout_seven_areas_plus_split_fit_two_textures():
    areas = ["forehead", "brow", "glabella", "eyes", "nose", "mouth", "chin"]
    names = [f"{a}_{s}" for a in areas for s in ("l", "r")]
    h = w = 4
    masks = np.zeros((14, h, w), np.float32)
    masks[0::2, :, 2:] = 0.75  # left regions on the image's right half
    masks[1::2, :, :2] = 0.25
    p = pack(masks, names, "lr-split")
    assert p.textures.shape == (2, h, w, 4)
    split = p.textures[1, ..., 3]
    np.testing.assert_array_equal(split, np.array([[0, 0, 1, 1]] * 4, np.float32))
    e = next(e for e in p.table if e["region"] == "brow_r")
    assert e["side"] == "right" and e["split"] == {"texture": 1, "channel": "a"}
    _, back = unpack(p.textures, p.table)
    np.testing.assert_array_equal(back, masks)


def test_lr_split_refuses_texels_on_both_sides_unless_dominant():
    from wrinklepipe.errors import InputError

    masks = np.zeros((2, 2, 2), np.float32)
    masks[0, 0, 0] = 0.9
    masks[1, 0, 0] = 0.2
    with pytest.raises(InputError, match="both a left and a right"):
        pack(masks, ["x_l", "x_r"], "lr-split")
    p = pack(masks, ["x_l", "x_r"], "lr-split", lr_conflict="dominant")
    _, back = unpack(p.textures, p.table)
    assert back[0, 0, 0] == pytest.approx(0.9) and back[1, 0, 0] == 0.0
    assert "0.2000" in p.notes[0]


def test_infer_side():
    assert infer_side("nose_l") == "left"
    assert infer_side("nose_R") == "right"
    assert infer_side("brow.left") == "left"
    assert infer_side("glabella") == "center"
    assert infer_side("chin") == "center"


def test_bad_channel_table_is_named():
    from wrinklepipe.errors import InputError

    tex = np.zeros((1, 2, 2, 4), np.float32)
    with pytest.raises(InputError) as e:
        unpack(tex, [{"region": "a", "texture": 3, "channel": "r"}, {"region": "a", "layer": 0}])
    text = str(e.value)
    assert "texture 3 not in 0..0" in text and "duplicate region 'a'" in text
