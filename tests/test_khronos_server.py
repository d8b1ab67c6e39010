"""The Khronos validator's persistent Node.js process (wrinklepipe.io.khronos): the same report
as a one-file run, and a dead server is replaced."""

from __future__ import annotations

import json
import subprocess

import pytest

from wrinklepipe.demo.package import demo_package
from wrinklepipe.gltf.package_write import write_gltf
from wrinklepipe.io import khronos

pytestmark = pytest.mark.skipif(not khronos.available(), reason="gltf-validator not installed")


def test_the_server_answers_as_a_one_file_run_and_is_replaced_when_it_dies(tmp_path):
    write_gltf(demo_package(16), tmp_path / "ok", "demo")
    gltf = tmp_path / "ok" / "demo.gltf"
    broken = tmp_path / "broken.gltf"
    broken.write_text('{"asset": {"version": "2.0"}, "meshes": [{"primitives": []}]}')
    for path in (gltf, broken):
        one = subprocess.run(
            ["node", str(khronos._SCRIPT), str(khronos.node_modules()), str(path), "1000"],
            capture_output=True,
            check=True,
        )
        want = json.loads(one.stdout)
        got = khronos.validate_gltf(path)
        for r in (want, got):
            r.pop("validatedAt")
        assert got == want
    assert khronos.validate_gltf(broken)["issues"]["numErrors"] > 0
    khronos._server.proc.kill()  # a server that died between two calls
    khronos._server.proc.wait()
    assert khronos.validate_gltf(gltf)["issues"]["numErrors"] == 0
    with pytest.raises(RuntimeError, match="missing.gltf"):
        khronos.validate_gltf(tmp_path / "missing.gltf")
    assert khronos.validate_gltf(gltf)["issues"]["numErrors"] == 0  # still serving
