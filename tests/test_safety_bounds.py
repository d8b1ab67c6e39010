"""Issue 39, bounds: every loop that searches ends, and every input's cost is checked before
anything the size of it is allocated, with a message naming the input."""

from __future__ import annotations

import contextlib
import shutil
import signal
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from pxr import Sdf, Usd

from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.normals.bc4 import encode_bc5
from wrinklepipe.normals.dds import dds_bytes
from wrinklepipe.usd import layer


class Hung(BaseException):
    """Raised in the main thread by the alarm: not an ``Exception``, so no handler hides it."""


@contextlib.contextmanager
def deadline(seconds: float) -> Iterator[None]:
    """Fail the block (raise :class:`Hung`) once it has used ``seconds`` of CPU (a loop that
    never ends spins), or ten times that in wall-clock time (a wait that never ends): a hang
    fails the test instead of hanging the suite, and a loaded machine, which stretches the wall
    clock but not the CPU a run needs, fails nothing."""

    def ring(signum, frame):  # noqa: ANN001
        what = "of CPU" if signum == signal.SIGPROF else "of wall-clock time"
        raise Hung(f"still running after {seconds} s {what}")

    old = {s: signal.signal(s, ring) for s in (signal.SIGPROF, signal.SIGALRM)}
    signal.setitimer(signal.ITIMER_PROF, seconds)
    signal.setitimer(signal.ITIMER_REAL, 10 * seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.setitimer(signal.ITIMER_REAL, 0)
        for s, handler in old.items():
            signal.signal(s, handler)


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return write_demo_source(tmp_path_factory.mktemp("src") / "demo", size=16)


def _copy_source(source: Path, tmp_path: Path) -> Path:
    src = tmp_path / "src"
    shutil.copytree(source.parent, src)
    return src / source.name


def _read_u16(path: Path) -> np.ndarray:
    inp = oiio.ImageInput.open(str(path))
    try:
        return inp.read_image("uint16")
    finally:
        inp.close()


def _grey_alpha_png(path: Path, xy: np.ndarray) -> None:
    """A two-channel (grey + alpha) 16-bit PNG holding x in grey and y in alpha, as stored
    (unassociated: OpenImageIO would otherwise divide grey by alpha)."""
    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(xy.shape[1], xy.shape[0], 2, "uint16")
    spec.attribute("oiio:UnassociatedAlpha", 1)
    out.open(str(path), spec)
    out.write_image(np.ascontiguousarray(xy))
    out.close()


def _bc5_dds(path: Path, xy8: np.ndarray) -> None:
    h, w = xy8.shape[:2]
    data = encode_bc5(xy8[..., 0], xy8[..., 1])
    path.write_bytes(dds_bytes("bc5", w, h, [data]))


# ------------------------------------------------------------------------------------------------
# a two-channel map with a texel on or past the horizon (x^2 + y^2 >= 1): the PD scale search
# looped forever (`while clips(safe): safe += 1/64`)


@pytest.mark.parametrize(
    "role, kind", [("state", "png"), ("base", "png"), ("state", "dds"), ("base", "dds")]
)
def test_a_two_channel_map_past_the_horizon_converts_in_bounded_time(
    source, tmp_path, capsys, role, kind
):
    src = _copy_source(source, tmp_path)
    name = "wrinkle_stretch.png" if role == "state" else "base_normal.png"
    rgb = _read_u16(src.parent / name)
    if kind == "png":
        xy = rgb[..., :2].copy()
        xy[3, 3] = (65535, 65535)  # x = y = 1: |xy| = 1.41, z rebuilt as 0
        bad = src.parent / "two_channel.png"
        _grey_alpha_png(bad, xy)
    else:
        xy = np.rint(rgb[..., :2] / 257.0).astype(np.uint8)
        xy[4:8, 4:8] = (255, 255)  # a whole block: BC5 keeps it exactly
        bad = src.parent / "two_channel.dds"
        _bc5_dds(bad, xy)
    text = src.read_text().replace(f'"{name}"', f'"{bad.name}"')
    src.write_text(text)
    out = tmp_path / "out"
    with deadline(60):
        rc = main(["convert", str(src), "-o", str(out), "--no-render"])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    # handled: converted (the validator's verdict is the caller's: 0 or 1), the horizon texels
    # reported as not unit length and clipped, and the scale chosen by the texels a scale holds
    assert rc in (0, 1), err
    assert "WP-MAP-007" in err and "not unit length" in err
    report = (out / "report.json").read_text()
    assert '"WP-MAP-004"' in report  # the horizon texels clip at every scale: said
    assert "pd_scale 64" not in err


def test_validate_asset_on_a_manifest_with_a_horizon_texel_ends(source, tmp_path, capsys):
    src = _copy_source(source, tmp_path)
    xy = _read_u16(src.parent / "wrinkle_stretch.png")[..., :2].copy()
    xy[0, 0] = (0, 65535)  # x = -1, y = 1
    _grey_alpha_png(src.parent / "two_channel.png", xy)
    src.write_text(src.read_text().replace('"wrinkle_stretch.png"', '"two_channel.png"'))
    with deadline(60):
        rc = main(["validate-asset", str(src), "--no-render"])
    err = capsys.readouterr().err
    assert rc == 1 and "Traceback" not in err


# ------------------------------------------------------------------------------------------------
# input costs, checked on what an input declares before anything its size is made


def test_a_usd_mesh_over_the_corner_cap_is_refused_before_its_arrays(tmp_path, monkeypatch):
    """The counts are read and summed first: a mesh declaring more corners than the cap is
    refused naming the prim, before its indices, points or any per-corner array are read (a
    258 KB usdc declaring 10^8 corners took 13.6 GB). The cap is lowered here so the test file
    stays small; the check is the same."""
    from pxr import Usd, UsdGeom, Vt

    from wrinklepipe import asset

    monkeypatch.setattr(asset, "MAX_MESH_CORNERS", 3000)
    path = tmp_path / "big.usdc"
    stage = Usd.Stage.CreateNew(str(path))
    mesh = UsdGeom.Mesh.Define(stage, "/Head")
    mesh.GetPointsAttr().Set(Vt.Vec3fArray([(0, 0, 0), (1, 0, 0), (0, 1, 0)]))
    mesh.GetFaceVertexCountsAttr().Set(Vt.IntArray([3] * 1001))
    # no faceVertexIndices at all: the refusal comes from the counts alone
    stage.Save()
    from wrinklepipe.errors import InputError
    from wrinklepipe.usd.meshes import read_usd_meshes

    with pytest.raises(InputError, match=r"/Head declares 3003 face corners, over the cap of 3000"):
        read_usd_meshes(path)


def test_meshopt_data_declaring_too_many_elements_is_refused_before_decoding():
    from wrinklepipe.gltf.decompress import DecodeError, meshopt_view

    with pytest.raises(DecodeError, match="over the cap"):
        meshopt_view({"count": 10**9, "byteStride": 16, "mode": "ATTRIBUTES"}, b"\xa0" * 64)
    with pytest.raises(DecodeError, match="over the cap"):
        meshopt_view({"count": 10**9, "byteStride": 4, "mode": "TRIANGLES"}, b"\xe0" * 64)


@pytest.mark.parametrize(
    "old, new, needle",
    [
        ("base = 16\n", "base = 16384\n", "[resolution.base]: 16384 is out of range"),
        ("fps = 24", "fps = 1e9", "[drivers[0].fps]: 1000000000.0 is out of range"),
        ("joy = [[0.0, 0.0]", "joy = [[1000000.0, 0.0]", "over the cap of 1048576"),
    ],
)
def test_resolutions_and_driver_spans_are_costed_before_allocation(
    source, tmp_path, capsys, old, new, needle
):
    src = _copy_source(source, tmp_path)
    text = src.read_text()
    assert old in text
    src.write_text(text.replace(old, new, 1))
    with deadline(60):  # main: minutes and gigabytes before "out of memory (try --max-pixels)"
        rc = main(["convert", str(src), "-o", str(tmp_path / "out"), "--no-render"])
    err = capsys.readouterr().err
    assert rc == 2 and needle in err and "Traceback" not in err, err
    assert "--max-pixels" not in err and "out of memory" not in err


def test_uninstancing_a_wrinkled_mesh_is_bounded(monkeypatch):
    """The layer makes the instances over a wrinkled mesh ordinary prims, a level of nesting a
    pass; an override that does not take (here: none is written) ends in an error after as
    many passes as the path has levels, instead of a loop that never ends."""
    stage = Usd.Stage.CreateInMemory()
    stage.GetRootLayer().ImportFromString(
        '#usda 1.0\ndef Xform "Proto" {\n    def Mesh "M" {\n    }\n}\n'
        'def Xform "I" (instanceable = true\n    references = </Proto>) {\n}\n'
    )
    assert stage.GetPrimAtPath("/I/M").IsInstanceProxy()

    class Ignored:
        def SetInfo(self, *args) -> None:  # noqa: ANN002, N802
            pass

    monkeypatch.setattr(Sdf, "CreatePrimInLayer", lambda *args: Ignored())
    with deadline(30), pytest.raises(RuntimeError, match="stay instances"):
        layer._deinstance(stage, ["/I/M"], [])


@pytest.mark.parametrize(
    "command, needle",
    [
        (["encode-normals", "{base}", "-o", "{out}.png", "--size", "100000"], "over the cap"),
        (["encode-normals", "{base}", "-o", "{out}.png", "--size", "9000",
          "--max-pixels", "1000000"],
         "9000 x 9000 = 81000000 pixels, over the cap of 1000000 pixels"),
        (["pack-masks", "{mask}", "-o", "{out}", "--size", "100000"], "over the cap"),
        (["bake", "{manifest}", "-o", "{out}", "--maps", "--size", "100000"],
         "100000 is out of range; expected 4..8192"),
        (["capture", "{base}", "{base}", "--neutral-landmarks", "{lm}", "--expression-landmarks",
          "{lm}", "--size", "9000x8000", "-o", "{out}"],
         "9000 x 8000 = 72000000 pixels, over the cap of 67108864 pixels"),
    ],
    ids=["encode-normals", "encode-normals-max-pixels", "pack-masks", "bake", "capture"],
)  # fmt: skip
def test_a_size_option_is_costed_before_allocation(source, tmp_path, capsys, command, needle):
    """A command's --size (the side of what it makes) is checked against the pixel cap (or the
    [resolution] range) before any input is read: it was an internal error ('ImageBuf unable to
    allocate 80000000000 bytes') or minutes and gigabytes before 'out of memory'."""
    paths = {
        "base": source.parent / "base_normal.png",
        "mask": source.parent / "masks" / "chin.png",
        "manifest": source,
        "lm": tmp_path / "landmarks.json",  # never read: the size is refused first
        "out": tmp_path / "out",
    }
    args = [a.format(**paths) for a in command]
    with deadline(60):
        rc = main(args)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("error")]
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("error: --size: "), err
    assert needle in lines[0] and "internal error" not in err and "out of memory" not in err
    assert not (tmp_path / "out").exists() and not (tmp_path / "out.png").exists()


