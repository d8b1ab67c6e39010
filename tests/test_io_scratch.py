"""Arrays held in a scratch file (wrinklepipe.io.scratch): every index a stage uses gives what
numpy's own indexing of the array in memory gives, the file leaves no trace, the memo keys it as
the array, and a normal stack over it decodes the same normals."""

from __future__ import annotations

import os
import pickle
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from output_hashes import assert_unchanged, folder_hashes

from wrinklepipe import reuse
from wrinklepipe.demo import avatar
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.errors import InputError
from wrinklepipe.io import scratch
from wrinklepipe.io.images import read_image, write_image
from wrinklepipe.io.scratch import ScratchArray, hold
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.normals.held import HeldMap, NormalStack, texels_at


@pytest.fixture(autouse=True)
def _small_bands(monkeypatch: pytest.MonkeyPatch) -> None:
    # a 16 MiB working set: 1 MiB bands, so a 64-row map is gathered over several bands
    monkeypatch.setenv("WRINKLEPIPE_WORKING_SET", "16M")


def _array(rng: np.random.Generator, h: int, w: int, c: int, dtype: type) -> np.ndarray:
    top = np.iinfo(dtype).max
    return rng.integers(0, top, (h, w, c), endpoint=True, dtype=dtype)


def _keys(rng: np.random.Generator, h: int, w: int) -> list:
    rows = rng.integers(-h, h, 50)
    cols = rng.integers(-w, w, 50)
    mask = rng.random((h, w)) < 0.3
    return [
        (slice(None), slice(None)),
        slice(3, 17),
        (slice(5, 60, 7), slice(2, 9)),
        (slice(None, None, -3),),
        7,
        -1,
        (4, slice(1, 5), 1),
        (rows, cols),
        (rows, cols, 1),
        (rows.reshape(5, 10), cols.reshape(5, 10)),
        (rows[:10], slice(None)),
        (rows[:10],),
        (rows.reshape(5, 10),),
        (rows.reshape(5, 10), slice(1, 3)),
        [3, 3, 0],
        (mask,),
        (mask, slice(0, 2)),
        (mask.any(axis=1),),
        (np.array([], np.int64), np.array([], np.int64)),
        (Ellipsis, 0),
    ]


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    seed=st.integers(0, 2**32 - 1),
    h=st.integers(8, 70),
    w=st.integers(5, 40),
    c=st.sampled_from([2, 3, 4]),
    dtype=st.sampled_from([np.uint8, np.uint16]),
)
def test_indexing_matches_numpy(seed: int, h: int, w: int, c: int, dtype: type) -> None:
    rng = np.random.default_rng(seed)
    a = _array(rng, h, w, c, dtype)
    s = ScratchArray(a, scratch.scratch_dir())
    assert (s.shape, s.dtype, s.ndim, s.nbytes, len(s)) == (a.shape, a.dtype, 3, a.nbytes, h)
    for key in _keys(rng, h, w):
        want = a[key]
        got = s[key]
        assert got.shape == want.shape and got.dtype == want.dtype, key
        assert np.array_equal(got, want), key
    assert np.array_equal(np.asarray(s), a)


def test_a_large_gather_spans_many_bands() -> None:
    # 600 x 700 x 3 uint16: 2.5 KB a row, 1 MiB bands of ~400 rows: two bands and a remainder
    rng = np.random.default_rng(3)
    a = _array(rng, 1000, 700, 3, np.uint16)
    s = ScratchArray(a, scratch.scratch_dir())
    rows, cols = rng.integers(0, 1000, 200_000), rng.integers(0, 700, 200_000)
    assert np.array_equal(s[rows, cols], a[rows, cols])
    assert np.array_equal(s[rows[:3000]], a[rows[:3000]])


def test_out_of_range_indices_are_refused_as_numpy_does() -> None:
    a = np.zeros((4, 5, 3), np.uint8)
    s = ScratchArray(a, scratch.scratch_dir())
    for key in (4, -5, (np.array([4]), np.array([0])), (np.array([0]), np.array([5]))):
        with pytest.raises(IndexError):
            a[key]
        with pytest.raises(IndexError):
            s[key]


def test_hold_spills_only_what_is_larger_than_its_share(monkeypatch, tmp_path: Path) -> None:
    monkeypatch.setenv("WRINKLEPIPE_SCRATCH", str(tmp_path))
    small = np.zeros((512, 512, 3), np.uint16)  # 1.5 MiB: within 16 MiB / 8
    large = np.arange(1024 * 1024 * 3, dtype=np.uint16).reshape(1024, 1024, 3)  # 6 MiB
    assert hold(small) is small
    held = hold(large)
    assert isinstance(held, ScratchArray)
    assert np.array_equal(held[100:300], large[100:300])
    assert list(tmp_path.iterdir()) == []  # an unnamed file: nothing to find or to clean up
    fd = held._file.fileno()
    assert os.fstat(fd).st_size == large.nbytes
    monkeypatch.setenv("WRINKLEPIPE_SCRATCH", "off")
    assert hold(large) is large


def test_a_directory_that_cannot_hold_it_is_one_clear_error(monkeypatch, tmp_path: Path) -> None:
    missing = tmp_path / "no-such-dir"
    monkeypatch.setenv("WRINKLEPIPE_SCRATCH", str(missing))
    with pytest.raises(InputError) as got:
        hold(np.zeros((1024, 1024, 3), np.uint16))
    text = str(got.value)
    assert str(missing) in text and "WRINKLEPIPE_SCRATCH" in text and "6 MiB" in text


