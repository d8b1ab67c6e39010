"""What a glTF reader may open: the size caps and the one URI confinement rule.

Used by the container of the glTF document model (:mod:`wrinklepipe.gltf.container`,
which every glTF reader opens files through) and the document's images
(:mod:`wrinklepipe.gltf.images`: ``max_pixels``): every URI must be relative and stay
inside the asset's folder (no ``..``, no absolute paths, no schemes other than ``data:``), data
URIs, external files and images are capped.
"""

from __future__ import annotations

import urllib.parse
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from wrinklepipe.errors import input_error
from wrinklepipe.io.confine import confine


@dataclass(frozen=True)
class GltfReadOptions:
    """Reader limits: ``max_data_uri_bytes`` (decoded size of one data URI), ``max_pixels`` per
    image, ``max_file_bytes`` for any external file."""

    max_data_uri_bytes: int = 16 * 1024 * 1024
    max_pixels: int = 8192 * 8192
    max_file_bytes: int = 2 * 1024**3


def safe_uri_path(folder: Path, uri: str, file: str, key: str) -> Path:
    """Resolve a relative glTF URI inside ``folder``; refuse absolute paths, ``..`` and schemes."""
    raw = urllib.parse.unquote(uri)
    if raw.startswith(("/", "\\")) or (len(raw) > 1 and raw[1] == ":"):
        raise input_error(
            file, f"URI {uri!r} is an absolute path; only relative URIs are read", key
        )
    parsed = urllib.parse.urlparse(uri)
    if parsed.scheme or parsed.netloc:
        raise input_error(file, f"URI {uri!r} is not a relative path (scheme not allowed)", key)
    parts = PurePosixPath(raw.replace("\\", "/")).parts
    if ".." in parts:
        raise input_error(file, f"URI {uri!r} leaves the asset folder ('..' not allowed)", key)
    if not parts:
        raise input_error(file, f"URI {uri!r} names no file", key)
    return confine(folder, Path(*parts), file, key, "URI")  # the one confinement check
