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
