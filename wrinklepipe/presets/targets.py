"""What a blend shape's name says: its face area, the character's side, its mirror twin.

:func:`describe` knows ARKit's 52 names (:mod:`~wrinklepipe.presets.arkit`), FACS action units
in their usual spellings (:mod:`~wrinklepipe.presets.facs`) and, for any other name, the side
tokens rigs use: a ``Left``/``Right`` word (``browDownLeft``, ``Left_Smile``), or a ``L``/``R``
token after or before a separator (``smile_L``, ``smile.R``, ``L_smile``). ARKit's ``Left`` is
the character's left, as :mod:`~wrinklepipe.presets.arkit` takes it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from wrinklepipe.presets import arkit, facs

_SIDE_RULES: tuple[tuple[re.Pattern[str], str, str], ...] = (
    # (pattern, side, the twin's token) — the first rule that matches decides
    (re.compile(r"(?<![A-Za-z])L(?=[_.\-\s]|$)|(?<=[_.\-\s])L(?![A-Za-z])"), "left", "R"),
    (re.compile(r"(?<![A-Za-z])R(?=[_.\-\s]|$)|(?<=[_.\-\s])R(?![A-Za-z])"), "right", "L"),
    (re.compile(r"(?<![A-Za-z])l(?=[_.\-\s]|$)|(?<=[_.\-\s])l(?![A-Za-z])"), "left", "r"),
    (re.compile(r"(?<![A-Za-z])r(?=[_.\-\s]|$)|(?<=[_.\-\s])r(?![A-Za-z])"), "right", "l"),
    (re.compile(r"Left(?![a-z])"), "left", "Right"),
    (re.compile(r"Right(?![a-z])"), "right", "Left"),
    (re.compile(r"(?<![A-Za-z])left(?![a-z])"), "left", "right"),
    (re.compile(r"(?<![A-Za-z])right(?![a-z])"), "right", "left"),
)


@dataclass(frozen=True)
class TargetInfo:
    """A blend shape's face area (None: unknown), side and name without its side token."""

    area: str | None
    side: str
    base: str
    preset: str = ""  # "arkit", "facs" or "" (the name alone)


def _split_side(name: str) -> tuple[str, str, str]:
    """(side, the name without its side token, the twin's name) by :data:`_SIDE_RULES`."""
    for pattern, side, twin in _SIDE_RULES:
        found = list(pattern.finditer(name))
        if len(found) == 1:
            m = found[0]
            base = (name[: m.start()] + name[m.end() :]).strip("_.- ") or name
            return side, base, name[: m.start()] + twin + name[m.end() :]
    return "center", name, name


def describe(name: str) -> TargetInfo:
    """The area, side and side-free name of the blend shape ``name``."""
    side, base, _ = _split_side(name)
    if name in arkit.AREAS:
        return TargetInfo(arkit.AREAS[name], side, base, "arkit")
    au = facs.action_unit(name)
    if au is not None:
        n, au_side = au
        return TargetInfo(facs.UNITS[n][1], au_side, f"AU{n:02d}", "facs")
    return TargetInfo(None, side, base)


def mirror_name(name: str) -> str:
    """``name`` with its side token swapped (``browDownLeft`` -> ``browDownRight``,
    ``smile_L`` -> ``smile_R``); ``name`` itself when it has none."""
    return _split_side(name)[2]
