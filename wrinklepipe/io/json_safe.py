"""JSON and TOML for untrusted inputs: one message naming the file for every way they go wrong.

A document nested deeper than :data:`MAX_DEPTH` is refused (after parsing, iteratively, or
when the parser itself runs out of stack), so no later recursive step (schema validation,
serialisation, readers) can hit Python's recursion limit on it. The limit is not raised.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

from wrinklepipe.errors import input_error

#: Deepest nesting of objects/arrays (tables/arrays for TOML) accepted in an input document;
#: glTF, USD metadata, manifests and configs need well under 20.
MAX_DEPTH = 128


def _too_deep(file: str | Path, what: str, key: str) -> Exception:
    return input_error(file, f"{what} is nested more than {MAX_DEPTH} levels deep", key)


def check_depth(doc: Any, file: str | Path, what: str = "JSON", key: str = "") -> Any:
    """Return ``doc`` if its containers nest at most :data:`MAX_DEPTH` deep, else refuse it."""
    stack = [(doc, 1)]
    while stack:
        obj, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise _too_deep(file, what, key)
        children = obj.values() if isinstance(obj, dict) else obj
        stack.extend((c, depth + 1) for c in children if isinstance(c, (dict, list)))
    return doc


def loads_json(data: bytes | str, file: str | Path, what: str = "JSON", key: str = "") -> Any:
    """Parse untrusted JSON (bytes: UTF-8, a BOM allowed); errors name the file and position."""
    if isinstance(data, bytes):
        try:
            data = data.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise input_error(
                file, f"{what} is not UTF-8 text (byte {exc.start}: {exc.reason})", key
            ) from None
    try:
        doc = json.loads(data)
    except RecursionError:
        raise _too_deep(file, what, key) from None
    except json.JSONDecodeError as exc:
        raise input_error(
            file, f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}", key
        ) from None
    if isinstance(doc, (dict, list)):
        check_depth(doc, file, what, key)
    return doc


def loads_toml(text: str, file: str | Path, what: str = "TOML") -> dict[str, Any]:
    """Parse untrusted TOML; errors name the file (and the line, from the parser)."""
    try:
        doc = tomllib.loads(text)
    except RecursionError:
        raise _too_deep(file, what, "") from None
    except tomllib.TOMLDecodeError as exc:
        raise input_error(file, f"invalid {what}: {exc}") from None
    return check_depth(doc, file, what)
