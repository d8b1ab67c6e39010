"""Film scale: the validator's memory (issue 42). Each bounded step gives what the whole-map
computation gives, bit for bit (docs/scale.md, "Memory")."""

from __future__ import annotations

from functools import cached_property

import numpy as np
import pytest

from wrinklepipe import fidelity as fd
from wrinklepipe import model, workset
from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.fidelity.metric import TexelErrors
from wrinklepipe.masks import resample_masks
from wrinklepipe.masks.stack import MaskStack
from wrinklepipe.metrics import angle_deg
from wrinklepipe.normals import compress as cmp
from wrinklepipe.normals import resample
from wrinklepipe.normals.dds import mip_dims
from wrinklepipe.sources import copies
from wrinklepipe.sources.validation import LoadOptions, load_input
from wrinklepipe.validate import fidelity_pictures as fp
from wrinklepipe.validate import rules_fidelity, rules_maps
from wrinklepipe.validate import textures as tx
from wrinklepipe.validate.context import Context, ValidateOptions, resize_masks, resize_normals
from wrinklepipe.validate.rules_fidelity import _outside
from wrinklepipe.validate.run import CHECKS

U32 = np.uint32


def _case(seed: int, H: int = 48, hm: int = 12):
    """A random source (two PD states, three regions, masks at ``hm``²) and shipped maps whose
    masks differ from the source's (so poses leak onto texels the source leaves alone)."""
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(H, H, 3)).astype(np.float32)
    base[..., 2] = np.abs(base[..., 2]) + 2.0
    base /= np.linalg.norm(base, axis=-1, keepdims=True)
    states = (0.2 * rng.normal(size=(2, H, H, 2))).astype(np.float32)
    masks = rng.random((3, hm, hm)).astype(np.float32)
    masks *= rng.random((3, hm, hm)) < 0.3
    poses = [
        fd.Pose("a", np.array([[1, 0], [0, 0], [0, 1]], np.float32)),
        fd.Pose("b", np.array([[0, 0], [1, 1], [0, 0]], np.float32)),
    ]
    ref = fd.prepare(base, states, masks, poses, ["r0", "r1", "r2"])
    shipped_masks = np.clip(masks + (rng.random(masks.shape) < 0.2) * 0.5, 0, 1)
    shipped_states = states + (0.01 * rng.normal(size=states.shape)).astype(np.float32)
    s = fd.sample(ref, base, shipped_states, shipped_masks.astype(np.float32))
    return ref, s


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_error_maps_as_texels_are_the_whole_maps(seed):
    """The judged texels' errors (``TexelErrors``) against the map the measure wrote on the
    whole grid (zeros, the pose's active texels' errors, then its leaks'): every bit, whole and
    at any texel, and the same statistics."""
    ref, s = _case(seed)
    fid = fd.evaluate(ref, s, error_maps=True, samples=True)
    assert fid.to_json() == fd.evaluate(ref, s).to_json()
    H, W = ref.shape
    leaked = 0
    for pi, pr in enumerate(ref.poses):
        e, _ = fid.samples[pr.pose.name]
        n = pr.sel.size
        whole = np.zeros(H * W, np.float32)  # the whole-map computation
        whole[ref.union[pr.sel]] = e[:n]
        written = ref.union[pr.sel]
        if s.leaks[pi] is not None:
            whole[s.leaks[pi][0]] = e[n:]
            written = np.union1d(written, s.leaks[pi][0])
            leaked += e.size - n
        got = fid.errors[pr.pose.name]
        assert isinstance(got, TexelErrors) and got.shape == (H, W)
        assert np.array_equal(got.dense().view(U32), whole.reshape(H, W).view(U32))
        flat = np.random.default_rng(seed).integers(0, H * W, 500)
        assert np.array_equal(got.at(flat).view(U32), whole[flat].view(U32))
        assert np.array_equal(got.flat, written)  # sorted, unique: the texels judged
    assert leaked > 0  # the case has leaks


def test_texel_errors_later_writes_win():
    t = TexelErrors.of((2, 3), [(np.array([4, 1]), np.array([1.0, 2.0])), (np.array([1]), [5.0])])
    assert t.flat.tolist() == [1, 4] and t.values.tolist() == [5.0, 1.0]
    assert t.dense().tolist() == [[0.0, 5.0, 0.0], [0.0, 1.0, 0.0]]
    assert t.at(np.array([0, 1, 4, 5])).tolist() == [0.0, 5.0, 1.0, 0.0]
    empty = TexelErrors.of((2, 2), [(np.zeros(0, np.int64), np.zeros(0, np.float32))])
    assert empty.at(np.arange(4)).tolist() == [0.0] * 4


def _mask_cases(rng):
    q = rng.integers(0, 256, (3, 24, 24)).astype(np.uint8)
    q[q < 180] = 0
    f = rng.random((4, 24, 24)).astype(np.float32)
    f[f < 0.7] = 0
    f[0, :3] = 1e-30  # tiny values: a float file's
    neg = f.copy()
    neg[1, 5, 5] = -0.25
    nan = f.copy()
    nan[2, 7, 1] = np.nan
    return {"stack": MaskStack(q), "float": f, "negative": neg, "nan": nan}


