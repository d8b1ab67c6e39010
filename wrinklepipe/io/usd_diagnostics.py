"""USD's own diagnostics (Tf warnings and status messages, and errors USD reports instead of
raising), captured, never printed raw to the terminal.

USD prints a diagnostic to stderr ("Warning: in _ReportErrors at line 3326 of ...") only when
no delegate is registered. The first :func:`captured_diagnostics` registers one
``UsdUtils.CoalescingDiagnosticDelegate`` for the rest of the process, so from then on nothing
of USD's reaches the terminal raw: each block gets the diagnostics posted while it ran, as one
line each in the tool's words (:func:`plain`), and decides what to say (a report issue, a note).
Diagnostics posted outside any block are kept for :func:`stray_diagnostics`.
"""

from __future__ import annotations

import contextlib
import functools
import re
import threading
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])

_LOCK = threading.Lock()
_DELEGATE: list[Any] = []  # the one delegate, once made
_OPEN: list[list[str]] = []  # the blocks running, innermost last
_STRAY: list[str] = []

_CONTEXT = re.compile(r"\s*\((?:instantiating|composing|opening|loading)[^()]*\)\s*$")
_ADDRESS = re.compile(r"\s*<0x[0-9a-fA-F]+>")


def plain(text: str) -> str:
    """One line of USD's commentary: no trailing "(instantiating stage on stage ... <0x..>)"
    context, no memory addresses, whitespace folded."""
    line = " ".join(str(text).split())
    line = _CONTEXT.sub("", line)
    return _ADDRESS.sub("", line).strip()


#: USD's C++ namespace in function and type names ("pxrInternal_v0_26_11__pxrReserved__::").
_NAMESPACE = re.compile(r"pxrInternal_v\d+(?:_\d+)*__pxrReserved__(?:_)?::")
#: The text parser's grammar rule in a parse error ("parse error matching pegtl::until<...> at
#: '' in </A.x>"): the position before it and the prim after it are what a user can use.
_GRAMMAR = re.compile(r"parse error matching .*? at '([^']*)'")


#: The text around a parse error that USD quotes ("at ', (0.3, 1.3, 0.1), ...' in </A.points>":
#: a whole array): its start is kept, so the prim and property after it still fit the line.
_ECHO = re.compile(r" at '([^']{40})[^']{8,}'")
#: The "layer:line:column: " USD puts before some errors it also reports without it.
_WHERE = re.compile(r"^\S+:\d+:\d+: ")


def _tidy(text: str) -> str:
    text = _NAMESPACE.sub("", text)
    text = _GRAMMAR.sub(
        lambda m: "parse error" + (f" at {m.group(1)!r}" if m.group(1) else ""), text
    )
    return _ECHO.sub(lambda m: f" at '{m.group(1)}...'", text)


def _once(lines: list[str]) -> list[str]:
    """``lines`` without repeats, an error said twice (with and without its layer:line:column)
    kept once, where it is said with its place."""
    kept: dict[str, str] = {}
    for line in lines:
        key = _WHERE.sub("", line)
        if key not in kept or _WHERE.match(line):
            kept[key] = line
    return list(kept.values())


def error_text(exc: BaseException) -> str:
    """A USD exception (``Tf.ErrorException``) as one line in plain words: the commentary of
    each error it carries (no C++ function, source file or line, no parser grammar), joined
    with "; ". Its text may hold the bytes of a damaged layer that are no UTF-8."""
    try:
        said = [str(getattr(a, "commentary", "") or a) for a in exc.args] or [str(exc)]
        lines = [plain(_tidy(s)) for s in said]
        return "; ".join(_once([s for s in lines if s]))
    except UnicodeDecodeError:
        return "USD cannot parse it (it holds bytes that are not UTF-8 text)"


def _take() -> list[str]:
    """The diagnostics posted since the last take (caller holds the lock)."""
    if not _DELEGATE:
        from pxr import UsdUtils  # deferred: usd-core, USD only

        _DELEGATE.append(UsdUtils.CoalescingDiagnosticDelegate())
        return []
    return [plain(d.commentary) for d in _DELEGATE[0].TakeUncoalescedDiagnostics()]


@contextlib.contextmanager
def captured_diagnostics() -> Iterator[list[str]]:
    """Yield a list that holds, after the block, USD's diagnostics posted while it ran (one
    line each, in order, repeats removed). Blocks nest: an inner block's diagnostics are its
    own, not the outer one's."""
    mine: list[str] = []
    with _LOCK:
        before = _take()
        (_OPEN[-1] if _OPEN else _STRAY).extend(before)
        _OPEN.append(mine)
    try:
        yield mine
    finally:
        with _LOCK:
            mine.extend(_take())
            del _OPEN[next(i for i, x in enumerate(_OPEN) if x is mine)]  # by identity
            mine[:] = list(dict.fromkeys(m for m in mine if m))


def quiet(fn: F) -> F:
    """``fn`` run inside :func:`captured_diagnostics` (for USD work whose diagnostics are not
    the user's business, such as composing the tool's own output layer): USD prints nothing."""

    @functools.wraps(fn)
    def run(*args: Any, **kwargs: Any) -> Any:
        with captured_diagnostics():
            return fn(*args, **kwargs)

    return run  # type: ignore[return-value]


def stray_diagnostics() -> list[str]:
    """Diagnostics USD posted outside any :func:`captured_diagnostics` block since the last
    call (one line each, repeats removed); empty before USD was first used."""
    with _LOCK:
        if _DELEGATE and not _OPEN:
            _STRAY.extend(_take())
        out = list(dict.fromkeys(m for m in _STRAY if m))
        _STRAY.clear()
    return out
