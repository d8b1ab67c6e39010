"""mkdocs hooks: the generated pages of the documentation site.

The command, manifest and batch-file references are generated from the parsers and JSON schemas
(``wrinklepipe.reference``) and the changelog is the repository's ``CHANGELOG.md``, so none of
them is ever a stale copy. Listed in ``mkdocs.yml``'s ``hooks``.
"""

from __future__ import annotations

from pathlib import Path

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.structure.files import File, Files

from wrinklepipe.reference import PAGES

ROOT = Path(__file__).resolve().parent.parent


def on_files(files: Files, config: MkDocsConfig) -> Files:
    for uri, page in PAGES.items():
        files.append(File.generated(config, uri, content=page()))
    # the changelog links pages as docs/PAGE.md (from the repository's root): on the site they
    # sit beside it
    changelog = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8").replace("](docs/", "](")
    files.append(File.generated(config, "changelog.md", content=changelog))
    return files