@pytest.mark.parametrize("size", [(24, 24), (6, 6), (8, 12), (10, 10), (40, 33)])
def test_masks_resized_a_mask_at_a_time_are_the_whole_resample(size):
    """The validator's source masks at the shipped size, a mask at a time: the whole stack's
    resample (box down, bilinear up, the same size) bit for bit."""
    for name, m in _mask_cases(np.random.default_rng(7)).items():
        whole = resample_masks(np.asarray(m, np.float32), size)
        got = resize_masks(m, *size)
        assert got.dtype == np.float32 and got.shape == whole.shape, name
        assert np.array_equal(got.view(U32), whole.view(U32)), name


def _outside_whole(masks, shape, fp):
    """The rule's texels outside every mask as computed before, on every mask at once."""
    H, W = shape
    m = np.asarray(masks, np.float32)
    if m.shape[1:] == (H, W):
        inside = (m > 0).any(axis=0)
    elif m.size and m.min() >= 0:
        some = (m > 0).any(axis=0).astype(np.float32)
        inside = fd.sample_masks_at(some[None], (H, W), np.arange(H * W)).reshape(H, W) > 0
    else:
        inside = (fd.sample_masks_at(m, (H, W), np.arange(H * W)) > 0).any(axis=0)
        inside = inside.reshape(H, W)
    out = ~inside
    return out & fp if fp is not None else out


@pytest.mark.parametrize("shape", [(24, 24), (48, 48), (37, 37), (12, 12)])
def test_outside_a_mask_at_a_time_is_the_whole_computation(shape):
    rng = np.random.default_rng(3)
    fp = rng.random(shape) < 0.8
    cases = _mask_cases(rng)
    cases["none"] = np.zeros((0, 24, 24), np.float32)
    for name, m in cases.items():
        for f in (None, fp):
            want = _outside_whole(m, shape, f)
            assert np.array_equal(_outside(m, shape, f), want), name


def test_bilinear_of_texels_read_per_tap_is_bilinear_of_the_values():
    """The render pass samples a texture's values from its integer texels, each tap's texels
    turned into values: ``bilinear(values, uv)`` bit for bit, without the values of the map."""
    rng = np.random.default_rng(5)
    for dtype, shape in ((np.uint8, (37, 21, 4)), (np.uint16, (16, 16, 2)), (np.uint8, (8, 8, 3))):
        q = rng.integers(0, np.iinfo(dtype).max + 1, shape).astype(dtype)
        uv = rng.random((300, 2)).astype(np.float32) * 1.2 - 0.1  # clamped at the edges too
        want = tx.bilinear(tx.unorm_values(q), uv)
        got = tx.bilinear(q, uv, tx.unorm_values)
        assert got.dtype == np.float32 and np.array_equal(got.view(U32), want.view(U32))


def test_texel_counts_in_bands_are_the_whole_maps(monkeypatch):
    """The unit-length and z checks of a normal map band by band (bands of 3 rows): the counts
    and first texels of the whole map's arrays."""
    rng = np.random.default_rng(9)
    v = rng.random((23, 17, 4)).astype(np.float32)
    v[4, 5] = np.nan
    v[10:12, :, 2] = 0.1  # z < 0
    monkeypatch.setattr(rules_maps, "band_rows", lambda w, b: 3)
    n = tx.raw_normals(v, "rgb").reshape(-1, 3)  # the whole map at once, as before
    nan = ~np.isfinite(n).all(axis=1)
    bad = nan | (np.abs(np.linalg.norm(np.nan_to_num(n), axis=1) - 1.0) > 0.05)
    neg = np.nan_to_num(n[:, 2]) < 0
    want = (
        int(bad.sum()),
        int(nan.sum()),
        int(neg.sum()),
        int(np.flatnonzero(bad)[0]),
        int(np.flatnonzero(neg)[0]),
    )
    assert rules_maps._texel_counts(v, 0.05) == want
    assert want[2] >= 2 * 17 and want[1] == 1
    q = (rng.random((23, 17, 4)) * 255).astype(np.uint8)
    whole = tx.raw_normals(tx.unorm_values(q), "rgb").reshape(-1, 3)
    lengths = np.linalg.norm(whole, axis=1)
    got = rules_maps._texel_counts(q, 0.05, tx.unorm_values)
    assert got[0] == int((np.abs(lengths - 1.0) > 0.05).sum()) and got[1] == 0
    assert got[2] == int((whole[:, 2] < 0).sum())


