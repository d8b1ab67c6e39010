"""Film scale: source masks held in their files' integers for the run (wrinklepipe.masks.stack),
seen as the float32 the reader gives, bit for bit (docs/scale.md)."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from wrinklepipe.io.images import read_image, write_image
from wrinklepipe.masks.read import read_masks
from wrinklepipe.masks.stack import CroppedMasks, MaskStack, quantized, to_float


@pytest.mark.parametrize("bits", [8, 16])
def test_integers_to_float_are_what_the_reader_gives(tmp_path, bits):
    """Every 8-bit (and 16-bit) value converts to the float32 OpenImageIO reads the file as."""
    top = (1 << bits) - 1
    v = np.arange(top + 1, dtype=np.uint8 if bits == 8 else np.uint16).reshape(-1, 256)
    path = write_image(tmp_path / "ramp.png", v.astype(np.float64) / top, bits)
    read, info = read_image(path)
    assert info.format == ("uint8" if bits == 8 else "uint16")
    assert np.array_equal(to_float(v).view(np.uint32), read[..., 0].view(np.uint32))
    assert np.array_equal(quantized(read[..., 0], bits), v)
    assert to_float(v)[0, 0] == 0.0 and to_float(v).reshape(-1)[-1] == 1.0


def _mask_files(tmp_path, bits=8, n=3, shape=(9, 11)):
    rng = np.random.default_rng(bits)
    top = (1 << bits) - 1
    ms = rng.integers(0, top + 1, (n, *shape))
    ms[0, :3] = 0
    ms[1, 4] = top
    return ms, [write_image(tmp_path / f"m{i}.png", m / top, bits) for i, m in enumerate(ms)]


@pytest.mark.parametrize("bits", [8, 16])
def test_masks_held_as_integers_are_the_float_masks(tmp_path, bits):
    """``read_masks(integers=True)`` holds the files' integers (a quarter or half of float32's
    bytes) and gives the float stack's values bit for bit: whole, per mask, by fancy index, and
    through what the stages do with masks (clip, compare, reduce, arithmetic, moveaxis)."""
    ms, paths = _mask_files(tmp_path, bits)
    want = read_masks(paths).masks
    got = read_masks(paths, integers=True).masks
    assert isinstance(got, MaskStack) and isinstance(want, np.ndarray)
    assert got.q.dtype == (np.uint8 if bits == 8 else np.uint16)
    assert np.array_equal(got.q, ms)
    assert got.q.nbytes * (4 if bits == 8 else 2) == want.nbytes
    assert got.shape == want.shape and got.dtype == np.float32 and len(got) == 3
    bits_of = np.uint32
    assert np.array_equal(np.asarray(got).view(bits_of), want.view(bits_of))
    assert np.array_equal(np.asarray(got, np.float32).view(bits_of), want.view(bits_of))
    for i in range(3):
        assert np.array_equal(got[i].view(bits_of), want[i].view(bits_of))
    assert np.array_equal(got[[2, 0]], want[[2, 0]])
    assert np.array_equal(got[:, 2:5], want[:, 2:5])
    assert np.array_equal(np.clip(got, 0.0, 1.0), np.clip(want, 0.0, 1.0))
    assert np.array_equal(got > 0, want > 0)
    assert np.array_equal(got * 0.5 + 1, want * 0.5 + 1)
    assert np.array_equal(got.max(axis=0), want.max(axis=0))
    assert np.array_equal(np.moveaxis(got, 0, -1), np.moveaxis(want, 0, -1))
    assert np.array_equal(np.stack(list(got)), want)
    back = pickle.loads(pickle.dumps(got))
    assert isinstance(back, MaskStack) and np.array_equal(back.q, got.q)
    deep = copy.deepcopy(got)
    assert deep.q is not got.q and np.array_equal(deep.q, got.q)


def test_masks_not_their_integers_stay_float(tmp_path):
    """Inverted masks (1 - v is not an integer's float) and float files stay float32, with the
    values read without ``integers``."""
    _, paths = _mask_files(tmp_path)
    inv = read_masks(paths, invert=True, integers=True).masks
    assert isinstance(inv, np.ndarray) and inv.dtype == np.float32
    assert np.array_equal(inv, read_masks(paths, invert=True).masks)
    exr = write_image(tmp_path / "f.exr", np.full((9, 11), 0.3, np.float32), 32)
    mixed = read_masks([*paths, exr], integers=True).masks
    assert isinstance(mixed, np.ndarray) and mixed.dtype == np.float32
    assert np.array_equal(mixed, read_masks([*paths, exr]).masks)
    assert np.allclose(mixed[3], 0.3, atol=1e-7)


def _stack(bits=8, r=3, shape=(12, 10), seed=1):
    rng = np.random.default_rng(seed)
    q = rng.integers(0, (1 << bits), (r, *shape)).astype(np.uint8 if bits == 8 else np.uint16)
    q[:, :, :3] = 0  # texels no region touches
    return MaskStack(q)


def test_reference_from_integer_masks_is_the_float_one():
    """The searches' and validator's full-resolution reference made from masks held as integers
    (a mask at a time) is the one made from the float32 stack, array for array; the memo keys
    the stack by its integers."""
    from wrinklepipe import model, reuse
    from wrinklepipe.fidelity import reference as fre

    rng = np.random.default_rng(2)
    base = model.normalize(rng.normal(0, 0.2, (12, 10, 3)) + [0, 0, 1]).astype(np.float32)
    states = rng.normal(0, 0.3, (2, 12, 10, 2)).astype(np.float32)
    stack = _stack()
    poses = [
        fre.Pose("a", np.array([[1, 0], [0, 0.5], [0, 0]], np.float32)),
        fre.Pose("b", np.array([[0, 0], [0, 0], [0.7, 0.2]], np.float32)),
    ]
    names = ["r0", "r1", "r2"]
    want = fre.prepare(base, states, np.asarray(stack), poses, names)
    got = fre.prepare(base, states, stack, poses, names)
    assert np.array_equal(got.union, want.union) and got.union.size < 120
    for g, w in zip(got.poses, want.poses):
        for f in ("sel", "act", "normal", "weight", "masks", "active"):
            assert np.array_equal(getattr(g, f), getattr(w, f)), f
    # union texel 0 of the masks: the integer over 255 (the reader's float)
    i = int(got.union[0])
    assert got.poses[0].masks[0, 0] == np.float32(stack.q[0].reshape(-1)[i]) * np.float32(1 / 255)
    key_a = reuse._key("f", (stack,), {})[0]
    assert key_a == reuse._key("f", (MaskStack(stack.q.copy()),), {})[0]
    assert key_a != reuse._key("f", (np.asarray(stack),), {})[0]


def test_mask_levels_and_plane_sampling_of_integer_masks():
    """The search's mask levels (2 x 2 box halvings) and the validator's plane-by-plane
    sampling take a MaskStack a band / a plane at a time, with the float stack's values."""
    from wrinklepipe.fidelity import ship
    from wrinklepipe.validate import textures as tx

    stack = _stack(16, shape=(12, 12))
    want, got = ship.mask_levels(np.asarray(stack)), ship.mask_levels(stack)
    assert sorted(got) == sorted(want) == [3, 6, 12]
    assert isinstance(dict.__getitem__(got, 12), MaskStack)
    for size in (3, 6, 12):
        assert np.array_equal(np.asarray(got[size]), np.asarray(want[size]))
    # level 6, texel (1, 2) of mask 0: the mean of its 2 x 2 source texels, rounded to 8 bits
    box = np.asarray(stack)[0, 2:4, 4:6].astype(np.float64).mean()
    assert got[6][0, 1, 2] == np.float32(np.rint(box * 255) / 255)
    uv = np.random.default_rng(3).random((50, 2)).astype(np.float32)
    assert np.array_equal(tx.bilinear_planes(stack, uv), tx.bilinear_planes(np.asarray(stack), uv))


@pytest.mark.parametrize("size", [None, 12, 6, 3, 5])
def test_shipped_mask_values_of_integer_masks_a_mask_at_a_time(size):
    """The masks as shipped (the chosen size: as given, a halving, a resample) from a MaskStack
    are those of the float32 stack, bit for bit, and each texel the 8-bit rounding."""
    from wrinklepipe.fidelity import ship

    stack = _stack(16, shape=(12, 12))
    got, want = ship.mask_values(stack, size), ship.mask_values(np.asarray(stack), size)
    assert got.dtype == want.dtype == np.float32
    assert got.shape == (len(stack), size or 12, size or 12)
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    if size is None:  # as given: every texel the nearest of 256 levels
        f = np.asarray(stack, np.float64)
        assert np.array_equal(got, (np.rint(f * 255) / 255).astype(np.float32))


@pytest.mark.parametrize("grid", [(12, 10), (30, 25)])
def test_masks_sampled_at_texels_a_mask_at_a_time(grid):
    """The measure's samples of masks held as integers (a mask at a time, on their own grid
    and magnified to a finer one) are those of the float32 stack, bit for bit."""
    from wrinklepipe.fidelity.sampling import sample_masks_at

    stack = _stack(seed=4)
    flat = np.random.default_rng(5).choice(grid[0] * grid[1], 40, replace=False)
    got = sample_masks_at(stack, grid, flat)
    want = sample_masks_at(np.asarray(stack), grid, flat)
    assert got.shape == (3, 40) and np.array_equal(got.view(np.uint32), want.view(np.uint32))
    if grid == (12, 10):  # the same grid: a plain gather of the reader's floats
        assert np.array_equal(got[1], np.asarray(stack)[1].reshape(-1)[flat])


def test_mask_levels_held_in_8_bits_read_as_the_float_levels():
    """The search's mask levels (2 x 2 box halvings rounded to 8 bits) are held as uint8 and
    read as the float32 the rounding gives (k / 255, not the reader's k * (1 / 255)), bit for
    bit; masks whose levels are not 8-bit values (NaN) stay float32."""
    from wrinklepipe.fidelity import ship

    stack = _stack(8, shape=(12, 12))
    lv = ship.mask_levels(stack, 3)
    f = np.asarray(stack, np.float64)
    for size, level in ((6, lv[6]), (3, lv[3])):
        assert isinstance(level, ship.U8Masks) and level.q.dtype == np.uint8
        k = 12 // size
        box = f.reshape(3, size, k, size, k).mean(axis=(2, 4)).astype(np.float32)
        if size == 3:  # a box of boxes, each rounded to float32 once (as the halving does)
            half = f.reshape(3, 6, 2, 6, 2).mean(axis=(2, 4)).astype(np.float32)
            box = half.astype(np.float64).reshape(3, 3, 2, 3, 2).mean(axis=(2, 4))
            box = box.astype(np.float32)
        want = (np.rint(np.clip(box, 0.0, 1.0) * 255.0) / 255.0).astype(np.float32)
        assert np.array_equal(np.asarray(level).view(np.uint32), want.view(np.uint32))
        assert np.array_equal(level[1].view(np.uint32), want[1].view(np.uint32))
    assert np.asarray(ship.mask_values(stack, 6)).dtype == np.float32
    nan = np.asarray(stack).copy()
    nan[0, 0, 0] = np.nan
    held = ship.mask_levels(nan, 6)[6]
    assert isinstance(held, np.ndarray) and np.isnan(held[0, 0, 0])


@pytest.mark.parametrize("bits", [8, 16])
def test_masks_mostly_zero_are_held_in_their_boxes(tmp_path, bits):
    """Region masks zero over most of the face are held as the integers inside each mask's box
    of non-zero texels (an all-zero mask holds nothing), and read back as the float stack bit
    for bit, however they are read."""
    top = (1 << bits) - 1
    rng = np.random.default_rng(11)
    ms = np.zeros((4, 48, 40), np.uint8 if bits == 8 else np.uint16)
    ms[0, 3:9, 30:39] = rng.integers(1, top + 1, (6, 9))
    ms[1, 20:47, 0:5] = rng.integers(0, top + 1, (27, 5))
    ms[3, 0, 0] = top  # one texel in a corner
    paths = [write_image(tmp_path / f"c{i}.png", m / top, bits) for i, m in enumerate(ms)]
    want = read_masks(paths).masks
    got = read_masks(paths, integers=True).masks
    assert isinstance(got, CroppedMasks)
    assert got.held_bytes == (6 * 9 + 27 * 5 + 0 + 1) * ms.itemsize  # the boxes only
    assert got.shape == want.shape and got.dtype == np.float32 and len(got) == 4
    b = np.uint32
    assert np.array_equal(np.asarray(got).view(b), want.view(b))
    for i in range(4):
        assert np.array_equal(got[i].view(b), want[i].view(b))
        assert np.array_equal(got[i, 5:25].view(b), want[i, 5:25].view(b))
        assert np.array_equal(got[i, 21].view(b), want[i, 21].view(b))
        assert np.array_equal(got[i, 2:40, 31:35].view(b), want[i, 2:40, 31:35].view(b))
    assert np.array_equal(got[-1].view(b), want[-1].view(b))
    assert np.array_equal(got[[2, 0]], want[[2, 0]])
    assert np.array_equal(got[:, 2:5], want[:, 2:5])
    assert np.array_equal(got.max(axis=0), want.max(axis=0))
    assert np.array_equal(got > 0, want > 0)
    back = pickle.loads(pickle.dumps(got))
    assert np.array_equal(np.asarray(back), want) and back.held_bytes == got.held_bytes
    assert np.array_equal(np.asarray(copy.deepcopy(got)), want)
    dense = np.ones((2, 8, 8), np.uint8)  # nothing to save: a plain stack
    assert not CroppedMasks.saves(dense)
