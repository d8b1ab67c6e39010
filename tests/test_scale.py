"""Film scale: the head case made band by band, PNGs streamed row band by row band, and the
tiled measures equal to the whole-image ones (docs/scale.md)."""

from __future__ import annotations

import io
import zlib

import numpy as np
import pytest

from wrinklepipe.bench import head_case, load_all
from wrinklepipe.demo import face_fixture as ff
from wrinklepipe.errors import InputError
from wrinklepipe.io.png import PngRows, png_bytes, png_pixels

# ------------------------------------------------------------------------------------------------
# PNG by bands


@pytest.mark.parametrize(
    ("dtype", "channels", "linear"),
    [(np.uint8, 1, False), (np.uint8, 4, True), (np.uint16, 3, True), (np.uint16, 2, False)],
)
@pytest.mark.parametrize("band", [1, 7, 64])
def test_png_rows_are_the_whole_image_png(dtype, channels, linear, band):
    """Rows fed in bands of any height give the bytes of the whole image's PNG (one IDAT), and
    an independent decoder (OpenImageIO) reads the texels back."""
    rng = np.random.default_rng(band)
    top = 65535 if dtype == np.uint16 else 255
    px = rng.integers(0, top + 1, (41, 29, channels)).astype(dtype)
    px[5:20] = px[4]  # runs that the Up filter turns into zeros
    f = io.BytesIO()
    w = PngRows(f, 29, 41, channels, 16 if dtype == np.uint16 else 8, 6, linear)
    for r in range(0, 41, band):
        w.add(px[r : r + band])
    w.close()
    data = f.getvalue()
    assert data == png_bytes(px, 6, shared=False, linear=linear)
    assert data.count(b"IDAT") == 1
    # the IDAT's length and CRC as a PNG reader checks them
    at = data.index(b"IDAT")
    n = int.from_bytes(data[at - 4 : at], "big")
    body = data[at + 4 : at + 4 + n]
    assert int.from_bytes(data[at + 4 + n : at + 8 + n], "big") == zlib.crc32(b"IDAT" + body)
    assert np.array_equal(png_pixels(data), px)  # OpenImageIO, alpha unassociated


def test_png_rows_refuses_wrong_rows():
    w = PngRows(io.BytesIO(), 4, 3, 3, 8, 6)
    with pytest.raises(ValueError, match="do not fit"):
        w.add(np.zeros((1, 5, 3), np.uint8))
    with pytest.raises(ValueError, match="do not fit"):
        w.add(np.zeros((1, 4, 3), np.uint16))
    w.add(np.zeros((2, 4, 3), np.uint8))
    with pytest.raises(ValueError, match="1 rows written|2 rows written"):
        w.close()
    with pytest.raises(ValueError, match="more than 3 rows"):
        w.add(np.zeros((2, 4, 3), np.uint8))


# ------------------------------------------------------------------------------------------------
# the case


@pytest.mark.shared
@pytest.mark.skipif(not head_case.MESH.is_file(), reason="../shared/data is absent")
def test_head_case_is_the_fixture_made_band_by_band(tmp_path, monkeypatch):
    """At 512² with bands of 96 rows the case's maps and masks are the fidelity fixture's
    files byte for byte (made whole), and its manifest puts every choice on auto."""
    monkeypatch.setattr(head_case, "BAND", 96)
    m = head_case.write_head_case(tmp_path / "case", 512)
    ff.write_fixture_source(tmp_path / "fixture", head_case.MESH, 512)
    files = sorted(
        p.relative_to(tmp_path / "fixture") for p in (tmp_path / "fixture").rglob("*.png")
    )
    assert len(files) == 11  # base, two states, eight masks
    for rel in files:
        assert (tmp_path / "case" / rel).read_bytes() == (tmp_path / "fixture" / rel).read_bytes()
    text = m.read_text()
    assert 'name = "head"' in text and 'pd_scale = "auto"' in text
    assert 'wrinkle = "auto"' in text and 'mask = "auto"' in text


