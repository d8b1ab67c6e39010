"""``wrinklepipe capture`` end to end, and one clear message (exit 2) per bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from wrinklepipe.cli import main
from wrinklepipe.io.images import read_header, read_image, write_image
from wrinklepipe.metrics import angle_deg
from wrinklepipe.model import normalize


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("cap") / "session"
    assert main(["capture", "--example", str(folder)]) == 0
    return folder


@pytest.fixture(scope="module")
def base(session, tmp_path_factory) -> Path:
    """One default run on the example session, shared by the tests that read its outputs."""
    out = tmp_path_factory.mktemp("cap_base") / "a"
    assert main(_args(session, out)) == 0
    return out


def _args(s: Path, out: Path) -> list[str]:
    return [
        "capture",
        str(s / "neutral.png"),
        str(s / "expression.png"),
        "--neutral-landmarks",
        str(s / "neutral.json"),
        "--expression-landmarks",
        str(s / "expression.csv"),
        "--texture-landmarks",
        str(s / "texture.json"),
        "--size",
        "128",
        "--roi",
        str(s / "roi.png"),
        "--truth",
        str(s / "truth_texture.png"),
        "-o",
        str(out),
    ]


def test_end_to_end_outputs_report_and_determinism(session, base, tmp_path, capsys):
    out = base
    report = json.loads((out / "report.json").read_text())
    info = read_header(out / "capture.png")
    assert (info.width, info.height, info.channels, info.format) == (128, 128, 3, "uint16")
    # The written map, decoded, is far closer to the truth than a flat map.
    n = normalize(2.0 * read_image(out / "capture.png")[0] - 1.0)
    t = normalize(2.0 * read_image(session / "truth_texture.png")[0] - 1.0)
    roi = read_image(out / "capture_roi.png")[0][..., 0] > 0.5
    err = angle_deg(n, t)[roi].mean()
    flat = np.degrees(np.arccos(np.clip(t[..., 2], -1, 1)))[roi].mean()
    assert err < 0.5 * flat
    # Report: residuals after each warp, clipped fractions, every method side by side.
    assert report["method"] == "integrable"
    w1, w2 = report["warps"]["expression_to_neutral"], report["warps"]["photo_to_texture"]
    assert w1["count"] == w2["count"] == 36 and w1["fit_max_px"] < 0.02
    assert 0.0 < w1["leave_one_out_max_px"] < 1.0
    for key in ("fraction_dark", "fraction_clipped", "fraction_clipped_raw", "exposure_factor"):
        assert key in report["ratio"]
    assert report["ratio"]["exposure_factor"] == pytest.approx(0.93 / 0.9, abs=3e-3)
    means = {m: report["orientation"][m]["truth"]["angular"]["mean"] for m in report["orientation"]}
    assert set(means) == {"gradient", "furrow", "integrable"}  # no neutral normals: no sfs
    # auto is the integrable prior, the best of the priors here
    assert min(means, key=means.get) == "integrable"
    # every method states how well it explains the photos (lower is better)
    resid = {m: report["orientation"][m]["ratio_residual"] for m in means}
    assert all(v > 0 for v in resid.values())
    assert resid["gradient"] > resid["integrable"]
    # The HTML sheet references pictures that exist beside it; no network.
    html = (out / "report.html").read_text()
    pics = sorted(p.name for p in (out / "pictures").iterdir())
    assert "ratio.png" in pics and "normal_texture_integrable.png" in pics
    for name in pics:
        assert f"pictures/{name}" in html
    assert "http" not in html
    snippet = (out / "manifest_snippet.toml").read_text()
    assert 'map = "capture.png"' in snippet and "states_include_base = false" in snippet
    # The snippet makes a valid manifest with a base map (the lead's loader and schema).
    from wrinklepipe.sources.manifest import load_manifest

    write_image(out / "base.png", np.broadcast_to([0.5, 0.5, 1.0], (128, 128, 3)), bits=16)
    text = 'name = "captured"\nbase = "base.png"\nstates_include_base = false\n\n' + snippet
    (out / "manifest.toml").write_text(text)
    m = load_manifest(out / "manifest.toml")
    assert [s.name for s in m.states] == ["capture"] and not m.states_include_base
    assert m.regions[0].states == ("capture",)
    (out / "manifest.toml").unlink()
    (out / "base.png").unlink()
    # Byte-identical on rerun; --json prints the same report.
    out2 = tmp_path / "b"
    capsys.readouterr()
    assert main(_args(session, out2) + ["--json"]) == 0
    assert json.loads(capsys.readouterr().out) == report
    for f in sorted(p for p in out.rglob("*") if p.is_file()):
        assert f.read_bytes() == (out2 / f.relative_to(out)).read_bytes(), f.name


def test_orientation_choice_and_photo_space(session, tmp_path):
    args = _args(session, tmp_path / "g")
    # Without texture landmarks the map stays in photo space (192 x 192 here).
    i = args.index("--texture-landmarks")
    del args[i : i + 4]
    j = args.index("--truth")
    del args[j : j + 2]
    assert main(args + ["--orientation", "gradient"]) == 0
    assert read_header(tmp_path / "g" / "capture.png").width == 192
    report = json.loads((tmp_path / "g" / "report.json").read_text())
    assert report["method"] == "gradient" and report["outputs"]["space"] == "photo"


def test_neutral_normals_choose_the_solve(session, tmp_path):
    # The example's neutral normal map (the dome seen from the camera, 16-bit 0.5 + 0.5 n):
    # every method is compared with its ratio residual, and the residual of the solve is the
    # lowest (it explains the photos best).
    out = tmp_path / "nn"
    args = _args(session, out) + ["--neutral-normals", str(session / "neutral_normals.png")]
    assert main(args) == 0
    rep = json.loads((out / "report.json").read_text())
    # this dome turns by 8 degrees at most (N_z >= 0.99): auto takes the solve because one of
    # its starts (the prior's height without its broad part) ended well below the prior's
    # residual (measured 0.0018 vs 0.0023), and it is the better map against the truth
    assert rep["method"] == "sfs" and rep["neutral_shape"] == "normal map"
    resid = {m: v["ratio_residual"] for m, v in rep["orientation"].items()}
    assert set(resid) == {"gradient", "furrow", "integrable", "sfs"}
    assert min(resid, key=resid.get) == "sfs"
    assert rep["sfs"]["start"] in rep["sfs"]["starts_ratio_residual"]
    # the share of crease pixels whose sign the photos leave open, in the JSON, HTML, picture
    amb = rep["sfs"]["sign_ambiguous_fraction"]
    assert 0.0 <= amb <= 1.0 and rep["sfs"]["sign_observable"] is True
    assert f"{100 * amb:.0f} %</b> of its crease pixels" in (out / "report.html").read_text()
    assert (out / "pictures" / "sfs_ambiguous.png").is_file()
    truth = rep["orientation"]["sfs"]["truth"]  # measured 2.69 / 1.71 of 7.42 degrees, 92 %
    prior = rep["orientation"]["integrable"]["truth"]  # measured 3.36 / 2.76 degrees, 84 %
    assert truth["angular"]["mean"] < min(0.45 * truth["flat"]["mean"], prior["angular"]["mean"])
    assert truth["tilt"]["mean"] < min(0.3 * truth["flat"]["mean"], prior["tilt"]["mean"])
    assert truth["orientation_correct"] > max(0.9, prior["orientation_correct"])


def test_a_neutral_facing_the_camera_is_reported_unobservable(session, tmp_path, capsys):
    # A neutral normal map facing the camera everywhere: c and -c give the same photos, so the
    # solve's starts tie and lean opposite ways on every crease; the run says the sign is not
    # observable, why, and which photos would make it so (summary, report.json, .html).
    write_image(tmp_path / "flat.png", np.broadcast_to([0.5, 0.5, 1.0], (192, 192, 3)), bits=16)
    out = tmp_path / "flat"
    capsys.readouterr()
    assert main(_args(session, out) + ["--neutral-normals", str(tmp_path / "flat.png")]) == 0
    text = " ".join(capsys.readouterr().err.split())  # the summary goes to stderr
    rep = json.loads((out / "report.json").read_text())
    assert rep["method"] == "integrable"  # auto keeps the prior
    assert rep["sfs"]["sign_ambiguous_fraction"] > 0.9 and rep["sfs"]["sign_observable"] is False
    for where in (text, " ".join((out / "report.html").read_text().split())):
        assert "most crease signs are not in these photos" in where
        assert "turned from the camera" in where and "lit from one side" in where


def test_bad_neutral_normals(session, tmp_path, capsys):
    write_image(tmp_path / "small.png", np.full((64, 64, 3), 0.5), bits=8)
    away = np.zeros((192, 192, 3))
    away[..., 2] = 0.0  # z = -1: facing away from the camera
    write_image(tmp_path / "away.png", away, bits=8)
    for name, text in (("small.png", "64 x 64"), ("away.png", "not normals facing the camera")):
        capsys.readouterr()
        args = _args(session, tmp_path / "x") + ["--neutral-normals", str(tmp_path / name)]
        assert main(args) == 2
        msg = " ".join(capsys.readouterr().err.split())
        assert name in msg and text in msg and msg.count("error:") == 1
        assert not (tmp_path / "x").exists()
    capsys.readouterr()
    args = _args(session, tmp_path / "x") + ["--neutral-normals", str(tmp_path / "away.png")]
    assert main(args + ["--nz", "0.9"]) == 2
    assert "drop --nz" in capsys.readouterr().err


# --- bad inputs: one clear message each, exit code 2, nothing written -------------------------


@pytest.fixture()
def small(tmp_path) -> Path:
    rng = np.random.default_rng(0)
    write_image(tmp_path / "n.png", rng.uniform(0.3, 0.7, (64, 64)), bits=16)
    write_image(tmp_path / "e.png", rng.uniform(0.3, 0.7, (64, 64)), bits=16)
    write_image(tmp_path / "big.png", rng.uniform(0.3, 0.7, (64, 80)), bits=16)
    write_image(tmp_path / "black.png", np.zeros((64, 64)), bits=16)
    pts = [[10, 10], [50, 12], [30, 50], [12, 40]]
    (tmp_path / "a.json").write_text(json.dumps(pts))
    (tmp_path / "two.json").write_text(json.dumps(pts[:2]))
    (tmp_path / "three.json").write_text(json.dumps(pts[:3]))
    (tmp_path / "out.json").write_text(json.dumps([[10, 10], [70, 12], [30, 50], [12, 40]]))
    (tmp_path / "b.csv").write_text("x,y\n11,10\n51,12\n31,50\n13,41\n")
    return tmp_path


def _bad(small: Path, capsys, neutral: str, expr: str, lm_n: str, lm_e: str) -> str:
    code = main(
        [
            "capture",
            str(small / neutral),
            str(small / expr),
            "--neutral-landmarks",
            str(small / lm_n),
            "--expression-landmarks",
            str(small / lm_e),
            "-o",
            str(small / "result"),
        ]
    )
    text = " ".join(capsys.readouterr().err.split())
    assert code == 2
    assert text.count("error:") == 1, text
    assert "Traceback" not in text
    assert not (small / "result").exists()
    return text


def test_photos_of_different_sizes(small, capsys):
    msg = _bad(small, capsys, "n.png", "big.png", "a.json", "b.csv")
    assert "big.png" in msg and "80 x 64" in msg and "64 x 64" in msg


def test_fewer_than_three_landmarks(small, capsys):
    msg = _bad(small, capsys, "n.png", "e.png", "two.json", "two.json")
    assert "only 2 landmark" in msg and "at least 3" in msg


def test_landmarks_outside_the_image(small, capsys):
    msg = _bad(small, capsys, "n.png", "e.png", "out.json", "b.csv")
    assert "out.json" in msg and "outside the neutral photo" in msg and "(70.0, 12.0)" in msg


def test_mismatched_counts(small, capsys):
    msg = _bad(small, capsys, "n.png", "e.png", "three.json", "b.csv")
    assert "b.csv" in msg and "4 landmarks" in msg and "has 3" in msg


def test_all_black_photo(small, capsys):
    msg = _bad(small, capsys, "n.png", "black.png", "a.json", "b.csv")
    assert "black.png" in msg and "all black" in msg


def test_eight_bit_srgb_photos(session, tmp_path):
    # Camera-style 8-bit sRGB files: decoded to linear before the ratio (--colorspace srgb, as
    # 'auto' would pick for an untagged JPEG).
    s8 = tmp_path / "s8"
    s8.mkdir()
    for name in ("neutral", "expression"):
        lin = read_image(session / f"{name}.png")[0][..., 0].astype(np.float64)
        enc = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
        write_image(s8 / f"{name}.png", enc, bits=8)
    for f in ("neutral.json", "expression.csv", "texture.json", "roi.png", "truth_texture.png"):
        (s8 / f).write_bytes((session / f).read_bytes())
    out = tmp_path / "o8"
    assert main(_args(s8, out) + ["--colorspace", "srgb"]) == 0
    report = json.loads((out / "report.json").read_text())
    truth = report["orientation"]["integrable"]["truth"]
    assert truth["tilt"]["mean"] < 0.5 * truth["flat"]["mean"]
    assert truth["angular"]["mean"] < 0.6 * truth["flat"]["mean"]  # measured 4.0 vs 7.4
    assert report["ratio"]["exposure_factor"] == pytest.approx(0.93 / 0.9, abs=3e-3)


def test_photo_landmarks_and_nz_regions(session, base, tmp_path, capsys):
    # An explicit photo-side set equal to the neutral landmarks changes nothing.
    same = tmp_path / "same"
    assert main(_args(session, same) + ["--photo-landmarks", str(session / "neutral.json")]) == 0
    assert (same / "capture.png").read_bytes() == (base / "capture.png").read_bytes()
    # A neutral surface tilted away from the camera in a region: the same ratio means less
    # wrinkle tilt there (the extra tilt beyond the neutral's own), nothing changes elsewhere.
    mask = np.zeros((192, 192))
    mask[:, :96] = 1.0
    write_image(tmp_path / "left.png", mask, bits=8)
    tilted = tmp_path / "tilted"
    assert main(_args(session, tilted) + ["--nz-region", f"{tmp_path / 'left.png'}=0.9"]) == 0
    rep = json.loads((tilted / "report.json").read_text())
    assert rep["options"]["nz_regions"] == [f"{tmp_path / 'left.png'}=0.9"]
    zb = read_image(base / "pictures" / "normal_photo_integrable.png")[0][..., 2]
    zt = read_image(tilted / "pictures" / "normal_photo_integrable.png")[0][..., 2]
    assert np.array_equal(zb[:, 100:], zt[:, 100:])
    creased = zb[:, :90] < 0.97  # 0.5 + 0.5 z: tilted more than ~17 degrees
    assert creased.any() and np.all(zt[:, :90][creased] >= zb[:, :90][creased])
    # A malformed region is one clear message.
    capsys.readouterr()
    assert main(_args(session, tmp_path / "x") + ["--nz-region", "left.png"]) == 2
    assert "expects MASK=VALUE" in capsys.readouterr().err


@pytest.fixture(scope="module")
def side_session(tmp_path_factory) -> Path:
    """The nearly flat mixed session (N_z 0.995: ridges and valleys whose signs a camera light
    cannot show) at 128 px, with the expression photographed again lit from one side."""
    from wrinklepipe.capture.sessions import MIXED, SessionOptions, make_session

    s = make_session(
        SessionOptions(size=128, texture_size=64, nz_min=0.995, folds=MIXED,
                       side_light=(0.4, 0.3, 0.866))
    )  # fmt: skip
    d = tmp_path_factory.mktemp("cap_side")
    for name, img in (("neutral", s.neutral), ("expression", s.expression), ("side", s.side_lit)):
        write_image(d / f"{name}.png", img, bits=16)
    write_image(d / "roi.png", s.roi, bits=8)
    write_image(d / "n0.png", 0.5 + 0.5 * s.neutral_normals, bits=16)
    write_image(d / "truth.png", 0.5 + 0.5 * s.truth_photo, bits=16)  # the map stays in photo space
    for name, pts in (("n", s.lm_neutral), ("e", s.lm_expression)):
        (d / f"{name}.json").write_text(json.dumps(pts.tolist()))
    return d


def _side_args(d: Path, out: Path) -> list[str]:
    return [
        "capture", str(d / "neutral.png"), str(d / "expression.png"), "--colorspace", "linear",
        "--neutral-landmarks", str(d / "n.json"), "--expression-landmarks", str(d / "e.json"),
        "--roi", str(d / "roi.png"),
        "--neutral-normals", str(d / "n0.png"), "-o", str(out),
    ]  # fmt: skip


def test_a_side_lit_photo_makes_the_sign_observable(side_session, tmp_path):
    d = side_session
    out = tmp_path / "side"
    args = _side_args(d, out) + ["--side-lit", str(d / "side.png"), "--side-light", "4,3,8.66"]
    assert main(args) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["method"] == "sfs" and rep["sfs"]["sign_observable"] is True
    assert rep["side_lit"]["exposure"] == pytest.approx(0.7 / 0.88, rel=0.01)  # the two lights
    assert np.allclose(rep["side_lit"]["light"], [0.4, 0.3, 0.866], atol=1e-3)  # normalised
    n = normalize(2.0 * read_image(out / "capture.png")[0] - 1.0)
    t = normalize(2.0 * read_image(d / "truth.png")[0] - 1.0)
    roi = read_image(out / "capture_roi.png")[0][..., 0] > 0.5
    tilt = angle_deg(t, np.array([0.0, 0.0, 1.0]))
    flat = tilt[roi].mean()
    crease = roi & (tilt > 3.0)
    right = np.einsum("...c,...c->...", n[..., :2], t[..., :2])[crease] > 0
    # the targets (measured in texture space 0.14x, 0.11x, 100 %; without the side
    # photo the prior's 0.89x / 0.41x / 58 %, the sign flagged not observable)
    assert angle_deg(n, t)[roi].mean() < 0.3 * flat
    tilt_n = angle_deg(n, np.array([0.0, 0.0, 1.0]))
    assert np.abs(tilt_n - tilt)[roi].mean() < 0.2 * flat
    assert right.mean() > 0.95


@pytest.mark.parametrize(
    "extra, needle",
    [
        (["--side-lit", "SIDE"], "--side-lit and --side-light go together"),
        (["--side-light", "1,0,1"], "--side-lit and --side-light go together"),
        (["--side-lit", "SIDE", "--side-light", "1,0"], "must be X,Y,Z"),
        (["--side-lit", "SIDE", "--side-light", "1,0,0"], "in front of the face"),
    ],
)
def test_bad_side_lit_options(side_session, tmp_path, capsys, extra, needle):
    args = _side_args(side_session, tmp_path / "x")
    args += [str(side_session / "side.png") if a == "SIDE" else a for a in extra]
    capsys.readouterr()
    assert main(args) == 2
    assert needle in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_side_lit_needs_the_neutral_shape(side_session, tmp_path, capsys):
    args = _side_args(side_session, tmp_path / "x")
    i = args.index("--neutral-normals")
    del args[i : i + 2]
    args += ["--side-lit", str(side_session / "side.png"), "--side-light", "1,0,2"]
    assert main(args) == 2
    assert "--side-lit needs the neutral's shape" in capsys.readouterr().err