@pytest.mark.parametrize("encoding", ["pd", "diff", "full", "composite"])
def test_source_sampled_from_the_taps_is_the_encoded_maps_sampled(encoding):
    """The render pass's source: the states encoded at the texels the taps read, then sampled,
    is the whole encoded maps sampled (what the validator held before) bit for bit."""
    rng = np.random.default_rng(11)
    H = W = 24
    base = rng.normal(size=(H, W, 3)).astype(np.float32)
    base[..., 2] = np.abs(base[..., 2]) + 1.5
    base /= np.linalg.norm(base, axis=-1, keepdims=True)
    states = base[None] + (0.3 * rng.normal(size=(2, H, W, 3))).astype(np.float32)
    states /= np.linalg.norm(states, axis=-1, keepdims=True)

    class Asset:
        pass

    a = Asset()
    a.base, a.states, a.encoding = base, states.astype(np.float32), encoding

    class Ctx:
        asset = a

    uv = rng.random((400, 2)).astype(np.float32)
    b, enc = rules_fidelity.source_encoded(Ctx())
    want_base = tx.bilinear(b, uv)
    want = np.stack([tx.bilinear(s, uv) for s in enc])
    got_base, got = rules_fidelity.source_sampled(Ctx(), uv)
    assert np.array_equal(got_base.view(U32), want_base.view(U32))
    assert got.shape == want.shape and got.flags.c_contiguous
    assert np.array_equal(got.view(U32), want.view(U32))


def test_shipped_base_decoded_in_bands_is_the_whole_decode(monkeypatch):
    """The shipped base's normals decoded band by band (bands of 5 rows) into one C-ordered
    array: the codec's decode of the whole map bit for bit."""
    rng = np.random.default_rng(13)
    q = rng.integers(0, 256, (29, 19, 4)).astype(np.uint8)
    whole = tx.decode_texels(q, "base", "rgb", 1.0)
    monkeypatch.setattr(workset, "band_rows", lambda w, b: 5)
    got = workset.map_rows(lambda b: tx.decode_texels(b, "base", "rgb", 1.0), q, 64)
    assert got.flags.c_contiguous and np.array_equal(got.view(U32), whole.view(U32))


def test_the_contexts_shipped_base_is_the_whole_decode(tmp_path, monkeypatch):
    """A demo's shipped base as the validator's context decodes it (bands of 7 rows) against
    the codec's decode of all its texels at once."""
    manifest = write_demo_source(tmp_path / "demo", size=64)
    ctx = Context(load_input(manifest))
    bt = ctx.base_tex
    whole = tx.decode_texels(ctx.texels(bt), "base", tx.xy_layout(bt), 1.0, flip_y=ctx.flips(bt))
    monkeypatch.setattr(workset, "band_rows", lambda w, b: 7)
    got = ctx.shipped_base
    assert got.flags.c_contiguous and np.array_equal(got.view(U32), whole.view(U32))


def _convention_score_whole(slopes):
    """The curl score as computed before: a float64 copy of both slope channels at once."""
    s = np.asarray(slopes, np.float64)
    a = np.gradient(s[..., 0], axis=0)
    b = np.gradient(s[..., 1], axis=1)
    den = np.sqrt(np.sum(a * a) * np.sum(b * b))
    if not np.isfinite(den) or den < 1e-12:
        return 0.0
    return float(-np.sum(a * b) / den)


@pytest.mark.parametrize("band", [1, 2, 5, 10000])
@pytest.mark.parametrize("shape", [(64, 64), (37, 129), (300, 300), (3, 5)])
def test_convention_score_a_channel_at_a_time_is_the_whole_computation(shape, band, monkeypatch):
    """The green-convention score of the shipped base from its normals a slope channel and a
    band of rows at a time (and of slopes): the whole computation's float bit for bit."""
    monkeypatch.setattr(rules_maps, "band_rows", lambda w, b: band)
    rng = np.random.default_rng(17)
    h = np.cumsum(np.cumsum(rng.normal(size=shape), axis=0), axis=1)  # a height field
    n = np.stack([-np.gradient(h, axis=1), np.gradient(h, axis=0), np.full(shape, 4.0)], -1)
    n = (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)
    want = _convention_score_whole(model.normal_to_pd(n))
    assert want != 0.0
    assert rules_maps.normals_convention_score(n) == want
    assert rules_maps.convention_score(model.normal_to_pd(n)) == want
    flipped = n * np.array([1, -1, 1], np.float32)
    assert rules_maps.normals_convention_score(flipped) == _convention_score_whole(
        model.normal_to_pd(flipped)
    )


