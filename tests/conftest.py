"""Fixtures several test files share (each built once per test session and worker)."""

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
