"""Issue 11, fuzz suite: hostile and careless inputs against the CLI verbs, run in-process;
issue 39 adds USD sources (hostile asset paths in textures, ``info:*``, sublayers, references,
payloads and value clips, cycles, counts, damaged text: and nothing of a file outside the
folder may reach any output) and images (lying PNG headers, damaged data, truncations, other
formats, two-channel maps past the horizon: an example running a minute is a hang).

Hypothesis mutates valid skeletons (the demo's manifest as TOML, its mesh as glTF JSON + .bin and
as GLB bytes, a converted asset's glTF with the wrinkle extension): fields set to wrong types
and hostile values (absolute and ``..`` paths, NaN, huge numbers, empty strings), keys deleted
and added, arrays grown to huge counts, values nested up to 100,000 deep, texts and containers
truncated, header fields lying. For every example the law is:

* the exit code is 0, 1 or 2, and no exception escapes (no traceback) -- nor does the CLI's last
  line of defence ("internal error") fire: every failure is a deliberate one-message error;
* exit 2 writes nothing at all (the working folder is exactly as before);
* whatever the exit code, nothing outside the output folder changes.

Derandomized (a fixed sequence of examples) and bounded, so CI is reproducible and takes about a
minute; ``WRINKLEPIPE_FUZZ_EXAMPLES=N`` runs N examples per test instead (e.g. nightly).
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import struct
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from wrinklepipe.cli import main
from wrinklepipe.demo.source import write_demo_source

_SCALE = int(os.environ.get("WRINKLEPIPE_FUZZ_EXAMPLES", "0"))


def _fuzz(examples: int) -> settings:
    return settings(
        max_examples=_SCALE or examples,
        derandomize=True,  # the same examples on every run: CI is reproducible
        database=None,  # nothing written into the repository
        deadline=None,
        suppress_health_check=list(HealthCheck),
        print_blob=True,
    )


# ------------------------------------------------------------------------------------------------
# skeletons (valid inputs, written once)


@pytest.fixture(scope="module")
def skeletons(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("skeletons")
    manifest = write_demo_source(root / "src", size=16)
    glb = (manifest.parent / "head.glb").read_bytes()
    n = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20 : 20 + n])
    doc["buffers"][0]["uri"] = "mesh.bin"
    mesh = root / "mesh"
    mesh.mkdir()
    (mesh / "mesh.gltf").write_text(json.dumps(doc))
    bin_off = 20 + n
    (mesh / "mesh.bin").write_bytes(
        glb[bin_off + 8 : bin_off + 8 + doc["buffers"][0]["byteLength"]]
    )
    asset = root / "asset"
    assert main(["convert", str(manifest), "-o", str(asset), "--no-validate", "--no-compress"]) == 0
    return {
        "manifest": manifest,
        "mesh": mesh / "mesh.gltf",
        "asset": asset,
        "glb": manifest.parent / "head.glb",
    }


def _link_tree(src: Path, dst: Path) -> None:
    """A cheap copy: hard links (an input replaced in it is unlinked first, never written
    through)."""
    shutil.copytree(src, dst, copy_function=os.link)


def _replace(path: Path, data: bytes) -> None:
    path.unlink(missing_ok=True)  # break the hard link
    path.write_bytes(data)


# ------------------------------------------------------------------------------------------------
# hostile values and mutations of a JSON-like tree


class Deep:
    """A value nested ``depth`` arrays deep (rendered as text: no recursion anywhere)."""

    def __init__(self, depth: int) -> None:
        self.depth = depth


_PATHS = [
    "",
    ".",
    "..",
    "../x.png",
    "/etc/passwd",
    "/dev/zero",
    "masks",
    "x/../../y.png",
    "file:///etc/passwd",
    "http://127.0.0.1:9/x.png",
    "C:\\x.png",
    "~/x.png",
    "$HOME/x.png",
    "-rf",
    "a" * 300,
    "nul\u0000.png",
    "\u00e9\u4e2d.png",
    "head.glb",
    "base_normal.png",
    "manifest.toml",
]
_NUMBERS = [0, -1, 1, 2, 3, 4, 255, 256, 2**31, 2**32 + 1, 2**53 + 1, 2**63 - 1, -(2**63), 10**30]
_FLOATS = [math.nan, math.inf, -math.inf, -0.0, 1e-320, 1e308, 0.5, 64.0001]

scalars = st.one_of(
    st.sampled_from(_PATHS),
    st.sampled_from(_NUMBERS),
    st.sampled_from(_FLOATS),
    st.integers(-(2**40), 2**40),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.booleans(),
)
values = st.recursive(
    scalars,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=8,
) | st.builds(Deep, st.sampled_from([3, 60, 200, 5_000, 100_000]))


def _paths(tree: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix]
    if isinstance(tree, dict):
        for k, v in tree.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(tree, list):
        for i, v in enumerate(tree[:8]):
            out += _paths(v, (*prefix, i))
    return out


def _get(tree: Any, path: tuple) -> Any:
    for p in path:
        tree = tree[p]
    return tree


def _mutate(data: st.DataObject, tree: Any, keys: list[str]) -> Any:
    """One to three mutations of a JSON-like tree (a deep copy is mutated)."""
    tree = json.loads(json.dumps(tree))
    for _ in range(data.draw(st.integers(1, 3), label="mutations")):
        paths = _paths(tree)
        path = data.draw(st.sampled_from(paths), label="at")
        kind = data.draw(
            st.sampled_from(["set", "set", "delete", "add", "grow", "wrap"]), label="kind"
        )
        if not path:
            if kind in ("set", "wrap"):
                tree = data.draw(values, label="root")
            continue
        parent, last = _get(tree, path[:-1]), path[-1]
        target = parent[last]
        if kind == "set":
            parent[last] = data.draw(values, label="value")
        elif kind == "delete":
            del parent[last]
        elif kind == "add" and isinstance(target, dict):
            key = data.draw(st.sampled_from(keys) | st.text(max_size=8), label="key")
            target[key] = data.draw(values, label="value")
        elif kind == "grow" and isinstance(target, list) and target:
            n = data.draw(st.sampled_from([2, 17, 300, 5_000]), label="count")
            parent[last] = (target * (n // len(target) + 1))[:n]
        elif kind == "wrap":
            parent[last] = [target] if data.draw(st.booleans()) else {"x": target}
    return tree


def _json_text(tree: Any) -> str:
    if isinstance(tree, Deep):
        return "[" * tree.depth + "]" * tree.depth
    if isinstance(tree, dict):
        return (
            "{" + ",".join(f"{json.dumps(str(k))}:{_json_text(v)}" for k, v in tree.items()) + "}"
        )
    if isinstance(tree, list):
        return "[" + ",".join(_json_text(v) for v in tree) + "]"
    if isinstance(tree, float) and not math.isfinite(tree):
        return {math.inf: "Infinity", -math.inf: "-Infinity"}.get(tree, "NaN")
    return json.dumps(tree)


def _toml_value(v: Any) -> str:
    if isinstance(v, Deep):
        return "[" * v.depth + "]" * v.depth
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return (
            "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
        )
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return (
            "{" + ", ".join(f"{json.dumps(str(k))} = {_toml_value(x)}" for k, x in v.items()) + "}"
        )
    return json.dumps(str(v))


def _toml_text(tree: Any) -> str:
    if not isinstance(tree, dict):
        return f'"value" = {_toml_value(tree)}\n'
    return "".join(f"{json.dumps(str(k))} = {_toml_value(v)}\n" for k, v in tree.items())


def _damage_text(data: st.DataObject, text: bytes) -> bytes:
    """Sometimes truncate the text or put stray bytes into it."""
    how = data.draw(st.sampled_from(["keep", "keep", "keep", "truncate", "bytes"]), label="text")
    if how == "truncate":
        return text[: data.draw(st.integers(0, len(text)), label="cut")]
    if how == "bytes":
        at = data.draw(st.integers(0, len(text)), label="at")
        return text[:at] + data.draw(st.binary(min_size=1, max_size=6), label="junk") + text[at:]
    return text


# ------------------------------------------------------------------------------------------------
# the law


def _snapshot(folder: Path, skip: Path | None = None) -> dict[str, tuple]:
    out = {}
    for p in sorted(folder.rglob("*")):
        if skip is not None and (p == skip or skip in p.parents):
            continue
        st_ = p.lstat()
        out[p.relative_to(folder).as_posix()] = (
            st_.st_mode,
            st_.st_size,
            st_.st_mtime_ns,
            st_.st_ino,
        )
    return out


_PYTHONISMS = re.compile(
    r"\b(Type|Key|Attribute|Index|Value|Recursion|Name|Overflow)Error\b|object has no attribute|"
    r"argument must be|indices must be|unhashable|not subscriptable|NoneType|object is not "
    r"(iterable|callable)|could not convert|invalid literal for"
)

#: A library's internals in a message: USD's C++ namespace, source files and grammar rules.
_LIBRARY_TEXT = re.compile(r"pxrInternal|Error in '|\.(?:cpp|h) :|pegtl|parse error matching")


def _check_law(capsys, work: Path, out: Path | None, run: Callable[[], int]) -> int:
    before, outside = _snapshot(work), _snapshot(work, out)
    try:
        code = run()
    except SystemExit as exc:  # argparse: only for bad arguments, which the fuzz never builds
        pytest.fail(f"SystemExit {exc.code}")
    err = capsys.readouterr().err
    assert code in (0, 1, 2), (code, err)
    assert "Traceback" not in err, err
    assert "internal error" not in err, err
    assert not _PYTHONISMS.search(err), err  # Python's own wording helps no user
    assert not _LIBRARY_TEXT.search(err), err  # nor a C++ library's (USD's error text)
    if code == 2:
        assert _snapshot(work) == before, f"exit 2 wrote or changed something: {err}"
    assert _snapshot(work, out) == outside, "something outside the output changed"
    return code


def _workdir() -> Path:
    return Path(tempfile.mkdtemp(prefix="wpfuzz-"))


# ------------------------------------------------------------------------------------------------
# manifests (TOML)

_MANIFEST_KEYS = [
    "name",
    "mesh",
    "base",
    "states",
    "regions",
    "drivers",
    "expressions",
    "policy",
    "encoding",
    "resolution",
    "formats",
    "budget",
    "pd_scale",
    "convention",
    "colour",
]


def _tame(tree: Any) -> Any:
    """A manifest may legitimately ask for 16384-texel maps; the fuzz keeps sizes small so an
    example takes milliseconds, not minutes (the law is about failure, not capacity)."""
    res = tree.get("resolution") if isinstance(tree, dict) else None
    if isinstance(res, dict):
        for k, v in list(res.items()):
            if isinstance(v, int) and not isinstance(v, bool) and v > 64:
                res[k] = 64
    return tree


@_fuzz(60)
@given(data=st.data())
def test_fuzz_manifest(skeletons, capsys, data):
    import tomllib

    src = skeletons["manifest"]
    tree = _tame(_mutate(data, tomllib.loads(src.read_text()), _MANIFEST_KEYS))
    text = _damage_text(data, _toml_text(tree).encode("utf-8", "surrogatepass"))
    work = _workdir()
    try:
        _link_tree(src.parent, work / "src")
        _replace(work / "src" / "manifest.toml", text)
        m = str(work / "src" / "manifest.toml")
        out = work / "out"
        verb = data.draw(st.sampled_from(["convert", "convert", "validate-asset"]), label="verb")
        if verb == "convert":
            extra = data.draw(
                st.sampled_from([["--no-validate", "--no-compress"], ["--no-render"]])
            )
            _check_law(capsys, work, out, lambda: main(["convert", m, "-o", str(out), *extra]))
        else:
            report = work / "r.json"
            _check_law(
                capsys,
                work,
                report,
                lambda: main(["validate-asset", m, "--no-render", "--report", str(report)]),
            )
    finally:
        shutil.rmtree(work, ignore_errors=True)


# ------------------------------------------------------------------------------------------------
# glTF JSON (a plain mesh: vertex-ids, dynamic) and a converted asset (validate-asset, export)

_GLTF_KEYS = [
    "accessors",
    "bufferViews",
    "buffers",
    "meshes",
    "nodes",
    "scenes",
    "scene",
    "asset",
    "extensionsUsed",
    "extensionsRequired",
    "extras",
    "images",
    "textures",
    "materials",
    "skins",
    "animations",
    "count",
    "byteOffset",
    "byteLength",
    "uri",
]


@_fuzz(80)
@given(data=st.data())
def test_fuzz_gltf_mesh(skeletons, capsys, data):
    src = skeletons["mesh"]
    tree = _mutate(data, json.loads(src.read_text()), _GLTF_KEYS)
    text = _damage_text(data, _json_text(tree).encode("utf-8", "surrogatepass"))
    work = _workdir()
    try:
        _link_tree(src.parent, work / "mesh")
        _replace(work / "mesh" / "mesh.gltf", text)
        g = str(work / "mesh" / "mesh.gltf")
        out = work / "w.npy"
        verb = data.draw(st.sampled_from(["vertex-ids", "dynamic", "inspect"]), label="verb")
        if verb == "vertex-ids":
            _check_law(capsys, work, out, lambda: main(["vertex-ids", g, "-o", str(out)]))
        elif verb == "inspect":
            _check_law(capsys, work, None, lambda: main(["inspect", g, "--json"]))
        else:
            args = ["dynamic", g, "--morph", "brow_furrow=1", "-o", str(out)]
            _check_law(capsys, work, out, lambda: main(args))
    finally:
        shutil.rmtree(work, ignore_errors=True)


@_fuzz(60)
@given(data=st.data())
def test_fuzz_converted_gltf(skeletons, capsys, data):
    src = skeletons["asset"]
    gltf = next(src.glob("*.gltf"))
    tree = _mutate(data, json.loads(gltf.read_text()), _GLTF_KEYS + ["WRINKLEPIPE_wrinkle_maps"])
    text = _damage_text(data, _json_text(tree).encode("utf-8", "surrogatepass"))
    work = _workdir()
    try:
        _link_tree(src, work / "asset")
        _replace(work / "asset" / gltf.name, text)
        g = str(work / "asset" / gltf.name)
        verb = data.draw(st.sampled_from(["validate-asset", "export"]), label="verb")
        if verb == "validate-asset":
            _check_law(capsys, work, None, lambda: main(["validate-asset", g, "--no-render"]))
        else:
            engine = data.draw(st.sampled_from(["unreal", "unity", "godot", "blender"]))
            out = work / "exp"
            _check_law(
                capsys, work, out, lambda: main(["export", g, "--engine", engine, "-o", str(out)])
            )
    finally:
        shutil.rmtree(work, ignore_errors=True)


# ------------------------------------------------------------------------------------------------
# GLB bytes: truncations, lying header and chunk fields, stray bytes

_U32 = [0, 1, 4, 8, 12, 20, 0x7FFFFFFF, 0xFFFFFFFF, 0x4E4F534A, 0x004E4942]


@_fuzz(80)
@given(data=st.data())
def test_fuzz_glb(skeletons, capsys, data):
    glb = bytearray(skeletons["glb"].read_bytes())
    json_len = struct.unpack_from("<I", glb, 12)[0]
    fields = [4, 8, 12, 16, 20 + json_len, 24 + json_len]  # version, length, chunk lengths/types
    for _ in range(data.draw(st.integers(1, 3), label="mutations")):
        how = data.draw(st.sampled_from(["field", "truncate", "flip", "json"]), label="how")
        if how == "field":
            at = data.draw(st.sampled_from(fields), label="field")
            value = data.draw(st.sampled_from(_U32) | st.integers(0, len(glb) + 64), label="u32")
            if at + 4 <= len(glb):
                struct.pack_into("<I", glb, at, value)
        elif how == "truncate":
            glb = glb[: data.draw(st.integers(0, len(glb)), label="cut")]
        elif how == "flip" and glb:
            at = data.draw(st.integers(0, min(len(glb) - 1, 20 + json_len + 64)), label="at")
            glb[at] ^= data.draw(st.integers(1, 255), label="bits")
        elif how == "json" and len(glb) > 20 + json_len:
            at = data.draw(st.integers(20, 20 + json_len - 1), label="at")
            glb[at] = data.draw(st.sampled_from(b'{}[]":,0\\\x00\xff'), label="byte")
    work = _workdir()
    try:
        p = work / "head.glb"
        p.write_bytes(bytes(glb))
        verb = data.draw(
            st.sampled_from(["vertex-ids", "dynamic", "validate-asset", "inspect"]), label="verb"
        )
        out = work / "w.npy"
        args = {
            "vertex-ids": ["vertex-ids", str(p), "-o", str(out)],
            "dynamic": ["dynamic", str(p), "--morph", "brow_furrow=1", "-o", str(out)],
            "validate-asset": ["validate-asset", str(p), "--no-render"],
            "inspect": ["inspect", str(p)],
        }[verb]
        _check_law(capsys, work, out, lambda: main(args))
    finally:
        shutil.rmtree(work, ignore_errors=True)


# ------------------------------------------------------------------------------------------------
# issue 39: USD sources (every path a layer can name, composition arcs, counts) and images


SECRET = b"wrinklepipe-fuzz-secret-outside-the-asset\n"


class _Hung(BaseException):
    """Raised by the alarm in the main thread: an example that runs a minute is a hang."""


def _within(seconds: float, run: Callable[[], int]) -> Callable[[], int]:
    """``run`` failed (:class:`_Hung`) once it has used ``seconds`` of CPU, or ten times that
    in wall-clock time: a spinning loop or an endless wait is a hang; a loaded machine, which
    stretches the wall clock but not the CPU an example needs, is not."""
    import signal

    def timed() -> int:
        def ring(signum, frame):  # noqa: ANN001
            what = "of CPU" if signum == signal.SIGPROF else "of wall-clock time"
            raise _Hung(f"still running after {seconds} s {what}")

        old = {s: signal.signal(s, ring) for s in (signal.SIGPROF, signal.SIGALRM)}
        signal.setitimer(signal.ITIMER_PROF, seconds)
        signal.setitimer(signal.ITIMER_REAL, 10 * seconds)
        try:
            return run()
        finally:
            signal.setitimer(signal.ITIMER_PROF, 0)
            signal.setitimer(signal.ITIMER_REAL, 0)
            for s, handler in old.items():
                signal.signal(s, handler)

    return timed


@pytest.fixture(scope="module")
def usd_skeleton(tmp_path_factory) -> Path:
    """The generated avatar (tests/test_usd_layer.py) with its manifest in its own folder."""
    from test_usd_layer import write_avatar
    from wrinkle_setups import write_setup

    folder = tmp_path_factory.mktemp("usd_skeleton") / "asset"
    usd = write_avatar(folder)
    write_setup(folder, Path(usd.name), "hero", material="Skin", meshes=["Head"], size=16)
    return folder


def _hostile_asset(data: st.DataObject, secret: Path) -> str:
    return data.draw(
        st.sampled_from(
            [
                str(secret),
                "../outside/secret.png",
                "textures/../../outside/secret.png",
                "link.png",  # a symbolic link to the secret, made in the work folder
                "nowhere.png",
                "./avatar.usda",  # itself: a cycle when used as a layer
                "./loop.usda",
                "pkg.usdz[x.png]",
            ]
            + [p for p in _PATHS if "\u0000" not in p and "@" not in p]
        ),
        label="asset",
    )


def _usd_mutation(data: st.DataObject, text: str, secret: Path) -> str:
    kind = data.draw(
        st.sampled_from(["texture", "info", "sublayer", "arc", "clips", "counts", "points"]),
        label="usd",
    )
    a = _hostile_asset(data, secret)
    if kind == "texture":
        return text.replace("@textures/skin.png@", f"@{a}@")
    if kind == "info":
        return text.replace(
            '(kind = "component") {', f'(kind = "component") {{\n    asset info:doc = @{a}@', 1
        )
    if kind == "sublayer":
        return text.replace("(\n    defaultPrim", f"(\n    subLayers = [@{a}@]\n    defaultPrim", 1)
    if kind == "arc":
        arc = data.draw(st.sampled_from(["references", "payload"]), label="arc")
        return text + f'\ndef Xform "Extra" ({arc} = @{a}@</Avatar>) {{}}\n'
    if kind == "clips":
        return text.replace(
            '(kind = "component")',
            '(kind = "component"\n    clips = { dictionary default = {\n'
            f'        asset[] assetPaths = [@{a}@]\n        string primPath = "/Clip"\n'
            "        double2[] active = [(0, 0)]\n    } }\n)",
            1,
        )
    if kind == "counts":
        n = data.draw(st.sampled_from(_NUMBERS), label="count")
        pattern = r"int\[\] faceVertexCounts = \[[^\]]*\]"
        return re.sub(pattern, f"int[] faceVertexCounts = [{n}]", text, count=1)
    n = data.draw(st.sampled_from(["nan", "inf", "-1e39", "1e30", "0"]), label="coord")
    return re.sub(r"point3f\[\] points = \[\(", f"point3f[] points = [({n}, ", text, count=1)


@_fuzz(30)
@given(data=st.data())
def test_fuzz_usd_source(usd_skeleton, capsys, data):
    """Besides the law: no byte of a file outside the asset folder reaches any output (the
    usdz included), and USD's own diagnostics never reach the terminal raw."""
    work = _workdir()
    try:
        (work / "outside").mkdir()
        secret = work / "outside" / "secret.png"
        secret.write_bytes(SECRET)
        _link_tree(usd_skeleton, work / "asset")
        (work / "asset" / "link.png").symlink_to(secret)
        (work / "asset" / "loop.usda").write_text(
            "#usda 1.0\n(\n    subLayers = [@./avatar.usda@]\n)\n"
        )
        usd = work / "asset" / "avatar.usda"
        text = usd.read_text()
        for _ in range(data.draw(st.integers(1, 2), label="mutations")):
            text = _usd_mutation(data, text, secret)
        _replace(usd, _damage_text(data, text.encode("utf-8", "surrogatepass")))
        out = work / "out"
        m = str(work / "asset" / "manifest.toml")
        verb = data.draw(st.sampled_from(["convert", "convert", "inspect"]), label="verb")
        args = (
            ["convert", m, "-o", str(out), "--no-render", "--no-compress"]
            if verb == "convert"
            else ["inspect", str(usd)]
        )
        _check_law(capsys, work, out, _within(60, lambda: main(args)))
        for f in out.rglob("*") if out.exists() else []:
            if f.is_file():
                assert SECRET not in f.read_bytes(), f"{f} holds bytes from outside the folder"
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _png_chunks(png: bytes) -> list[tuple[bytes, bytes]]:
    out, at = [], 8
    while at + 8 <= len(png):
        n = struct.unpack(">I", png[at : at + 4])[0]
        out.append((png[at + 4 : at + 8], png[at + 8 : at + 8 + n]))
        at += 12 + n
    return out


