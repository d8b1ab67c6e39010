"""Maps that are not what they claim: refused up front with one line naming the file and what
it looks like (wrinklepipe.normals.identify), and a green convention wrong beyond doubt refused
by the flip rule before anything is written (pipeline.ingest.check_conventions)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.io.images import read_image, write_image
from wrinklepipe.normals.identify import looks_like

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"


def _sphere(n: int = 64) -> np.ndarray:
    """Object-space normals of a sphere seen from the front and the back (unit, half z < 0)."""
    y, x = np.mgrid[-1 : 1 : n * 1j, -1 : 1 : n * 1j]
    z = np.sqrt(np.clip(1 - x * x - y * y, 0, None))
    v = np.stack([x, y, z], -1)
    v[:, n // 2 :, 2] *= -1  # the right half seen from behind
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    return 0.5 + 0.5 * v


def test_what_images_look_like():
    rng = np.random.default_rng(0)
    ramp = np.repeat(np.linspace(0, 1, 64)[None, :, None], 64, 0).repeat(3, -1)
    assert looks_like(ramp).startswith("a grey image (R = G = B on 100.0 %")
    photo = rng.uniform(0, 1, (64, 64, 3))  # every colour: lengths all over
    assert looks_like(photo).startswith("a colour image: ")
    assert "not unit length" in looks_like(photo)
    pale = np.broadcast_to(np.array([0.8, 0.75, 0.7]), (64, 64, 3))  # near-unit, but lying down
    assert "lean more than 6" in looks_like(pale), looks_like(pale)
    assert "object-space normal map" in looks_like(_sphere())
    # a tangent-space map: bumps of 30 degrees, 8-bit
    h = np.sin(np.linspace(0, 8 * np.pi, 64))[None, :] * np.ones((64, 1))
    n = np.stack([-np.gradient(h, axis=1) * 3, np.zeros_like(h), np.ones_like(h)], -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    assert looks_like(np.round((0.5 + 0.5 * n) * 255) / 255) == ""
    # two channels: (x, y) longer than 1 is no normal map; (0.5, 0.5) is flat and fine
    assert looks_like(np.full((8, 8, 2), 0.5), "rg") == ""
    assert "longer than 1" in looks_like(np.full((8, 8, 2), 0.99), "rg")


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data is absent")
def test_the_shared_samples_normal_maps_pass_and_their_colour_textures_do_not():
    normal = [
        SHARED / "gltf-samples/NormalTangentMirrorTest/glTF/NormalTangentTest_Normal.png",
    ]
    colour = [
        SHARED / "gltf-samples/NormalTangentMirrorTest/glTF/NormalTangentMirrorTest_BaseColor.png",
        SHARED / "usd/usd-wg/full_assets/Teapot/textures/tea_set_01_diff_2k.jpg",
        SHARED / "usd/usd-wg/full_assets/Teapot/textures/tea_set_01_arm_2k.jpg",
        SHARED / "gltf-samples/MultiUVTest/glTF/uv1.png",
    ]
    for p in normal + colour:
        if not p.is_file():
            pytest.skip(f"{p} is absent")
    for p in normal:
        v, _ = read_image(p)
        assert looks_like(v) == "", p
    for p in colour:
        v, _ = read_image(p)
        assert looks_like(v) != "", p


@pytest.fixture()
def source(tmp_path):
    return write_demo_source(tmp_path / "src", 64)


_PROGRESS = re.compile(r"^\s*\d+(\.\d+)? s  ")


def _convert(tmp_path, manifest, capsys) -> tuple[int, list[str]]:
    code = main(["convert", str(manifest), "-o", str(tmp_path / "out"), "--no-render"])
    err = capsys.readouterr().err
    # the progress log's lines ("   0.0 s  wrinklepipe convert ...") are not messages
    lines = [
        ln for ln in err.replace("\n ", " ").splitlines() if ln.strip() and not _PROGRESS.match(ln)
    ]
    assert not (tmp_path / "out").exists()  # nothing written
    assert not any(tmp_path.glob(".out*"))
    return code, lines


def test_a_colour_photo_given_as_base_is_refused_in_one_line(source, tmp_path, capsys):
    rng = np.random.default_rng(3)
    # a photo-like image: smooth colour blobs (low frequencies of every channel)
    spec = np.fft.rfft2(rng.normal(size=(3, 64, 64)))
    spec[:, 8:-8] = 0
    spec[:, :, 8:] = 0
    img = np.fft.irfft2(spec, s=(64, 64))
    img = (img - img.min()) / (img.max() - img.min())
    write_image(source.parent / "base_normal.png", np.moveaxis(img, 0, -1), bits=8)
    code, lines = _convert(tmp_path, source, capsys)
    assert code == 2 and len(lines) == 1, lines
    assert (
        "base_normal.png: is not a tangent-space normal map: it looks like a colour image"
        in (lines[0])
    )


PHOTO = SHARED / "usd/usd-wg/full_assets/Teapot/textures/tea_set_01_diff_2k.jpg"


@pytest.mark.skipif(not PHOTO.is_file(), reason="../shared/data is absent")
def test_a_real_photo_given_as_base_is_refused_in_one_line(source, tmp_path, capsys):
    """A photographed texture (the USD Teapot's diffuse scan, 2048^2 JPEG, averaged down to
    the demo's 64^2): exit 2, one line naming the file and what it looks like."""
    photo, _ = read_image(PHOTO)
    photo = photo[..., :3].reshape(64, 32, 64, 32, 3).mean(axis=(1, 3))
    write_image(source.parent / "base_normal.png", photo, bits=8)
    code, lines = _convert(tmp_path, source, capsys)
    assert code == 2 and len(lines) == 1, lines
    assert "base_normal.png: is not a tangent-space normal map: it looks like a colour" in lines[0]


def test_a_grey_image_given_as_base_is_refused_in_one_line(source, tmp_path, capsys):
    ramp = np.linspace(0.1, 0.9, 64)[None, :] * np.ones((64, 1))
    write_image(source.parent / "base_normal.png", np.stack([ramp] * 3, -1), bits=8)
    code, lines = _convert(tmp_path, source, capsys)
    assert code == 2 and len(lines) == 1, lines
    assert (
        "base_normal.png: is not a tangent-space normal map: it looks like a grey image"
        in (lines[0])
    )


def test_a_directx_base_declared_opengl_hits_the_flip_rule_up_front(source, tmp_path, capsys):
    base, _ = read_image(source.parent / "base_normal.png")
    base = base.copy()
    base[..., 1] = 1.0 - base[..., 1]  # exported as DirectX
    write_image(source.parent / "base_normal.png", base, bits=16)
    code, lines = _convert(tmp_path, source, capsys)
    assert code == 2 and len(lines) == 1, lines
    assert "base_normal.png: declared opengl (+Y up)" in lines[0]
    assert "matches the other maps' only with green flipped" in lines[0]
    assert "(WP-MAP-003)" in lines[0]


def test_every_map_directx_says_the_manifest_convention_is_wrong(source, tmp_path, capsys):
    for name in ("base_normal.png", "wrinkle_stretch.png", "wrinkle_compress.png"):
        v, _ = read_image(source.parent / name)
        v = v.copy()
        v[..., 1] = 1.0 - v[..., 1]
        write_image(source.parent / name, v, bits=16)
    code, lines = _convert(tmp_path, source, capsys)
    assert code == 2 and len(lines) == 1, lines
    assert 'set convention = "directx"' in lines[0] and "every normal map" in lines[0]
    # and declared as what they are, they convert
    text = source.read_text().replace('convention = "opengl"', 'convention = "directx"')
    source.write_text(text)
    assert main(["convert", str(source), "-o", str(tmp_path / "ok"), "--no-render"]) == 0
