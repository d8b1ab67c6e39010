"""Automatic choices by fidelity: the pyramid, the shipped-texel helpers and the searches."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from scipy.ndimage import map_coordinates

from wrinklepipe import codec, model
from wrinklepipe import fidelity as fd
from wrinklepipe.demo import demo_asset
from wrinklepipe.fidelity import pyramid, ship
from wrinklepipe.fidelity import search as fs
from wrinklepipe.masks import resample_masks
from wrinklepipe.metrics import Budget, angle_deg
from wrinklepipe.pipeline.package import encode_base, encode_state


def test_halving_is_a_lanczos3_filter_that_keeps_linear_ramps():
    rng = np.random.default_rng(0)
    x = rng.normal(0, 1, (32, 32, 2)).astype(np.float32)
    # an independent implementation: full correlation with the 12 taps, every second sample
    w = pyramid.WEIGHTS
    want = ndimage.correlate1d(x, w, axis=0, mode="nearest")[1::2]
    want = ndimage.correlate1d(want, w, axis=1, mode="nearest")[:, 1::2]
    assert np.abs(pyramid.halve(x) - want).max() < 1e-5
    # weights sum to 1 and are symmetric: a linear ramp comes back exactly inside the map
    assert w.sum() == pytest.approx(1.0, abs=1e-6) and np.allclose(w, w[::-1])
    ramp = np.broadcast_to(np.arange(64, dtype=np.float32)[None, :, None], (64, 64, 1))
    half = pyramid.halve(ramp)[:, 4:-4, 0]
    centres = 2 * np.arange(32, dtype=np.float32) + 0.5  # output texel i covers 2i and 2i+1
    assert np.allclose(half, centres[4:-4][None], atol=1e-4)
    lv = pyramid.levels(x, 4)
    assert sorted(lv) == [4, 8, 16, 32]


def test_halving_in_chunks_is_bit_for_bit_one_pass():
    # chunks of a few outputs (windows at both ends: edge texels repeated) give exactly the
    # values of one window over the whole axis, on either axis, and the columns by transpose
    rng = np.random.default_rng(3)
    for shape in [(2, 40, 24, 2), (1, 12, 12, 3), (6, 6, 2)]:
        x = rng.normal(0, 1, shape).astype(np.float32)
        for ax in (x.ndim - 3, x.ndim - 2):
            whole = pyramid.halve_axis(x, ax, chunk_bytes=1 << 30)
            for chunk in (1, 200, 4096):
                assert np.array_equal(pyramid.halve_axis(x, ax, chunk_bytes=chunk), whole)
        by_axis = pyramid.halve_axis(
            pyramid.halve_axis(x, x.ndim - 3, 1 << 30), x.ndim - 2, 1 << 30
        )
        assert np.array_equal(pyramid.halve(x), by_axis)


def test_shipped_texels_are_what_the_package_writes():
    rng = np.random.default_rng(1)
    base = model.pd_to_normal(rng.normal(0, 0.2, (16, 16, 2)).astype(np.float32))
    state = model.pd_to_normal(rng.normal(0, 0.5, (16, 16, 2)).astype(np.float32))
    d = model.normal_to_pd(state) - model.normal_to_pd(base)
    for scale in (0.5, 1.0):
        q, clipped = ship.pd_texels(d, scale)
        assert np.array_equal(q, encode_state(base, state, "pd", scale)[..., :2])
        assert clipped == int(np.any(np.abs(d) > scale, axis=-1).sum())
    assert np.array_equal(ship.base_texels(base), encode_base(base))


@pytest.mark.parametrize("fmt", ship.BLOCK_FORMATS)
def test_encoding_only_the_blocks_read_gives_the_whole_map_roundtrip_there(fmt):
    rng = np.random.default_rng(2)
    q = np.clip(rng.normal(128, 40, (30, 38, 2)), 0, 255).astype(np.uint8)  # not a multiple of 4
    full = ship.block_roundtrip(q, fmt)
    t = rng.choice(q.shape[0] * q.shape[1], 50, replace=False)
    part = ship.block_roundtrip_at(q, fmt, t)
    assert np.array_equal(part.reshape(-1, 2)[t], full.reshape(-1, 2)[t])


def test_mask_levels_are_box_halvings_stored_in_8_bits():
    rng = np.random.default_rng(3)
    m = rng.random((3, 64, 64), dtype=np.float32)
    lv = ship.mask_levels(m, 8)
    assert sorted(lv) == [8, 16, 32, 64] and lv[64] is not None
    for size in (32, 8):
        want = np.rint(resample_masks(m, size) * 255) / 255
        assert np.abs(lv[size] - want).max() <= 1 / 255 + 1e-7
        assert np.mean(lv[size] != want) < 0.001  # ties only


def scene(size=64, width=6.0, amp=0.3, seed=4):
    """One region, one state: sinusoidal creases of ``width`` texels in a band of columns."""
    rng = np.random.default_rng(seed)
    base = model.pd_to_normal(rng.normal(0, 0.02, (size, size, 2)).astype(np.float32))
    x = np.arange(size, dtype=np.float32)
    slopes = np.zeros((1, size, size, 2), np.float32)
    slopes[0, :, :, 0] = amp * np.sin(2 * np.pi * x / (2 * width))[None, :]
    masks = np.zeros((1, size, size), np.float32)
    masks[0, 8:56, 8:56] = 1.0
    poses = [fd.Pose("on", np.ones((1, 1), np.float32))]
    return fs.Source(base, slopes, masks, poses, ["r"])


def test_smooth_wrinkles_ship_small_and_fine_ones_ship_at_full_size():
    smooth = fs.search(scene(width=16.0), Budget(mean=0.5, p99=1.0))
    assert smooth.wrinkle_size < 64 and smooth.png.meets(Budget(mean=0.5, p99=1.0))
    fine = fs.search(scene(width=2.0), Budget(mean=0.5, p99=1.0))
    assert fine.wrinkle_size == 64
    # the choice is the smallest: half its size is over the budget
    tried = {t.value: t for t in smooth.tried if t.step == "wrinkle"}
    assert not tried[smooth.wrinkle_size // 2].ok


def test_the_scale_is_the_one_with_the_least_error_and_clipping_counts():
    src = scene(width=8.0, amp=0.9)
    choice = fs.search(src, Budget(mean=1.0, p99=2.0), fixed=fs.Fixed(wrinkle=64, mask=64))
    scales = [t for t in choice.tried if t.step == "pd_scale (full size)"]
    best = min(scales, key=lambda t: (t.p99, t.mean))
    assert choice.pd_scale == best.value
    # clipping at a scale below the largest slope costs more than the coarser steps save
    assert choice.pd_scale >= 0.9 * 0.75
    assert choice.clipped_texels == fs.clipped_texels(src.slopes, choice.pd_scale)


def test_a_fixed_choice_is_measured_not_searched():
    choice = fs.search(scene(width=2.0), Budget(p99=1.0), fixed=fs.Fixed(wrinkle=16))
    assert choice.wrinkle_size == 16 and not choice.png.meets(Budget(p99=1.0))
    assert not [t for t in choice.tried if t.step == "wrinkle"]


def test_the_measure_equals_the_plain_formula_on_the_demo():
    """The measure's planar, per-pose path against the model's whole-map blend: every shipped
    map magnified by scipy (bilinear between texel centres, edges clamped), decoded as the
    shader decodes sampled values, both blends on the whole grid, the angle in float64,
    weighted stats by sorting; active texels: the source's or the shipped masks'."""
    a = demo_asset(128)
    poses = fd.expression_poses(a.region_names, a.region_state_matrix(), a.expressions)
    slopes = model.normal_to_pd(a.states) - model.normal_to_pd(a.base)[None]
    ref = fd.prepare(a.base, slopes, a.masks, poses, a.region_names)
    base_q = ship.base_texels(a.base)
    states_q = np.stack([ship.pd_texels(x, 0.5)[0] for x in pyramid.levels(slopes, 32)[32]])
    masks_q = ship.mask_values(a.masks, 32)
    got = fd.evaluate(
        ref,
        fd.merge(
            fd.sample(ref, base=base_q, base_reader=ship.base_reader()),
            fd.sample(ref, masks=masks_q),
            fd.sample(ref, states=states_q, states_reader=ship.pd_reader(0.5, quantise=False)),
        ),
        regions=False,
    )

    def magnify(img):  # [h, w, C] -> [128, 128, C], float64
        c = (np.arange(128) + 0.5) * (img.shape[0] / 128) - 0.5
        yy, xx = np.meshgrid(c, c, indexing="ij")
        v = np.asarray(img, np.float64)
        return np.stack(
            [
                map_coordinates(v[..., k], [yy, xx], order=1, mode="nearest")
                for k in range(v.shape[-1])
            ],
            axis=-1,
        )

    base = codec.decode_sampled(codec.BASE, magnify(base_q) / 255.0, "rgb", bits=8)
    base = model.normalize(np.asarray(base, np.float32))
    states = np.stack(
        [
            codec.decode_sampled(
                "pd", magnify(q) / 255.0, "rg", bits=8, param=0.5, version=ship.MAPPING_VERSION
            )
            for q in states_q
        ]
    ).astype(np.float32)
    masks = np.moveaxis(magnify(np.moveaxis(masks_q, 0, -1)), -1, 0).astype(np.float32)
    src_base = model.normalize(a.base)
    for p, g in zip(poses, got.poses):
        a_src = model.activations(a.masks, p.weights, a.policy)
        a_got = model.activations(masks, p.weights, a.policy)
        w = np.maximum(np.abs(a_src).sum(0), np.abs(a_got).sum(0))
        on = w > 0
        err = angle_deg(
            model.combine(base, states, a_got)[on], model.combine(src_base, slopes, a_src)[on]
        )
        order = np.argsort(err)
        cw = np.cumsum(w[on][order])
        p99 = err[order][np.searchsorted(cw, 0.99 * cw[-1])]
        mean = float((err * w[on]).sum() / w[on].sum())
        assert g.overall.texels == int(on.sum()), p.name
        assert g.overall.mean == pytest.approx(mean, abs=1e-4), p.name
        assert g.overall.p99 == pytest.approx(p99, abs=1e-3), p.name
        assert g.overall.max == pytest.approx(err.max(), abs=1e-3), p.name


@pytest.mark.parametrize("fmt", ship.BLOCK_FORMATS)
def test_one_pass_for_several_maps_gives_each_maps_own_encoding(fmt, monkeypatch):
    """Several maps' blocks in one encoder pass: each map's texels are its own whole-map round
    trip, and (inside a conversion's memo) encoding a map whole afterwards is a hit with the
    bytes the encoder gives that map alone."""
    from wrinklepipe import reuse
    from wrinklepipe.normals import compress as nc

    monkeypatch.setattr(reuse, "MIN_INPUT_BYTES", 0)
    rng = np.random.default_rng(5)
    maps = [np.clip(rng.normal(128, 40, (s, s, 2)), 0, 255).astype(np.uint8) for s in (16, 12)]
    alone = [nc.encode_bc(nc.pack_rgba(nc.pad_to_blocks(q)[0], fmt), fmt) for q in maps]
    with reuse.reuse() as memo:
        got = ship.block_roundtrip_many(maps, fmt, [None, None])
        again = [nc.encode_bc(nc.pack_rgba(nc.pad_to_blocks(q)[0], fmt), fmt) for q in maps]
    assert memo.hits.get("wrinklepipe.normals.compress.encode_bc") == 2
    assert again == alone
    for q, g in zip(maps, got):
        assert np.array_equal(g, ship.block_roundtrip(q, fmt))


def test_compressed_copies_are_judged_at_the_sizes_the_confirmation_raised_to():
    """The block formats are screened beside the PNG confirmation (for the screened sizes);
    when the confirmation raises a size, the compressed copies are judged at the raised one:
    their fidelity is that of the chosen formats' whole-map round trips with the masks
    shipped, and differs from what the screened (smaller) masks give."""
    src = scene(width=8.0)
    c = fs.search(src, Budget(mean=0.3, p99=1.0), options=fs.SearchOptions(screen_texels=64))
    steps = [t.step for t in c.tried]
    assert (
        steps.index("confirmed (png)") < steps.index("raised (png)") < steps.index("state format")
    )
    assert (c.wrinkle_size, c.mask_size) == (64, 64) and c.compressed is not None
    ref = fd.prepare(src.base, src.slopes, src.masks, src.poses, src.region_names)
    states = np.stack(
        [ship.block_roundtrip(ship.pd_texels(x, c.pd_scale)[0], c.state_format) for x in c.states]
    )
    base = ship.base_texels(src.base)
    base_reader = ship.base_reader("rgb")
    if c.base_format != "png":
        base, base_reader = ship.block_roundtrip(base, c.base_format), ship.base_reader("rg")

    def measured(mask_size: int) -> tuple[float, float]:
        s = fd.sample(
            ref,
            base=base,
            base_reader=base_reader,
            states=states,
            states_reader=ship.pd_reader(c.pd_scale, quantise=False),
            masks=ship.mask_values(src.masks, mask_size),
        )
        return fd.evaluate(ref, s, regions=False).score()

    assert measured(64) == pytest.approx(c.compressed.score(), abs=1e-6)
    assert measured(32) != pytest.approx(c.compressed.score(), abs=1e-3)


def test_what_the_search_made_goes_when_it_returns(monkeypatch):
    """The search's own arrays (the slopes' pyramid, the mask levels, the judge's samples) are
    let go when it returns, not whenever the garbage collector next breaks the reference
    cycles its candidate factories make: of the smaller levels only the one shipped is left."""
    import gc
    import weakref

    made = []
    original = pyramid.levels

    def levels(img, min_size=1):
        out = original(img, min_size)
        made.extend(weakref.ref(v) for k, v in out.items() if k < img.shape[1])
        return out

    monkeypatch.setattr(pyramid, "levels", levels)
    gc.disable()
    try:
        choice = fs.search(scene(width=16.0), Budget(mean=0.5, p99=1.0))
        alive = [r() for r in made if r() is not None]
    finally:
        gc.enable()
    assert len(made) >= 2 and choice.wrinkle_size < 64
    assert len(alive) == 1 and alive[0] is choice.states