def test_the_memo_keys_it_as_the_array_in_memory() -> None:
    rng = np.random.default_rng(5)
    a = _array(rng, 300, 200, 3, np.uint16)
    s = ScratchArray(a, scratch.scratch_dir())
    assert reuse._key("f", (a,), {}) == reuse._key("f", (s,), {})
    b = a.copy()
    b[299, 199, 2] ^= 1
    assert reuse._key("f", (ScratchArray(b, scratch.scratch_dir()),), {}) != reuse._key(
        "f", (a,), {}
    )


def test_it_travels_to_another_process_as_the_array() -> None:
    a = np.arange(60, dtype=np.uint16).reshape(4, 5, 3)
    back = pickle.loads(pickle.dumps(ScratchArray(a, scratch.scratch_dir())))
    assert isinstance(back, np.ndarray) and np.array_equal(back, a)


def test_a_normal_stack_over_scratch_decodes_as_over_memory() -> None:
    rng = np.random.default_rng(9)
    n = rng.normal(0, 0.3, (80, 60, 3))
    n[..., 2] = 1
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    q = np.rint((n * 0.5 + 0.5) * 65535).astype(np.uint16)
    mem = NormalStack([HeldMap(q, "rgb", True)], single=True)
    disk = NormalStack([HeldMap(ScratchArray(q, scratch.scratch_dir()), "rgb", True)], single=True)
    assert np.array_equal(np.asarray(disk), np.asarray(mem))
    assert np.array_equal(disk[10:30], mem[10:30])
    flat = rng.integers(0, 80 * 60, 1000)
    assert np.array_equal(texels_at(disk, flat), texels_at(mem, flat))
    assert np.array_equal(disk.reshape(-1, 3)[flat > 2000], mem.reshape(-1, 3)[flat > 2000])
    mask = rng.random((80, 60)) < 0.5
    assert np.array_equal(disk[mask], mem[mask])


def _spill_everything(monkeypatch: pytest.MonkeyPatch, where: Path) -> list[ScratchArray]:
    """Every source map held in a scratch file under ``where`` from now on (its share of the
    working set set to 0); the list fills with each scratch array made."""
    monkeypatch.setenv("WRINKLEPIPE_SCRATCH", str(where))
    monkeypatch.setattr(scratch, "SPILL_SHARE", 0.0)
    made: list[ScratchArray] = []
    real_init = ScratchArray.__init__

    def counted(self: ScratchArray, a: np.ndarray, directory: Path) -> None:
        real_init(self, a, directory)
        made.append(self)

    monkeypatch.setattr(ScratchArray, "__init__", counted)
    return made


def test_a_conversion_with_every_map_spilled_writes_the_recorded_bytes(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # every source map held in a scratch file (its share of the working set set to 0): the
    # avatar (its base the glTF material's own normal texture, its states manifest files)
    # converts to the very bytes recorded for it, and the scratch directory is left empty
    monkeypatch.delenv("WRINKLEPIPE_WORKING_SET")
    where = tmp_path / "scratch"
    where.mkdir()
    made = _spill_everything(monkeypatch, where)
    res = convert(
        avatar.avatar_source_dir(), tmp_path / "out", ConvertOptions(glb=True, render=False)
    )
    assert res.exit_code == 0
    assert len(made) >= 2 and all(s.ndim == 3 for s in made)  # the base and the states
    assert_unchanged("avatar", tmp_path / "out")
    assert list(where.iterdir()) == []


def _float_demo(folder: Path) -> Path:
    """The 64² demo with its base and first state saved as float32 EXR (read as float32 unit
    normals, not integers)."""
    manifest = write_demo_source(folder, 64)
    text = manifest.read_text(encoding="utf-8")
    for name in ("base_normal", "wrinkle_stretch"):
        values, _ = read_image(folder / f"{name}.png")
        write_image(folder / f"{name}.exr", values, 32)
        text = text.replace(f"{name}.png", f"{name}.exr")
    manifest.write_text(text, encoding="utf-8")
    return manifest


def test_float_maps_held_in_scratch_convert_to_the_same_bytes(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    # float32 maps (EXR files) go to a scratch file as unit normals: the folder converted with
    # every map spilled is byte for byte the one converted with every map in memory
    monkeypatch.delenv("WRINKLEPIPE_WORKING_SET")
    manifest = _float_demo(tmp_path / "src")
    monkeypatch.setenv("WRINKLEPIPE_SCRATCH", "off")
    kept = convert(manifest, tmp_path / "memory", ConvertOptions(render=False))
    assert kept.exit_code == 0, kept.report["validation"]
    made = _spill_everything(monkeypatch, tmp_path)
    spilled = convert(manifest, tmp_path / "scratch", ConvertOptions(render=False))
    assert spilled.exit_code == 0
    assert sum(s.dtype == np.float32 for s in made) >= 2  # the EXR base and state at least
    assert folder_hashes(tmp_path / "scratch") == folder_hashes(tmp_path / "memory")


def test_without_preadv_rows_are_read_by_seek_and_read(monkeypatch: pytest.MonkeyPatch) -> None:
    # a system without os.preadv (Windows): the same rows and texels, read under a lock
    monkeypatch.setattr(scratch, "_PREADV", False)
    rng = np.random.default_rng(11)
    a = _array(rng, 900, 300, 3, np.uint16)
    s = ScratchArray(a, scratch.scratch_dir())
    rows, cols = rng.integers(0, 900, 50_000), rng.integers(0, 300, 50_000)
    got = reuse.map_threads(lambda k: s[rows[k::4], cols[k::4]], range(4), workers=4)
    for k in range(4):
        assert np.array_equal(got[k], a[rows[k::4], cols[k::4]])
    assert np.array_equal(s[100:700], a[100:700])
