"""Every shell example of the README and the documentation pages runs, and ends with the exit
code it documents (``tests/docs_examples.py`` says how a page marks its examples).

Each page runs in a sandbox of its own (``tests/docs_sandbox.py``: the files the examples name),
its blocks in order (a later example may use what an earlier one wrote).
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest
from docs_examples import SHELL, apply_edit, blocks, hidden_examples
from docs_sandbox import (
    HAVE_SHARED,
    PAGES,
    REPO,
    SHARED,
    build_sandbox,
    cli_server,
    environment,
    page_id,
    run_block,
    run_server,
)


@pytest.fixture(scope="module")
def base_sandbox(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_sandbox(tmp_path_factory.mktemp("docs-sandbox"))


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    with cli_server(tmp_path_factory.mktemp("docs-server")) as sock:
        yield sock


def _examples(page: Path) -> list:
    return [b for b in blocks(page) if b.lang in SHELL or b.edit]


# only the pages that have shell examples (a page of prose alone has nothing to run)
EXAMPLE_PAGES = [page for page in PAGES if _examples(page)]


def test_the_example_pages_are_found():
    assert REPO / "README.md" in EXAMPLE_PAGES and len(EXAMPLE_PAGES) >= 10, EXAMPLE_PAGES


@pytest.mark.parametrize("page", EXAMPLE_PAGES, ids=page_id)
def test_page_examples_run(page: Path, base_sandbox: Path, server: Path, tmp_path: Path):
    found = _examples(page)
    if not HAVE_SHARED and any(b.needs_shared and b.skip is None for b in found):
        # later examples build on what those make (robot/manifest.toml ...): none is run
        pytest.skip("../shared/data is absent (examples on this page read it)")
    cwd = tmp_path / "repo"
    shutil.copytree(base_sandbox, cwd, symlinks=True)
    if SHARED.is_dir():
        (tmp_path / "shared").symlink_to(SHARED)
    env = environment(cwd, server)
    skipped = []
    for block in found:
        if block.skip is not None:
            skipped.append(f"{block.where}: {block.skip}")
        elif block.edit:
            apply_edit(block, cwd / block.edit)
        elif block.server:
            run_server(block, cwd, env)
        elif block.checkout:
            run_block(block, REPO, env)
        else:
            run_block(block, cwd, env)
    if skipped:
        print("not run:", *skipped, sep="\n  ")


def test_examples_are_marked_as_shell() -> None:
    """A command a reader would copy sits in an ``sh`` block (so the test above runs it); a
    synopsis (``wrinklepipe convert MANIFEST -o OUT [--glb]``) may sit in a plain block."""
    hidden = [
        f"{b.where}: {line}" for page in PAGES for b in blocks(page) for line in hidden_examples(b)
    ]
    assert not hidden, "examples outside sh blocks (mark them ```sh):\n" + "\n".join(hidden)


def test_skips_say_why() -> None:
    skips = [b for page in PAGES for b in blocks(page) if b.skip is not None]
    assert all(b.skip.strip() for b in skips)
    assert len(skips) <= 3, [b.where for b in skips]  # running is the rule
