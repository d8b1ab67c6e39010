"""The Khronos glTF-Validator (npm ``gltf-validator``), run through Node.js.

The npm package is a library with no command line; ``wrinklepipe/data/gltf_validate.cjs`` calls
its ``validateBytes`` and prints the JSON report. ``ci/bootstrap.sh`` installs the package into
``tools/node/node_modules`` (or set ``WRINKLEPIPE_NODE_MODULES``).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

from wrinklepipe.paths import ROOT

_SCRIPT = Path(__file__).resolve().parent.parent / "data" / "gltf_validate.cjs"


def node_modules() -> Path | None:
    """Where ``gltf-validator`` is installed, or None."""
    env = os.environ.get("WRINKLEPIPE_NODE_MODULES")
    for cand in ([Path(env)] if env else []) + [ROOT / "tools" / "node" / "node_modules"]:
        if (cand / "gltf-validator" / "package.json").is_file():
            return cand
    return None


def available() -> bool:
    """True when Node.js and the npm ``gltf-validator`` package are both present."""
    return shutil.which("node") is not None and node_modules() is not None


def validate_gltf(
    path: str | Path, max_issues: int = 1000, timeout: float = 120.0
) -> dict[str, Any]:
    """Validate a .gltf/.glb with the Khronos validator; return its report (``issues`` etc.)."""
    mods = node_modules()
    if mods is None or shutil.which("node") is None:
        raise RuntimeError("Khronos glTF-Validator not installed (run: bash ci/bootstrap.sh setup)")
    proc = subprocess.run(
        ["node", str(_SCRIPT), str(mods), str(path), str(max_issues)],
        capture_output=True,
        timeout=timeout,
        check=False,
    )
    if proc.returncode != 0:
        raise RuntimeError(
            f"gltf-validator failed on {path}: {proc.stderr.decode(errors='replace')}"
        )
    return json.loads(proc.stdout)
