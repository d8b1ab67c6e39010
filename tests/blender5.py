"""Blender 5 for the tests: PyPI's ``bpy`` (Blender as a Python module) in its own environment.

``bash ci/bootstrap.sh`` installs ``bpy`` 5.x into ``.venv-blender/`` (not ``.venv``: bpy pins
numpy<2; bpy 5.0 is built for Python 3.11). The tests run Blender scripts with that Python:
:func:`run_session` runs many in ONE process (tests/blender_session.py: each from Blender's
factory settings), so a test session starts Blender once, plus :func:`run_script` for what
needs a process of its own (an import under a chosen ``PYTHONHASHSEED``).

When the environment is missing the tests skip, naming the setup command, except under CI
(``CI`` set), where a missing Blender is a failure: the default test command must run them.
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

from wrinklepipe.paths import ROOT

BLENDER_PYTHON = ROOT / ".venv-blender" / "bin" / "python"
HERE = Path(__file__).parent


def require() -> None:
    """Skip (fail under CI) when Blender 5's Python is not installed."""
    if BLENDER_PYTHON.is_file():
        return
    reason = f"{BLENDER_PYTHON} is missing (bash ci/bootstrap.sh setup installs PyPI bpy 5.x)"
    if os.environ.get("CI"):
        pytest.fail(reason)
    pytest.skip(reason)


def run_script(
    script: str | Path, args: list[str], env: dict[str, str] | None = None, timeout: int = 300
) -> subprocess.CompletedProcess:
    """``script -- args`` in Blender 5's Python (its own process)."""
    return subprocess.run(
        [str(BLENDER_PYTHON), str(script), "--", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, **(env or {})},
    )


def run_session(jobs: list[dict], folder: Path) -> dict[str, tuple[int, str, str]]:
    """Run ``jobs`` (``{"name", "script", "args"}``) in one Blender 5 process, each script
    from the factory settings with its own stdout/stderr: name -> (exit code, stdout,
    stderr)."""
    full = [
        {
            **j,
            "script": str(j["script"]),
            "args": [str(a) for a in j["args"]],
            "stdout": str(folder / f"{j['name']}.out"),
            "stderr": str(folder / f"{j['name']}.err"),
        }
        for j in jobs
    ]
    path = folder / "jobs.json"
    path.write_text(json.dumps(full))
    r = run_script(HERE / "blender_session.py", [str(path)], timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    results = json.loads(Path(str(path) + ".results.json").read_text())
    return {
        j["name"]: (
            results[j["name"]]["exit_code"],
            Path(j["stdout"]).read_text(),
            Path(j["stderr"]).read_text(),
        )
        for j in full
    }