@pytest.mark.shared
@pytest.mark.skipif(not head_case.MESH.is_file(), reason="../shared/data is absent")
def test_scale_bench_quick_runs(tmp_path, monkeypatch):
    """``bench scale --quick`` at 128² (at 64² too few texels tell the green convention):
    both commands exit 0 and their own peak
    memory is measured (a child's ``ru_maxrss``, more than the interpreter alone)."""
    monkeypatch.setenv("WRINKLEPIPE_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("WRINKLEPIPE_SCALE_SIZES", "128")
    res = load_all()["scale"][1](True)
    assert [r.step for r in res.rows] == ["128^2 convert + validate-asset"]
    got = res.extra["sizes"]["128"]
    for cmd in ("convert", "validate_asset"):
        assert got[cmd]["exit"] == 0
        assert 50 < got[cmd]["peak_rss_mb"] < 2000
        assert got[cmd]["cpu_s"] > 0
    assert res.failures() == [] and res.rows[0].ratio == 1.0


# ------------------------------------------------------------------------------------------------
# band by band == whole image


def _hostile_texels(rng: np.random.Generator, channels: int, bits: int) -> np.ndarray:
    """Texels [37, 23, C] in [0, 1] (integer levels when ``bits``) with NaN, zero-length,
    short and z < 0 vectors at known places."""
    v = rng.uniform(0.0, 1.0, (37, 23, channels)).astype(np.float32)
    if bits:
        top = (1 << bits) - 1
        v = (np.rint(v * top) / top).astype(np.float32)
    v[3, 4] = np.nan
    v[20, 1, :3] = 0.5  # zero length once decoded
    v[30, 7, :2] = 0.5 + 1e-4  # short
    return v


@pytest.mark.parametrize(
    ("layout", "channels", "bits", "signed"),
    [("auto", 3, 16, False), ("rgb", 3, 8, False), ("rg", 2, 0, False), ("ag", 4, 8, False),
     ("rgb", 3, 0, True)],
)  # fmt: skip
@pytest.mark.parametrize("keep_short", [False, True])
def test_decode_by_bands_is_the_whole_image(
    monkeypatch, layout, channels, bits, signed, keep_short
):
    """Normal-map decoding in bands of 5 rows gives the whole image's vectors bit for bit and
    the same counts, first texels included (found in a later band, told in image rows)."""
    from wrinklepipe.normals import read as nr

    v = _hostile_texels(np.random.default_rng(channels + bits), channels, bits)
    if signed:
        v = v * np.float32(2.0) - np.float32(1.0)
    whole, ws = nr.decode_texels(v, layout, signed, 0.05, bits, keep_short)
    monkeypatch.setattr(nr, "band_rows", lambda width, per: 5)
    band, bs = nr.decode_texels(v, layout, signed, 0.05, bits, keep_short)
    assert band.dtype == np.float32 and band.shape == (37, 23, 3)
    assert np.array_equal(band.view(np.uint32), whole.view(np.uint32))  # NaN payloads too
    assert bs == ws
    assert ws.first_nan == (3, 4) and ws.nan == 1 and ws.texels == 37 * 23
    # into a given array (a map's place in a stack), banded and whole: the same bits
    stack = np.full((2, 37, 23, 3), 9.0, np.float32)
    got, gs = nr.decode_texels(v, layout, signed, 0.05, bits, keep_short, out=stack[1])
    assert np.shares_memory(got, stack) and gs == ws and (stack[0] == 9.0).all()
    assert np.array_equal(stack[1].view(np.uint32), whole.view(np.uint32))
    monkeypatch.setattr(nr, "band_rows", lambda width, per: 100)
    stack[1] = 9.0
    nr.decode_texels(v, layout, signed, 0.05, bits, keep_short, out=stack[1])
    assert np.array_equal(stack[1].view(np.uint32), whole.view(np.uint32))


def test_masks_read_into_one_stack(tmp_path):
    """Masks read one by one into their place in the stack: the values of each file, and
    masks of another size refused naming both files."""
    from wrinklepipe.io.images import write_image
    from wrinklepipe.masks.read import read_masks

    rng = np.random.default_rng(3)
    ms = rng.integers(0, 256, (3, 9, 11)).astype(np.uint8)
    paths = []
    for i, m in enumerate(ms):
        paths.append(write_image(tmp_path / f"m{i}.png", m.astype(np.float32) / 255, 8))
    got = read_masks(paths)
    assert got.masks.dtype == np.float32 and got.masks.shape == (3, 9, 11)
    assert np.array_equal(np.rint(got.masks * 255).astype(np.uint8), ms)
    write_image(tmp_path / "odd.png", np.zeros((9, 12), np.float32), 8)
    with pytest.raises(InputError, match="masks of different sizes"):
        read_masks([*paths, tmp_path / "odd.png"])


def test_working_set_sizes(monkeypatch):
    from wrinklepipe import workset

    assert workset.parse_size("512M") == 512 << 20 and workset.parse_size("2g") == 2 << 30
    assert workset.parse_size("1.5G") == 3 << 29 and workset.parse_size("33554432") == 1 << 25
    for bad in ("lots", "1T", "1M"):
        with pytest.raises(InputError, match="WRINKLEPIPE_WORKING_SET|16M|not a size"):
            workset.parse_size(bad)
    monkeypatch.setenv(workset.ENV, "64M")
    assert workset.working_set_bytes() == 64 << 20
    assert workset.band_rows(1024, 16) == (4 << 20) // (1024 * 16)  # 1/16 of 64M
    assert workset.band_rows(1 << 20, 1 << 10) == 1
    monkeypatch.delenv(workset.ENV)
    assert workset.working_set_bytes() == workset.DEFAULT_BYTES


@pytest.mark.parametrize("encoding", ["pd", "diff", "full", "composite"])
def test_source_states_by_bands_are_the_whole_image(monkeypatch, encoding):
    """The source states in combine's representation, made in bands of 3 rows, are the whole
    image's bit for bit (what the searches and the validator measure against)."""
    from wrinklepipe import model
    from wrinklepipe.fidelity import reference as fre

    rng = np.random.default_rng(7)
    base = model.normalize(rng.normal(0, 0.3, (17, 13, 3)) + [0, 0, 1]).astype(np.float32)
    states = model.normalize(rng.normal(0, 0.4, (2, 17, 13, 3)) + [0, 0, 1]).astype(np.float32)
    whole = fre.source_states(base, states, encoding)
    monkeypatch.setattr(fre, "band_rows", lambda width, per: 3)
    band = fre.source_states(base, states, encoding)
    assert band.dtype == whole.dtype and band.shape == whole.shape
    assert np.array_equal(band, whole)
    if encoding == "pd":  # x/z, y/z of the state less the base's, by hand at one texel
        n, b = states[1, 16, 12], base[16, 12]
        want = n[:2] / n[2] - b[:2] / b[2]
        assert np.allclose(band[1, 16, 12], want, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("bits", [8, 16])
def test_base_texels_by_bands_are_the_whole_image(monkeypatch, bits):
    """The base's stored texels and their decoded normals, made in bands of 4 rows, are the
    whole map's; the texels are the glTF mapping's by hand (round(255 (n + 1) / 2))."""
    from wrinklepipe import model, workset
    from wrinklepipe.pipeline import package as pp

    rng = np.random.default_rng(bits)
    base = model.normalize(rng.normal(0, 0.3, (19, 11, 3)) + [0, 0, 1]).astype(np.float32)
    whole = pp.encode_base(base, bits)
    back = pp.decode_base(whole)
    monkeypatch.setattr(workset, "band_rows", lambda width, per: 4)
    band = pp.encode_base(base, bits)
    assert band.dtype == whole.dtype and np.array_equal(band, whole)
    assert np.array_equal(pp.decode_base(band), back)
    top = (1 << bits) - 1
    assert np.abs(whole.astype(np.int64) - np.rint((base + 1) / 2 * top)).max() <= 1


@pytest.mark.parametrize("fmt", ["bc1", "bc3nm"])
def test_quicktex_blocks_by_bands_are_the_whole_image(monkeypatch, fmt):
    """quicktex's best blocks picked band by band (4 block rows... here 1 or 2) are the whole
    map's, and they decode (texture2ddecoder) near the texels."""
    from wrinklepipe.normals import compress as nc

    rng = np.random.default_rng(11)
    a = rng.integers(0, 256, (24, 20, 4)).astype(np.uint8)
    a[8:16] = a[0:8]  # repeated rows of blocks
    whole = nc._quicktex_best(a, fmt)
    for rows in (4, 8):
        monkeypatch.setattr(nc, "band_rows", lambda width, per, r=rows: r)
        assert np.array_equal(nc._quicktex_best(a, fmt), whole)
    assert whole.shape == (30, 8 if fmt == "bc1" else 16)
    if fmt == "bc1":
        got = nc.decode_bc_bgra(whole.tobytes(), 20, 24, "bc1")[..., 2::-1].astype(int)
        assert np.abs(got - a[..., :3]).mean() < 48  # random texels: a 4-colour palette's error


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_masks_sampled_plane_by_plane_are_the_channels_last_samples(dtype):
    """Masks sampled plane by plane are the channels-last bilinear samples bit for bit (UVs
    outside [0, 1] clamp), and a texel centre gives the texel itself."""
    from wrinklepipe.validate import textures as tx

    rng = np.random.default_rng(5)
    masks = rng.uniform(0, 1, (5, 13, 9)).astype(dtype)
    uv = rng.uniform(-0.2, 1.2, (300, 2)).astype(np.float32)
    uv[0] = ((4 + 0.5) / 9, (7 + 0.5) / 13)  # texel (row 7, column 4)'s centre
    want = tx.bilinear(np.moveaxis(masks, 0, -1), uv)
    got = tx.bilinear_planes(masks, uv)
    assert got.dtype == want.dtype == np.float32 and got.shape == (300, 5)
    assert np.array_equal(got, want)
    assert np.allclose(got[0], masks[:, 7, 4], atol=1e-6)


@pytest.mark.parametrize("convention", ["opengl", "directx"])
def test_states_read_into_one_stack_are_each_file_read_alone(tmp_path, convention):
    """read_maps decodes each full-face state into its place in the stack (a flipped green
    channel put in place too): every state's bits are its file's read alone."""
    from types import SimpleNamespace

    from wrinklepipe.io.images import write_image
    from wrinklepipe.normals.read import ReadOptions, read_normal_map
    from wrinklepipe.pipeline.ingest import read_maps

    rng = np.random.default_rng(7)
    paths = []
    for name in ("base", "a", "b"):
        n = rng.normal(0.0, 0.3, (24, 20, 3))
        n[..., 2] = 1.0
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        paths.append(write_image(tmp_path / f"{name}.png", n * 0.5 + 0.5, 16))
    states = [SimpleNamespace(name=p.stem, map=p) for p in paths[1:]]
    states.append(SimpleNamespace(name="colour only", map=None))
    manifest = SimpleNamespace(
        base=paths[0], convention=convention, states=states, states_include_base=True, regions=[]
    )
    base, stack, masks, _ = read_maps(manifest)
    o = ReadOptions(convention=convention)
    assert stack.shape == (3, 24, 20, 3) and stack.dtype == np.float32 and masks.shape[0] == 0
    for got, p in zip([base, stack[0], stack[1]], paths):
        want = read_normal_map(p, o).normals
        assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    assert np.array_equal(stack[2], base)  # a colour-only state's normal is the base


@pytest.mark.parametrize("rows", [1, 2, 5])
@pytest.mark.parametrize("kind", ["opengl", "directx", "seams", "masked", "hostile"])
def test_convention_detected_by_bands_is_the_whole_maps(monkeypatch, rows, kind):
    """The curl test made band by band of rows (each band reading a row either side) gives the
    whole map's report to the last bit: the same texels, differences, seam limit and means."""
    from wrinklepipe.normals import convention as cv

    rng = np.random.default_rng(11)
    h, w = 29, 23
    f = rng.normal(0.0, 1.0, (h + 2, w + 2)).cumsum(0).cumsum(1) * 0.01  # a height field
    px, py = np.diff(f, axis=1)[1:-1, :-1], np.diff(f, axis=0)[:-1, 1:-1]  # [h, w] each
    if kind != "directx":  # rows run down the image (v), so +Y up is the other sign
        py = -py
    n = np.stack([-px, -py, np.ones_like(px)], -1)
    n = (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)
    mask = None
    if kind == "seams":
        n[:, 11:] = n[:, 11:, [1, 0, 2]]  # an island edge: a jump far beyond the texture
    if kind == "masked":
        mask = rng.random((h, w)) > 0.2
    if kind == "hostile":
        n[3, 4] = np.nan
        n[10:12, 5:9, 2] = 0.1  # below the z limit
    whole = cv.detect_convention(n, mask)
    monkeypatch.setattr(cv, "band_rows", lambda width, per: rows)
    band = cv.detect_convention(n, mask)
    assert band == whole  # every float of the report equal
    assert whole.texels_used > 0
    if kind in ("opengl", "directx"):
        assert whole.convention == kind and whole.confidence > cv.MIN_CONFIDENCE


def test_rasterised_in_small_chunks_is_the_whole_raster(monkeypatch):
    """The UV rasteriser's chunks of candidate texels (a band's share of the working set)
    change no triangle id: overlapping triangles keep the highest index whatever the chunk."""
    from wrinklepipe.geometry import rasterise as ra

    rng = np.random.default_rng(2)
    uvs = rng.random((60, 2))
    idx = rng.integers(0, 60, (40, 3))
    whole = ra.triangle_ids(uvs, idx, 48)
    monkeypatch.setattr(ra, "band_rows", lambda width, per: 7)
    assert np.array_equal(ra.triangle_ids(uvs, idx, 48), whole)
    assert (whole >= 0).sum() > 500 and whole.max() == 39  # overlaps: many texels, top id
    # a texel's id is the highest triangle whose test passes at its centre
    y, x = np.argwhere(whole >= 0)[0]
    hits = [t for t in range(40) if ra.triangle_ids(uvs, idx[t : t + 1], 48)[y, x] == 0]
    assert whole[y, x] == max(hits)


def test_base_normalised_band_by_band_is_the_whole_maps(monkeypatch):
    """The package's unit base, made band by band of rows, is model.normalize of the whole
    map bit for bit (zero vectors stay zero, NaN stays NaN)."""
    from wrinklepipe import model, workset

    rng = np.random.default_rng(9)
    v = rng.normal(0.0, 1.0, (37, 23, 3)).astype(np.float32)
    v[2, 3] = 0.0
    v[5, 6, 1] = np.nan
    whole = model.normalize(v)
    monkeypatch.setattr(workset, "band_rows", lambda width, per: 5)
    band = workset.map_rows(model.normalize, v, 20)
    assert np.array_equal(band.view(np.uint32), whole.view(np.uint32))
    assert (band[2, 3] == 0).all() and np.isnan(band[5, 6]).all()


def test_pd_slopes_of_a_resample_made_band_by_band(monkeypatch):
    """resize_normals in PD space takes the slopes band by band: the resampled normals are
    those of the whole map's slopes, bit for bit."""
    from wrinklepipe import model, workset
    from wrinklepipe.normals import resample as rs

    rng = np.random.default_rng(4)
    n = rng.normal(0.0, 0.3, (40, 40, 3)).astype(np.float32)
    n[..., 2] = np.abs(n[..., 2]) + 0.2
    n[7, 8, 2] = 0.0  # a horizon texel: a large finite slope
    n = model.normalize(n)
    want = model.pd_to_normal(rs.resize(model.normal_to_pd(n), (10, 10)))
    monkeypatch.setattr(workset, "band_rows", lambda width, per: 3)
    got = rs.resize_normals(n, (10, 10), space="pd")
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))


