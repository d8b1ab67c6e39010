"""The one unique-name rule, and the HLSL identifiers and file stems built on it."""

from hypothesis import given
from hypothesis import strategies as st

from wrinklepipe.names import unique_name
from wrinklepipe.package import safe_name
from wrinklepipe.shading.hlsl import identifier


@given(st.text(min_size=1, max_size=6), st.sets(st.text(max_size=8), max_size=12))
def test_unique_name_is_new_and_recorded(stem: str, taken: set[str]) -> None:
    before = set(taken)
    out = unique_name(stem, taken)
    assert out not in before
    assert taken == before | {out}
    # the stem itself when free, else the first free stem_<i> counting from 2
    free = [stem] + [f"{stem}_{i}" for i in range(2, len(before) + 3)]
    assert out == next(n for n in free if n not in before)


def test_clashing_names_get_the_same_suffixes_everywhere() -> None:
    taken_hlsl: set[str] = set()
    got = [identifier(n, taken_hlsl) for n in ("brow-L", "brow_L", "brow L", "3d")]
    assert got == ["brow_L", "brow_L_2", "brow_L_3", "_3d"]
    taken_files: set[str] = set()
    stems = [safe_name(n, taken_files) for n in ("brow L", "brow?L", "../x")]
    assert stems == ["brow_L", "brow_L_2", "_x"]


def test_counts_are_pluralised_in_words() -> None:
    from wrinklepipe.names import noun, plural

    assert [plural(n, "warning") for n in (0, 1, 2)] == ["0 warnings", "1 warning", "2 warnings"]
    assert [plural(n, "info") for n in (1, 3)] == ["1 info", "3 info"]
    assert [plural(n, "mesh") for n in (1, 2)] == ["1 mesh", "2 meshes"]
    assert plural(2, "degenerate triangle") == "2 degenerate triangles"
    assert plural(1, "NaN texel") == "1 NaN texel"
    assert [noun(n, "is", "are") for n in (1, 2, 0)] == ["is", "are", "are"]


def _message_strings() -> list[tuple[str, int, str]]:
    """Every f-string of the package (docstrings and comments are not messages)."""
    import io
    import tokenize
    from pathlib import Path

    import wrinklepipe

    out = []
    for path in sorted(Path(wrinklepipe.__file__).parent.rglob("*.py")):
        tokens = tokenize.generate_tokens(io.StringIO(path.read_text(encoding="utf-8")).readline)
        for tok in tokens:
            if tok.type == tokenize.STRING and tok.string.lstrip("rRbB").lower().startswith("f"):
                out.append((path.name, tok.start[0], tok.string))
    return out


def test_no_message_counts_in_word_s() -> None:
    """``1 position(s)`` or ``2 mesh(es)`` nowhere: a count says ``1 position``, ``2
    positions`` (``wrinklepipe.names.plural``; ``noun`` for a verb that agrees)."""
    import re

    strings = _message_strings()
    assert len(strings) > 1000  # the package's f-strings are read

    def words(s: str) -> str:  # the text, without the code in its {...} fields
        while re.search(r"\{[^{}]*\}", s):
            s = re.sub(r"\{[^{}]*\}", "#", s)
        return s

    bad = [
        f"{f}:{line}: {s}" for f, line, s in strings if re.search(r"[A-Za-z]\((?:s|es)\)", words(s))
    ]
    assert not bad, "\n".join(bad)
