"""``wrinklepipe view``: preview a converted character in a local three.js page."""

from __future__ import annotations

import argparse
import webbrowser

from wrinklepipe.console import err
from wrinklepipe.errors import input_error
from wrinklepipe.view.server import Site, ViewServer, find_asset, find_three

NAME = "view"
HELP = "preview a converted character in the browser (three.js, local, loopback only)"
DESCRIPTION = """\
Serve a local page that renders PATH (a convert output folder, a .gltf or a .glb) with three.js
and wrinklepipe's GLTFLoader plugin: expression sliders (the asset's expression table), a
timeline that plays its animations (morph targets and wrinkle weights together), a region
overlay and debug views (tangent-space normal, UV and activation). The server listens on
127.0.0.1 only and serves nothing but the page, three.js (npm, installed by ci/bootstrap.sh under
tools/node; no CDN) and PATH's folder. Ctrl-C stops it.

examples:
  wrinklepipe view build/ada
  wrinklepipe view build/ada/ada.glb --port 8765 --open
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("path", metavar="PATH", help="convert output folder, .gltf or .glb")
    p.add_argument("--port", type=int, default=8765, help="port on 127.0.0.1 (0: any free one)")
    p.add_argument("--three", metavar="DIR", default=None, help="an npm `three` package folder")
    p.add_argument("--open", action="store_true", help="open the page in the default browser")


def run(args: argparse.Namespace) -> int:
    folder, gltf = find_asset(args.path)
    site = Site(folder, gltf, find_three(args.three))
    try:
        server = ViewServer(site, args.port)
    except OSError as exc:
        raise input_error(
            f"127.0.0.1:{args.port}", f"cannot listen: {exc.strerror or exc}"
        ) from None
    err.print(f"[bold green]viewing[/] {gltf} at {server.url}  (Ctrl-C stops)")
    if args.open:
        webbrowser.open(server.url)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
    return 0