def _png(chunks: list[tuple[bytes, bytes]]) -> bytes:
    import zlib

    body = b"".join(
        struct.pack(">I", len(d)) + k + d + struct.pack(">I", zlib.crc32(k + d) & 0xFFFFFFFF)
        for k, d in chunks
    )
    return b"\x89PNG\r\n\x1a\n" + body


def _image_mutation(data: st.DataObject, png: bytes) -> bytes:
    import zlib

    kind = data.draw(
        st.sampled_from(["ihdr", "ihdr", "idat", "truncate", "flip", "other", "two_channel"]),
        label="image",
    )
    chunks = _png_chunks(png)
    if kind == "ihdr":
        w, h, depth, colour = struct.unpack(">IIBB", chunks[0][1][:10])
        field = data.draw(st.sampled_from(["w", "h", "depth", "colour"]), label="field")
        big = st.sampled_from([0, 1, 3, 2**16, 2**24, 2**31 - 1, 2**32 - 1])
        if field == "w":
            w = data.draw(big, label="w")
        elif field == "h":
            h = data.draw(big, label="h")
        elif field == "depth":
            depth = data.draw(st.sampled_from([0, 1, 2, 4, 8, 16, 32, 255]), label="depth")
        else:
            colour = data.draw(st.sampled_from([0, 1, 2, 3, 4, 5, 6, 7, 255]), label="colour")
        chunks[0] = (b"IHDR", struct.pack(">IIBB", w, h, depth, colour) + chunks[0][1][10:])
        return _png(chunks)
    if kind == "idat":
        idat = [i for i, (k, _) in enumerate(chunks) if k == b"IDAT"]
        raw = bytearray(zlib.decompress(b"".join(chunks[i][1] for i in idat)))
        at = data.draw(st.integers(0, max(0, len(raw) - 1)), label="at")
        raw[at : at + 4] = data.draw(st.binary(min_size=1, max_size=4), label="bytes")
        chunks = [c for i, c in enumerate(chunks) if i not in idat[1:]]
        chunks[idat[0]] = (b"IDAT", zlib.compress(bytes(raw)))
        return _png(chunks)
    if kind == "truncate":
        return png[: data.draw(st.integers(0, len(png)), label="cut")]
    if kind == "flip":
        b = bytearray(png)
        b[data.draw(st.integers(0, len(b) - 1), label="at")] ^= data.draw(st.integers(1, 255))
        return bytes(b)
    if kind == "two_channel":  # grey + alpha, texels on and past the horizon (the PD hang)
        size = 16
        x = data.draw(st.sampled_from([0, 128, 200, 255]), label="x")
        y = data.draw(st.sampled_from([0, 128, 200, 255]), label="y")
        rows = b"".join(b"\0" + bytes([x, y]) * size for _ in range(size))
        ihdr = struct.pack(">IIBBBBB", size, size, 8, 4, 0, 0, 0)
        return _png([(b"IHDR", ihdr), (b"IDAT", zlib.compress(rows)), (b"IEND", b"")])
    return data.draw(
        st.sampled_from(
            [
                b"",
                b"plain text, not an image\n",
                b"DDS " + b"\xff" * 124,
                b"\xabKTX 20\xbb\r\n\x1a\n" + b"\xff" * 80,
                b"\xff\xd8\xff\xe0" + b"\0" * 16,
                b"GIF89a" + b"\xff" * 10,
            ]
        ),
        label="bytes",
    )


@_fuzz(40)
@given(data=st.data())
def test_fuzz_images(skeletons, capsys, data):
    src = skeletons["manifest"]
    which = data.draw(
        st.sampled_from(["base_normal.png", "wrinkle_stretch.png", "masks/chin.png"]),
        label="file",
    )
    work = _workdir()
    try:
        _link_tree(src.parent, work / "src")
        target = work / "src" / which
        _replace(target, _image_mutation(data, target.read_bytes()))
        m = str(work / "src" / "manifest.toml")
        out = work / "out"
        verb = data.draw(st.sampled_from(["convert", "validate-asset"]), label="verb")
        if verb == "convert":
            run = lambda: main(["convert", m, "-o", str(out), "--no-render"])  # noqa: E731
        else:
            out = work / "r.json"
            run = lambda: main(["validate-asset", m, "--no-render", "--report", str(out)])  # noqa: E731
        _check_law(capsys, work, out, _within(60, run))
    finally:
        shutil.rmtree(work, ignore_errors=True)
