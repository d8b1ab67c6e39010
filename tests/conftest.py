"""Fixtures several test files share (each built once per test session and worker).

How the suite shares out on ``pytest -n 2`` (the CI machine: 2 cores):

``pyproject.toml`` runs xdist with ``--dist loadfile --no-loadscope-reorder``: every test module
goes whole to one worker, so a module-scoped fixture (a conversion, a browser page) is built
once, not once on each worker that happens to run one of its tests (the three.js page test built
its ~30 s page twice under ``--dist load``).

With whole modules as the units, the two longest modules must not start last: a worker that
picks up a long module at the end leaves the other idle. So under xdist the modules below go
first, longest first (the rest follow in file order; they are a few seconds each). The list is
the modules' share of the suite's time in a ``--durations=0`` run (2026-12-02, 03:05 UTC) and
their ``-n 0`` times after that day's first merge train; refresh it from such a run when a
module's cost changes a lot. The order changes nothing but
when a test starts; ``-n 0`` runs keep file order.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from wrinkle_setups import ROBOT, write_robot_setup

from wrinklepipe.io.confine import allowed_roots
from wrinklepipe.pipeline.convert import ConvertOptions, convert


@pytest.fixture(scope="session")
def robot_converted(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """RobotExpressive converted once (:func:`wrinkle_setups.write_robot_setup`; .gltf + .glb,
    validation without the render pass): (output folder, report). Read only."""
    if not ROBOT.is_file():
        pytest.skip("../shared/data is absent")
    root = tmp_path_factory.mktemp("robot")
    manifest = write_robot_setup(root / "src")
    with allowed_roots([ROBOT.parent]):
        res = convert(manifest, root / "out", ConvertOptions(glb=True, render=False))
    assert res.exit_code == 0
    return root / "out", res.report


LONGEST_FIRST = [
    "test_batch_run.py",  # 11 % (the isolation test: converts, a LocalCluster)
    "test_viewer.py",  # one browser page, ~40 s in one piece
    "test_export_engines.py",  # 9 %
    "test_convert_fidelity.py",  # 7 %
    "test_convert_formats.py",  # 6 %
    "test_validate_render.py",  # 5 %
    "test_safety_faults.py",  # 6 % (22 killed CLI runs and their reruns)
    "test_capture_cli.py",  # 4 %
    "test_convert_cli.py",  # 4 %
    "test_safety_outputs.py",  # 3 %
    "test_document_convert.py",  # 3 %
    "test_batch_bench.py",  # 3 %
    "test_validate_cli.py",  # 2 %
    "test_validate_corpus.py",  # 2 %
    "test_safety_fuzz.py",  # 2 %
    "test_face_fixture.py",  # 1-2 %
    "test_batch_ci.py",  # 1-2 %
    "test_normals_bc4.py",  # 1-2 %
]


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not hasattr(config, "workerinput"):  # not an xdist worker: keep file order
        return
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: file order kept
