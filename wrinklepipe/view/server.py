"""The viewer's HTTP server: four read-only roots on 127.0.0.1, nothing else.

``/`` the page, ``/viewer/*`` its script and style, ``/plugin/*`` the GLTFLoader plugin,
``/three/*`` the three.js package, ``/asset/*`` the asset, ``/asset.json`` which glTF to show.

- **Only the asset's files.** Under ``/asset/`` it serves the glTF shown (given a folder: every
  glTF in it) and the files those glTFs reference (buffers, images, the compressed copies an
  extension lists): nothing else of the folder, whatever it holds (a ``.env``, ``.ssh/``,
  reports, the sources). Read from the glTFs at each request, so a conversion written meanwhile
  is served as it now is.
- **No hidden files, no listings, no writes.** A path with a part starting with ``.`` is not
  served from any root; paths are resolved and must stay inside their root (no ``..``, no
  symbolic links out); a folder is never listed.
- **Loopback only.** The server listens on 127.0.0.1 and answers only requests whose ``Host``
  is ``127.0.0.1`` or ``localhost`` (with its port): a page on another site that rebinds its
  DNS name to 127.0.0.1 gets 421 and nothing else.
- **Streamed.** Files go out in chunks of :data:`CHUNK` bytes from the open file, whatever their
  size (a 3 GB buffer costs no more memory than a 3 KB one; concurrent requests too).
"""

from __future__ import annotations

import json
import mimetypes
import os
import shutil
import subprocess
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path, PurePosixPath
from typing import Any
from urllib.parse import unquote, urlsplit

from wrinklepipe.errors import InputError, input_error
from wrinklepipe.gltf.container import split_glb
from wrinklepipe.io.json_safe import loads_json
from wrinklepipe.paths import ROOT
from wrinklepipe.sources.package import asset_file
from wrinklepipe.suffixes import GLTF_SUFFIXES, is_gltf

DATA = Path(__file__).resolve().parent.parent / "data"
#: Bytes sent per write when a file is streamed.
CHUNK = 1 << 20
#: Host names a request may be addressed to (with or without the server's port).
LOOPBACK_NAMES = ("127.0.0.1", "localhost")
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


def _references(gltf: Path) -> Iterator[str]:
    """The relative URIs a glTF or GLB names (buffers, images, and any ``uri`` / ``uris`` of an
    extension, such as the compressed copies), percent-decoded; ``data:`` URIs left out."""
    try:
        raw = gltf.read_bytes()
        text = split_glb(raw, str(gltf))[0] if raw[:4] == b"glTF" else raw
        doc = loads_json(text, gltf, "glTF JSON")
    except (OSError, InputError):
        return
    stack: list[Any] = [doc]
    while stack:
        obj = stack.pop()
        if isinstance(obj, dict):
            for k, v in obj.items():
                if k == "uri" and isinstance(v, str):
                    yield v
                elif k == "uris" and isinstance(v, list):
                    yield from (u for u in v if isinstance(u, str))
                else:
                    stack.append(v)
        elif isinstance(obj, list):
            stack.extend(obj)


def _hidden(parts: tuple[str, ...] | list[str]) -> bool:
    return any(x.startswith(".") for x in parts)


