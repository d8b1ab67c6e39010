"""The pages a user looks at, looked at: ``report.html``, ``validation.html`` and the viewer,
screenshotted in Debian's chromium (headless, ``tests/browser_shots.mjs``), their key pixels
compared with what the files hold, read independently (OpenImageIO, unassociated alpha).

- report.html: a packed mask texture (a region in alpha) shows on a checkerboard where it is
  transparent, never black, its colour where it is opaque; its alpha view shows the alpha texels
  as grey levels; the regions table shows each region's mask as grey levels.
- validation.html: the raw JSON is folded in ``<details>`` (the page is short until opened); the
  mask overlay's legend shows Paul Tol's colour-blind-safe colours, region by region.
- the viewer on RobotExpressive (14 clips of its own, then convert's wrinkle clip): the timeline
  opens on the wrinkle clip (``--clip NAME`` on another), the clock follows the scrubbed time,
  the canvas shows the character.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from wrinklepipe.demo.source import demo_source_dir
from wrinklepipe.io.images import read_image
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.palette import REGION_COLOURS
from wrinklepipe.paths import ROOT
from wrinklepipe.view.server import Site, ViewServer, find_asset

CHROMIUM = Path("/usr/bin/chromium")
NODE_MODULES = ROOT / "tools" / "node" / "node_modules"
CHECKER = {(0xC8, 0xC8, 0xC8), (0xF4, 0xF4, 0xF4)}


def _missing() -> str:
    if not CHROMIUM.exists():
        return "Debian chromium is not installed (ci/bootstrap.sh installs it)"
    if shutil.which("node") is None:
        return "node is not installed"
    if not (NODE_MODULES / "playwright-core" / "package.json").exists():
        return "npm playwright-core is not installed under tools/node (ci/bootstrap.sh)"
    return ""


pytestmark = pytest.mark.skipif(bool(_missing()), reason=_missing() or "ok")


def _shots(out: Path, pages: list[dict]) -> list[dict]:
    job = {
        "playwright": str(NODE_MODULES / "playwright-core"),
        "chromium": str(CHROMIUM),
        "out": str(out),
        "pages": pages,
    }
    (out / "job.json").write_text(json.dumps(job))
    r = subprocess.run(
        ["node", str(Path(__file__).with_name("browser_shots.mjs")), str(out / "job.json")],
        capture_output=True,
        text=True,
        timeout=600,
    )
    res = json.loads((out / "results.json").read_text())
    assert r.returncode == 0 and "error" not in res, (r.stderr[-2000:], res.get("error"))
    errors = [x for x in res["log"] if x.startswith("pageerror")]
    assert not errors, errors
    return res["results"]


def _pixels(png: Path) -> np.ndarray:
    img, _ = read_image(png)
    return np.rint(np.asarray(img)[..., :3] * 255).astype(int)


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The 64² demo converted (with the render pass), and its two pages screenshotted."""
    root = tmp_path_factory.mktemp("pictures")
    folder = root / "demo"
    convert(demo_source_dir(64), folder, ConvertOptions())
    rect = "(e) => { const r = e.getBoundingClientRect(); return [r.x, r.y, r.width, r.height]; }"
    imgs = "Array.from(document.images).every((i) => i.complete)"
    pages = [
        {
            "url": (folder / "report.html").as_uri(),
            "width": 1400,
            "height": 1000,
            "ready": imgs,
            "steps": ["document.querySelector('h2').scrollIntoView()"],
            "shot": "report.png",
            "evaluate": "Object.fromEntries(Array.from(document.querySelectorAll("
            "'figure.tex img')).map((e) => [e.alt, (" + rect + ")(e)]))",
        },
        {
            "url": (folder / "validation.html").as_uri(),
            "width": 1400,
            "height": 900,
            "ready": imgs,
            "steps": ["document.querySelector('.swatch').scrollIntoView()"],
            "shot": "validation.png",
            "evaluate": "(() => { const closed = document.documentElement.scrollHeight;"
            " const n = document.querySelectorAll('details').length;"
            " const swatches = Array.from(document.querySelectorAll('.swatch'))"
            ".map((e) => (" + rect + ")(e));"
            " document.querySelectorAll('details').forEach((d) => { d.open = true; });"
            " return { closed, open: document.documentElement.scrollHeight, n, swatches,"
            " pres: document.querySelectorAll('pre').length,"
            " loose: Array.from(document.querySelectorAll('pre'))"
            ".filter((p) => !p.closest('details')).length }; })()",
        },
    ]
    results = _shots(root, pages)
    return {"folder": folder, "root": root, "report": results[0], "validation": results[1]}


