"""The faster convert: validation reuses the asset convert ingested (no second read and decode
of the source files) and still judges the written folder; PNGs at a chosen zlib level, the
same bytes on every run."""

from __future__ import annotations

import json
import zlib
from pathlib import Path

import numpy as np
import pytest

from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.io.png import DEFAULT_PNG_LEVEL, png_bytes
from wrinklepipe.jobs import validation as pv
from wrinklepipe.jobs.convert import ConvertOptions, convert


@pytest.fixture(scope="module")
def manifest(tmp_path_factory) -> Path:
    return write_demo_source(tmp_path_factory.mktemp("src") / "demo", 32)


def _idat(png: bytes) -> bytes:
    i = png.index(b"IDAT")
    n = int.from_bytes(png[i - 4 : i], "big")
    return png[i + 4 : i + 4 + n]


def test_png_level_is_an_argument_with_a_default():
    px = (np.arange(64 * 64 * 3, dtype=np.uint32) % 251).astype(np.uint8).reshape(64, 64, 3)
    assert DEFAULT_PNG_LEVEL == 6
    assert png_bytes(px) == png_bytes(px, 6)
    fast = png_bytes(px, 1)
    # the IDAT stream is zlib at the level asked for: the same bytes as zlib itself makes
    rows = np.concatenate([np.full((64, 1), 2, np.uint8), px.reshape(64, -1)], axis=1)
    rows[1:, 1:] = px.reshape(64, -1)[1:] - px.reshape(64, -1)[:-1]
    assert _idat(fast) == zlib.compress(rows.tobytes(), 1)
    assert _idat(png_bytes(px, level=9)) == zlib.compress(rows.tobytes(), 9)
    with pytest.raises(ValueError):
        png_bytes(px, 10)


def test_validation_reuses_the_ingested_source_and_judges_the_written_folder(
    manifest, tmp_path, monkeypatch
):
    out = tmp_path / "out"
    reads = []
    real = pv.load_input

    def counting(path, options=None):
        reads.append((Path(path), options))
        return real(path, options)

    monkeypatch.setattr(pv, "load_input", counting)
    result = convert(manifest, out, ConvertOptions(render=False))
    # one read: the written folder (in its staging place), not the manifest's source files
    assert len(reads) == 1 and reads[0][1].source is None
    assert reads[0][0].name == out.name and reads[0][0].parent != manifest.parent
    # the same judgement as reading the source again from the manifest
    again = pv.validate_output(out, manifest, render=False)
    got = json.loads((out / "report.json").read_text())["validation"]
    assert got == json.loads(json.dumps(again).replace(str(manifest.parent), "<source>"))
    assert result.report["validation"]["status"] == "ran"


def test_png_level_changes_bytes_not_pixels_and_reruns_are_identical(manifest, tmp_path):
    from wrinklepipe.io.png import png_pixels

    a, b, c = (tmp_path / n for n in "abc")
    convert(manifest, a, ConvertOptions(validate=False, compressed=False))
    convert(manifest, b, ConvertOptions(validate=False, compressed=False))
    convert(manifest, c, ConvertOptions(validate=False, compressed=False, png_level=9))
    tex = sorted(p.relative_to(a) for p in (a / "textures").glob("*.png"))
    assert tex
    for rel in tex:
        assert (a / rel).read_bytes() == (b / rel).read_bytes()
        assert np.array_equal(
            png_pixels((a / rel).read_bytes()), png_pixels((c / rel).read_bytes())
        )
    assert any((a / r).read_bytes() != (c / r).read_bytes() for r in tex)


def test_reuse_changes_no_byte_of_the_folder(manifest, tmp_path, monkeypatch):
    """convert computes a resample, a PNG or a block encoding asked twice once (wrinklepipe.reuse);
    the folder is byte for byte the one every stage computing everything itself writes."""
    import contextlib

    from wrinklepipe import reuse
    from wrinklepipe.jobs import convert as pc

    monkeypatch.setattr(reuse, "MIN_INPUT_BYTES", 0)  # the 32^2 demo's maps are small
    memos = []
    real = pc.reuse

    @contextlib.contextmanager
    def spy():
        with real() as memo:
            memos.append(memo)
            yield memo

    monkeypatch.setattr(pc, "reuse", spy)
    convert(manifest, tmp_path / "reused")
    monkeypatch.setattr(pc, "reuse", contextlib.nullcontext)
    convert(manifest, tmp_path / "plain")
    (memo,) = memos
    # the glTF document and the textures folder hold the same PNGs; the search's block
    # roundtrip of the chosen format is the copy's encoding
    assert memo.hits["wrinklepipe.io.png._png"] >= 4
    assert memo.hits["wrinklepipe.normals.compress.encode_bc"] >= 1
    # the validator's MikkTSpace reference of the mesh read back is the tangents convert made
    assert memo.hits["wrinklepipe.geometry.tangents._mikktspace"] >= 1
    files = sorted(p.relative_to(tmp_path / "plain") for p in (tmp_path / "plain").rglob("*"))
    assert files == sorted(
        p.relative_to(tmp_path / "reused") for p in (tmp_path / "reused").rglob("*")
    )
    for rel in files:
        if (tmp_path / "plain" / rel).is_file():
            assert (tmp_path / "plain" / rel).read_bytes() == (
                tmp_path / "reused" / rel
            ).read_bytes(), rel
