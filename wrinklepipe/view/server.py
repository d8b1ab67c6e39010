"""The viewer's HTTP server: four read-only roots on 127.0.0.1, nothing else.

``/`` the page, ``/viewer/*`` its script and style, ``/plugin/*`` the GLTFLoader plugin,
``/three/*`` the three.js package, ``/asset/*`` the folder holding the glTF, ``/asset.json`` which
glTF to show. Paths are resolved and must stay inside their root (no ``..``, no symlinks out);
there are no directory listings and no writes.
"""

from __future__ import annotations

import json
import mimetypes
import os
import shutil
import subprocess
import threading
from dataclasses import dataclass
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote, urlsplit

from wrinklepipe.errors import input_error
from wrinklepipe.paths import ROOT
from wrinklepipe.sources.package import asset_file
from wrinklepipe.suffixes import GLTF_SUFFIXES, is_gltf

DATA = Path(__file__).resolve().parent.parent / "data"
VIEWER_DIR = DATA / "viewer"
PLUGIN_DIR = DATA / "threejs"
_TYPES = {
    ".js": "text/javascript",
    ".mjs": "text/javascript",
    ".gltf": "model/gltf+json",
    ".glb": "model/gltf-binary",
    ".bin": "application/octet-stream",
    ".ktx2": "image/ktx2",
}


def find_three(explicit: str | Path | None = None) -> Path:
    """The three.js npm package folder: ``explicit``, ``$WRINKLEPIPE_THREE``, the project's
    ``tools/node`` (``ci/bootstrap.sh`` installs it there) or the global npm root."""
    candidates = [
        explicit,
        os.environ.get("WRINKLEPIPE_THREE"),
        ROOT / "tools/node/node_modules/three",
    ]
    npm = shutil.which("npm")
    if npm:
        try:
            out = subprocess.run([npm, "root", "-g"], capture_output=True, text=True, timeout=20)
            candidates.append(Path(out.stdout.strip()) / "three")
        except (OSError, subprocess.SubprocessError):
            pass
    for c in candidates:
        if c and (Path(c) / "build" / "three.module.js").is_file():
            return Path(c).resolve()
    raise input_error(
        "three.js",
        "not found: run `bash ci/bootstrap.sh setup` (installs npm's three under tools/node), "
        "or pass --three DIR / set WRINKLEPIPE_THREE to an npm `three` package folder",
    )


def find_asset(path: str | Path) -> tuple[Path, Path]:
    """(folder to serve, the glTF in it) for a convert folder, a .gltf/.glb, or a folder whose
    first glTF (sorted, searched recursively) is shown."""
    p = Path(path)
    if not p.exists():
        raise input_error(p, "not found")
    if p.is_file():
        if not is_gltf(p):
            raise input_error(p, "expected a .gltf or .glb (or a convert output folder)")
        return p.parent.resolve(), p.resolve()
    found = asset_file(p, GLTF_SUFFIXES)  # a convert folder: its glTF
    if found is None:  # any folder: its first glTF below
        below = [q for s in GLTF_SUFFIXES for q in sorted(p.rglob("*" + s)) if q.is_file()]
        found = below[0] if below else None
    if found is None:
        raise input_error(p, "no .gltf or .glb in this folder (is it a convert output?)")
    return p.resolve(), found.resolve()


@dataclass(frozen=True)
class Site:
    """What the server serves."""

    asset_dir: Path
    gltf: Path
    three_dir: Path

    def roots(self) -> dict[str, Path]:
        return {
            "viewer": VIEWER_DIR,
            "plugin": PLUGIN_DIR,
            "three": self.three_dir,
            "asset": self.asset_dir,
        }

    def info(self) -> dict[str, str]:
        rel = self.gltf.relative_to(self.asset_dir).as_posix()
        return {"gltf": f"/asset/{rel}", "name": self.gltf.stem}

    def resolve(self, url_path: str) -> Path | None:
        """The file a URL path names, or None when it is outside every root or missing."""
        parts = [unquote(x) for x in url_path.split("/") if x]
        if not parts or parts[0] not in self.roots():
            return None
        root = self.roots()[parts[0]].resolve()
        if any(x in ("..", ".") or "\\" in x or "\0" in x for x in parts[1:]):
            return None
        target = root.joinpath(*parts[1:]).resolve()
        if target != root and root not in target.parents:
            return None
        return target if target.is_file() else None


def _handler(site: Site) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        server_version = "wrinklepipe-view"

        def log_message(self, format: str, *args: object) -> None:  # noqa: A002
            pass  # quiet: the command prints the address once

        def _send(self, status: int, body: bytes, ctype: str) -> None:
            self.send_response(status)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            if self.command != "HEAD":
                self.wfile.write(body)

        def do_HEAD(self) -> None:  # noqa: N802
            self.do_GET()

        def do_GET(self) -> None:  # noqa: N802
            path = urlsplit(self.path).path
            if path in ("/", "/index.html"):
                body = (VIEWER_DIR / "index.html").read_bytes()
                return self._send(HTTPStatus.OK, body, "text/html; charset=utf-8")
            if path == "/asset.json":
                body = json.dumps(site.info()).encode("utf-8")
                return self._send(HTTPStatus.OK, body, "application/json")
            target = site.resolve(path)
            if target is None:
                return self._send(HTTPStatus.NOT_FOUND, b"not found", "text/plain")
            ctype = _TYPES.get(target.suffix.lower()) or (
                mimetypes.guess_type(target.name)[0] or "application/octet-stream"
            )
            self._send(HTTPStatus.OK, target.read_bytes(), ctype)

    return Handler


class ViewServer:
    """A running viewer server on ``127.0.0.1:port`` (0: any free port)."""

    def __init__(self, site: Site, port: int = 0) -> None:
        self.site = site
        self.httpd = ThreadingHTTPServer(("127.0.0.1", port), _handler(site))
        self.httpd.daemon_threads = True
        self.thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host, port = self.httpd.server_address[:2]
        return f"http://{host}:{port}/"

    def start(self) -> ViewServer:
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self.thread.start()
        return self

    def serve_forever(self) -> None:
        self.httpd.serve_forever()

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()

    def __enter__(self) -> ViewServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
