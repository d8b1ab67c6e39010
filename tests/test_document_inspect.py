"""``wrinklepipe inspect`` against an independent reader: glTF-Transform's ``inspect`` (npm
``@gltf-transform/cli``), on real files; ``--diff`` on a hand-made change."""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import gltf_reference as ref
import pytest

from wrinklepipe.cli import main
from wrinklepipe.gltf.document import read_document
from wrinklepipe.gltf.inspect import diff, image_size, summary
from wrinklepipe.gltf.write import write_document
from wrinklepipe.paths import ROOT

SAMPLES = Path(__file__).resolve().parents[2] / "shared" / "data" / "gltf-samples"
GLTF_TRANSFORM = ROOT / "tools" / "node" / "node_modules" / ".bin" / "gltf-transform"
needs_tools = pytest.mark.skipif(
    not SAMPLES.is_dir() or not GLTF_TRANSFORM.exists() or shutil.which("node") is None,
    reason="../shared/data or npm @gltf-transform/cli absent",
)


def gltf_transform_inspect(path: Path) -> dict[str, list[dict[str, str]]]:
    """glTF-Transform's inspect tables (CSV) by section title."""
    proc = subprocess.run(
        [str(GLTF_TRANSFORM), "inspect", str(path), "--format", "csv"],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    sections: dict[str, list[dict[str, str]]] = {}
    title, lines = None, []
    for line in proc.stdout.splitlines() + [" END"]:
        if line.startswith(" ") and line.strip().isupper():
            if title and lines:
                sections[title] = list(csv.DictReader(io.StringIO("\n".join(lines))))
            title, lines = line.strip(), []
        elif line.strip() and not line.strip().startswith("─") and "," in line:
            lines.append(line)
    return sections


def compare_with_gltf_transform(path: Path) -> dict:
    ours = summary(read_document(path))
    theirs = gltf_transform_inspect(path)
    assert [(m["name"], str(m["vertices"])) for m in ours["meshes"]] == [
        (r["name"], r["vertices"]) for r in theirs["MESHES"]
    ]
    assert [(m["name"], str(m["instances"])) for m in ours["materials"]] == [
        (r["name"], r["instances"]) for r in theirs["MATERIALS"]
    ]
    by_image = {t["image"]: t for t in ours["textures"]}
    assert [
        (by_image[i]["format"], "x".join(map(str, by_image[i]["size"])), str(by_image[i]["bytes"]))
        for i in sorted(by_image)
    ] == [(r["mimeType"], r["resolution"], r["size"]) for r in theirs.get("TEXTURES", [])]
    assert [
        (a["name"], str(a["channels"]), f"{a['duration']:.3f}", str(a["keyframes"]))
        for a in ours["animations"]
    ] == [
        (r["name"], r["channels"], f"{float(r['duration']):.3f}", r["keyframes"])
        for r in theirs.get("ANIMATIONS", [])
    ]
    return ours


@needs_tools
def test_robot_matches_gltf_transform():
    s = compare_with_gltf_transform(SAMPLES / "RobotExpressive" / "RobotExpressive.glb")
    assert len(s["meshes"]) == 14 and len(s["materials"]) == 3 and len(s["animations"]) == 14
    g = ref.load(SAMPLES / "RobotExpressive" / "RobotExpressive.glb")
    parent = {c: i for i, n in enumerate(g.nodes) for c in n.children}

    def depth(j: int, joints: set[int]) -> int:  # joints on the path up to the root joint
        return 1 + (depth(parent[j], joints) if parent.get(j) in joints else 0)

    expect = [(len(k.joints), max(depth(j, set(k.joints)) for j in k.joints)) for k in g.skins]
    assert [(k["joints"], k["depth"]) for k in s["skins"]] == expect == [(43, 11), (43, 11)]


@needs_tools
def test_helmet_textures_match_gltf_transform():
    s = compare_with_gltf_transform(SAMPLES / "DamagedHelmet" / "glTF-Binary" / "DamagedHelmet.glb")
    assert [t["size"] for t in s["textures"]] == [[2048, 2048]] * 5


def test_image_size_headers():
    png = b"\x89PNG\r\n\x1a\n" + b"\0\0\0\rIHDR" + (640).to_bytes(4, "big") + (8).to_bytes(4, "big")
    assert image_size(png) == (640, 8)
    ktx2 = (
        b"\xabKTX 20\xbb\r\n\x1a\n"
        + bytes(8)
        + (32).to_bytes(4, "little")
        + (16).to_bytes(4, "little")
    )
    assert image_size(ktx2) == (32, 16)
    jpeg = b"\xff\xd8" + b"\xff\xe0\x00\x04ab" + b"\xff\xc0\x00\x11\x08" + (7).to_bytes(2, "big")
    jpeg += (9).to_bytes(2, "big") + bytes(12)
    assert image_size(jpeg) == (9, 7)


@needs_tools
def test_diff_lists_exactly_the_change(tmp_path, capsys):
    src = SAMPLES / "RobotExpressive" / "RobotExpressive.glb"
    doc = read_document(src)
    doc.gltf["materials"][2]["doubleSided"] = True
    doc.add_animation({"name": "extra", "samplers": [], "channels": []})
    out = tmp_path / "r.glb"
    write_document(doc, out)
    lines = diff(summary(read_document(src)), summary(read_document(out)))
    assert lines == ["+ animations[14]: 'extra'", "~ materials[2].doubleSided: False -> True"]
    assert main(["inspect", "--diff", str(src), str(out), "--json"]) == 1
    assert json.loads(capsys.readouterr().out)["differences"] == lines
    assert main(["inspect", "--diff", str(src), str(src)]) == 0


@pytest.mark.skipif(not SAMPLES.is_dir(), reason="../shared/data is absent")
def test_piped_inspect_cuts_no_cell():
    """In a CI log (a pipe, no COLUMNS) the tables are as wide as their cells: every attribute
    list and name whole, never cut to 80 columns with an ellipsis."""
    robot = SAMPLES / "RobotExpressive" / "RobotExpressive.glb"
    env = {k: v for k, v in os.environ.items() if k != "COLUMNS"}
    proc = subprocess.run(
        [sys.executable, "-m", "wrinklepipe", "inspect", str(robot)],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    text = proc.stdout
    assert "…" not in text and "\x1b[" not in text
    attrs = "JOINTS_0:VEC4:u16, NORMAL:VEC3:f32, POSITION:VEC3:f32, WEIGHTS_0:VEC4:f32"
    assert attrs in text  # the longest cell, whole
    assert max(len(line) for line in text.splitlines()) > 120  # wider than a terminal's 80
