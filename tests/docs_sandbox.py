"""The sandbox the documentation's shell examples run in (``tests/test_docs_examples.py``,
``tests/test_help_examples.py``): the files they name, the fork server that runs
``wrinklepipe``, and the runners.

The sandbox holds two demo characters at 64² as ``chars/ada`` and ``chars/ben``; the demo's
mesh (its material named ``Skin``), maps and masks at the top (``head.glb``, ``base.png``,
``stretch.png``, ``compress.png``, ``unreal_normal.png``, ``masks/``); ``maps/`` as
``bake-states`` writes it; OBJ sculpts of the head (``neutral.obj``, ``frown.obj``,
``surprise.obj`` and ``sculpts/``: its morph targets); a batch file (``studio-batch.toml``);
``RobotExpressive.glb``, ``RiggedFigure.glb`` and ``blendshapes.usda`` (links into
``../shared/data`` when it is there); ``../shared`` beside it as beside a checkout.
``wrinklepipe`` runs the CLI's ``main`` in a process forked for it from a server that imported
the CLI once (``tests/docs_cli_server.py``); a server example (``view``) runs the real console
script.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pygltflib
import pytest
from docs_examples import Block

from wrinklepipe.demo.source import demo_source_dir
from wrinklepipe.io.images import read_image, write_image

REPO = Path(__file__).resolve().parent.parent
SHARED = REPO.parent / "shared"
HAVE_SHARED = (SHARED / "data" / "gltf-samples" / "RobotExpressive").is_dir()
PAGES = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
VENV_BIN = Path(sys.executable).parent

#: Files of ../shared/data the examples name, linked into the sandbox by their file names.
SHARED_FILES = (
    "gltf-samples/RobotExpressive/RobotExpressive.glb",
    "gltf-samples/RiggedFigure/glTF-Binary/RiggedFigure.glb",
    "usd/openusd/usd/usdSkel/testenv/testUsdSkelBakeSkinning/blendshapes.usda",
)

BATCH_FILE = """\
schema = "wrinklepipe/batch@1"
include = ["chars/**/manifest.toml"]
output = "build/studio"

[defaults]
fail_on = "error"
"""


def _demo_character(folder: Path, name: str) -> None:
    shutil.copytree(demo_source_dir(64).parent, folder)
    manifest = folder / "manifest.toml"
    text = manifest.read_text(encoding="utf-8").replace('name = "demo_head"', f'name = "{name}"')
    manifest.write_text(text, encoding="utf-8")


def _sculpts(head: Path, folder: Path, names: dict[str, str]) -> None:
    """OBJ sculpts of the demo head: ``{file stem: morph target}`` (``""``: the neutral)."""
    gltf = pygltflib.GLTF2.load_binary(str(head))
    blob = gltf.binary_blob()

    def accessor(i: int) -> np.ndarray:
        a = gltf.accessors[i]
        view = gltf.bufferViews[a.bufferView]
        dtype = np.uint32 if a.componentType == pygltflib.UNSIGNED_INT else np.float32
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[a.type]
        start = (view.byteOffset or 0) + (a.byteOffset or 0)
        return np.frombuffer(blob, dtype, a.count * width, start).reshape(a.count, width)

    mesh = gltf.meshes[0]
    prim = mesh.primitives[0]
    positions = accessor(prim.attributes.POSITION).astype(np.float64)
    faces = accessor(prim.indices).reshape(-1, 3) + 1
    targets = mesh.extras["targetNames"]
    folder.mkdir(parents=True, exist_ok=True)
    for stem, target in names.items():
        p = positions
        if target:
            p = p + accessor(prim.targets[targets.index(target)]["POSITION"])
        lines = [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in p]
        lines += [f"f {a} {b} {c}" for a, b, c in faces]
        (folder / f"{stem}.obj").write_text("\n".join(lines) + "\n", encoding="utf-8")


def _head_with_skin(source: Path, target: Path) -> None:
    """The demo head (8 named morph targets) with its primitive's material named ``Skin``."""
    gltf = pygltflib.GLTF2.load_binary(str(source))
    gltf.materials = [pygltflib.Material(name="Skin")]
    for mesh in gltf.meshes:
        for prim in mesh.primitives:
            prim.material = 0
    gltf.save_binary(str(target))


