"""Issue 39, messages: every bad input ends in one line in the tool's own words, naming the input:
non-finite numbers, a UTF-8 byte-order mark, a text file used as an image, libpng's own stderr
line, OpenImageIO's limit text, numpy's shape message, driver errors naming the manifest, and no
RuntimeWarning or misleading hint on the way."""

from __future__ import annotations

import shutil
import struct
import warnings
import zlib
from pathlib import Path

import pytest

from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return write_demo_source(tmp_path_factory.mktemp("src") / "demo", size=16)


@pytest.fixture(scope="module")
def converted(source, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("conv") / "asset"
    assert main(["convert", str(source), "-o", str(out), "--no-render", "--no-validate"]) == 0
    return out


def _copy(folder: Path, tmp_path: Path, name: str = "src") -> Path:
    dst = tmp_path / name
    shutil.copytree(folder, dst)
    return dst


def _edit(manifest: Path, old: str, new: str) -> None:
    text = manifest.read_text(encoding="utf-8")
    assert old in text, old
    manifest.write_text(text.replace(old, new, 1), encoding="utf-8")


def _one_line(capsys, *needles: str, fd: bool = False) -> str:
    """The run's stderr: exactly one ``error:`` line, no traceback, no raw library text."""
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, err
    assert "libpng" not in err and "OIIO" not in err and "RuntimeWarning" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, err
    for n in needles:
        assert n in lines[0], err
    return lines[0]


def _convert(manifest: Path, tmp_path: Path, *extra: str) -> int:
    return main(["convert", str(manifest), "-o", str(tmp_path / "out"), "--no-render", *extra])


# ------------------------------------------------------------------------------------------------
# numbers: finite, in range; one message per key


@pytest.mark.parametrize(
    "old, new, key",
    [
        ("max_mean_deg = 0.5", "max_mean_deg = nan", "budget.max_mean_deg"),
        ("max_p99_deg = 2.0", "max_p99_deg = inf", "budget.max_p99_deg"),
        ('pd_scale = "auto"', "pd_scale = nan", "pd_scale"),
        ("joy = [[0.0, 0.0]", "joy = [[-inf, 0.0]", "drivers[0].keys.joy[0][0]"),
    ],
)
def test_a_non_finite_number_is_one_clear_message(source, tmp_path, capsys, old, new, key):
    src = _copy(source.parent, tmp_path) / source.name
    _edit(src, old, new)
    assert _convert(src, tmp_path) == 2
    _one_line(capsys, "manifest.toml", f"[{key}]", "is not a finite number")


@pytest.mark.parametrize(
    "args",
    [
        ["bake", "{m}", "-o", "{o}", "--fps", "nan"],
        ["bake", "{m}", "-o", "{o}", "--end", "inf"],
        ["batch", "{d}", "-o", "{o}", "--timeout", "nan"],
        ["batch", "{d}", "-o", "{o}", "--no-workers", "inf"],
        ["vertex-ids", "{d}/head.glb", "-o", "{o}.npy", "--tolerance", "nan"],
    ],
)
def test_a_non_finite_number_option_is_refused(source, tmp_path, capsys, args):
    """A number option given nan or inf (which float() accepts) is refused like any other value
    that is not a number: before the command runs (bake's --end inf, batch's --timeout nan, a
    watchdog that never fires, passed)."""
    fill = {"m": str(source), "d": str(source.parent), "o": str(tmp_path / "out")}
    with pytest.raises(SystemExit) as stop:
        main([a.format(**fill) for a in args])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and "is not a finite number" in err, err
    assert not (tmp_path / "out").exists()


def test_bake_between_start_and_end_is_costed_in_words(source, tmp_path, capsys):
    """--end far out: one message naming the options, not an internal error."""
    assert main(["bake", str(source), "-o", str(tmp_path / "out"), "--end", "1e9"]) == 2
    _one_line(capsys, "--start/--end", "over the cap")
    assert not (tmp_path / "out").exists()


def test_a_tiny_pd_scale_is_refused_without_runtime_warnings(source, tmp_path, capsys):
    src = _copy(source.parent, tmp_path) / source.name
    _edit(src, 'pd_scale = "auto"', "pd_scale = 1e-46")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning on the way fails the test
        assert _convert(src, tmp_path) == 2
    _one_line(capsys, "[pd_scale]", "0.015625")


@pytest.mark.parametrize(
    "args, flag",
    [
        (["--encoding", "pd", "--scale", "1e-300"], "--scale"),
        (["--encoding", "pd", "--scale", "1e300"], "--scale"),
        (["--encoding", "diff", "--base", "{base}", "--gain", "1e300"], "--gain"),
    ],
)
def test_encode_normals_scale_and_gain_out_of_range_are_one_line(
    source, tmp_path, capsys, args, flag
):
    """encode-normals' --scale/--gain keep the range a manifest's pd_scale has: beyond it the
    slopes overflowed float32 (numpy's RuntimeWarnings on the terminal, a 180-degree map
    written with exit 0)."""
    base = str(source.parent / "base_normal.png")
    out = tmp_path / "en.png"
    argv = ["encode-normals", str(source.parent / "wrinkle_stretch.png"), "-o", str(out)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning on the way fails the test
        assert main(argv + [a.format(base=base) for a in args]) == 2
    _one_line(capsys, f"{flag}: ", "is out of range; expected auto or a number >= 0.015625")
    assert not out.exists()


def test_a_manifest_with_a_utf8_bom_is_read(source, tmp_path, capsys):
    src = _copy(source.parent, tmp_path) / source.name
    src.write_bytes(b"\xef\xbb\xbf" + src.read_bytes())
    assert _convert(src, tmp_path, "--no-validate") == 0, capsys.readouterr().err


def test_a_batch_file_with_nan_names_the_key(source, tmp_path, capsys):
    batch = tmp_path / "batch.toml"
    batch.write_text(
        f'schema = "wrinklepipe/batch@1"\noutput = "out"\n[[assets]]\n'
        f'manifest = "{source.as_posix()}"\n[assets.options]\npng_level = nan\n'
    )
    assert main(["batch", str(batch), "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert "is not a finite number" in err and "Traceback" not in err, err


def test_strict_json_refuses_nan(tmp_path):
    from wrinklepipe.errors import InputError
    from wrinklepipe.io.json_safe import loads_json

    with pytest.raises(InputError, match="NaN is not finite"):
        loads_json(b'{"a": NaN}', tmp_path / "x.json")


# ------------------------------------------------------------------------------------------------
# images


def test_a_text_file_used_as_a_gltf_texture_is_not_read_as_a_size(converted, tmp_path, capsys):
    """A glTF source whose base (its material's normalTexture) is a text file named .png: the
    message says it is not a PNG (it was "image is 1931505263 x 543780193, over the cap")."""
    src = _copy(converted, tmp_path)
    for f in ("base_normal.png",):
        (src / "textures" / f).write_text("some notes, not an image at all\n")
    demo = write_demo_source(tmp_path / "maps", 16)
    shutil.copytree(demo.parent / "masks", src / "masks")
    for f in demo.parent.glob("*.png"):  # the wrinkle and colour maps
        if f.name != "base_normal.png":
            shutil.copy(f, src / f.name)
    text = demo.read_text().replace('mesh = "head.glb"', 'mesh = "demo_head.gltf"')
    text = "\n".join(ln for ln in text.splitlines() if not ln.startswith("base = "))
    (src / "manifest.toml").write_text(text + "\n")
    assert _convert(src / "manifest.toml", tmp_path) == 2
    line = _one_line(capsys, "demo_head.gltf", "not a PNG file")
    assert " x " not in line


def _corrupt_png(good: bytes) -> bytes:
    """A PNG whose compressed data is damaged (its CRC made right): libpng reports it."""
    i = good.index(b"IDAT")
    n = struct.unpack(">I", good[i - 4 : i])[0]
    data = bytearray(good[i + 4 : i + 4 + n])
    data[2] ^= 0xFF
    crc = struct.pack(">I", zlib.crc32(b"IDAT" + bytes(data)) & 0xFFFFFFFF)
    return good[: i + 4] + bytes(data) + crc + good[i + 8 + n :]


def test_a_corrupt_png_texture_gives_no_stray_libpng_line(converted, tmp_path, capfd):
    out = _copy(converted, tmp_path, "asset")
    png = out / "textures" / "base_normal.png"
    png.write_bytes(_corrupt_png(png.read_bytes()))
    rc = main(["validate-asset", str(out / "demo_head.gltf"), "--no-render", "--textures", "png"])
    assert rc == 2
    err = capfd.readouterr().err  # the file descriptor: libpng writes to fd 2 itself
    assert "libpng" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "cannot decode" in lines[0], err


def _png_header(w: int, h: int) -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0"))


def test_an_image_bomb_header_is_refused_in_the_tools_words(source, tmp_path, capsys):
    src = _copy(source.parent, tmp_path) / source.name
    (src.parent / "bomb.png").write_bytes(_png_header(100_000, 100_000))
    _edit(src, '"base_normal.png"', '"bomb.png"')
    assert _convert(src, tmp_path) == 2
    line = _one_line(capsys, "bomb.png", "100000 x 100000", "over the cap")
    assert "limits:imagesize_MB" not in line and "--max-pixels" not in line  # convert has none


# ------------------------------------------------------------------------------------------------
# numpy's words, drivers' labels


def test_usd_time_samples_of_different_lengths_are_named(converted, tmp_path, capsys):
    out = _copy(converted, tmp_path, "asset")
    usda = out / "demo_head.usda"
    text = usda.read_text()
    start = text.index("float[] wrinkle:weights.timeSamples")
    first = text.index("[", text.index(":", start + 40))
    end = text.index("]", first)
    usda.write_text(text[:first] + "[0.5]" + text[end + 1 :])  # one value for 8 regions
    rc = main(["validate-asset", str(usda), "--no-render"])
    assert rc == 2
    _one_line(capsys, "wrinkle:weights", "for 8 regions")


def test_a_driver_error_names_the_manifest(source, tmp_path, capsys):
    src = _copy(source.parent, tmp_path) / source.name
    _edit(src, 'kind = "expressions"', 'kind = "curves"')  # keys name expressions, not regions
    assert _convert(src, tmp_path) == 2
    line = _one_line(capsys, str(src), "[drivers[0]")
    assert "<driver>" not in line
