"""``wrinklepipe view``: preview a converted character in a local three.js page."""

from __future__ import annotations

import argparse
import webbrowser
from pathlib import Path
from urllib.parse import urlencode

from rich.markup import escape

from wrinklepipe.console import info
from wrinklepipe.errors import input_error
from wrinklepipe.gltf.container import open_container
from wrinklepipe.names import unknown_names
from wrinklepipe.view.server import Site, ViewServer, find_asset, find_three

NAME = "view"
HELP = "preview a converted character in the browser (three.js, local, loopback only)"
DESCRIPTION = """\
Serve a local page that renders PATH (a convert output folder, a .gltf or a .glb) with three.js
and wrinklepipe's GLTFLoader plugin: expression sliders (the asset's expression table), a
timeline that plays its animations (morph targets and wrinkle weights together), a region
overlay and debug views (tangent-space normal, UV and activation). The server listens on
127.0.0.1 only, answers only requests addressed to 127.0.0.1 or localhost, and serves nothing
but the page, three.js (npm, installed by ci/bootstrap.sh under tools/node; no CDN), the glTF(s)
of PATH and the files they reference (no hidden files, no listings). Ctrl-C stops it.

examples:
  wrinklepipe view build/ada
  wrinklepipe view build/ada/ada.glb --port 8765 --open
  wrinklepipe view build/robot --clip Dance
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("path", metavar="PATH", help="convert output folder, .gltf or .glb")
    p.add_argument(
        "--port", type=int, default=8765, metavar="PORT", help="port on 127.0.0.1 (0: any free one)"
    )
    p.add_argument("--three", metavar="DIR", default=None, help="an npm `three` package folder")
    p.add_argument("--open", action="store_true", help="open the page in the default browser")
    p.add_argument(
        "--clip",
        metavar="NAME",
        default=None,
        help="the animation the timeline opens on (default: the wrinkle weights' clip)",
    )


def _clip_query(gltf: Path, name: str | None) -> str:
    """``?clip=NAME`` for the page, after checking the asset has an animation of that name."""
    if name is None:
        return ""
    names = [
        str(a.get("name", ""))
        for a in open_container(gltf).gltf.get("animations", [])
        if isinstance(a, dict)
    ]
    if name not in names:
        raise input_error("--clip", unknown_names("clip", [name], names, f" of {gltf.name}"))
    return "?" + urlencode({"clip": name})


def run(args: argparse.Namespace) -> int:
    folder, gltf = find_asset(args.path)
    query = _clip_query(gltf, args.clip)
    site = Site(folder, gltf, find_three(args.three), only_gltf=Path(args.path).is_file())
    try:
        server = ViewServer(site, args.port)
    except OSError as exc:
        raise input_error(
            f"127.0.0.1:{args.port}", f"cannot listen: {exc.strerror or exc}"
        ) from None
    url = server.url + query
    info(f"[bold green]viewing[/] {escape(str(gltf))} at {url}  (Ctrl-C stops)", markup=True)
    if args.open:
        webbrowser.open(url)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
    return 0
