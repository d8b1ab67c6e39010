"""Cache keys: what an asset's output depends on, hashed.

``asset_key(job)`` is the SHA-256 of a canonical JSON document holding

* the **tool**: wrinklepipe's version, a digest of its own files (every module, schema, shader
  and data file of the package, so an edited checkout never serves stale outputs), and the
  versions of the libraries that write or decide output bytes (numpy, OpenImageIO, usd-core,
  etcpak, zlib, ...);
* the **options** that change the output (:meth:`AssetOptions.output_fields`);
* every **input**: the manifest and each file it reads (meshes with the buffers and images a
  ``.gltf`` names and the layers and assets a USD file pulls in, maps, masks, driver files),
  as (path relative to the manifest's folder, SHA-256 of the bytes);
* for a USD source, the path the output layer names it by (relative to the output folder:
  :func:`wrinklepipe.usd.layer.source_reference`).

Paths are relative, so a character checked out elsewhere (another CI runner, another farm node)
hits the same entry. Reading the inputs to hash them is the only work a cached asset costs.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import zlib
from functools import cache
from importlib import metadata
from pathlib import Path
from typing import Any
from urllib.parse import unquote

from wrinklepipe import __version__
from wrinklepipe.batch.options import AssetOptions
from wrinklepipe.io.confine import confine_usd
from wrinklepipe.paths import ROOT
from wrinklepipe.sources.manifest import load_manifest
from wrinklepipe.suffixes import USD_SUFFIXES
from wrinklepipe.usd.layer import source_reference

KEY_SCHEMA = "wrinklepipe/batch-cache@1"
#: Libraries whose version can change the bytes convert writes or the validation it records.
LIBRARIES = (
    "numpy",
    "scipy",
    "openimageio",
    "usd-core",
    "pygltflib",
    "etcpak",
    "texture2ddecoder",
    "trimesh",
    "xatlas",
    "moderngl",
    "alktx2",
)
_PACKAGE_PARTS = ("wrinklepipe", "schemas", "shaders")


def sha256_file(path: Path, chunk: int = 1 << 20) -> str:
    """SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


@cache
def code_digest() -> str:
    """SHA-256 over the package's own files (path and bytes), in a fixed order."""
    h = hashlib.sha256()
    for part in _PACKAGE_PARTS:
        base = ROOT / part
        if not base.is_dir():
            continue
        for p in sorted(base.rglob("*")):
            if p.is_file() and p.suffix != ".pyc" and "__pycache__" not in p.parts:
                h.update(p.relative_to(ROOT).as_posix().encode("utf-8") + b"\0")
                h.update(p.read_bytes())
    return h.hexdigest()


def _version(name: str) -> str:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return ""


@cache
def tool_fingerprint() -> dict[str, Any]:
    """What identifies the tool that writes the outputs (see the module docstring)."""
    return {
        "wrinklepipe": __version__,
        "code": code_digest(),
        "python": ".".join(platform.python_version_tuple()[:2]),
        "zlib": zlib.ZLIB_RUNTIME_VERSION,
        "libraries": {name: _version(name) for name in LIBRARIES},
    }


def _gltf_dependencies(path: Path) -> list[Path]:
    """Files a .gltf names by relative URI (buffers, images); none for a .glb."""
    if path.suffix.lower() != ".gltf":
        return []
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    out = []
    for item in [*doc.get("buffers", []), *doc.get("images", [])]:
        uri = item.get("uri") if isinstance(item, dict) else None
        if isinstance(uri, str) and uri and not uri.startswith("data:") and "://" not in uri:
            out.append(path.parent / unquote(uri))
    return out


def _usd_dependencies(path: Path) -> list[Path]:
    """Layers and assets a USD file pulls in (sublayers, references, payloads, value clips,
    textures, any asset path): the files :func:`~wrinklepipe.io.confine.confine_usd` found
    inside the allowed folders; a path outside fails the asset as convert would, before any
    byte of it is read or hashed."""
    if path.suffix.lower() not in (".usd", ".usda", ".usdc"):
        return []  # a .usdz carries its dependencies inside
    return [p for p in confine_usd(path) if p.is_file()]


def input_files(manifest_path: Path) -> list[Path]:
    """Every file converting the manifest reads, the manifest itself included (sorted)."""
    m = load_manifest(manifest_path)
    files = set(m.input_files)
    if m.mesh is not None:
        files.update(_gltf_dependencies(m.mesh))
        files.update(_usd_dependencies(m.mesh))
    return sorted(Path(os.path.abspath(p)) for p in files)


def asset_key(
    manifest_path: Path, options: AssetOptions, output: Path | None = None
) -> tuple[str, list[dict[str, Any]]]:
    """The cache key of one asset and the input rows it was made from. ``output``: where it is
    written; for a USD source the layer names the source relative to it, so that path is part
    of the key (an entry is never restored where its sublayer path would not resolve)."""
    manifest_path = Path(os.path.abspath(manifest_path))
    root = manifest_path.parent
    rows = []
    for p in input_files(manifest_path):
        rows.append({"file": Path(os.path.relpath(p, root)).as_posix(), "sha256": sha256_file(p)})
    doc = {
        "schema": KEY_SCHEMA,
        "tool": tool_fingerprint(),
        "options": options.output_fields(),
        "inputs": rows,
    }
    m = load_manifest(manifest_path)
    if output is not None and m.mesh is not None and m.mesh.suffix.lower() in USD_SUFFIXES:
        doc["usd_source_reference"] = source_reference(m.mesh, Path(output))
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest(), rows
