"""The source manifest: the demo loads; bad manifests list every problem with file and key."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.errors import InputError
from wrinklepipe.io.images import write_image
from wrinklepipe.options import ResolutionOptions
from wrinklepipe.paths import SCHEMAS_DIR
from wrinklepipe.sources.manifest import load_manifest, manifest_schema


@pytest.fixture(scope="module")
def demo_src(tmp_path_factory) -> Path:
    return write_demo_source(tmp_path_factory.mktemp("demo") / "src", size=64).parent


@pytest.fixture
def src(demo_src, tmp_path) -> Path:
    out = tmp_path / "src"
    shutil.copytree(demo_src, out)
    return out


def test_schema_is_valid_json_schema():
    jsonschema.Draft202012Validator.check_schema(manifest_schema())
    assert json.loads((SCHEMAS_DIR / "manifest.schema.json").read_text())["title"]


def test_demo_manifest_loads(src):
    m = load_manifest(src / "manifest.toml")
    assert m.name == "demo_head"
    assert [s.name for s in m.states] == ["stretch", "compress"]
    assert len(m.regions) == 8
    assert m.expressions["surprise"]["forehead_inner_l"] == 0.8
    assert m.mesh == (src / "head.glb").resolve()
    assert m.resolution == ResolutionOptions(base=64, wrinkle="auto", mask="auto", color="auto")
    assert m.resolution.sizes() == {"base": 64}
    assert m.resolution.automatic() == ["color", "mask", "wrinkle"]


def _problems(path: Path) -> list[tuple[str, str, str]]:
    with pytest.raises(InputError) as info:
        load_manifest(path)
    return [(p.file, p.key, p.message) for p in info.value.problems]


def test_every_schema_problem_is_listed_at_once(src):
    text = (src / "manifest.toml").read_text()
    text = text.replace('encoding = "pd"', 'encoding = "pd"\ncolour = "blue"')  # unknown key
    text = text.replace('policy = "clamp01"', "policy = 3")  # wrong type
    text = text.replace("max_p99_deg = 2.0", 'max_p99_deg = "two"')
    (src / "manifest.toml").write_text(text)
    probs = _problems(src / "manifest.toml")
    keys = {k for _, k, _ in probs}
    assert {"colour", "policy", "budget.max_p99_deg"} <= keys
    assert all(f.endswith("manifest.toml") for f, _, _ in probs)
    assert len(probs) == 3


def test_every_semantic_problem_is_listed_at_once(src):
    text = (src / "manifest.toml").read_text()
    text = text.replace('base = "base_normal.png"', 'base = "missing_base.png"')
    # duplicate region: rename chin to glabella
    text = text.replace('name = "chin"', 'name = "glabella"')
    # an out-of-range weight and an unknown region in a custom expression table (at the end:
    # TOML tables come after top-level keys)
    text = text.replace('expressions = "jimenez"\n', "")
    text += "\n[expressions.wince]\nnose_l = 3.5\ncheek = 0.5\n"
    (src / "manifest.toml").write_text(text)
    # a mask of another size
    write_image(src / "masks" / "nose_l.png", np.zeros((32, 32)), bits=8)
    probs = _problems(src / "manifest.toml")
    by_key = {k: m for _, k, m in probs}
    assert "file not found" in by_key["base"]
    assert "duplicate region name 'glabella'" in by_key["regions[7].name"]
    assert "out of range" in by_key["expressions.wince.nose_l"]
    assert "unknown region 'cheek'" in by_key["expressions.wince.cheek"]
    assert "different sizes" in by_key["regions"]
    # the demo's expressions driver keys Table 1.1's expressions, which the new table lacks:
    # found at load too (not after the stages have run)
    driver = [m for _, k, m in probs if k.startswith("drivers[0].keys.")]
    assert driver and all("unknown expression" in m and "wince" in m for m in driver)
    assert len(probs) == 5 + len(driver)


def test_invalid_toml_names_the_line(src):
    (src / "manifest.toml").write_text('name = "x"\nbase = \n')
    probs = _problems(src / "manifest.toml")
    assert len(probs) == 1 and "invalid TOML" in probs[0][2] and "line 2" in probs[0][2]


def test_missing_manifest(tmp_path):
    probs = _problems(tmp_path / "nope.toml")
    assert probs[0][2] == "manifest not found"


def test_signed_policy_needs_two_states(src):
    text = (src / "manifest.toml").read_text().replace('policy = "clamp01"', 'policy = "signed"')
    text, n = re.subn(r'\[\[states\]\]\nname = "compress"\n(?:[^\[\n][^\n]*\n)*', "", text)
    assert n == 1  # the state and its lines (map, color), up to the next table
    (src / "manifest.toml").write_text(text)
    probs = _problems(src / "manifest.toml")
    # Table 1.1 weights are in [-1, 1], so only the state count is wrong.
    assert [(k, "two states" in m) for _, k, m in probs] == [("policy", True)]
