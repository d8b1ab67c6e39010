"""The three.js plugin's pieces without a browser: its GLSL is the template's, its JavaScript
setup (slot table, groups, #defines) equals the Python one on every mask layout, and the viewer's
server serves its four roots on the loopback interface and nothing else."""

from __future__ import annotations

import json
import shutil
import subprocess
import urllib.error
import urllib.request
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from wrinklepipe.demo import demo_asset
from wrinklepipe.gltf.package_write import gltf_document
from wrinklepipe.pipeline.package import PackOptions, package_from_asset
from wrinklepipe.pipeline.prepare import prepare_mesh
from wrinklepipe.shading import template as tpl
from wrinklepipe.shading import threejs
from wrinklepipe.shading.setup import from_meta
from wrinklepipe.view.server import PLUGIN_DIR, Site, ViewServer, find_asset

_JS = """
import { wrinkleSetup } from %s;
import fs from 'node:fs';
const exts = JSON.parse(fs.readFileSync(0, 'utf8'));
const out = exts.map((e) => { const s = wrinkleSetup(e); return { slots: s.slots,
  used: Array.from(s.used), defines: s.defines, problems: s.problems, gather: s.gather }; });
process.stdout.write(JSON.stringify(out));
"""


def test_core_module_is_the_template():
    assert threejs.CORE_MODULE.read_text(encoding="utf-8") == threejs.core_module(), (
        "data/threejs/wrinkle_core.js is stale: run python -m wrinklepipe.shading.threejs"
    )
    assert "wp_pd(" in threejs.core_module()  # the codec's decode is inside


def _packages():
    a = demo_asset(64)
    a = replace(a, mesh=prepare_mesh(a.mesh))
    m = a.masks.copy()
    for left, right in [(0, 1), (2, 3), (4, 5)]:  # one side per texel (lr-split)
        m[right][(m[left] > 0) & (m[right] > 0)] = 0
    a = replace(a, masks=m)
    for layout in ("rgba", "array", "lr-split", "jimenez8"):
        for policy in ("clamp01", "signed", "renormalize"):
            yield (
                layout,
                policy,
                package_from_asset(replace(a, policy=policy), PackOptions(mask_layout=layout)),
            )


@pytest.mark.skipif(shutil.which("node") is None, reason="node is not installed")
def test_javascript_setup_equals_python_setup():
    cases, exts = [], []
    for layout, policy, pkg in _packages():
        doc, _, _ = gltf_document(pkg)
        exts.append(doc["materials"][0]["extensions"]["WRINKLEPIPE_wrinkle_maps"])
        chans = [pkg.texture(n).pixels.shape[-1] for n in pkg.meta.masks.textures]
        cases.append((layout, policy, from_meta(pkg.meta, chans)))
    url = json.dumps((PLUGIN_DIR / "wrinkle_setup.js").as_uri())
    r = subprocess.run(
        ["node", "--input-type=module", "-e", _JS % url],
        input=json.dumps(exts),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    for (layout, policy, py), js in zip(cases, json.loads(r.stdout), strict=True):
        assert js["problems"] == [], (layout, policy, js["problems"])
        assert js["gather"] == py.gather, (layout, policy)
        assert js["slots"] == py.slots(), (layout, policy)
        np.testing.assert_array_equal(js["used"], py.used_vectors().ravel())
        d = tpl.defines(py)
        assert set(js["defines"]) == set(d), set(js["defines"]) ^ set(d)
        for k, v in d.items():
            assert float(js["defines"][k]) == float(v), (layout, policy, k)


@pytest.mark.skipif(shutil.which("node") is None, reason="node is not installed")
def test_javascript_setup_names_the_colour_states_as_python_does():
    a = demo_asset(64, color=True)
    a = replace(a, mesh=prepare_mesh(a.mesh))
    pkg = package_from_asset(a)
    doc, _, _ = gltf_document(pkg)
    ext = doc["materials"][0]["extensions"]["WRINKLEPIPE_wrinkle_maps"]
    chans = [pkg.texture(n).pixels.shape[-1] for n in pkg.meta.masks.textures]
    py = from_meta(pkg.meta, chans)
    assert py.color_states == (0, 1)
    url = json.dumps((PLUGIN_DIR / "wrinkle_setup.js").as_uri())
    r = subprocess.run(
        ["node", "--input-type=module", "-e", _JS % url],
        input=json.dumps([ext]),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    js = json.loads(r.stdout)[0]
    assert js["defines"] == tpl.defines(py)  # WP_NUM_COLORS, WP_COLOR_STATE(c) included


def test_the_server_serves_its_roots_and_nothing_else(tmp_path):
    (tmp_path / "a.gltf").write_text("{}")
    (tmp_path / "secret.txt").write_text("no")
    three = tmp_path / "three"
    (three / "build").mkdir(parents=True)
    (three / "build" / "three.module.js").write_text("export {};")
    asset = tmp_path / "asset"
    asset.mkdir()
    (asset / "head.gltf").write_text('{"asset": {}}')
    folder, gltf = find_asset(asset)
    with ViewServer(Site(folder, gltf, three)) as srv:
        assert srv.httpd.server_address[0] == "127.0.0.1"

        def get(path: str) -> tuple[int, bytes]:
            try:
                with urllib.request.urlopen(srv.url.rstrip("/") + path, timeout=10) as resp:
                    return resp.status, resp.read()
            except urllib.error.HTTPError as exc:
                return exc.code, b""

        assert get("/")[0] == 200 and b"importmap" in get("/")[1]
        assert json.loads(get("/asset.json")[1]) == {"gltf": "/asset/head.gltf", "name": "head"}
        assert get("/asset/head.gltf") == (200, b'{"asset": {}}')
        assert get("/three/build/three.module.js")[0] == 200
        assert get("/plugin/WrinkleMapsPlugin.js")[0] == 200
        for bad in (
            "/asset/../secret.txt",
            "/asset/%2e%2e/secret.txt",
            "/etc/passwd",
            "/asset/",
            "/viewer/../../errors.py",
            "/asset/nothing.png",
        ):
            assert get(bad)[0] == 404, bad


def test_view_refuses_what_it_cannot_show(tmp_path):
    from wrinklepipe.errors import InputError

    with pytest.raises(InputError, match="no .gltf or .glb"):
        find_asset(tmp_path)
    (tmp_path / "x.png").write_bytes(b"")
    with pytest.raises(InputError, match="expected a .gltf or .glb"):
        find_asset(tmp_path / "x.png")
    with pytest.raises(InputError, match="not found"):
        find_asset(Path(tmp_path / "missing"))