def test_reference_base_is_the_callers_map_normalised_where_read():
    """The reference's unit base is no normalised copy of the map: rows read from it are the
    whole map normalised, bit for bit (zero and NaN vectors too), and two references of one
    source share the memo's work while each holds its caller's own map."""
    from wrinklepipe import reuse
    from wrinklepipe.fidelity import reference as fre
    from wrinklepipe.fidelity.sampling import normalize_rows

    rng = np.random.default_rng(12)
    base = rng.normal(0.0, 0.2, (64, 64, 3)).astype(np.float32)
    base[..., 2] += 1.0
    base[3, 4] = 0.0
    base[5, 6, 0] = np.nan
    whole = normalize_rows(base).reshape(-1, 3)
    rows = fre.UnitRows(base).reshape(-1, 3)
    idx = rng.choice(64 * 64, 500)
    for at in (idx, np.array([3 * 64 + 4, 5 * 64 + 6]), np.arange(64 * 64)):
        assert np.array_equal(rows[at].view(np.uint32), whole[at].view(np.uint32))
    assert np.array_equal(np.asarray(rows).view(np.uint32), whole.view(np.uint32))
    states = rng.normal(0.0, 0.1, (1, 64, 64, 2)).astype(np.float32)
    masks = np.zeros((1, 64, 64), np.float32)
    masks[0, 10:50, 10:50] = 1.0
    poses = [fre.Pose("on", np.ones((1, 1), np.float32))]
    with reuse.reuse() as memo:
        a = fre.prepare(base, states, masks, poses, ["r"])
        b = fre.prepare(base.copy(), states, masks, poses, ["r"])
    assert memo.hits == {"wrinklepipe.fidelity.reference._prepare": 1}
    assert a.base.v is base and not np.shares_memory(b.base.v, base)
    assert np.shares_memory(a.poses[0].normal, b.poses[0].normal)  # the memo's one result
    flat = a.union[:50]
    assert np.array_equal(a.base.reshape(-1, 3)[flat], whole[flat])


@pytest.mark.parametrize("size", [48, 12])
def test_package_unit_base_made_band_by_band(monkeypatch, size):
    """The package's base texels and its base at the states' size, made from the base band by
    band (no whole unit map when the sizes differ), are those of the whole unit map."""
    from wrinklepipe import model, workset
    from wrinklepipe.pipeline import package as pk

    rng = np.random.default_rng(13)
    base = rng.normal(0.0, 0.3, (48, 48, 3)).astype(np.float32)
    base[..., 2] = np.abs(base[..., 2]) + 0.5
    unit = model.normalize(base)
    want_tex = pk.encode_base(unit, 8)
    want_at = pk._base_at(unit, (size, size), {})
    monkeypatch.setattr(workset, "band_rows", lambda width, per: 5)
    assert np.array_equal(pk.encode_base(base, 8, normalize=True), want_tex)
    got = pk._unit_base_at(base, (size, size), {})
    assert got.dtype == np.float32 and np.array_equal(got.view(np.uint32), want_at.view(np.uint32))