def _texel_pixel(rect: list[float], shape: tuple[int, int], i: int, j: int) -> tuple[int, int]:
    x, y, w, h = rect
    return int(y + (i + 0.5) * h / shape[0]), int(x + (j + 0.5) * w / shape[1])


def test_report_shows_a_packed_mask_on_a_checkerboard_and_its_alpha(demo) -> None:
    texture = demo["folder"] / "textures" / "mask_0.png"
    texels, info = read_image(texture)
    texels = np.rint(np.asarray(texels) * 255).astype(int)
    assert texels.shape[2] == 4
    shot = _pixels(demo["root"] / "report.png")
    rects = demo["report"]["value"]
    name = "textures/mask_0.png"
    clear = np.argwhere(texels[..., 3] == 0)
    opaque = np.argwhere(texels[..., 3] == 255)
    assert len(clear) and len(opaque)
    seen = set()
    for i, j in clear[:: max(len(clear) // 40, 1)]:
        y, x = _texel_pixel(rects[f"{name} {name}"], texels.shape[:2], i, j)
        seen.add(tuple(shot[y, x]))
    assert seen <= CHECKER, seen  # transparent texels: the checkerboard, never black
    assert len(seen) == 2  # both squares of it
    for i, j in opaque[:: max(len(opaque) // 40, 1)]:
        y, x = _texel_pixel(rects[f"{name} {name}"], texels.shape[:2], i, j)
        assert np.abs(shot[y, x] - texels[i, j, :3]).max() <= 2
    for i, j in np.argwhere(np.ones(texels.shape[:2], bool))[::7]:
        y, x = _texel_pixel(rects[f"{name} alpha"], texels.shape[:2], i, j)
        assert np.abs(shot[y, x] - texels[i, j, 3]).max() <= 2, (i, j)


def test_validation_page_folds_raw_json_and_uses_tol_colours(demo) -> None:
    v = demo["validation"]["value"]
    assert v["n"] >= 2 and v["loose"] == 0  # every <pre> of raw JSON sits in a <details>
    assert v["open"] > v["closed"] + 1000  # unfolded, the JSON is long; folded, it is gone
    shot = _pixels(demo["root"] / "validation.png")
    page = (demo["folder"] / "validation.html").read_text(encoding="utf-8")
    legend = re.findall(r"background:(#[0-9a-f]{6})'></span>([^<]+)", page)
    assert [c for c, _ in legend] == [c.lower() for c in REGION_COLOURS[: len(legend)]]
    for (x, y, w, h), (colour, region) in zip(v["swatches"], legend):
        want = np.array([int(colour[k : k + 2], 16) for k in (1, 3, 5)])
        got = shot[int(y + h / 2), int(x + w / 2)]
        assert np.abs(got - want).max() <= 2, (region, got, colour)


def test_viewer_opens_on_the_wrinkle_clip_and_its_clock_follows_the_timeline(
    robot_converted, tmp_path: Path
) -> None:
    folder, _ = robot_converted
    found_folder, gltf = find_asset(folder)
    ready = "window.wrinklepipe && document.getElementById('status').textContent !== 'loading...'"
    state = (
        "({ clip: document.getElementById('clip').selectedOptions[0].text,"
        " clips: document.getElementById('clip').options.length,"
        " clock: document.getElementById('clock').textContent,"
        " max: Number(document.getElementById('time').max) })"
    )
    scrub = (
        "(() => { const t = document.getElementById('time'); t.value = 1.5;"
        " t.dispatchEvent(new Event('input')); })()"
    )
    with ViewServer(Site(found_folder, gltf, NODE_MODULES / "three")) as srv:
        results = _shots(
            tmp_path,
            [
                {
                    "url": srv.url,
                    "ready": ready,
                    "steps": [f"window.opened = {state}", scrub],
                    "shot": "viewer.png",
                    "evaluate": f"({{ opened: window.opened, scrubbed: {state} }})",
                },
                {"url": srv.url + "?clip=Dance&still", "ready": ready, "evaluate": state},
            ],
        )
    opened, scrubbed = results[0]["value"]["opened"], results[0]["value"]["scrubbed"]
    dance = results[1]["value"]
    assert opened["clips"] == 15
    assert opened["clip"].startswith("blendshapes ("), opened  # convert's weight curve
    assert opened["clock"] == "0.00 s"
    assert scrubbed["clock"] == "1.50 s", scrubbed  # the clock follows the scrubbed time
    assert dance["clip"].startswith("Dance ("), dance
    shot = _pixels(tmp_path / "viewer.png")
    canvas = shot[: shot.shape[0], : shot.shape[1] * 2 // 3]
    corner = canvas[5, 5]
    drawn = np.abs(canvas - corner).max(axis=-1) > 8
    assert drawn.mean() > 0.02, "the character is on screen"
