"""JSON and TOML for untrusted inputs: one message naming the file for every way they go wrong.

A document nested deeper than :data:`MAX_DEPTH` is refused (after parsing, iteratively, or
when the parser itself runs out of stack), so no later recursive step (schema validation,
serialisation, readers) can hit Python's recursion limit on it. The limit is not raised.

Numbers are finite: TOML's ``nan`` / ``inf`` and the ``NaN`` / ``Infinity`` Python's JSON parser
would take are refused with the key that holds them (a NaN passes every range check of a
schema, ``x > 0`` and ``x <= 64`` alike, and fails much later as an internal error). A UTF-8
byte-order mark (as some Windows editors write) is accepted.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from typing import Any

from wrinklepipe.errors import ProblemList, input_error

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
        doc = json.loads(data, parse_constant=_no_constant)
    except ValueError as exc:
        if isinstance(exc, json.JSONDecodeError):
            raise input_error(
                file, f"invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}", key
            ) from None
        raise input_error(file, f"invalid {what}: {exc}", key) from None
    except RecursionError:
        raise _too_deep(file, what, key) from None
    if isinstance(doc, (dict, list)):
        check_depth(doc, file, what, key)
    return doc


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not finite (JSON numbers are finite)")


def loads_toml(text: str, file: str | Path, what: str = "TOML") -> dict[str, Any]:
    """Parse untrusted TOML; errors name the file (and the line, from the parser, or the key of
    a number that is not finite)."""
    if text.startswith("\ufeff"):
        text = text[1:]  # a UTF-8 byte-order mark
    try:
        doc = tomllib.loads(text)
    except RecursionError:
        raise _too_deep(file, what, "") from None
    except tomllib.TOMLDecodeError as exc:
        raise input_error(file, f"invalid {what}: {exc}") from None
    check_depth(doc, file, what)
    check_finite(doc, file)
    return doc


def check_finite(doc: Any, file: str | Path) -> None:
    """Refuse every number of ``doc`` that is NaN or infinite, one problem per key
    (``budget.max_mean_deg``, ``drivers[0].keys.joy[1][0]``)."""
    problems = ProblemList()
    stack: list[tuple[Any, str]] = [(doc, "")]
    while stack:
        obj, key = stack.pop()
        if isinstance(obj, float) and not math.isfinite(obj):
            problems.add(file, f"{obj} is not a finite number", key)
        elif isinstance(obj, dict):
            stack.extend((v, f"{key}.{k}" if key else str(k)) for k, v in obj.items())
        elif isinstance(obj, list):
            stack.extend((v, f"{key}[{i}]") for i, v in enumerate(obj))
    problems.problems.sort(key=lambda p: p.key)
    problems.raise_if_any()
