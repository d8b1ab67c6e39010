"""FACS action units (Ekman, Friesen and Hager, 2002): the numbers, names and face areas.

Rigs built on FACS name their blend shapes after action units in several spellings:
``AU01``, ``AU1``, ``AU_01``, ``AU12_L``, ``AU12L``, ``au12.R``, or the unit's name
(``InnerBrowRaiser``, ``inner_brow_raiser_L``, ``lipCornerPuller.R``). :func:`action_unit`
reads any of these to the unit's number and the character's side. The areas use the same words
as :data:`wrinklepipe.presets.arkit.AREAS` (the Jimenez zones where they apply).
"""

from __future__ import annotations

import re

#: number -> (name, face area)
UNITS: dict[int, tuple[str, str]] = {
    1: ("Inner Brow Raiser", "forehead_inner"),
    2: ("Outer Brow Raiser", "forehead_outer"),
    4: ("Brow Lowerer", "glabella"),
    5: ("Upper Lid Raiser", "eyelid_upper"),
    6: ("Cheek Raiser", "crowsfeet"),
    7: ("Lid Tightener", "eyelid_lower"),
    9: ("Nose Wrinkler", "nose"),
    10: ("Upper Lip Raiser", "lip_upper"),
    11: ("Nasolabial Deepener", "nasolabial"),
    12: ("Lip Corner Puller", "nasolabial"),
    13: ("Sharp Lip Puller", "cheek"),
    14: ("Dimpler", "mouth_corner"),
    15: ("Lip Corner Depressor", "mouth_corner"),
    16: ("Lower Lip Depressor", "lip_lower"),
    17: ("Chin Raiser", "chin"),
    18: ("Lip Pucker", "lips"),
    20: ("Lip Stretcher", "mouth_corner"),
    22: ("Lip Funneler", "lips"),
    23: ("Lip Tightener", "lips"),
    24: ("Lip Pressor", "lips"),
    25: ("Lips Part", "lips"),
    26: ("Jaw Drop", "jaw"),
    27: ("Mouth Stretch", "jaw"),
    28: ("Lip Suck", "lips"),
    41: ("Lid Droop", "eyelid_upper"),
    43: ("Eyes Closed", "eyelid_upper"),
    44: ("Squint", "eyelid_lower"),
    45: ("Blink", "eyelid_upper"),
    46: ("Wink", "eyelid_upper"),
}

_SIDE = r"(?:[_.\-\s]?(?P<side>L|R|Left|Right|l|r|left|right))?"
_NUMBER = re.compile(r"^AU[_\-\s]?0*(?P<n>\d{1,2})" + _SIDE + "$", re.IGNORECASE)


def _squash(text: str) -> str:
    return re.sub(r"[^a-z]", "", text.lower())


_BY_NAME = {_squash(name): n for n, (name, _) in UNITS.items()}
_NAMED = re.compile(r"^(?P<body>.*?[A-Za-z])" + _SIDE + "$")


def action_unit(name: str) -> tuple[int, str] | None:
    """``(unit number, side)`` for a FACS blend-shape name (side ``left``, ``right`` or
    ``center``), or None when the name is not an action unit this table knows."""
    m = _NUMBER.match(name.strip())
    if m and int(m.group("n")) in UNITS:
        return int(m.group("n")), _side(m.group("side"))
    for cut in (_NAMED.match(name.strip()), None):
        body = cut.group("body") if cut and cut.group("side") else name
        n = _BY_NAME.get(_squash(body))
        if n is not None:
            return n, _side(cut.group("side") if cut and cut.group("side") else None)
    return None


def _side(token: str | None) -> str:
    if not token:
        return "center"
    return "left" if token.lower() in ("l", "left") else "right"
