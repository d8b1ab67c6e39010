"""The span rasteriser (per triangle and row, only the texels near the covered span are tested)
gives exactly what testing every texel of every bounding box gives: a brute-force reference
written here, on random, sliver, degenerate and overlapping triangles and on the demo mesh."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.geometry.rasterise import _inside, rasterise_triangle_ids


def _every_texel(uvs: np.ndarray, indices: np.ndarray, size: int) -> np.ndarray:
    """Every texel centre against every triangle (edge functions, highest index wins)."""
    uv = np.asarray(uvs, np.float64) * size - 0.5
    tri = uv[np.asarray(indices, np.int64)]
    yy, xx = np.mgrid[0:size, 0:size]
    x, y = xx.ravel().astype(np.float64), yy.ravel().astype(np.float64)
    out = np.full(size * size, -1, np.int64)
    for t in range(len(tri)):
        if not np.isfinite(tri[t]).all():
            continue
        inside = _inside(np.repeat(tri[t][None], len(x), axis=0), x, y)
        out[inside] = t
    return out.reshape(size, size)


_coord = st.floats(-0.2, 1.2, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(
    pts=st.lists(st.tuples(_coord, _coord), min_size=3, max_size=24),
    size=st.integers(1, 40),
    data=st.data(),
)
def test_spans_equal_every_texel(pts, size, data):
    uv = np.array(pts, np.float64)
    n_tri = data.draw(st.integers(1, 12))
    idx = np.array(
        data.draw(st.lists(st.integers(0, len(uv) - 1), min_size=3 * n_tri, max_size=3 * n_tri))
    ).reshape(-1, 3)
    got = rasterise_triangle_ids(uv, idx, size)
    assert np.array_equal(got, _every_texel(uv, idx, size))


@pytest.mark.filterwarnings("ignore:invalid value encountered in cast")
def test_slivers_edges_on_texel_centres_and_nan():
    s = 16
    c = (np.arange(s) + 0.5) / s  # texel centres
    uv = np.array(
        [
            [c[2], c[2]],
            [c[12], c[2]],
            [c[2], c[12]],  # edges through texel centres
            [0.0, 0.3],
            [1.0, 0.3 + 1e-9],
            [0.5, 0.3],  # a horizontal sliver
            [0.31, 0.0],
            [0.31 + 1e-12, 1.0],
            [0.9, 0.5],  # a near-vertical edge
            [0.1, 0.1],
            [0.5, 0.5],
            [0.9, 0.9],  # degenerate (collinear)
            [np.nan, 0.2],
            [0.4, 0.4],
            [0.2, 0.8],  # not finite
        ]
    )
    idx = np.arange(len(uv)).reshape(-1, 3)
    idx = np.concatenate([idx, idx[:, ::-1]])  # both windings, overlapping: highest wins
    for size in (s, 7, 33):
        assert np.array_equal(rasterise_triangle_ids(uv, idx, size), _every_texel(uv, idx, size))
