"""The demo character: geometry, maps, masks, table; the demo command; bad manifests via convert."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from output_hashes import assert_unchanged

from wrinklepipe import model
from wrinklepipe.cli import main
from wrinklepipe.commands import demo as demo_command
from wrinklepipe.demo.character import MORPH_NAMES, generate
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.presets import jimenez


@pytest.fixture(scope="module")
def demo():
    return generate(256)


def test_mesh_is_closed_with_a_uv_seam_and_enough_triangles(demo):
    m = demo.mesh
    assert m.indices.shape[0] >= 5000
    # Closed: after welding equal positions, every edge is shared by exactly two triangles.
    _, weld = np.unique(m.positions, axis=0, return_inverse=True)
    tri = weld.reshape(-1)[m.indices]
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)
    # A seam: some positions carry two different UVs.
    n_pos = weld.max() + 1
    assert n_pos < m.positions.shape[0]
    seam = np.bincount(weld.reshape(-1), minlength=n_pos) > 1
    assert seam.sum() >= 60
    # Outward-facing triangles (the surface is star-shaped around the origin).
    p = m.positions[m.indices].astype(np.float64)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert np.all(np.einsum("ij,ij->i", n, p.mean(axis=1)) > 0)
    assert np.allclose(np.linalg.norm(m.normals, axis=1), 1.0, atol=1e-5)


def test_morph_targets_are_named_and_local(demo):
    m = demo.mesh
    assert len(MORPH_NAMES) >= 6 and m.morph_deltas.shape == (len(MORPH_NAMES),) + m.positions.shape
    for name in ("brow_raise", "brow_furrow", "smile_L", "smile_R", "squint_L", "squint_R"):
        assert name in m.morph_names
    # smile_L moves the character's left (+X) only; brow_raise moves up (+Y).
    left = m.morph_deltas[m.morph_names.index("smile_L")]
    moved = np.linalg.norm(left, axis=1) > 1e-4
    assert moved.any() and np.all(m.positions[moved, 0] > 0)
    assert m.morph_deltas[m.morph_names.index("brow_raise")][:, 1].max() > 0.004


def test_maps_are_the_normals_of_their_height_fields(demo):
    # An independent finite difference of the heights at one texel (x right, y up).
    h = demo.base_height + demo.wrinkle_heights[0]
    r, c = 100, 120
    gx = (h[r, c + 1] - h[r, c - 1]) / 2
    gy = -(h[r + 1, c] - h[r - 1, c]) / 2
    n = np.array([-gx, -gy, 1.0]) / np.sqrt(gx * gx + gy * gy + 1)
    assert demo.wrinkled_normal(0)[r, c] == pytest.approx(n, abs=1e-6)
    # Pore-scale detail: the base slopes vary from texel to texel.
    slope = model.normal_to_pd(demo.base_normal)
    assert np.abs(np.diff(slope[..., 0], axis=1)).mean() > 0.02


def test_wrinkle_states_lie_where_the_paper_puts_them(demo):
    # Stretch: horizontal forehead lines only (slopes mostly vertical, i.e. along y).
    s = model.normal_to_pd(demo.wrinkle_only_normal(0))
    assert np.abs(s[..., 1]).max() > 0.3 and np.abs(s[..., 1]).sum() > 3 * np.abs(s[..., 0]).sum()
    names = demo.region_names
    fore = demo.masks[[names.index(n) for n in names if n.startswith("forehead")]].sum(0)
    active = np.linalg.norm(s, axis=-1) > 0.05
    assert (fore[active] > 0.5).mean() > 0.9
    # Compress: wrinkles under the glabella, nose and chin zones.
    c = np.linalg.norm(model.normal_to_pd(demo.wrinkle_only_normal(1)), axis=-1)
    for zone in ("glabella", "nose_l", "nose_r", "chin"):
        m = demo.masks[names.index(zone)] > 0.9
        assert c[m].max() > 0.2, zone


def test_masks_are_the_jimenez_zones(demo):
    assert demo.region_names == jimenez.REGION_NAMES
    assert demo.masks.min() >= 0 and demo.masks.max() <= 1
    assert demo.masks.sum(axis=0).max() <= 1 + 1e-6
    # left zones on the image's right half (character's left is +X -> u > 0.5)
    w = demo.masks.shape[-1]
    for i, side in enumerate(demo.region_sides):
        cols = np.nonzero(demo.masks[i].sum(axis=0))[0]
        if side == "left":
            assert cols.min() >= w // 2 - 2
        elif side == "right":
            assert cols.max() <= w // 2 + 1


def test_expression_table_is_table_1_1():
    import csv

    from wrinklepipe.paths import FIXTURES_DIR

    rows = [
        r
        for r in csv.reader((FIXTURES_DIR / "jimenez_table_1_1.csv").read_text().splitlines())
        if r and not r[0].startswith("#")
    ]
    header, body = rows[0], rows[1:]
    assert header[1:] == [z[0].capitalize() for z in jimenez.ZONES]
    table = generate(64).expressions
    for r in body:
        assert table[r[0].lower()] == dict(zip(jimenez.REGION_NAMES, map(float, r[1:])))


def test_generation_is_deterministic():
    a, b = generate(64), generate(64)
    assert np.array_equal(a.base_height, b.base_height)
    assert np.array_equal(a.wrinkle_heights, b.wrinkle_heights)
    assert np.array_equal(a.mesh.positions, b.mesh.positions)


def test_demo_source_is_byte_identical(tmp_path):
    a = write_demo_source(tmp_path / "a", 64).parent
    b = write_demo_source(tmp_path / "b", 64).parent
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert len(files) == 16  # 13 + the colour maps: base_color, color_stretch, color_compress
    assert {"base_color.png", "color_stretch.png", "color_compress.png"} <= {f.name for f in files}
    for f in files:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f


def test_demo_command(tmp_path, monkeypatch, capsys):
    """One full run at the smallest size: converted, validated with renders, and told where."""
    monkeypatch.setenv("WRINKLEPIPE_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "demo-out"
    assert main(["demo", "-o", str(out), "--size", "64"]) == 0
    assert (out / "report.html").is_file() and (out / "demo_head.gltf").is_file()
    assert (out / "validation.html").is_file()
    assert (out / "validation_files" / "render_anger.png").is_file()
    printed = capsys.readouterr().err
    assert "report.html" in printed and "valid" in printed
    assert_unchanged("demo", out)  # every byte as recorded on main (tests/output_hashes.py)


def test_demo_rerun_replaces_its_own_output_only(tmp_path, monkeypatch, capsys):
    """A rerun replaces the previous demo without --force; another non-empty folder is refused
    and left as it was. (About the folder, so validation is off here; the run above has it.)"""
    monkeypatch.setenv("WRINKLEPIPE_CACHE", str(tmp_path / "cache"))
    real = demo_command.convert
    monkeypatch.setattr(
        demo_command, "convert", lambda m, o, opt: real(m, o, replace(opt, validate=False))
    )
    out = tmp_path / "demo-out"
    assert main(["demo", "-o", str(out), "--size", "64"]) == 0
    first = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert json.loads(first["report.json"])["validation"]["status"] == "skipped"
    (out / "demo_head.gltf").write_text("edited since")
    assert main(["demo", "-o", str(out), "--size", "64"]) == 0
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == first
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("keep")
    capsys.readouterr()
    assert main(["demo", "-o", str(other), "--size", "64"]) == 2
    assert "--force" in capsys.readouterr().err
    assert [p.name for p in other.iterdir()] == ["notes.txt"]
    assert (other / "notes.txt").read_text() == "keep"


@pytest.fixture
def bad_src(tmp_path) -> Path:
    src = tmp_path / "src"
    write_demo_source(src, 64)
    return src


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (lambda t: t.replace('base = "base_normal.png"', 'base = "nope.png"'), "base"),
        (lambda t: t.replace('policy = "clamp01"', "policy = 7"), "policy"),
        (lambda t: t.replace('encoding = "pd"', 'encoding = "pd"\ncolour = 1'), "colour"),
        (lambda t: t.replace('name = "chin"', 'name = "glabella"'), "regions[7].name"),
        (
            lambda t: (
                t.replace('expressions = "jimenez"\n', "") + "\n[expressions.x]\nchin = 2.0\n"
            ),
            "expressions.x.chin",
        ),
    ],
)
def test_bad_manifest_exits_2_and_creates_no_output(bad_src, tmp_path, capsys, edit, key):
    m = bad_src / "manifest.toml"
    m.write_text(edit(m.read_text()))
    out = tmp_path / "out"
    assert main(["convert", str(m), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(m.name) in err and f"[{key}]" in err
    assert "Traceback" not in err
    assert not out.exists()
    assert not any(p.name.startswith(".out") for p in tmp_path.iterdir())


def test_masks_of_different_sizes_exit_2(bad_src, tmp_path, capsys):
    from wrinklepipe.io.images import write_image

    write_image(bad_src / "masks" / "chin.png", np.zeros((8, 8)), bits=8)
    assert main(["convert", str(bad_src / "manifest.toml"), "-o", str(tmp_path / "o")]) == 2
    assert "different sizes" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
    shutil.rmtree(bad_src)
