"""A fork server for the documentation's shell examples: ``wrinklepipe ...`` without paying
Python's and the CLI's import time (~1 s) for each of the examples' many commands.

``python tests/docs_cli_server.py SOCKET`` imports the CLI and every command once, then, for
each client, forks a child that takes the client's standard input, output and error (passed
over the socket), working folder, environment and arguments, runs :func:`wrinklepipe.cli.main`
exactly as the console script does, and sends back its exit code. ``client`` is what the
sandbox's ``wrinklepipe`` script runs: it exits with that code. The server forks from its one
Python thread (importing USD starts a thread of USD's own, as in the batch fork server; a child
runs only the forking thread); each run is a process of its own, as on the command line.
"""

from __future__ import annotations

import array
import json
import os
import signal
import socket
import sys

_HEADER = 4

# Each child starts warm, as the batch fork server's do: the server imports once what the
# commands import where they first need them (``wrinklepipe.batch.engines._PRELOAD``: the
# writers, the validator's renderer and report, USD), colour science (CIEDE2000, ~0.5 s), and
# numba with the BC4 / BC5 kernels loaded from its cache (~0.7 s). Importing them starts no GL
# context; the children still run every command's whole code.


def _recv_request(conn: socket.socket) -> tuple[dict, list[int]]:
    fds = array.array("i")
    data, ancdata, _, _ = conn.recvmsg(1 << 16, socket.CMSG_SPACE(3 * fds.itemsize))
    for level, kind, payload in ancdata:
        if level == socket.SOL_SOCKET and kind == socket.SCM_RIGHTS:
            fds.frombytes(payload[: len(payload) - len(payload) % fds.itemsize])
    size = int.from_bytes(data[:_HEADER], "big")
    body = data[_HEADER:]
    while len(body) < size:
        chunk = conn.recv(1 << 16)
        if not chunk:
            break
        body += chunk
    return json.loads(body), list(fds)


def _child(conn: socket.socket, request: dict, fds: list[int]) -> None:
    from wrinklepipe import cli

    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    for target, fd in enumerate(fds[:3]):
        os.dup2(fd, target)
    for fd in fds:
        os.close(fd)
    os.chdir(request["cwd"])
    os.environ.clear()
    os.environ.update(request["env"])
    sys.argv = ["wrinklepipe", *request["argv"]]
    try:
        code = cli.main(request["argv"])
    except SystemExit as exc:  # argparse: --help, bad arguments
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
    conn.sendall(str(int(code or 0)).encode())
    conn.close()


def _preload() -> None:
    import importlib

    import numpy as np

    from wrinklepipe.batch.engines import _PRELOAD
    from wrinklepipe.normals import bc4

    for name in _PRELOAD:
        importlib.import_module(name)
    importlib.import_module("wrinklepipe.metrics.delta_e")._colour()
    bc4.encode_bc4(np.zeros((4, 4), np.uint8))  # numba's kernels, from its cache


def serve(path: str) -> None:
    from wrinklepipe import cli

    cli._command_modules()  # every command's module, imported once for all the children
    _preload()
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(path)
    server.listen(32)
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # children are reaped by the kernel
    print("ready", flush=True)
    while True:
        conn, _ = server.accept()
        try:
            request, fds = _recv_request(conn)
        except (OSError, ValueError):
            conn.close()
            continue
        if os.fork() == 0:
            server.close()
            code = 70
            try:
                _child(conn, request, fds)
                code = 0
            finally:
                os._exit(code)
        for fd in fds:
            os.close(fd)
        conn.close()


def client() -> None:
    """The sandbox's ``wrinklepipe``: run the command in a child of the server; its exit code."""
    conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    conn.connect(os.environ["WRINKLEPIPE_DOCS_SERVER"])
    body = json.dumps({"argv": sys.argv[1:], "cwd": os.getcwd(), "env": dict(os.environ)})
    data = body.encode()
    conn.sendmsg(
        [len(data).to_bytes(_HEADER, "big") + data],
        [(socket.SOL_SOCKET, socket.SCM_RIGHTS, array.array("i", [0, 1, 2]))],
    )
    reply = b""
    while chunk := conn.recv(64):
        reply += chunk
    sys.exit(int(reply) if reply else 70)  # 70: the child died without an answer


if __name__ == "__main__":
    if sys.argv[1] == "--client":
        sys.argv = [sys.argv[0], *sys.argv[2:]]
        client()
    else:
        serve(sys.argv[1])
