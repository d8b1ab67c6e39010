"""The golden corpus: every case gives exactly the codes it was built to trigger, and its whole
report (volatile fields removed) matches the stored one. Rebuild with tests/corpus/generate.py."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from wrinklepipe.atomic import dumps_json
from wrinklepipe.validate import RULES, load_config, validate
from wrinklepipe.validate.loader import read_bundle
from wrinklepipe.validate.report import normalized, report_json

CORPUS = Path(__file__).resolve().parent / "corpus"
CASES = json.loads((CORPUS / "cases.json").read_text())["cases"]


@pytest.fixture(scope="module")
def need_gl():
    from wrinklepipe.validate import gl as glw

    try:
        glw.create_context().release()
    except glw.GLUnavailable as exc:
        pytest.skip(f"the golden reports include the render pass; no OpenGL: {exc}")


@pytest.fixture(scope="module")
def config():
    return load_config(CORPUS / "config.toml")


@pytest.mark.gpu
@pytest.mark.parametrize("case", CASES, ids=[c["name"] for c in CASES])
def test_corpus_case(case, config, need_gl):
    folder = CORPUS / case["name"]
    report = validate(read_bundle(folder / "asset.wpv"), config=config)
    assert sorted({i.code for i in report.issues}) == case["expect"], case["description"]
    got = normalized(report_json(report))
    want = json.loads((folder / "expected.json").read_text())
    assert dumps_json(got) == dumps_json(want)


def test_every_error_rule_has_a_corpus_case():
    covered = {code for c in CASES for code in c["expect"]}
    errors = {r.code for r in RULES if r.severity == "error"}
    assert errors - covered == set()
    # each error code is the *point* of at least one case: named in a case that is about it
    assert len(CASES) >= len(errors)


@pytest.mark.parametrize(
    "defect, case, code",
    [
        ("flipped green channel", "map_flipped_green", "WP-MAP-003"),
        ("swapped mask channels", "mask_swapped_channels", "WP-MASK-004"),
        ("swapped left/right mask channels", "mask_lr_swapped", "WP-MASK-005"),
        ("mask painted on the wrong side", "mask_wrong_side", "WP-MASK-005"),
        ("sRGB-tagged normal map", "tex_srgb_normal", "WP-TEX-001"),
        ("sRGB-tagged normal map seen by the GPU", "tex_srgb_normal", "WP-RND-001"),
        ("diff map declared as pd", "map_diff_declared_pd", "WP-MAP-006"),
        ("a base of another face", "fid_other_face", "WP-FID-007"),
        ("a base mirrored vertically", "map_base_flipped_v", "WP-FID-006"),
    ],
)
def test_injected_defects_are_caught(defect, case, code):
    expect = next(c for c in CASES if c["name"] == case)["expect"]
    assert code in expect, defect
    # and the clean asset does not give it
    clean = next(c for c in CASES if c["name"] == "clean")["expect"]
    assert code not in clean


def test_states_with_relief_everywhere_are_not_misaligned():
    """The WP-FID-007 false alarm: states that keep the base's detail and add wrinkle relief
    over the whole face are of one face (the clean demo's codes only)."""
    expect = next(c for c in CASES if c["name"] == "fid_detail_everywhere")["expect"]
    clean = next(c for c in CASES if c["name"] == "clean")["expect"]
    assert expect == clean


def test_a_mirrored_base_is_said_once():
    """A base flipped vertically also fails the curl test; the report names the mirror
    (WP-FID-006) and not also a green flip (WP-MAP-003)."""
    expect = next(c for c in CASES if c["name"] == "map_base_flipped_v")["expect"]
    assert "WP-FID-006" in expect and "WP-MAP-003" not in expect