def _damaged_block_whole(decoded, reference):
    """The block check as computed before, on the whole maps at once."""
    d = np.abs(decoded - reference).max(axis=-1, keepdims=True)
    err = copies._block_view(d, np.nan)[..., 0]
    ref = copies._block_view(reference, np.nan)
    spread = (np.nanmax(ref, axis=2) - np.nanmin(ref, axis=2)).max(axis=-1)
    mean = np.nanmean(err, axis=2)
    excess = mean - np.maximum(spread, copies.BLOCK_TOLERANCE)
    i = int(np.argmax(excess))
    if excess.flat[i] <= 0:
        return None
    wb = excess.shape[1]
    return float(mean.flat[i]), (i % wb) * 4, (i // wb) * 4


@pytest.mark.parametrize("band", [4, 8, 1000])
@pytest.mark.parametrize("shape", [(37, 29), (64, 64), (13, 7)])
def test_damaged_blocks_in_bands_are_the_whole_check(monkeypatch, band, shape):
    """A copy's block check in bands of block rows: the whole maps' worst block (its mean
    and place) bit for bit, damaged or not, on sizes that are not whole blocks too."""
    monkeypatch.setattr(copies, "band_rows", lambda w, b: band)
    rng = np.random.default_rng(shape[0] * band)
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    ref = np.stack([100 + 0.5 * yy, 80 + 0.7 * xx], -1).round().astype(np.float32)
    dec = ref + np.round(rng.normal(size=ref.shape) * 3).astype(np.float32)
    assert copies.damaged_block(dec, ref) is None is _damaged_block_whole(dec, ref)
    for y, x in ((shape[0] - 3, 1), (5, 2), (shape[0] - 1, shape[1] - 1), (0, 0)):
        dec[max(y - 3, 0) : y + 1, max(x - 3, 0) : x + 1] = 255.0  # damage
        want = _damaged_block_whole(dec, ref)
        assert want is not None and copies.damaged_block(dec, ref) == want


def test_a_copys_levels_judged_in_turn_are_the_whole_levels_judged(tmp_path, monkeypatch):
    """Every level of a demo's copies decoded in turn (the level above held as integers,
    bands of 4 rows): the findings of all levels decoded as float and judged whole, with
    damage in level 0 and in level 2."""
    src = write_demo_source(tmp_path / "src", 64)
    out = tmp_path / "out"
    assert main(["convert", str(src), "-o", str(out), "--no-render", "--no-validate", "-q"]) == 0
    inp = load_input(out, LoadOptions(textures="png"))
    monkeypatch.setattr(copies, "band_rows", lambda w, b: 4)
    checked = 0
    for t in inp.textures:
        path = out / "compressed" / f"{t.name}.dds"
        if t.role not in ("base", "state") or not path.is_file():
            continue
        c = copies._read(path, "dds")
        fmt = copies._decoder_format(c.format, None)
        for damage in (None, 0, 2):
            if damage is not None:
                lv = bytearray(c.levels[damage])
                lv[: len(lv) // 2] = np.random.default_rng(damage).bytes(len(lv) // 2)
                c.levels[damage] = bytes(lv)
            dims = mip_dims(c.width, c.height, len(c.levels))
            levels = [  # as before: every level decoded to float32 codes first
                cmp.unpack_u8(cmp.decode_bc(d, w, h, fmt), fmt, channels=2).astype(np.float32)
                for (w, h), d in zip(dims, c.levels)
            ]
            png = copies._xy_of_png(t)
            want = []
            if png is not None and png.shape[:2] == levels[0].shape[:2]:
                bad = _damaged_block_whole(levels[0], png)
                if bad is not None:
                    want.append(bad)
            for k in range(1, len(levels)):
                h, w = levels[k].shape[:2]
                if levels[k - 1].shape[:2] == (2 * h, 2 * w):
                    half = levels[k - 1].reshape(h, 2, w, 2, 2).mean(axis=(1, 3))
                    bad = _damaged_block_whole(levels[k], half)
                    if bad is not None:
                        want.append(bad)
            found, refused = copies._judge_copy(c, fmt, copies._png_xy_rows(t), png.shape[:2])
            assert refused is None and len(found) == len(want)
            for msg, (worst, x, y) in zip(found, want):
                assert f"texel ({x}, {y}) is {worst:.0f} codes away" in msg
            assert (damage is None) == (not found)
            checked += 1
    assert checked >= 3


@pytest.mark.parametrize("band", [1, 3, 10000])
def test_spread_in_bands_is_the_whole_computation(monkeypatch, band):
    """The misalignment rule's share of texels outside the masks where a state differs from
    the base, band by band of rows: the whole maps' share bit for bit."""
    monkeypatch.setattr(rules_fidelity, "band_rows", lambda w, b: band)
    rng = np.random.default_rng(band)
    base = rng.normal(size=(23, 19, 3)).astype(np.float32)
    states = base[None] + (0.03 * rng.normal(size=(2, 23, 19, 3))).astype(np.float32)
    outside = rng.random((23, 19)) < 0.6
    b = base[outside]  # the whole computation, as before
    far = np.zeros(b.shape[0], bool)
    for s in states:
        far |= angle_deg(s[outside], b) > rules_fidelity.MISALIGNED_DEG
    want = float(far.mean())
    assert 0 < want < 1
    assert rules_fidelity._spread(base, states, outside) == want
    assert rules_fidelity._spread(base, states, np.zeros((23, 19), bool)) == 0.0


def test_the_shipped_base_decoded_where_asked_gives_the_held_bases_findings(tmp_path):
    """The validator decodes the shipped base where a rule asks for it (not held from the map
    rules to the compression rule): every rule's findings and metrics are those of a context
    that decodes it once and holds it, and the context holds no decoded base afterwards."""

    class Held(Context):
        @cached_property
        def shipped_base(self):
            return Context.shipped_base.fget(self)

    src = write_demo_source(tmp_path / "src", 64)
    out = tmp_path / "out"
    assert main(["convert", str(src), "-o", str(out), "--no-render", "--no-validate", "-q"]) == 0
    inp = load_input(out, LoadOptions(textures="png", source=str(src)))
    runs = []
    for cls in (Held, Context):
        ctx = cls(inp)
        issues = [i for _, check in CHECKS for i in check(ctx)]
        runs.append(([(i.code, i.pointer, i.message) for i in issues], repr(ctx.metrics)))
    assert runs[0] == runs[1]
    assert "shipped_base" not in vars(ctx) and ctx.has_shipped_base
    a, b = ctx.shipped_base, ctx.shipped_base
    assert a is not b and np.array_equal(a.view(U32), b.view(U32))


def test_the_shipped_base_read_from_its_texels_is_the_decoded_maps(tmp_path):
    """The measure's samples, the base over the face and the pose pictures made from the
    shipped base's texels (decoded where read): those of the decoded map, to the last bit."""
    src = write_demo_source(tmp_path / "src", 64)
    out = tmp_path / "out"
    assert main(["convert", str(src), "-o", str(out), "--no-render", "--no-validate", "-q"]) == 0
    ctx = Context(load_input(out, LoadOptions(textures="png", source=str(src))))
    ref = rules_fidelity.reference(ctx)
    q, reader = ctx.shipped_base_texels()
    whole, masks = ctx.shipped_base, ctx.shipped_masks
    states = np.stack(ctx.shipped_states)
    got, want = (
        fd.sample(ref, b, states, masks, base_reader=r) for b, r in ((q, reader), (whole, None))
    )
    assert np.array_equal(got.base.view(U32), want.base.view(U32))
    fids = [
        fd.evaluate(ref, s, base_over_face=True, error_maps=True, samples=True) for s in (got, want)
    ]
    assert fids[0].to_json() == fids[1].to_json() and fids[0].base is not None
    pics = [
        fp.pose_pictures(ref, fids[1], b, states, masks, base_reader=r)
        for b, r in ((q, reader), (whole, None))
    ]
    assert pics[0].keys() == pics[1].keys() and pics[0]
    for k in pics[1]:
        assert np.array_equal(pics[0][k].view(U32), pics[1][k].view(U32)), k


@pytest.mark.parametrize("band", [1, 2, 5])
def test_convention_score_of_texels_by_rows_is_the_decoded_maps(tmp_path, monkeypatch, band):
    """The shipped base's convention score from its texels decoded a band of rows at a time
    (the context's reader) against the score of the whole decoded map: the same float."""
    src = write_demo_source(tmp_path / "src", 64)
    out = tmp_path / "out"
    assert main(["convert", str(src), "-o", str(out), "--no-render", "--no-validate", "-q"]) == 0
    ctx = Context(load_input(out, LoadOptions(textures="png")))
    want = rules_maps.normals_convention_score(ctx.shipped_base)
    assert want != 0.0
    q, reader = ctx.shipped_base_texels()
    h, w = q.shape[:2]
    monkeypatch.setattr(rules_maps, "band_rows", lambda w, b: band)

    def rows(r0, r1):
        return reader.store(q[r0:r1].reshape((r1 - r0) * w, -1)).reshape(r1 - r0, w, 3)

    assert rules_maps.normal_rows_convention_score(rows, (h, w)) == want


@pytest.mark.parametrize("grid", [24, 40, 512])
def test_the_shipped_base_on_the_grid_from_its_texels_is_the_decoded_maps(tmp_path, grid):
    """The compression rule's shipped base on the comparison grid, its texels decoded where the
    grid's taps read them: the decoded map resampled to the grid (and at its own size), every
    bit; the states and masks on the grid unchanged."""
    src = write_demo_source(tmp_path / "src", 64)
    out = tmp_path / "out"
    assert main(["convert", str(src), "-o", str(out), "--no-render", "--no-validate", "-q"]) == 0
    ctx = Context(load_input(out, LoadOptions(textures="png")), ValidateOptions(grid=grid))
    base, states, masks = ctx.shipped_on_grid
    want = model.normalize(ctx.to_grid(ctx.shipped_base))
    assert base.shape == (min(grid, 64), min(grid, 64), 3)
    assert np.array_equal(base.view(U32), want.view(U32))
    st = np.stack([ctx.to_grid(s) for s in ctx.shipped_states]).astype(np.float32)
    assert np.array_equal(states.view(U32), st.view(U32))
    assert np.array_equal(masks, ctx.masks_to_grid(ctx.shipped_masks))


def test_the_validators_reference_from_a_pd_level_is_the_whole_arrays(tmp_path):
    """The validator's reference made from the source states' slopes where it reads them (a
    PdLevel, pd): the reference made from the whole array (no memo: computed twice), every
    array bit for bit, and the same fidelity of the shipped maps."""
    src = write_demo_source(tmp_path / "src", 64)
    out = tmp_path / "out"
    assert main(["convert", str(src), "-o", str(out), "--no-render", "--no-validate", "-q"]) == 0
    ctx = Context(load_input(out, LoadOptions(textures="png", source=str(src))))
    assert ctx.asset.encoding == "pd"
    got = rules_fidelity.reference(ctx)
    base, states = rules_fidelity.source_encoded(ctx)
    a = ctx.asset
    want = fd.prepare(
        base,
        states,
        a.masks,
        rules_fidelity.poses(ctx),
        a.region_names,
        a.encoding,
        a.policy,
        rules_fidelity.footprint(ctx, a.states.shape[1:3]),
    )
    assert np.array_equal(got.union, want.union) and len(got.poses) == len(want.poses) > 0
    for p, q in zip(got.poses, want.poses):
        for name in ("sel", "act", "normal", "weight", "masks", "active"):
            x, y = getattr(p, name), getattr(q, name)
            assert (x is None) == (y is None), name
            if x is not None:
                x, y = np.ascontiguousarray(x), np.ascontiguousarray(y)
                assert x.dtype == y.dtype and np.array_equal(x.view(np.uint8), y.view(np.uint8))
    s = rules_fidelity.shipped_samples(ctx, np.stack(ctx.shipped_states))
    assert fd.evaluate(got, s).to_json() == fd.evaluate(want, s).to_json()


@pytest.mark.parametrize("limit", [1, 128, 1000, 4096, 1 << 20])
@pytest.mark.parametrize("n", [1, 7, 8, 129, 1000, 65_537, 2_000_003])
def test_pairwise_sums_are_numpys_whole_array_sums(n, limit):
    """The curl score's sums made piece by piece split as numpy's pairwise summation does: the
    same float64 as ``np.sum`` of the whole contiguous array, to the last bit (values of mixed
    signs and magnitudes, and their squares)."""
    rng = np.random.default_rng(n)
    x = rng.standard_normal(n) * 10.0 ** rng.integers(-6, 6, n)
    sq = x * x
    got = rules_maps._pairwise_sums(n, lambda lo, hi: (x[lo:hi], sq[lo:hi]), limit)
    want = (np.sum(x), np.sum(sq))
    assert [(0.0 + g).tobytes() for g in got] == [np.float64(v).tobytes() for v in want]


class _WholeBaseAt(Context):
    """The shipped base at a state's size as computed before: the whole decoded map resampled
    whole (``resize_normals``), then picked."""

    def shipped_base_at(self, h, w, where):
        return resize_normals(self.shipped_base, h, w)[where]


@pytest.mark.parametrize("band", [1, 3, 1000])
@pytest.mark.parametrize("size", [(64, 64), (32, 32), (37, 23), (16, 64), (100, 80)])
def test_the_shipped_base_at_a_states_size_by_bands_is_the_whole_resample(
    tmp_path, monkeypatch, size, band
):
    """The shipped base at another size, picked where a mask says, made band by band of output
    rows from the source rows the filter reaches (bands of 1, 3, all rows; down, up, mixed and
    the base's own size): the whole decoded map resampled whole and picked, every bit, in the
    same order."""
    src = write_demo_source(tmp_path / "src", 64)
    out = tmp_path / "out"
    assert main(["convert", str(src), "-o", str(out), "--no-render", "--no-validate", "-q"]) == 0
    ctx = Context(load_input(out, LoadOptions(textures="png")))
    h, w = size
    where = np.random.default_rng(h * w).random((h, w)) < 0.4
    where[h // 2] = True  # a whole row
    want = resize_normals(ctx.shipped_base, h, w)[where]
    monkeypatch.setattr(resample, "band_rows", lambda w, b: band)
    monkeypatch.setattr(workset, "band_rows", lambda w, b: band)
    got = ctx.shipped_base_at(h, w, where)
    assert got.shape == (int(where.sum()), 3) and got.dtype == np.float32
    assert np.array_equal(got.view(U32), want.view(U32))
    none = ctx.shipped_base_at(h, w, np.zeros((h, w), bool))
    assert none.shape == (0, 3)


@pytest.mark.parametrize("states_size", [64, 32])
def test_the_encoding_rule_from_the_picked_base_is_the_whole_maps(tmp_path, states_size):
    """The encoding rule (WP-MAP-006) with the shipped base decoded and resampled only where it
    compares (at the states' own size and at half the base's): the same findings and the same
    fit metrics as from the whole resampled map."""
    src = write_demo_source(tmp_path / "src", 64)
    out = tmp_path / "out"
    text = src.read_text().replace('wrinkle = "auto"', f"wrinkle = {states_size}")
    src.write_text(text)
    assert f"wrinkle = {states_size}" in text
    assert main(["convert", str(src), "-o", str(out), "--no-render", "--no-validate", "-q"]) == 0
    inp = load_input(out, LoadOptions(textures="png", source=str(src)))
    runs = []
    for cls in (_WholeBaseAt, Context):
        ctx = cls(inp)
        issues = rules_maps._encoding_match(ctx)
        runs.append(([(i.code, i.message) for i in issues], repr(ctx.metrics)))
    assert "encoding_fit_mean_deg" in runs[1][1]
    assert ctx.inp.state_textures()[0].height == states_size
    assert runs[0] == runs[1]


@pytest.mark.parametrize("bits", [8, 16])
def test_planes_of_integer_masks_sampled_at_the_taps_are_the_float_planes(bits, monkeypatch):
    """A MaskStack's planes sampled (bilinear, clamped) from its integers made float32 at the
    taps only: the float32 stack's planes sampled, every bit (UVs inside, on and past the
    edges); no plane of it is made float32 whole."""
    rng = np.random.default_rng(bits)
    top = (1 << bits) - 1
    q = rng.integers(0, top + 1, (3, 37, 29)).astype(np.uint8 if bits == 8 else np.uint16)
    stack = MaskStack(q)
    uv = rng.uniform(-0.1, 1.1, (2000, 2)).astype(np.float32)
    uv[:4] = [[0, 0], [1, 1], [0.5 / 29, 0.5 / 37], [1, 0]]
    want = tx.bilinear_planes(np.asarray(stack), uv)
    assert want.dtype == np.float32 and want.shape == (2000, 3)
    assert want[0, 1] == np.float32(q[1, 0, 0]) * np.float32(1.0 / top)  # the corner texel

    def whole(self, key):
        raise AssertionError("a whole float plane")

    monkeypatch.setattr(MaskStack, "__getitem__", whole)
    got = tx.bilinear_planes(stack, uv)
    assert np.array_equal(got.view(U32), want.view(U32))


def _unit_normals(shape, seed):
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(*shape, 3)).astype(np.float32)
    n[..., 2] = np.abs(n[..., 2]) + 0.5
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


@pytest.mark.parametrize("band", [1, 3, 1000])
@pytest.mark.parametrize(
    "shape, size",
    [((40, 36), (20, 18)), ((40, 36), (13, 50)), ((21, 30), (64, 64)), ((8, 8), (8, 8))],
)
def test_source_normals_resampled_by_bands_are_the_whole_resample(shape, size, band, monkeypatch):
    """The validator's PD-space resample of source normals made band by band of output rows
    from the rows each band's filter reaches (bands of 1, 3, all rows; down, mixed, up, none):
    convert's whole resample (``resize_normals_pd`` of the whole map), every bit; reading the
    rows only (the map is never asked for whole)."""
    from wrinklepipe.normals import resample
    from wrinklepipe.pipeline.package import resize_normals_pd
    from wrinklepipe.validate import context

    n = _unit_normals(shape, band)
    h, w = size
    want = np.asarray(resize_normals_pd(n, h, w), np.float32)
    monkeypatch.setattr(resample, "band_rows", lambda w, b: band)
    monkeypatch.setattr(workset, "band_rows", lambda w, b: band)
    asked = []

    class Rows:  # a map that gives its rows (a held map decodes a band)
        shape = n.shape

        def __getitem__(self, rows):
            asked.append(rows)
            assert isinstance(rows, slice) and rows != slice(None)
            return n[rows]

    got = context.resize_normals(Rows() if shape != size else n, h, w)
    assert got.shape == (h, w, 3) and got.dtype == np.float32
    assert np.array_equal(got.view(U32), want.view(U32))
    assert shape == size or (asked and band >= 1000) or len(asked) > 1


def test_the_source_states_at_the_shipped_size_are_each_resampled_whole(tmp_path, monkeypatch):
    """The validator's source states at the states' shipped size (32² of a 64² demo), a state's
    band of rows at a time: each state resampled whole (``resize_normals_pd``), stacked."""
    from wrinklepipe.normals import resample
    from wrinklepipe.pipeline.package import resize_normals_pd

    src = write_demo_source(tmp_path / "src", 64)
    src.write_text(src.read_text().replace('wrinkle = "auto"', "wrinkle = 32"))
    out = tmp_path / "out"
    assert main(["convert", str(src), "-o", str(out), "--no-render", "--no-validate", "-q"]) == 0
    ctx = Context(load_input(out, LoadOptions(textures="png", source=str(src))))
    a = ctx.asset
    assert a.states.shape[1:3] == (64, 64)
    want = np.stack([np.asarray(resize_normals_pd(s, 32, 32), np.float32) for s in a.states])
    base = np.asarray(resize_normals_pd(np.asarray(a.base, np.float32), 32, 32), np.float32)
    monkeypatch.setattr(resample, "band_rows", lambda w, b: 5)
    ref = ctx.source_at_shipped_size
    assert ref["states"].shape == (2, 32, 32, 3)
    assert np.array_equal(ref["states"].view(U32), want.view(U32))
    assert np.array_equal(ref["base_at_states"].view(U32), base.view(U32))


@pytest.mark.parametrize("fmt", cmp.FORMATS)
def test_a_copys_level_decoded_from_the_decoders_texels_is_the_rgba_pick(fmt):
    """A copy's level read back as its stored x, y codes picked from the decoder's BGRA texels
    (no RGBA copy of the level): the codes picked from the RGBA decode, every byte, at sizes of
    whole blocks and of partial blocks (a mip level)."""
    rng = np.random.default_rng(len(fmt))
    for w, h in ((16, 8), (10, 6), (2, 2)):
        data = rng.integers(0, 256, cmp.block_data_size(fmt, w, h), dtype=np.uint8).tobytes()
        want = np.ascontiguousarray(cmp.unpack_u8(cmp.decode_bc(data, w, h, fmt), fmt, channels=2))
        got = copies._decoded_level(data, w, h, fmt)
        assert got.dtype == np.uint8 and got.shape == want.shape and got.flags.c_contiguous
        assert np.array_equal(got, want)
        ix = 3 if fmt == "bc3nm" else 0  # x: R (alpha in DXT5nm)
        assert np.array_equal(got[..., 0], cmp.decode_bc(data, w, h, fmt)[..., ix])


@pytest.mark.parametrize("grid", [24, 40, 512])
def test_the_source_base_on_the_grid_from_its_texels_is_the_whole_maps(tmp_path, grid):
    """The compression rule's source base on the comparison grid read at the grid's taps from
    the source base's texels: the whole map resampled to the grid (and at its own size), every
    bit; the taps ask for texels only, never the whole map."""
    src = write_demo_source(tmp_path / "src", 64)
    out = tmp_path / "out"
    assert main(["convert", str(src), "-o", str(out), "--no-render", "--no-validate", "-q"]) == 0
    inp = load_input(out, LoadOptions(textures="png", source=str(src)))
    ctx = Context(inp, ValidateOptions(grid=grid))
    n = np.asarray(ctx.asset.base, np.float32)
    want = model.normalize(ctx.to_grid(resize_normals(n, 64, 64)))
    asked = []

    class Texels:  # a held map: gives the texels it is asked for
        shape = n.shape

        def __getitem__(self, key):
            assert isinstance(key, tuple) and all(isinstance(k, np.ndarray) for k in key)
            asked.append(key[0].size)
            return n[key]

        def __array__(self, dtype=None, copy=None):
            assert grid >= 64, "the whole map"
            return n

    assert "base" not in ctx.source_at_shipped_size  # (made first: the states' size here)
    ctx.asset.base = Texels()
    base, states, masks = ctx.source_on_grid
    assert base.shape == (min(grid, 64), min(grid, 64), 3)
    assert np.array_equal(base.view(U32), want.view(U32))
    assert grid >= 64 or (asked and max(asked) <= grid * grid)


@pytest.mark.parametrize("size", [(5, 7), (16, 16), (40, 3)])
def test_a_map_resized_by_its_taps_is_the_bilinear_resize(size):
    """A map resized by bilinear sampling at the new grid's texel centres from the texels its
    taps gather: ``resize_bilinear`` of the whole map, every bit."""
    img = np.random.default_rng(size[0]).normal(size=(16, 12, 3)).astype(np.float32)
    flat = img.reshape(-1, 3)
    got = tx.resize_bilinear_at(lambda i: flat[i], (16, 12), *size)
    want = tx.resize_bilinear(img, *size)
    assert got.shape == (*size, 3) and np.array_equal(got.view(U32), want.view(U32))


@pytest.mark.parametrize("fmt", ["bc1", "bc3", "bc4", "bc5", "bc7"])
@pytest.mark.parametrize("band", [1, 8, 10000])
def test_block_texels_decoded_by_block_rows_are_the_whole_decode(fmt, band, monkeypatch):
    """A block-compressed texture's level-0 texels decoded band by band of block rows into one
    array (bands of 4, 8, all rows): texture2ddecoder's decode of the whole level picked to RGBA
    as before, every byte, at sizes of whole and partial blocks."""
    from wrinklepipe.validate.inputs import FORMATS

    ch, nbytes, _ = FORMATS[fmt]
    rng = np.random.default_rng(nbytes + band)
    monkeypatch.setattr(tx, "band_rows", lambda w, b: band)
    for w, h in ((16, 24), (13, 17), (4, 4)):
        pw, ph = -(-w // 4) * 4, -(-h // 4) * 4
        data = rng.integers(0, 256, pw * ph // 16 * nbytes, dtype=np.uint8).tobytes()
        fn = getattr(tx.t2d, f"decode_{fmt}")
        whole = np.frombuffer(fn(data, pw, ph), np.uint8).reshape(ph, pw, 4)[:h, :w]
        want = np.ascontiguousarray(whole[..., [2, 1, 0, 3]][..., :ch])
        got = tx.block_texels(data, fmt, w, h, ch)
        assert got.shape == (h, w, ch) and got.dtype == np.uint8 and got.flags.c_contiguous
        assert np.array_equal(got, want)