@pytest.mark.parametrize(
    "option, needle",
    [
        (["--scale", "1e300"], "--blur: 1 x 1e+300 (--scale) makes a blur of 1e+300 pixels"),
        (["--furrow-sigma", "1e300"], "--furrow-sigma: 1e+300 x 1 (--scale) makes a blur"),
        (["--blur", "5000"], "--blur: 5000 x 1 (--scale) makes a blur of 5000 pixels"),
    ],
)
def test_a_capture_blur_wider_than_the_photo_is_refused(tmp_path, capsys, option, needle):
    """capture's blurs (a sigma times --scale) are costed against the photo before they run:
    a 1e300-pixel sigma was an internal error ('Maximum allowed size exceeded'), a merely huge
    one minutes of filtering."""
    s = tmp_path / "session"
    assert main(["capture", "--example", str(s)]) == 0
    capsys.readouterr()
    args = ["capture", str(s / "neutral.png"), str(s / "expression.png")]
    args += ["--neutral-landmarks", str(s / "neutral.json")]
    args += ["--expression-landmarks", str(s / "expression.csv"), "-o", str(tmp_path / "out")]
    with deadline(60):
        rc = main([*args, *option])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("error")]
    assert rc == 2 and len(lines) == 1 and needle in lines[0], err
    assert "wider than the photo (192 x 192)" in lines[0]
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "option, needle",
    [
        (["--morph", "brow_raise=1e300"], "--morph: brow_raise=1e300: a weight is at most 10"),
        (["--morph", "brow_raise=1e30"], "--morph: brow_raise=1e30: a weight is at most 10"),
        (["--morph", "brow_raise=1", "--texture-space", "64", "--blur", "1e300"],
         "--blur: 1e+300 is out of range; expected 0..64 texels"),
        (["--morph", "brow_raise=1", "--texture-space", "64", "--blur", "-1"],
         "--blur: -1 is out of range; expected 0..64 texels"),
    ],
)  # fmt: skip
def test_dynamic_weights_and_blur_out_of_range_are_one_line(
    source, tmp_path, capsys, option, needle
):
    """dynamic's morph weights (1e300: NaN weights, an internal error writing JSON; 1e30: a
    stray numpy warning line) and texture-space blur (1e300: 'Maximum allowed size exceeded')
    are checked before anything is computed."""
    out = tmp_path / "w.json"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rc = main(["dynamic", str(source.parent / "head.glb"), "-o", str(out), *option])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("error")]
    assert rc == 2 and len(lines) == 1 and needle in lines[0], err
    assert "Warning" not in err and not out.exists()


@pytest.mark.parametrize("blur", ["5000", "1e300", "-1"])
def test_a_regions_blur_out_of_range_is_one_line(source, tmp_path, capsys, blur):
    """regions' mask blur is checked before anything is rendered: --blur 5000 on 64² masks
    filtered for minutes (1024²: over ten), 1e300 was an internal error."""
    out = tmp_path / "regions"
    args = ["regions", str(source.parent / "head.glb"), "-o", str(out), "--size", "64"]
    with deadline(60):
        rc = main([*args, "--blur", blur])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("error")]
    assert rc == 2 and len(lines) == 1, err
    assert lines[0].startswith(f"error: --blur: {float(blur):g} is out of range; expected 0..64 ")
    assert not out.exists()
