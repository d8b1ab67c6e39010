"""Issue 39, the viewer's server (``wrinklepipe view``): it answers only requests addressed to
127.0.0.1 / localhost (a DNS-rebinding page gets nothing), serves only the asset's glTF and the
files it references (no hidden files, no other file of the folder, no listings), and streams
files instead of reading them whole (a 1 GB buffer costs no memory)."""

from __future__ import annotations

import http.client
import json
import shutil
import threading
import tracemalloc
from pathlib import Path

import pytest

from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.view.server import Site, ViewServer, find_asset

GIB = 1 << 30


@pytest.fixture(scope="module")
def converted(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("view")
    src = write_demo_source(root / "src", 16)
    out = root / "asset"
    assert main(["convert", str(src), "-o", str(out), "--no-render", "--no-validate"]) == 0
    return out


@pytest.fixture
def folder(converted, tmp_path) -> Path:
    """The converted asset, plus what a studio folder holds beside it."""
    out = tmp_path / "asset"
    shutil.copytree(converted, out)
    (out / ".env").write_text("SECRET=1\n")
    (out / ".ssh").mkdir()
    (out / ".ssh" / "id_ed25519").write_text("-----BEGIN OPENSSH PRIVATE KEY-----\n")
    (out / "notes.txt").write_text("not part of the asset\n")
    return out


def _get(url: str, path: str, host: str | None = None, method: str = "GET") -> tuple[int, bytes]:
    hostport = url.split("//", 1)[1].rstrip("/")
    conn = http.client.HTTPConnection(hostport, timeout=30)
    try:
        conn.putrequest(method, path, skip_host=True)
        conn.putheader("Host", host if host is not None else hostport)
        conn.endheaders()
        r = conn.getresponse()
        return r.status, r.read() if method == "GET" else b""
    finally:
        conn.close()


def _server(folder: Path, only: bool = False) -> ViewServer:
    f, gltf = find_asset(folder / "demo_head.gltf" if only else folder)
    return ViewServer(Site(f, gltf, folder, only_gltf=only))


def test_only_the_assets_files_are_served(folder):
    with _server(folder) as srv:
        info = json.loads(_get(srv.url, "/asset.json")[1])
        assert _get(srv.url, info["gltf"])[0] == 200
        doc = json.loads(_get(srv.url, info["gltf"])[1])
        for uri in [b["uri"] for b in doc["buffers"]] + [i["uri"] for i in doc["images"]]:
            assert _get(srv.url, f"/asset/{uri}")[0] == 200, uri
        for path in (
            "/asset/.env",
            "/asset/.ssh/id_ed25519",
            "/asset/notes.txt",
            "/asset/report.json",  # in the folder, but no glTF references it
            "/asset/",
            "/asset/textures/",
            "/asset/textures",
            "/asset/%2e%2e/asset/demo_head.gltf",
            "/three/.env",  # the three.js root holds it here: hidden files are never served
        ):
            assert _get(srv.url, path)[0] == 404, path


def test_a_gltf_given_as_a_file_serves_that_glTF_only(folder):
    other = folder / "other.gltf"
    shutil.copy(folder / "demo_head.gltf", other)
    with _server(folder, only=True) as srv:
        assert _get(srv.url, "/asset/demo_head.gltf")[0] == 200
        assert _get(srv.url, "/asset/other.gltf")[0] == 404


@pytest.mark.parametrize(
    "host, status",
    [
        ("evil.example", 421),
        ("evil.example:{port}", 421),
        ("127.0.0.1.evil.example", 421),
        ("", 421),
        ("localhost:{port}", 200),
        ("127.0.0.1:{port}", 200),
        ("LOCALHOST", 200),
    ],
)
def test_only_loopback_host_names_are_answered(folder, host, status):
    with _server(folder) as srv:
        port = srv.httpd.server_address[1]
        got, body = _get(srv.url, "/asset.json", host=host.format(port=port))
        assert got == status, (host, got)
        if status != 200:
            assert b"gltf" not in body


def test_files_are_streamed_not_read_whole(folder):
    """A glTF whose buffer is a 1 GiB file (sparse on disk): HEAD gives its size, three
    concurrent GETs that read the first MiB and hang up make the server allocate a few MiB at
    most (it read each file whole into memory: 1 GiB per request)."""
    big = folder / "big.bin"
    with open(big, "wb") as f:
        f.truncate(GIB)
    gltf = json.loads((folder / "demo_head.gltf").read_text())
    gltf["buffers"].append({"uri": "big.bin", "byteLength": GIB})
    (folder / "demo_head.gltf").write_text(json.dumps(gltf))
    with _server(folder) as srv:
        hostport = srv.url.split("//", 1)[1].rstrip("/")
        conn = http.client.HTTPConnection(hostport, timeout=30)
        conn.request("HEAD", "/asset/big.bin")
        assert int(conn.getresponse().getheader("Content-Length")) == GIB
        conn.close()
        tracemalloc.start()
        try:

            def first_mib() -> None:
                c = http.client.HTTPConnection(hostport, timeout=60)
                c.request("GET", "/asset/big.bin")
                r = c.getresponse()
                assert r.status == 200 and len(r.read(1 << 20)) == 1 << 20
                c.close()

            threads = [threading.Thread(target=first_mib) for _ in range(3)]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert peak < 64 << 20, f"the server allocated {peak >> 20} MiB for three requests"
