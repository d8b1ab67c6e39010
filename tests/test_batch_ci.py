"""The CI examples: ``ci/asset_conversion.sh`` runs ``wrinklepipe batch`` over a repository with
the cache and writes JUnit, SARIF and the summary; the GitHub and GitLab examples use it so."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import xmlschema
import yaml

from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.paths import ROOT

SCRIPT = ROOT / "ci" / "asset_conversion.sh"
SCHEMAS = Path(__file__).parent / "schemas"


def test_asset_conversion_script_converts_then_serves_from_the_cache(tmp_path):
    repo = tmp_path / "repo"
    # two characters whose folders have the same name: the old loop wrote both to $OUT/face
    write_demo_source(repo / "heroes" / "face", 32)
    write_demo_source(repo / "villains" / "face", 32)
    wp = shutil.which("wrinklepipe", path=str(Path(sys.executable).parent))
    env = {
        **os.environ,
        "WRINKLEPIPE": wp,
        "OUT": str(tmp_path / "out"),
        "CACHE": str(tmp_path / "cache"),
        "REPORTS": str(tmp_path / "reports"),
    }

    def run(**extra: str) -> dict:
        proc = subprocess.run(
            ["bash", str(SCRIPT), "--no-render", "--jobs", "1"],
            cwd=repo,
            env={**env, **extra},
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert proc.returncode == 0, proc.stderr + proc.stdout
        logs.append(proc.stderr)
        return json.loads((tmp_path / "reports" / "summary.json").read_text())

    logs: list[str] = []
    first = run()
    # a CI log: one plain line per asset as it finishes, its verdict, time and where it came from
    for asset in ("heroes/face/manifest", "villains/face/manifest"):
        assert re.search(rf"^passed {asset} \(\d+\.\d s, converted\)$", logs[0], re.M), logs[0]
    assert "\x1b[" not in logs[0]  # no terminal codes in a log
    assert [(a["id"], a["source"]) for a in first["assets"]] == [
        ("heroes/face/manifest", "converted"),
        ("villains/face/manifest", "converted"),
    ]
    assert (tmp_path / "out/heroes/face/manifest/demo_head.gltf").is_file()
    assert (tmp_path / "out/villains/face/manifest/demo_head.gltf").is_file()
    xmlschema.XMLSchema(SCHEMAS / "junit-10.xsd").validate(tmp_path / "reports" / "junit.xml")
    assert json.loads((tmp_path / "reports" / "wrinkles.sarif").read_text())["version"] == "2.1.0"
    second = run()
    assert [a["source"] for a in second["assets"]] == ["cache", "cache"]
    assert re.search(r"^passed heroes/face/manifest \(\d+\.\d s, from cache\)$", logs[1], re.M)
    assert second["cache"]["hits"] == 2

    # BASE: only the manifests changed since BASE (the cache still applies)
    def git(*args: str) -> None:
        subprocess.run(
            ["git", "-c", "user.name=ci", "-c", "user.email=ci@example.com", *args],
            cwd=repo,
            check=True,
            capture_output=True,
        )

    git("init", "-q")
    git("add", "-A")
    git("commit", "-q", "-m", "characters")
    m = repo / "villains" / "face" / "manifest.toml"
    m.write_text(m.read_text().replace("# wrinklepipe demo", "# the villain, wrinklepipe demo"))
    git("commit", "-q", "-am", "villain")
    third = run(BASE="HEAD~1")
    assert [(a["id"], a["source"]) for a in third["assets"]] == [
        ("villains/face/manifest", "converted")
    ]


def test_ci_examples_run_batch_with_cache_junit_and_sarif():
    gh = yaml.safe_load((ROOT / "ci" / "github-actions-example.yml").read_text())
    steps = gh["jobs"]["convert-and-validate"]["steps"]
    script = next(s["run"] for s in steps if "wrinklepipe batch" in s.get("run", ""))
    for flag in ("--cache .wrinkle-cache", "--junit", "--sarif", "--report"):
        assert flag in script
    uses = [s.get("uses", "") for s in steps]
    assert any(u.startswith("actions/cache@") for u in uses)
    assert any(u.startswith("github/codeql-action/upload-sarif@") for u in uses)
    gl = yaml.safe_load((ROOT / "ci" / "gitlab-ci-example.yml").read_text())["wrinkle-assets"]
    command = " ".join(gl["script"])
    assert "wrinklepipe batch" in command and "--junit wrinkle-reports/junit.xml" in command
    assert gl["artifacts"]["reports"]["junit"] == "wrinkle-reports/junit.xml"
    assert gl["cache"]["paths"] == [".wrinkle-cache/"]
    text = SCRIPT.read_text()
    assert "batch" in text and "for m in" not in text  # no shell loop over manifests
