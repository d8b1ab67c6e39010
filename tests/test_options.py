"""The manifest's ``[budget]`` declared once (``wrinklepipe.options``): its defaults are the
schema's, the loader builds it typed, and the automatic choices, the compressed copies and the
validator judge by the same budget."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from wrinklepipe.metrics import Budget
from wrinklepipe.options import (
    BUDGET_SCHEMA,
    DEFAULT_MAX_MEAN_DEG,
    DEFAULT_MAX_P99_DEG,
    RESOLUTION_SCHEMA,
    BudgetOptions,
    ResolutionOptions,
)
from wrinklepipe.paths import SCHEMAS_DIR
from wrinklepipe.pipeline import auto
from wrinklepipe.sources.manifest import load_manifest


def test_the_defaults_are_the_schemas():
    schema = json.loads((SCHEMAS_DIR / "manifest.schema.json").read_text())
    keys = schema["properties"]["budget"]["properties"]
    assert keys == BUDGET_SCHEMA
    assert (DEFAULT_MAX_MEAN_DEG, DEFAULT_MAX_P99_DEG) == (0.5, 2.0)
    assert (keys["max_mean_deg"]["default"], keys["max_p99_deg"]["default"]) == (0.5, 2.0)
    # every schema key is a field, so a new statistic is one more key and one more field
    assert set(keys) == set(BudgetOptions.__dataclass_fields__)


def test_a_left_out_key_takes_the_default_and_copies_fall_back_to_the_maps():
    assert BudgetOptions().maps() == Budget(0.5, 2.0, None)
    assert BudgetOptions(max_p99_deg=1.0).maps() == Budget(0.5, 1.0, None)
    assert BudgetOptions(max_max_deg=9.0).maps() == Budget(0.5, 2.0, 9.0)
    b = BudgetOptions(max_p99_deg=1.0)
    assert b.copies() == b.maps() and not b.compressed_given
    c = BudgetOptions(compressed_max_p99_deg=2.5)
    assert c.copies() == Budget(None, 2.5, None) and c.compressed_given
    assert auto.budgets(c) == (Budget(0.5, 2.0, None), Budget(None, 2.5, None))


def test_json_round_trip_keeps_only_what_was_given():
    table = {"max_mean_deg": 0.25, "compressed_max_p99_deg": 3, "max_bytes": 1024}
    b = BudgetOptions.from_json(table)
    assert b.compressed_max_p99_deg == 3.0 and isinstance(b.max_bytes, int)
    assert b.to_json() == {"compressed_max_p99_deg": 3.0, "max_bytes": 1024, "max_mean_deg": 0.25}
    assert BudgetOptions.from_json(b.to_json()) == b
    assert BudgetOptions.from_json(None) == BudgetOptions() and not BudgetOptions().given
    with pytest.raises(ValueError, match="max_typo"):
        BudgetOptions.from_json({"max_typo": 1})


def test_the_loader_builds_it_typed(tmp_path: Path):
    from wrinklepipe.demo.source import write_demo_source

    manifest = load_manifest(write_demo_source(tmp_path / "demo", 64))
    assert manifest.budget == BudgetOptions(max_mean_deg=0.5, max_p99_deg=2.0)
    text = manifest.path.read_text()
    start = text.index("[budget]")
    end = text.index("\n[", start + 1)
    manifest.path.write_text(text[:start] + text[end + 1 :])
    assert load_manifest(manifest.path).budget == BudgetOptions()


def test_formats_default_to_the_schema_and_load_typed(tmp_path: Path):
    from wrinklepipe.options import FORMATS_SCHEMA, FormatOptions

    assert FormatOptions().to_json() == {k: v["default"] for k, v in FORMATS_SCHEMA.items()}
    assert FormatOptions() == FormatOptions(
        base="auto", wrinkle="auto", mask="rgba8", mask_layout="rgba", color="auto"
    )
    assert FormatOptions.from_json({"base": "bc5"}) == FormatOptions(base="bc5")
    with pytest.raises(ValueError, match="wrinkles"):
        FormatOptions.from_json({"wrinkles": "bc5"})
    from wrinklepipe.demo.source import write_demo_source

    manifest = load_manifest(write_demo_source(tmp_path / "demo", 64))
    assert isinstance(manifest.formats, FormatOptions)


def test_resolution_is_typed_by_the_schema(tmp_path: Path):
    from wrinklepipe.demo.source import write_demo_source

    assert set(RESOLUTION_SCHEMA) == set(ResolutionOptions.__dataclass_fields__)
    r = ResolutionOptions.from_json({"mask": "auto", "base": 64, "color": 32})
    assert r == ResolutionOptions(base=64, mask="auto", color=32)
    assert r.sizes() == {"base": 64, "color": 32} and r.automatic() == ["mask"]
    assert ResolutionOptions.from_json(r.to_json()) == r
    assert ResolutionOptions.from_json(None) == ResolutionOptions()
    assert ResolutionOptions().sizes() == {} and ResolutionOptions().automatic() == []
    with pytest.raises(ValueError, match="height"):
        ResolutionOptions.from_json({"height": 4})
    manifest = load_manifest(write_demo_source(tmp_path / "demo", 64))
    assert manifest.resolution == ResolutionOptions(
        base=64, wrinkle="auto", mask="auto", color="auto"
    )