def build_sandbox(parent: Path) -> Path:
    """The files the examples name (see the module doc) under ``parent/repo``."""
    root = parent / "repo"
    _demo_character(root / "chars" / "ada", "ada")
    _demo_character(root / "chars" / "ben", "ben")
    demo = demo_source_dir(64).parent
    _head_with_skin(demo / "head.glb", root / "head.glb")
    _sculpts(
        root / "head.glb", root, {"neutral": "", "frown": "brow_furrow", "surprise": "brow_raise"}
    )
    _sculpts(
        root / "head.glb",
        root / "sculpts",
        {"neutral": "", "frown": "brow_furrow", "brows_up": "brow_raise"},
    )
    (root / "maps").mkdir()  # as `bake-states` writes them
    shutil.copy(demo / "base_normal.png", root / "maps" / "base_normal.png")
    for state in ("stretch", "compress"):
        shutil.copy(demo / f"wrinkle_{state}.png", root / "maps" / f"wrinkle_{state}.png")
    shutil.copy(demo / "base_normal.png", root / "base.png")
    shutil.copy(demo / "wrinkle_stretch.png", root / "stretch.png")
    shutil.copy(demo / "wrinkle_compress.png", root / "compress.png")
    shutil.copytree(demo / "masks", root / "masks")
    base, _ = read_image(demo / "base_normal.png")
    flipped = np.array(base, dtype=np.float64)
    flipped[..., 1] = 1.0 - flipped[..., 1]  # the same face in DirectX (-Y) green
    write_image(root / "unreal_normal.png", flipped, 16)
    (root / "studio-batch.toml").write_text(BATCH_FILE, encoding="utf-8")
    (root / ".venv" / "bin").mkdir(parents=True)
    (root / ".venv" / "bin" / "activate").write_text(
        f'export PATH="{VENV_BIN}:$PATH"\n', encoding="utf-8"
    )
    if HAVE_SHARED:
        for rel in SHARED_FILES:
            if (SHARED / "data" / rel).is_file():
                (root / Path(rel).name).symlink_to(SHARED / "data" / rel)
    return root


@contextlib.contextmanager
def cli_server(folder: Path) -> Iterator[Path]:
    """The fork server (``tests/docs_cli_server.py``) running; its socket."""
    sock = folder / "cli.sock"
    proc = subprocess.Popen(
        [sys.executable, str(Path(__file__).with_name("docs_cli_server.py")), str(sock)],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "ready"
        yield sock
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def page_id(page: Path) -> str:
    return page.relative_to(REPO).as_posix()


def environment(sandbox: Path, sock: Path) -> dict[str, str]:
    shim = sandbox.parent / "bin"
    shim.mkdir(exist_ok=True)
    script = shim / "wrinklepipe"
    script.write_text(
        f'#!/bin/sh\nexec "{sys.executable}" -I -S '
        f'"{Path(__file__).with_name("docs_cli_server.py")}" --client "$@"\n',
        encoding="utf-8",
    )
    script.chmod(0o755)
    node_bin = REPO / "tools" / "node" / "node_modules" / ".bin"
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(shim), str(VENV_BIN), str(node_bin), env["PATH"]])
    env["WRINKLEPIPE_DOCS_SERVER"] = str(sock)
    env["REPO"] = str(REPO)
    env.pop("COLUMNS", None)
    return env


def run_server(block: Block, cwd: Path, env: dict[str, str]) -> None:
    """Start the server example with the real console script, fetch the address it prints."""
    (command, _), *_ = block.commands()
    env = {**env, "PATH": env["PATH"].split(os.pathsep, 1)[1]}  # the real script, no shim
    proc = subprocess.Popen(
        ["bash", "-c", "exec " + command],
        cwd=cwd,
        env=env,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        seen = ""
        while time.monotonic() < deadline:
            line = proc.stderr.readline()
            if not line:
                break
            seen += line
            if m := re.search(r"http://127\.0\.0\.1:\d+/\S*", line):
                with urllib.request.urlopen(m.group(0), timeout=60) as page:
                    assert page.status == 200
                    assert b"<html" in page.read(4096).lower()
                return
        pytest.fail(f"{block.where}: `{command}` printed no address:\n{seen}")
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def run_block(block: Block, cwd: Path, env: dict[str, str]) -> None:
    for command, expected in block.commands():
        start = time.monotonic()
        proc = subprocess.run(
            ["bash", "-c", command],
            cwd=cwd,
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        print(f"{time.monotonic() - start:6.1f} s  {block.where}  {command[:90]}")
        if proc.returncode != expected:
            out = (proc.stdout + proc.stderr)[-4000:]
            pytest.fail(
                f"{block.where}: `{command}` exited {proc.returncode}, the page says "
                f"{expected}:\n{out}"
            )
