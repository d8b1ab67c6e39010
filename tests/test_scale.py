"""Film scale: the head case made band by band, PNGs streamed row band by row band, and the
tiled measures equal to the whole-image ones (docs/scale.md)."""

from __future__ import annotations

import io
import zlib

import numpy as np
import pytest

from wrinklepipe.bench import head_case, load_all
from wrinklepipe.demo import face_fixture as ff
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
    """``bench scale --quick`` at 128² (the smallest the case validates at: at 64² too few texels tell the green convention): both commands exit 0 and their own peak
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
