"""Errors a user can act on: every one names the file (and key, texel or vertex) and what is wrong.

The CLI turns :class:`InputError` into one clear message per problem and exit code 2, never a
traceback. Stages raise them; they never print.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class Problem:
    """One thing wrong with an input: where (file, key/pointer) and what."""

    file: str
    message: str
    key: str = ""

    def __str__(self) -> str:
        where = f"{self.file}" + (f" [{self.key}]" if self.key else "")
        return f"{where}: {self.message}"


class InputError(Exception):
    """A bad input. Carries one or more :class:`Problem` so all of them are reported at once."""

    def __init__(self, problems: list[Problem] | Problem | str, file: str | Path = "") -> None:
        if isinstance(problems, str):
            problems = [Problem(str(file), problems)]
        elif isinstance(problems, Problem):
            problems = [problems]
        self.problems: list[Problem] = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems))


def input_error(file: str | Path, message: str, key: str = "") -> InputError:
    """Shorthand for a single-problem :class:`InputError`."""
    return InputError([Problem(str(file), message, key)])


@dataclass
class ProblemList:
    """Collects problems while checking an input, then raises them all together."""

    problems: list[Problem] = field(default_factory=list)

    def add(self, file: str | Path, message: str, key: str = "") -> None:
        self.problems.append(Problem(str(file), message, key))

    def __bool__(self) -> bool:
        return bool(self.problems)

    def raise_if_any(self) -> None:
        if self.problems:
            raise InputError(self.problems)


_PYTHON_CONVERSIONS = ("could not convert", "invalid literal", "cannot convert", "math domain")
#: numpy's words for arrays whose shapes do not line up (stack, broadcast, reshape, ragged lists)
_NUMPY_SHAPES = (
    "must have the same shape",
    "could not be broadcast",
    "cannot reshape array",
    "inhomogeneous shape",
    "setting an array element with a sequence",
)


def plain_reason(exc: BaseException) -> str:
    """A Python exception from reading a malformed structure, in words a user can act on (never
    "'list' object has no attribute 'get'"). Messages of other kinds are kept."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    if isinstance(exc, KeyError):
        return f"the member {exc.args[0]!r} is missing" if exc.args else "a member is missing"
    if isinstance(exc, IndexError):
        return "an index points past the end of its array"
    if isinstance(exc, (TypeError, AttributeError)):
        return "a member has the wrong type"
    if isinstance(exc, ValueError) and (not text or text.startswith(_PYTHON_CONVERSIONS)):
        return "a value is not a number or out of range"
    if isinstance(exc, ValueError) and any(m in text for m in _NUMPY_SHAPES):
        return "arrays that must hold one value per item have different lengths"
    if isinstance(exc, (OverflowError, ZeroDivisionError)):
        return "a number is out of range"
    return text or type(exc).__name__
