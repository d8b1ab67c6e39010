"""Names: the one ``stem, stem_2, stem_3 ...`` rule for unique names, and the "did you mean"
hint of every message about a name that is not there.

File stems (:func:`wrinklepipe.package.safe_name`), USD prim and variant names and HLSL
identifiers (:func:`wrinklepipe.shading.hlsl.identifier`) are all kept apart with it, so two
regions, textures or prims whose names clash get the same suffixes wherever they are written.
File names are kept apart *case-insensitively* (``fold_case``): ``wrinkle_Ab.png`` and
``wrinkle_ab.png`` are one file on macOS and Windows, so the second becomes ``wrinkle_ab_2``.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def unique_name(stem: str, taken: set[str], fold_case: bool = False) -> str:
    """``stem``, or ``stem_2``, ``stem_3`` ... the first not in ``taken`` (which it updates);
    ``fold_case``: compared case-insensitively (``taken`` then holds case-folded names)."""

    def key(name: str) -> str:
        return name.casefold() if fold_case else name

    out, i = stem, 1
    while key(out) in taken:
        i += 1
        out = f"{stem}_{i}"
    taken.add(key(out))
    return out


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """``" (did you mean 'Main'?)"`` when a known name is close to ``name`` (the same but for
    case, else the closest by :func:`difflib.get_close_matches`), else ``""``: the hint every
    "unknown material / region / blend shape / clip" message carries."""
    names = [k for k in dict.fromkeys(str(k) for k in known) if k != name]
    folded = [k for k in names if k.casefold() == name.casefold()]
    close = folded or difflib.get_close_matches(name, names, n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


#: Words whose plural is the word itself in the tool's messages.
_UNCOUNTABLE = frozenset({"info", "information", "data"})

#: Irregular plurals of the words the messages count.
_IRREGULAR = {"mesh": "meshes", "inbetween": "inbetweens", "vertex": "vertices"}


def plural(n: int, word: str, many: str | None = None) -> str:
    """``1 info``, ``2 warnings``, ``0 errors``, ``1 mesh``, ``3 meshes`` (``many``: an irregular
    plural the table does not know): every count in a message, never ``word(s)``."""
    return f"{n} {noun(n, word, many)}"


def noun(n: int, word: str, many: str | None = None) -> str:
    """``word`` for one, its plural for any other count (``plural`` without the number)."""
    if n == 1:
        return word
    if many is not None:
        return many
    if word in _UNCOUNTABLE:
        return word
    head, _, last = word.rpartition(" ")
    last = _IRREGULAR.get(last, last + "s")
    return f"{head} {last}" if head else last


def listing(known: Iterable[str], limit: int = 12) -> str:
    """``'a', 'b', 'c'`` (the first ``limit``, then ``... and N more``), or ``none``."""
    names = [repr(str(k)) for k in dict.fromkeys(known)]
    if not names:
        return "none"
    more = f" ... and {len(names) - limit} more" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more


def unknown_names(what: str, unknown: Iterable[str], known: Iterable[str], where: str = "") -> str:
    """``unknown region 'brw_l' (did you mean 'brow_l'?); the regions: 'brow_l', 'chin'`` for
    one name or several (``what`` in the singular; ``where``: ``" of head.glb"``)."""
    known = list(known)
    names = list(unknown)
    parts = ", ".join(f"{n!r}{did_you_mean(n, known)}" for n in names)
    noun = what if len(names) == 1 else f"{what}s"
    return f"unknown {noun} {parts}; the {what}s{where}: {listing(known)}"


def file_stems(keys: list[str]) -> dict[str, str]:
    """Each key (``"region_mask/Brow"``) -> a file stem (``"region_mask_Brow"``: ``/`` as
    ``_``), unique case-insensitively, given in sorted key order: every writer of one set of
    keys names their files alike."""
    taken: set[str] = set()
    return {k: unique_name(k.replace("/", "_"), taken, fold_case=True) for k in sorted(keys)}