@dataclass(frozen=True)
class Site:
    """What the server serves. ``only_gltf``: the asset is that one glTF and what it references
    (given a file); otherwise every glTF under ``asset_dir`` and what they reference."""

    asset_dir: Path
    gltf: Path
    three_dir: Path
    only_gltf: bool = False
    _cache: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

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

    def _gltfs(self) -> list[Path]:
        if self.only_gltf:
            return [self.gltf]
        root = self.asset_dir.resolve()
        found = []
        for folder, dirs, files in os.walk(root):
            dirs[:] = sorted(d for d in dirs if not d.startswith("."))
            found += [
                Path(folder) / f
                for f in sorted(files)
                if not f.startswith(".") and is_gltf(f) and (Path(folder) / f).is_file()
            ]
        return found

    def asset_files(self) -> frozenset[Path]:
        """Every file ``/asset/`` may serve (resolved): the glTFs and what they reference,
        inside the asset folder and not hidden. Kept while the glTFs are unchanged."""
        root = self.asset_dir.resolve()
        gltfs = self._gltfs()
        stamp = tuple((str(g), g.stat().st_mtime_ns) for g in gltfs if g.is_file())
        if self._cache.get("stamp") == stamp:
            return self._cache["files"]
        files: set[Path] = set()
        for g in gltfs:
            g = g.resolve()
            files.add(g)
            for uri in _references(g):
                if uri.startswith("data:") or "://" in uri or uri.startswith(("/", "\\")):
                    continue
                rel = PurePosixPath(unquote(uri).replace("\\", "/"))
                if ".." in rel.parts or _hidden(rel.parts):
                    continue
                target = (g.parent / Path(*rel.parts)).resolve()
                if target.is_relative_to(root) and not _hidden(target.relative_to(root).parts):
                    files.add(target)
        self._cache.update(stamp=stamp, files=frozenset(files))
        return self._cache["files"]

    def resolve(self, url_path: str) -> Path | None:
        """The file a URL path names, or None when it is outside every root, hidden, missing,
        or (under ``/asset/``) not one of the asset's files."""
        parts = [unquote(x) for x in url_path.split("/") if x]
        if not parts or parts[0] not in self.roots():
            return None
        root = self.roots()[parts[0]].resolve()
        rest = parts[1:]
        if any(x in ("..", ".") or "\\" in x or "\0" in x for x in rest) or _hidden(rest):
            return None
        target = root.joinpath(*rest).resolve()
        if target != root and root not in target.parents:
            return None
        if _hidden(target.relative_to(root).parts) or not target.is_file():
            return None
        if parts[0] == "asset" and target not in self.asset_files():
            return None
        return target


def _handler(site: Site) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        server_version = "wrinklepipe-view"

        def log_message(self, format: str, *args: object) -> None:  # noqa: A002
            pass  # quiet: the command prints the address once

        def _head(self, status: int, length: int, ctype: str) -> None:
            self.send_response(status)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(length))
            self.send_header("Cache-Control", "no-store")
            self.send_header("X-Content-Type-Options", "nosniff")
            self.end_headers()

        def _send(self, status: int, body: bytes, ctype: str) -> None:
            self._head(status, len(body), ctype)
            if self.command != "HEAD":
                self.wfile.write(body)

        def _stream(self, target: Path, ctype: str) -> None:
            try:
                f = open(target, "rb")  # noqa: SIM115 - closed below; sent in chunks
            except OSError:
                return self._send(HTTPStatus.NOT_FOUND, b"not found", "text/plain")
            with f:
                self._head(HTTPStatus.OK, os.fstat(f.fileno()).st_size, ctype)
                if self.command != "HEAD":
                    try:
                        shutil.copyfileobj(f, self.wfile, CHUNK)
                    except (BrokenPipeError, ConnectionResetError):
                        pass  # the page went away

        def _host_ok(self) -> bool:
            """The request is addressed to this server by a loopback name (DNS rebinding: a
            page on another site reaching 127.0.0.1 still sends its own Host)."""
            host = (self.headers.get("Host") or "").strip().lower()
            port = self.server.server_address[1]
            return host in {n for name in LOOPBACK_NAMES for n in (name, f"{name}:{port}")}

        def do_HEAD(self) -> None:  # noqa: N802
            self.do_GET()

        def do_GET(self) -> None:  # noqa: N802
            if not self._host_ok():
                return self._send(
                    HTTPStatus.MISDIRECTED_REQUEST, b"wrong host", "text/plain; charset=utf-8"
                )
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
            self._stream(target, ctype)

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
