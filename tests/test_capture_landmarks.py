"""Landmark files: every accepted shape, UV scaling, pairing by name, and the refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.capture.landmarks import check_inside, pair, read_landmarks
from wrinklepipe.errors import InputError

PTS = [[10.0, 20.0], [30.5, 5.0], [12.0, 40.0]]


@pytest.mark.parametrize(
    "body",
    [
        PTS,
        {"points": PTS},
        {"points": {"a": PTS[0], "b": PTS[1], "c": PTS[2]}},
        {"a": PTS[0], "b": PTS[1], "c": PTS[2]},
        [{"name": n, "x": p[0], "y": p[1]} for n, p in zip("abc", PTS)],
    ],
)
def test_json_shapes(tmp_path, body):
    f = tmp_path / "l.json"
    f.write_text(json.dumps(body))
    lm = read_landmarks(f)
    assert np.array_equal(lm.points, np.array(PTS)) and lm.space == "pixels"


def test_csv_with_header_names_and_comments(tmp_path):
    f = tmp_path / "l.csv"
    f.write_text("# picked in GIMP\nname,x,y\na,10,20\nb,30.5,5\nc,12,40\n")
    lm = read_landmarks(f)
    assert lm.names == ("a", "b", "c") and np.array_equal(lm.points, np.array(PTS))


def test_uv_space_is_scaled_by_the_image_size(tmp_path):
    f = tmp_path / "uv.csv"
    f.write_text("u,v\n0.25,0.5\n1,0\n0,1\n")
    lm = read_landmarks(f).to_pixels(200, 100)
    assert np.array_equal(lm.points, [[50.0, 50.0], [200.0, 0.0], [0.0, 100.0]])


def test_named_sets_pair_by_name(tmp_path):
    (tmp_path / "a.json").write_text(json.dumps({"a": [0, 0], "b": [10, 0], "c": [0, 10]}))
    (tmp_path / "b.json").write_text(json.dumps({"c": [1, 11], "a": [1, 1], "b": [11, 1]}))
    pa, pb = pair(read_landmarks(tmp_path / "a.json"), read_landmarks(tmp_path / "b.json"))
    assert np.array_equal(pb - pa, np.ones((3, 2)))


def test_named_sets_report_missing_names(tmp_path):
    (tmp_path / "a.json").write_text(json.dumps({"a": [0, 0], "b": [10, 0], "c": [0, 10]}))
    (tmp_path / "b.json").write_text(json.dumps({"a": [0, 0], "b": [10, 0], "d": [0, 10]}))
    with pytest.raises(InputError) as exc:
        pair(read_landmarks(tmp_path / "a.json"), read_landmarks(tmp_path / "b.json"))
    assert "missing landmark c" in str(exc.value) and "missing landmark d" in str(exc.value)


@pytest.mark.parametrize(
    ("pts", "needle"),
    [
        ([[0, 0], [1, 1], [2, 2], [3, 3]], "on one line"),
        ([[0, 0], [5, 0], [5, 0], [0, 5]], "share the position"),
    ],
)
def test_degenerate_sets(tmp_path, pts, needle):
    (tmp_path / "a.json").write_text(json.dumps(pts))
    lm = read_landmarks(tmp_path / "a.json")
    with pytest.raises(InputError, match=needle):
        pair(lm, lm)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("{not json", "invalid JSON at line 1"),
        ('[[1, "x"]]', "expected a number"),
        ("[[1, NaN]]", "not finite"),
        ('{"points": [[1, 2]], "space": "mm"}', "unknown space"),
    ],
)
def test_bad_files(tmp_path, text, needle):
    f = tmp_path / "bad.json"
    f.write_text(text)
    with pytest.raises(InputError, match=needle):
        read_landmarks(f)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-5, 70), st.floats(-5, 70)), min_size=1, max_size=8))
def test_check_inside_matches_the_definition(pts):
    from wrinklepipe.capture.landmarks import Landmarks

    lm = Landmarks(np.array(pts, float).reshape(-1, 2), file="p.json")
    outside = [(x, y) for x, y in pts if not (0 <= x <= 64 and 0 <= y <= 48)]
    if outside:
        with pytest.raises(InputError, match=f"{len(outside)} landmark"):
            check_inside(lm, 64, 48, "photo")
    else:
        check_inside(lm, 64, 48, "photo")
