"""Polygon soup -> render triangles (wrinklepipe.geometry.polygons): laws of the corner weld and
the fan, and a hand-counted example."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.geometry.polygons import drop_degenerate, fan_triangles, weld_corners


def test_a_quad_and_a_pentagon_by_hand():
    np.testing.assert_array_equal(
        fan_triangles(np.array([4, 5])),
        [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [4, 7, 8]],
    )


@settings(max_examples=50, deadline=None)
@given(st.lists(st.integers(3, 9), min_size=1, max_size=20))
def test_every_polygon_fans_from_its_first_corner(counts):
    tris = fan_triangles(np.array(counts))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    assert len(tris) == sum(c - 2 for c in counts)
    poly = np.repeat(np.arange(len(counts)), np.array(counts) - 2)
    assert (tris[:, 0] == starts[poly]).all()  # the fan's apex
    assert (tris[:, 1] + 1 == tris[:, 2]).all()
    assert (tris[:, 2] < starts[poly] + np.array(counts)[poly]).all()  # inside its polygon


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 5), st.integers(0, 2)), min_size=1, max_size=40))
def test_the_weld_keeps_each_corner_and_nothing_more(rows):
    key = np.array(rows, np.int64)
    for point in (None, key[:, 0]):
        corner_vertex, src = weld_corners(key, point)
        assert len(src) == len({tuple(r) for r in rows})  # one vertex per distinct corner
        np.testing.assert_array_equal(key[src][corner_vertex], key)  # each corner kept
        if point is None:  # numbered by first appearance
            assert (np.diff(src) > 0).all()
        else:  # by point, then first appearance
            assert (np.diff(key[src, 0]) >= 0).all()


def test_degenerate_triangles_are_counted_out():
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]], np.float32)
    tris = np.array([[0, 1, 2], [0, 0, 1], [0, 1, 3]])  # good, repeated, collinear
    kept, n = drop_degenerate(p, tris)
    np.testing.assert_array_equal(kept, [[0, 1, 2]])
    assert n == 2
