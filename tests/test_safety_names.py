"""Issue 39, names: every file convert writes is unique case-insensitively (states ``Ab`` and
``ab``, regions ``Nose`` and ``nose``, expressions ``Joy`` and ``joy``): the USD layer's
textures, the compressed copies and the validation pictures no longer overwrite each other on
macOS and Windows, and every reference (glTF URIs, USD asset paths, HTML images) names the file
written for it."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.names import file_stems, unique_name
from wrinklepipe.presets import jimenez


def test_unique_names_fold_case_only_when_asked():
    taken: set[str] = set()
    assert [unique_name(n, taken, fold_case=True) for n in ("Ab", "ab", "AB", "ab_2")] == [
        "Ab",
        "ab_2",
        "AB_3",
        "ab_2_2",
    ]
    assert [unique_name(n, set()) for n in ("Ab", "ab")] == ["Ab", "ab"]
    assert file_stems(["r/joy", "r/Joy", "s/joy"]) == {
        "r/Joy": "r_Joy",
        "r/joy": "r_joy_2",
        "s/joy": "s_joy",
    }


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("names")
    m = write_demo_source(root / "src", 16)
    regions = {"nose_l": "Nose", "nose_r": "nose"}
    table = jimenez.expression_table()
    table["Joy"] = dict(table["joy"])
    rows = []
    for expr, row in table.items():
        rows.append(f"[expressions.{expr}]")
        rows += [f"{regions.get(r, r)} = {w}" for r, w in row.items()]
    text = m.read_text()
    for old, new in {**regions, "stretch": "Ab", "compress": "ab"}.items():
        text = text.replace(f'name = "{old}"', f'name = "{new}"')
    text = text.replace('expressions = "jimenez"\n', "")
    text = text.replace("[resolution]", "\n".join(rows) + "\n\n[resolution]", 1)
    m.write_text(text)
    out = root / "out"
    assert main(["convert", str(m), "-o", str(out), "--no-render", "--usdc"]) in (0, 1)
    return out


def test_no_two_outputs_differ_only_in_case(written):
    files = [p.relative_to(written).as_posix() for p in written.rglob("*") if p.is_file()]
    folded = [f.casefold() for f in files]
    assert len(set(folded)) == len(folded), sorted(
        f for f in files if folded.count(f.casefold()) > 1
    )
    assert {"textures/wrinkle_Ab.png", "textures/wrinkle_ab_2.png"} <= set(files)
    assert {"compressed/wrinkle_Ab.dds", "compressed/wrinkle_ab_2.ktx2"} <= set(files)


def test_every_reference_names_a_file_that_was_written(written):
    doc = json.loads((written / "demo_head.gltf").read_text())
    uris = [i["uri"] for i in doc["images"]] + [b["uri"] for b in doc["buffers"]]
    for m in doc["materials"]:
        for c in m.get("extensions", {}).get("WRINKLEPIPE_wrinkle_maps", {}).get("compressed", []):
            uris += c["uris"]
    usda = (written / "demo_head.usda").read_text()
    uris += [u for u in re.findall(r"@([^@]+)@", usda) if not u.endswith((".usda", ".usdc"))]
    for page in ("validation.html", "report.html"):
        uris += re.findall(r"src='([^']+)'", (written / page).read_text())
    missing = sorted({u for u in uris if not (written / u.lstrip("./")).is_file()})
    assert not missing, missing
    assert (
        "wrinkle_ab_2" in usda
        and "validation_files/region_mask_nose_2.png" in (written / "report.html").read_text()
    )


def test_batch_outputs_that_differ_only_in_case_are_refused(tmp_path, capsys):
    """Characters ``Ada/`` and ``ada/`` (a case-sensitive source tree) would be written to
    ``OUT/Ada/...`` and ``OUT/ada/...``: one folder on macOS and Windows. Refused up front,
    nothing written."""
    for name in ("Ada", "ada"):
        m = write_demo_source(tmp_path / "src" / name, 16)
        m.write_text(m.read_text() + f"# {name}\n")
    out = tmp_path / "out"
    assert main(["batch", str(tmp_path / "src"), "-o", str(out), "--no-render"]) == 2
    err = capsys.readouterr().err
    assert "differs only in case from 'Ada/manifest'" in err, err
    assert not out.exists()
