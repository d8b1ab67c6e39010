"""The Khronos glTF-Validator (npm ``gltf-validator``), run through Node.js.

The npm package is a library with no command line; ``wrinklepipe/data/gltf_validate.cjs`` calls
its ``validateBytes`` and prints the JSON report. ``ci/bootstrap.sh`` installs the package into
``tools/node/node_modules`` (or set ``WRINKLEPIPE_NODE_MODULES``).
"""

from __future__ import annotations

import atexit
import json
import os
import select
import shutil
import subprocess
import threading
import time
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


class _Server:
    """One ``node gltf_validate.cjs --serve`` process answering one request a line: Node.js
    and the validator's JavaScript start once per Python process (~0.3 s CPU each time)
    instead of once per file. Requests are serialised by a lock; a server that dies, times out
    or belongs to the parent of a forked process is replaced."""

    def __init__(self, mods: Path) -> None:
        self.pid = os.getpid()
        self.proc = subprocess.Popen(
            ["node", str(_SCRIPT), str(mods), "--serve"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
        )
        self.buffer = b""

    def alive(self) -> bool:
        return self.pid == os.getpid() and self.proc.poll() is None

    def close(self) -> None:
        if self.pid == os.getpid() and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()

    def ask(self, request: dict[str, Any], timeout: float) -> dict[str, Any]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps(request).encode() + b"\n")
        self.proc.stdin.flush()
        fd = self.proc.stdout.fileno()
        deadline = time.monotonic() + timeout
        while b"\n" not in self.buffer:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                raise TimeoutError(f"no answer in {timeout:g} s")
            chunk = os.read(fd, 1 << 20)
            if not chunk:
                raise EOFError("the validator process ended")
            self.buffer += chunk
        line, self.buffer = self.buffer.split(b"\n", 1)
        return json.loads(line)


_server: _Server | None = None
_server_lock = threading.Lock()


@atexit.register
def _stop_server() -> None:
    if _server is not None:
        _server.close()


def validate_gltf(
    path: str | Path, max_issues: int = 1000, timeout: float = 120.0
) -> dict[str, Any]:
    """Validate a .gltf/.glb with the Khronos validator; return its report (``issues`` etc.)."""
    global _server
    mods = node_modules()
    if mods is None or shutil.which("node") is None:
        raise RuntimeError("Khronos glTF-Validator not installed (run: bash ci/bootstrap.sh setup)")
    request = {"file": str(Path(path).resolve()), "maxIssues": int(max_issues)}
    with _server_lock:
        if _server is None or not _server.alive():
            _server = _Server(mods)
        try:
            answer = _server.ask(request, timeout)
        except (OSError, ValueError, TimeoutError, EOFError) as exc:
            _server.close()
            _server = None
            raise RuntimeError(f"gltf-validator failed on {path}: {exc}") from None
    if "error" in answer:
        raise RuntimeError(f"gltf-validator failed on {path}: {answer['error']}")
    return answer["report"]
