"""WP-FID-006/007 on a real character: RobotExpressive's head with a base that has detail of
its own (a smooth random relief) and wrinkle states that keep that detail and add ridges over
the whole face (``states_include_base``: the common practice the old rule alarmed on).

Independent expectations: a state built as *base + independent relief* keeps all of the
base's detail (the regression slope of its PD slopes on the base's is 1), a state built on
another face's relief keeps none of it (slope 0), and a base given upside down keeps none of
it until it is flipped back. Each is converted the way a user runs it (``convert``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from wrinkle_setups import ROBOT, write_robot_setup

from wrinklepipe.cli import main
from wrinklepipe.io.confine import allowed_roots
from wrinklepipe.io.images import write_image

SIZE = 64

needs_robot = pytest.mark.skipif(not ROBOT.is_file(), reason="../shared/data is absent")


def _relief_pd(seed: int, cutoff: float = 12.0, slope: float = 0.08) -> np.ndarray:
    """PD slopes ``[H, W, 2]`` of a smooth random height field (frequencies below ``cutoff``
    cycles per texture), its slopes' std ``slope``."""
    rng = np.random.default_rng(seed)
    spec = np.fft.rfft2(rng.normal(size=(SIZE, SIZE)))
    fy = np.fft.fftfreq(SIZE)[:, None] * SIZE
    fx = np.fft.rfftfreq(SIZE)[None, :] * SIZE
    spec *= np.exp(-(fx**2 + fy**2) / (2 * cutoff**2))
    h = np.fft.irfft2(spec, s=(SIZE, SIZE))
    gy, gx = np.gradient(h)
    pd = np.stack([-gx, gy], -1)  # OpenGL: +Y up, rows run down
    return pd * (slope / pd.std())


def _ridges_pd(freq: int, slope: float = 0.06) -> np.ndarray:
    """PD slopes of ridges along u (``sin 2 pi freq v``): the wrinkle relief, everywhere."""
    v = (np.arange(SIZE) + 0.5) / SIZE
    pd = np.zeros((SIZE, SIZE, 2))
    pd[..., 1] = (slope * np.cos(2 * np.pi * freq * v))[:, None]
    return pd


def _encoded(pd: np.ndarray) -> np.ndarray:
    n = np.concatenate([pd, np.ones(pd.shape[:2] + (1,))], -1)
    return 0.5 + 0.5 * n / np.linalg.norm(n, axis=-1, keepdims=True)


def _setup(folder: Path, base_pd: np.ndarray, states_of: np.ndarray) -> Path:
    """The RobotExpressive setup with ``base_pd`` as the base and the states built on the
    relief ``states_of`` plus ridges everywhere (16-bit maps)."""
    manifest = write_robot_setup(folder)
    write_image(folder / "base.png", _encoded(base_pd), 16)
    write_image(folder / "stretch.png", _encoded(states_of + _ridges_pd(4)), 16)
    write_image(folder / "compress.png", _encoded(states_of + _ridges_pd(9)), 16)
    return manifest


def _convert(manifest: Path, out: Path, capsys) -> tuple[int, dict, list[str]]:
    with allowed_roots([ROBOT.parent]):
        code = main(["convert", str(manifest), "-o", str(out), "--no-render"])
    err = capsys.readouterr().err.replace("\n ", " ")
    said = [ln for ln in err.splitlines() if ln.startswith(("error ", "warning "))]
    return code, json.loads((out / "report.json").read_text()), said


def _fid(report: dict) -> list[dict]:
    return [i for i in report["validation"]["issues"] if i["code"] in ("WP-FID-006", "WP-FID-007")]


@needs_robot
def test_robot_states_that_keep_the_base_detail_everywhere_are_silent(tmp_path, capsys):
    face = _relief_pd(1)
    code, report, said = _convert(_setup(tmp_path / "src", face, face), tmp_path / "out", capsys)
    assert code == 0, said
    assert _fid(report) == [] and not [s for s in said if "WP-FID" in s], said
    # the validator's own measurement of the shipped folder: the states differ from the base
    # on (nearly) the whole face outside the masks, and keep all of the base's detail
    capsys.readouterr()
    with allowed_roots([ROBOT.parent]):
        assert main(["validate-asset", str(tmp_path / "out"), "--json", "--no-render"]) == 0
    metrics = json.loads(capsys.readouterr().out)["metrics"]
    assert metrics["base_state_spread"] > 0.9
    assert metrics["base_detail_kept"] == pytest.approx([1.0, 1.0], abs=0.05)


@needs_robot
def test_robot_states_of_another_face_are_said_once(tmp_path, capsys):
    code, report, said = _convert(
        _setup(tmp_path / "src", _relief_pd(1), _relief_pd(2)), tmp_path / "out", capsys
    )
    assert code == 0  # a warning: the files are well formed, the bake is suspect
    issues = _fid(report)
    assert [i["code"] for i in issues] == ["WP-FID-007"], issues
    assert abs(issues[0]["data"]["detail_kept"]) < 0.15  # two independent faces: none kept
    assert issues[0]["data"]["spread"] > 0.9
    assert len([s for s in said if "WP-FID-007" in s]) == 1, said


@needs_robot
def test_robot_base_upside_down_is_a_mirror_not_another_face(tmp_path, capsys):
    face = _relief_pd(1)
    upside_down = face[::-1].copy()  # the base's image exported upside down
    manifest = _setup(tmp_path / "src", upside_down, face)
    code, report, said = _convert(manifest, tmp_path / "out", capsys)
    assert code == 1
    issues = _fid(report)
    assert [i["code"] for i in issues] == ["WP-FID-006"], issues
    assert "with the base flipped vertically (V) they keep it" in issues[0]["message"]
    assert abs(issues[0]["data"]["detail_kept"]) < 0.15
    # said once: not also a green flip (WP-MAP-003) or another face (WP-FID-007)
    codes = [i["code"] for i in report["validation"]["issues"]]
    assert "WP-MAP-003" not in codes and "WP-FID-007" not in codes
