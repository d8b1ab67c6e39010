"""The validate-asset command: exit codes, --fail-on, config, reports, bad inputs."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import jsonschema
import pytest

from wrinklepipe.cli import main
from wrinklepipe.paths import SCHEMAS_DIR

CORPUS = Path(__file__).resolve().parent / "corpus"
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
CFG = CORPUS / "config.toml"


def _gl() -> bool:
    from wrinklepipe.validate import gl as glw

    try:
        glw.create_context().release()
        return True
    except glw.GLUnavailable:
        return False


needs_gl = pytest.mark.skipif(not _gl(), reason="no OpenGL 3.3 (EGL) on this machine")


def run(capsys, *args):
    code = main(["validate-asset", *map(str, args)])
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return code, out, err


def test_clean_asset_exits_0_and_json_matches_the_schema(capsys):
    code, out, err = run(
        capsys, CORPUS / "clean" / "asset.wpv", "--config", CFG, "--json", "--no-render"
    )
    assert code == 0, err
    doc = json.loads(out)
    jsonschema.validate(doc, json.loads((SCHEMAS_DIR / "report.schema.json").read_text()))
    assert doc["counts"] == {"error": 0, "warning": 0, "info": 1}
    assert doc["issues"][0]["code"] == "WP-TEX-007"
    assert "passed" in err


def test_errors_exit_1(capsys):
    code, out, err = run(capsys, CORPUS / "map_flipped_green" / "asset.wpv", "--config", CFG)
    assert code == 1
    assert "WP-MAP-003" in err and "FAILED" in err


def test_fail_on_warning_and_info(capsys):
    case = CORPUS / "mask_empty" / "asset.wpv"  # a warning (WP-MASK-003) and an info
    assert run(capsys, case, "--config", CFG, "--no-render")[0] == 0
    assert run(capsys, case, "--config", CFG, "--no-render", "--fail-on", "warning")[0] == 1
    clean = CORPUS / "clean" / "asset.wpv"
    assert run(capsys, clean, "--config", CFG, "--no-render", "--fail-on", "info")[0] == 1


def test_config_ignores_and_changes_severity(capsys, tmp_path):
    case = CORPUS / "weight_out_of_range" / "asset.wpv"
    cfg = tmp_path / "v.toml"
    cfg.write_text('ignore = ["WP-TEX-007"]\n[severity]\n"WP-WGT-001" = "warning"\n')
    code, out, _ = run(capsys, case, "--config", cfg, "--no-render", "--json")
    doc = json.loads(out)
    assert code == 0
    assert [i["code"] for i in doc["issues"]] == ["WP-WGT-001"]
    assert doc["issues"][0]["severity"] == "warning"
    assert doc["ignored"] == 1
    # the Khronos validator's JSON keys work too (0 error, 1 warning, 2 info, 3 ignore)
    kcfg = tmp_path / "k.json"
    kcfg.write_text(json.dumps({"validation": {"severityOverrides": {"WP-TEX-007": 0}}}))
    code, out, _ = run(capsys, case, "--config", kcfg, "--no-render", "--json")
    doc = json.loads(out)
    assert code == 1
    assert {i["code"]: i["severity"] for i in doc["issues"]}["WP-TEX-007"] == "error"


def test_bad_config_exits_2(capsys, tmp_path):
    cfg = tmp_path / "v.toml"
    cfg.write_text('ignore = ["WP-NOPE-001"]\n[severity]\n"WP-TEX-007" = "fatal"\n')
    code, _, err = run(capsys, CORPUS / "clean" / "asset.wpv", "--config", cfg)
    assert code == 2
    assert "WP-NOPE-001" in err and "fatal" in err


@pytest.mark.parametrize(
    "name, content, words",
    [
        ("missing.glb", None, "not found"),
        ("empty.gltf", b"", "empty"),
        ("broken.gltf", b"{nope", "invalid JSON"),
        ("plain.gltf", b'{"asset": {"version": "2.0"}}', "carries no wrinkle data"),
        ("picture.png", b"\x89PNG....", "unsupported file type"),
        ("bad.wpv", b"PK nope", "not a validation bundle"),
    ],
)
def test_unusable_inputs_exit_2(capsys, tmp_path, name, content, words):
    p = tmp_path / name
    if content is not None:
        p.write_bytes(content)
    code, _, err = run(capsys, p)
    assert code == 2
    assert words in err


@needs_gl
def test_html_report_with_images_beside_it(capsys, tmp_path):
    html = tmp_path / "out" / "report.html"
    code, _, err = run(
        capsys,
        CORPUS / "render_leak" / "asset.wpv",
        "--config",
        CFG,
        "--html",
        html,
        "--report",
        tmp_path / "out" / "report.json",
    )
    assert code == 1, err
    text = html.read_text()
    files = sorted(p.name for p in (tmp_path / "out" / "report_files").iterdir())
    assert "render_neutral.png" in files and "gpu_error_anger.png" in files
    assert "mask_overlay.png" in files and "shipping_error_anger.png" in files
    for f in files:
        assert f"report_files/{f}" in text
    assert "http://" not in text and "https://" not in text  # opens with no network
    assert "WP-RND-002" in text
    doc = json.loads((tmp_path / "out" / "report.json").read_text())
    assert doc["exit_code"] == 1


def test_report_is_byte_identical_on_rerun(capsys, tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    case = CORPUS / "mask_lr_swapped" / "asset.wpv"
    run(capsys, case, "--config", CFG, "--no-timings", "--report", a)
    run(capsys, case, "--config", CFG, "--no-timings", "--report", b)
    assert a.read_bytes() == b.read_bytes()
    assert json.loads(a.read_text())["timings"] == {}


@needs_gl
def test_converted_gltf_folder_loads(capsys, tmp_path):
    from wrinklepipe.demo.package import demo_package
    from wrinklepipe.gltf.package_write import write_gltf

    write_gltf(demo_package(64), tmp_path / "out", "demo")
    code, out, err = run(capsys, tmp_path / "out", "--render-size", "128", "--json")
    doc = json.loads(out)
    assert doc["input"]["kind"] == "folder"
    assert {t["role"] for t in doc["input"]["textures"]} == {"base", "state", "mask"}
    assert code in (0, 1), err
    assert "gpu_vs_reference_deg" in doc["metrics"]


GLTF_CORPUS = SHARED / "gltf-validator-corpus"


@pytest.mark.shared
@pytest.mark.skipif(not GLTF_CORPUS.is_dir(), reason="../shared/data is absent")
def test_khronos_validator_corpus_gives_clear_messages(capsys):
    files = sorted(p for p in GLTF_CORPUS.rglob("*") if p.is_file())
    assert len(files) > 100
    slow = []
    for p in files:
        # CPU seconds, not wall-clock: a loaded machine stretches the one, not the other
        t0 = time.process_time()
        code = main(["validate-asset", str(p)])
        dt = time.process_time() - t0
        _, err = capsys.readouterr()
        err = re.sub(r"(?m)^ *\d+\.\d s  .*\n", "", err)  # the progress lines of a log
        assert code in (1, 2), p
        assert "Traceback" not in err, p
        assert err.strip().startswith("error:") or "FAILED" in err, (p, err)
        if dt > 10.0:
            slow.append((p, dt))
    assert not slow


@needs_gl
def test_bench_validate_quick_smoke():
    from wrinklepipe.bench.validate import bench_validate

    res = bench_validate(quick=True)
    steps = {r.step for r in res.rows}
    assert "plain normal-map shader" in steps
    assert res.extra["wrinkle_vs_plain_split"] > 0


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    from wrinklepipe.demo.source import write_demo_source
    from wrinklepipe.jobs.convert import ConvertOptions, convert

    root = tmp_path_factory.mktemp("conv")
    manifest = write_demo_source(root / "src", size=128)
    # without the render pass: these tests validate the folder themselves (--no-render)
    convert(manifest, root / "out", ConvertOptions(glb=True, usd_format="usdz", render=False))
    return manifest, root / "out"


def test_convert_output_with_its_source(capsys, converted):
    manifest, out = converted
    code, text, err = run(
        capsys, out, "--source", manifest, "--render-size", "128", "--json", "--no-render"
    )
    doc = json.loads(text)
    assert doc["input"]["kind"] == "folder" and doc["input"]["has_source"]
    # the BC5 copies in compressed/ (written where BC5 meets the budget) are what is validated
    fmts = {t["role"]: t["format"] for t in doc["input"]["textures"]}
    compressed = {p.stem for p in (out / "compressed").glob("*.dds")}
    for t in doc["input"]["textures"]:
        if t["role"] in ("base", "state"):
            assert (t["format"] == "bc5") == (t["name"] in compressed), t
        elif t["role"] != "mask":  # the demo's colour maps: their sRGB BC7 copies
            assert (t["format"] == "bc7") == (t["name"] in compressed), t
    assert fmts["mask"] == "rgba8"
    assert set(doc["metrics"]["shipping_error_deg"]) >= {"neutral", "joy", "anger"}
    assert code == (1 if doc["counts"]["error"] else 0)
    # the PNGs of the same folder, and the USD package, load too
    code, text, _ = run(capsys, out, "--textures", "png", "--no-render", "--json")
    assert {t["format"] for t in json.loads(text)["input"]["textures"]} <= {"rgb8", "rgba8"}
    usdz = next(out.glob("*.usdz"))
    code, text, _ = run(capsys, usdz, "--no-render", "--json")
    assert json.loads(text)["input"]["kind"] == "usd"


def test_manifest_before_conversion(capsys, converted):
    manifest, _ = converted
    code, text, err = run(capsys, manifest, "--no-render", "--json")
    doc = json.loads(text)
    assert doc["input"]["kind"] == "manifest" and doc["input"]["has_source"]
    assert code == 0, err
    assert "shipping_error_deg" in doc["metrics"]


@needs_gl
def test_html_report_is_byte_identical_on_rerun(capsys, tmp_path):
    case = CORPUS / "mask_wrong_side" / "asset.wpv"
    pages = []
    for d in ("a", "b"):
        html = tmp_path / d / "report.html"
        run(capsys, case, "--config", CFG, "--html", html)
        pages.append((html.read_bytes(), sorted((tmp_path / d / "report_files").iterdir())))
    assert pages[0][0] == pages[1][0]
    for fa, fb in zip(pages[0][1], pages[1][1]):
        assert fa.name == fb.name and fa.read_bytes() == fb.read_bytes()
