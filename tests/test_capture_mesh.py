"""The neutral's shape from the character's mesh: UV lookup, camera fit, rendered normals, CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from wrinklepipe.asset import Mesh
from wrinklepipe.capture import mesh_view as MV
from wrinklepipe.capture.sessions import SessionOptions, make_session, neutral_mesh
from wrinklepipe.cli import main
from wrinklepipe.io.images import write_image
from wrinklepipe.validate.gl import create_context


def test_points_at_uv_by_hand():
    # one quad, two triangles; UV (0.25, 0.5) lies in the first, (0.75, 0.25) in the second
    mesh = Mesh(
        positions=np.array([[0, 0, 0], [2, 0, 0], [0, 4, 1], [2, 4, 3]], np.float32),
        indices=np.array([[0, 1, 2], [1, 3, 2]], np.uint32),
        uvs=np.array([[0, 0], [1, 0], [0, 1], [1, 1]], np.float32),
    )
    pts, found = MV.points_at_uv(mesh, np.array([[0.25, 0.5], [0.75, 0.75], [1.5, 0.5]]))
    assert found.tolist() == [True, True, False]
    # first: 0.25 of edge 0-1 plus 0.5 of edge 0-2 -> (0.5, 2, 0.5)
    assert pts[0] == pytest.approx([0.5, 2.0, 0.5])
    # second, in (1, 3, 2): u = 1 - b2, v = b3 + b2 ... by hand: 0.25 v1 + 0.5 v3 + 0.25 v2
    assert pts[1] == pytest.approx(
        0.25 * np.array([2, 0, 0]) + 0.5 * np.array([2, 4, 3]) + 0.25 * np.array([0, 4, 1])
    )


def _project(world: np.ndarray, rot: np.ndarray, s: float, off: np.ndarray) -> np.ndarray:
    c = world @ rot.T
    return np.stack([s * c[:, 0], -s * c[:, 1]], axis=-1) + off


@pytest.mark.parametrize("depth", [1.0, 0.02])  # a solid cloud, and a nearly flat patch
def test_camera_fit_recovers_a_known_camera(depth):
    rng = np.random.default_rng(3)
    world = rng.uniform(-1, 1, (30, 3)) * [1.0, 1.2, depth]
    world[:, 2] -= 0.3 * (world[:, 0] ** 2 + world[:, 1] ** 2)  # a dome, as a face is
    rot = Rotation.from_euler("yxz", [25.0, -12.0, 4.0], degrees=True).as_matrix()
    photo = _project(world, rot, 180.0, np.array([256.0, 300.0]))
    cam = MV.fit_camera(world, photo)
    assert cam.residual_px < 1e-6
    assert np.abs(cam.rotation - rot).max() < 1e-6
    assert cam.scale == pytest.approx(180.0) and cam.offset == pytest.approx([256.0, 300.0])


@pytest.fixture(scope="module")
def curved():
    s = make_session(SessionOptions(size=96, texture_size=48, nz_min=0.8))
    return s, neutral_mesh(s, step=4.0)


def test_rendered_normals_match_the_analytic_neutral(curved):
    s, mesh = curved
    uv = s.lm_texture / s.options.texture_size
    world, found = MV.points_at_uv(mesh, uv)
    assert found.all()
    cam = MV.fit_camera(world, s.lm_neutral)
    # the mesh was turned 20 degrees about Y: the camera found from the landmarks says so
    assert cam.view_deg == pytest.approx(20.0, abs=0.01) and cam.residual_px < 0.01
    ctx = create_context()
    try:
        n, covered = MV.render_normals(mesh, cam, s.neutral.shape, ctx)
    finally:
        ctx.release()
    roi = s.roi > 0.5
    assert covered[roi].all()
    err = np.degrees(np.arccos(np.clip(np.sum(n * s.neutral_normals, axis=-1), -1, 1)))[roi]
    assert err.mean() < 0.05 and err.max() < 0.5  # linear normals across 4 px facets
    assert n[..., 2][roi].min() == pytest.approx(0.8, abs=2e-3)


def _write_obj(path: Path, mesh: Mesh, uvs: bool = True) -> None:
    v = "\n".join(f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in mesh.positions)
    vt = "\n".join(f"vt {u:.7g} {1.0 - w:.7g}" for u, w in mesh.uvs) if uvs else ""
    vn = "\n".join(f"vn {x:.7g} {y:.7g} {z:.7g}" for x, y, z in mesh.normals)
    k = mesh.indices.astype(np.int64) + 1
    fmt = "{0}/{0}/{0}" if uvs else "{0}//{0}"
    f = "\n".join("f " + " ".join(fmt.format(i) for i in tri) for tri in k)
    path.write_text("\n".join(p for p in (v, vt, vn, f) if p) + "\n")


@pytest.fixture(scope="module")
def files(curved, tmp_path_factory) -> Path:
    s, mesh = curved
    d = tmp_path_factory.mktemp("mesh_session")
    write_image(d / "neutral.png", np.clip(s.neutral, 0, 1), bits=16)
    write_image(d / "expression.png", np.clip(s.expression, 0, 1), bits=16)
    write_image(d / "roi.png", s.roi, bits=8)
    t = s.options.texture_size
    on = np.all((s.lm_texture > 0.5) & (s.lm_texture < t - 0.5), axis=1)  # inside the texture
    names = [f"p{i:02d}" for i in np.flatnonzero(on)]
    for name, pts, scale in (
        ("neutral", s.lm_neutral[on], 1.0),
        ("expression", s.lm_expression[on], 1.0),
        ("texture", s.lm_texture[on], 1.0 / t),
    ):
        body = {
            "points": {n: [float(x) * scale, float(y) * scale] for n, (x, y) in zip(names, pts)}
        }
        if name == "texture":
            body["space"] = "uv"
        (d / f"{name}.json").write_text(json.dumps(body))
    _write_obj(d / "face.obj", mesh)
    _write_obj(d / "nouv.obj", mesh, uvs=False)
    # the left half of the layout only: landmarks with u > 0.55 are not on this mesh
    keep = mesh.uvs[mesh.indices.astype(np.int64)][..., 0].max(axis=1) < 0.55
    half = Mesh(mesh.positions, mesh.indices[keep], mesh.uvs, mesh.normals)
    _write_obj(d / "half.obj", half)
    return d


def _args(d: Path, out: Path) -> list[str]:
    return [
        "capture",
        str(d / "neutral.png"),
        str(d / "expression.png"),
        "--neutral-landmarks",
        str(d / "neutral.json"),
        "--expression-landmarks",
        str(d / "expression.json"),
        "--texture-landmarks",
        str(d / "texture.json"),
        "--size",
        "48",
        "--roi",
        str(d / "roi.png"),
        "--colorspace",
        "linear",
        "-o",
        str(out),
    ]


def test_capture_with_the_neutral_mesh(files, tmp_path):
    out = tmp_path / "m"
    assert main(_args(files, out) + ["--neutral-mesh", str(files / "face.obj")]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["neutral_shape"] == "mesh" and rep["options"]["neutral_shape"] == "mesh"
    info = rep["neutral_mesh"]
    assert info["view_from_mesh_z_deg"] == pytest.approx(20.0, abs=0.05)
    assert info["landmark_residual_rms_px"] < 0.05
    assert info["roi_min_nz"] == pytest.approx(0.8, abs=3e-3)  # the session's dome
    # the neutral turns from the camera (N_z 0.8): auto solves, as with --neutral-normals
    assert rep["method"] == "sfs" and "sfs" in rep["orientation"]


def test_bad_neutral_mesh(files, tmp_path, capsys):
    cases = (
        (["--neutral-mesh", str(files / "nouv.obj")], "no texture coordinates"),
        (
            ["--neutral-mesh", str(files / "face.obj"), "--neutral-normals", "x.png"],
            "--neutral-normals or --neutral-mesh",
        ),
        (["--neutral-mesh", str(files / "face.obj"), "--nz", "0.9"], "drop --nz"),
    )
    for extra, text in cases:
        capsys.readouterr()
        assert main(_args(files, tmp_path / "x") + extra) == 2
        msg = " ".join(capsys.readouterr().err.split())
        assert text in msg and msg.count("error:") == 1, msg
        assert not (tmp_path / "x").exists()
    # texture landmarks off the mesh's layout: named, counted
    pts = json.loads((files / "texture.json").read_text())["points"]
    off = sorted(n for n, (u, _) in pts.items() if u > 0.55)
    capsys.readouterr()
    assert main(_args(files, tmp_path / "x") + ["--neutral-mesh", str(files / "half.obj")]) == 2
    msg = " ".join(capsys.readouterr().err.split())
    assert "half.obj" in msg and "outside the mesh's UV layout" in msg
    assert f"{len(off)} texture landmark" + ("s" if len(off) > 1 else "") in msg and off[0] in msg
    # no texture landmarks: the camera cannot be found
    args = _args(files, tmp_path / "x")
    i = args.index("--texture-landmarks")
    del args[i : i + 4]
    capsys.readouterr()
    assert main(args + ["--neutral-mesh", str(files / "face.obj")]) == 2
    assert "needs --texture-landmarks" in capsys.readouterr().err
