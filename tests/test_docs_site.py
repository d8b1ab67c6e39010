"""The documentation site: it builds with warnings as errors (dead links and anchors, pages
missing from the nav), and every page under docs/ is in the nav."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from wrinklepipe.reference import PAGES

ROOT = Path(__file__).resolve().parent.parent
GENERATED = {*PAGES, "changelog.md"}  # made by ci/mkdocs_hooks.py when the site is built


def _nav_pages(node: object) -> list[str]:
    if isinstance(node, str):
        return [node]
    if isinstance(node, list):
        return [p for item in node for p in _nav_pages(item)]
    if isinstance(node, dict):
        return [p for v in node.values() for p in _nav_pages(v)]
    return []


def _config() -> dict:
    return yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))


def test_every_docs_page_is_in_the_nav() -> None:
    nav = _nav_pages(_config()["nav"])
    on_disk = {p.relative_to(ROOT / "docs").as_posix() for p in (ROOT / "docs").rglob("*.md")}
    orphans = sorted(on_disk - set(nav))
    assert not orphans, (
        f"pages under docs/ missing from mkdocs.yml's nav: {orphans}; add each under the "
        "section it belongs to (Guides for a user guide)"
    )
    missing = sorted(set(nav) - on_disk - GENERATED)
    assert not missing, f"mkdocs.yml's nav names pages that do not exist: {missing}"
    assert len(nav) == len(set(nav)), "a page is listed twice in the nav"
    assert not (GENERATED & on_disk), "a generated page also exists as a file under docs/"


def test_site_builds_with_warnings_as_errors(tmp_path: Path) -> None:
    if not (importlib.util.find_spec("mkdocs") and importlib.util.find_spec("material")):
        pytest.fail("mkdocs-material is not installed: rerun `bash ci/bootstrap.sh setup`")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=env,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    site = tmp_path / "site"
    for page in GENERATED:
        assert (site / page.replace(".md", ".html")).is_file(), page
    reference = (site / "reference" / "commands.html").read_text(encoding="utf-8")
    assert "--fail-on" in reference and "validate-asset" in reference


def test_home_page_points_at_every_page() -> None:
    """The site's home page (docs/index.md, which the README links) names every page, so a
    newcomer reading the docs on GitHub finds each one: add a new page to its list."""
    home = (ROOT / "docs" / "index.md").read_text(encoding="utf-8")
    files = {p.relative_to(ROOT / "docs").as_posix() for p in (ROOT / "docs").rglob("*.md")}
    pages = (files | set(_nav_pages(_config()["nav"]))) - {"index.md"}  # generated ones too
    missing = sorted(p for p in pages if f"({p})" not in home and f"({p}#" not in home)
    assert not missing, f"add to docs/index.md's list of pages: {missing}"
