"""Spatial-hash vertex IDs: seam twins share IDs, distinct positions differ, jitter and order don't
matter. Expectations come from exact position equality (np.unique), never from the code itself."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.demo.character import generate
from wrinklepipe.errors import InputError
from wrinklepipe.geometry.primitives import uv_sphere
from wrinklepipe.geometry.vertex_ids import VertexIdOptions, compute_vertex_ids


def same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """True when labels a and b group the elements identically."""
    pairs = np.unique(np.stack([a, b], axis=1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


def exact_groups(p: np.ndarray) -> np.ndarray:
    return np.unique(p + 0.0, axis=0, return_inverse=True)[1].reshape(-1)


@pytest.fixture(scope="module")
def head():
    return generate(64).mesh


@pytest.fixture(scope="module")
def sphere():
    return uv_sphere(48, 24)


def test_sphere_ids_equal_distinct_positions(sphere):
    ids = compute_vertex_ids(sphere.positions)
    assert ids.dtype == np.int64
    expected = exact_groups(sphere.positions)
    # 48 * 23 ring positions + 2 poles.
    assert ids.max() + 1 == len(np.unique(expected)) == 48 * 23 + 2
    assert same_partition(ids, expected)


def test_sphere_seam_twins_and_poles_share_ids(sphere):
    ids = compute_vertex_ids(sphere.positions).reshape(25, 49)
    np.testing.assert_array_equal(ids[:, 0], ids[:, -1])  # seam column
    assert len(np.unique(ids[0])) == 1 and len(np.unique(ids[-1])) == 1  # poles
    assert len(np.unique(ids[5, :-1])) == 48  # a ring: all different


def test_head_ids_equal_distinct_positions(head):
    ids = compute_vertex_ids(head.positions)
    # The head's seam twins differ by ~1e-16 (sin(-pi) vs sin(pi)): rounding to 0.1 um is the
    # independent notion of "same position" here.
    p = np.round(head.positions.astype(np.float64), 7)
    assert same_partition(ids, exact_groups(p))
    assert ids.max() + 1 == 63 * 96 + 2
    # The seam: first and last column of every ring are bit-identical twins.
    n_lon = 96
    ring = ids[: 63 * (n_lon + 1)].reshape(63, n_lon + 1)
    np.testing.assert_array_equal(ring[:, 0], ring[:, -1])
    assert len(np.unique(ids)) < len(ids)


def test_first_appearance_numbering_and_rerun(head):
    ids = compute_vertex_ids(head.positions)
    first_seen = np.maximum.accumulate(ids)
    assert ids[0] == 0
    # Each new ID is exactly one more than the largest seen before it.
    assert np.all(ids <= np.concatenate([[0], first_seen[:-1] + 1]))
    np.testing.assert_array_equal(ids, compute_vertex_ids(head.positions.copy()))


@pytest.mark.parametrize("mesh_name", ["sphere", "head"])
def test_jitter_below_tenth_of_tolerance_changes_nothing(mesh_name, sphere, head):
    mesh = sphere if mesh_name == "sphere" else head
    p = mesh.positions.astype(np.float64)
    tol = 1e-4 * float(np.linalg.norm(p.max(0) - p.min(0)))
    ids = compute_vertex_ids(p, tolerance=tol)
    rng = np.random.default_rng(3)
    for _ in range(3):
        jit = p + rng.uniform(-tol / 10, tol / 10, size=p.shape)
        np.testing.assert_array_equal(compute_vertex_ids(jit, tolerance=tol), ids)


@pytest.mark.parametrize("mesh_name", ["sphere", "head"])
def test_permutation_gives_same_partition(mesh_name, sphere, head):
    mesh = sphere if mesh_name == "sphere" else head
    ids = compute_vertex_ids(mesh.positions)
    perm = np.random.default_rng(5).permutation(len(ids))
    ids_perm = compute_vertex_ids(mesh.positions[perm])
    assert same_partition(ids_perm, ids[perm])


def test_pair_straddling_a_cell_border_shares_an_id():
    tol = 1e-3
    cell = 16 * tol  # coarse_factor 16 below
    opts = VertexIdOptions(tolerance=tol, coarse_factor=16)
    base = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])  # fixes the grid origin at 0
    for axis in range(3):
        for gap in (0.05 * tol, 0.5 * tol, 0.9 * tol):
            border = np.full(3, 0.3)
            border[axis] = 7 * cell  # exactly on a cell face
            a = border.copy()
            b = border.copy()
            a[axis] -= gap / 2
            b[axis] += gap / 2
            ids = compute_vertex_ids(np.vstack([base, a, b]), options=opts)
            assert ids[2] == ids[3], (axis, gap)
            assert len(np.unique(ids)) == 3
    # Diagonal straddle of a cell corner.
    corner = np.full(3, 7 * cell)
    pts = np.vstack([base, corner - 0.3 * tol, corner + 0.3 * tol])
    ids = compute_vertex_ids(pts, options=opts)
    assert ids[2] == ids[3]
    # Far apart (> 3 tol): different IDs.
    pts = np.vstack([base, corner - 2 * tol, corner + 2 * tol])
    assert len(np.unique(compute_vertex_ids(pts, options=opts))) == 4


def test_dense_cells_are_refined():
    # Many distinct positions inside one coarse cell (spacing 5 tol) plus twins of each.
    tol = 1e-3
    g = np.stack(np.meshgrid(*[np.arange(6) * 5 * tol] * 3, indexing="ij"), -1).reshape(-1, 3)
    pts = np.vstack([g, g + 0.2 * tol])
    ids = compute_vertex_ids(pts, options=VertexIdOptions(tolerance=tol, coarse_factor=1024))
    assert ids.max() + 1 == len(g)
    np.testing.assert_array_equal(ids[: len(g)], ids[len(g) :])


def test_negative_zero_equals_zero():
    p = np.array([[0.0, -0.0, 0.0], [-0.0, 0.0, -0.0], [1.0, 1.0, 1.0]], dtype=np.float32)
    assert compute_vertex_ids(p).tolist() == [0, 0, 1]
    assert compute_vertex_ids(p, tolerance=0.0).tolist() == [0, 0, 1]


def test_bad_inputs_raise_input_errors():
    p = np.zeros((4, 3), dtype=np.float32)
    p[2, 1] = np.nan
    with pytest.raises(InputError, match="NaN or infinite.*vertex 2"):
        compute_vertex_ids(p, source="head.glb")
    with pytest.raises(InputError, match=r"\[V, 3\]"):
        compute_vertex_ids(np.zeros((4, 2)))
    with pytest.raises(InputError, match="tolerance"):
        compute_vertex_ids(np.zeros((4, 3)), tolerance=-1.0)
    assert compute_vertex_ids(np.zeros((0, 3))).shape == (0,)


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(2, 60),
    offset=st.floats(-10, 10),
    scale=st.floats(0.01, 100),
    seed=st.integers(0, 2**16),
)
def test_property_twins_share_and_separated_differ(n, offset, scale, seed):
    rng = np.random.default_rng(seed)
    tol = 1e-3 * scale
    # Distinct points on a lattice of 8 tol (so no two are within 3 tol), random origin.
    lattice = rng.choice(20**3, size=n, replace=False)
    base = np.stack(np.unravel_index(lattice, (20, 20, 20)), -1) * 8 * tol + offset
    copies = rng.integers(0, n, size=2 * n)
    twins = base[copies] + rng.uniform(-tol / 10, tol / 10, size=(2 * n, 3))
    pts = np.vstack([base, twins])
    order = rng.permutation(len(pts))
    ids = compute_vertex_ids(pts[order], tolerance=tol)
    truth = np.concatenate([np.arange(n), copies])[order]
    assert same_partition(ids, truth)
    # First-appearance numbering: relabelling truth the same way gives identical arrays.
    _, first_idx = np.unique(truth, return_index=True)
    rank = np.empty(n, dtype=np.int64)
    rank[np.argsort(first_idx)] = np.arange(n)
    np.testing.assert_array_equal(ids, rank[truth])


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("mesh_name", ["sphere", "head"])
def test_jitter_at_cell_borders(mesh_name, dtype, sphere, head):
    # Snap every vertex onto a corner of the hash grid (coarse_factor 16 -> cells of 16 tol),
    # then jitter by < tol/10: twins now straddle cell faces in every axis.
    mesh = sphere if mesh_name == "sphere" else head
    p = mesh.positions.astype(np.float64)
    tol = 1e-5 * float(np.linalg.norm(p.max(0) - p.min(0)))
    cell = 16 * tol
    snapped = (np.round((p - p.min(0)) / cell) * cell + 0.05).astype(dtype)
    opts = VertexIdOptions(tolerance=tol, coarse_factor=16)
    ids = compute_vertex_ids(snapped, options=opts)
    assert same_partition(ids, exact_groups(snapped.astype(np.float64)))
    rng = np.random.default_rng(11)
    for _ in range(3):
        jit = (snapped + rng.uniform(-tol / 10, tol / 10, size=p.shape)).astype(dtype)
        np.testing.assert_array_equal(compute_vertex_ids(jit, options=opts), ids)


def _twins_and_strangers(spread: float, tol: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """300 positions on a 10*tol lattice scattered over ``spread`` (distinct ones far apart
    against the tolerance), each repeated with jitter below tol/10; expected groups = lattice
    sites."""
    rng = np.random.default_rng(seed)
    sites = rng.integers(0, int(spread / (10 * tol)), size=(300, 3)).astype(np.float64)
    sites = np.unique(sites, axis=0) * (10 * tol)
    reps = np.repeat(np.arange(len(sites)), 3)
    pts = sites[reps] + rng.uniform(-0.09, 0.09, size=(len(reps), 3)) * tol
    order = rng.permutation(len(pts))
    return pts[order], reps[order]


@pytest.mark.parametrize(
    ("spread", "tol", "factor"),
    [
        (1.0, 1e-6, 16.0),  # cell key + index in one int64 (the fast path)
        (10.0, 1e-6, 16.0),  # 20 bits a cell axis: cell key alone, indirect sort
        (1e3, 1e-6, 16.0),  # 2^26 cells an axis: lexicographic sort of the rows
    ],
)
def test_wide_grids_fall_back_and_agree(spread, tol, factor):
    pts, expected = _twins_and_strangers(spread, tol, 3)
    ids = compute_vertex_ids(pts, options=VertexIdOptions(tolerance=tol, coarse_factor=factor))
    assert same_partition(ids, expected)
    first = np.unique(ids, return_index=True)[1]
    assert np.all(np.diff(first) > 0)  # numbered by first appearance


def test_grid_finer_than_float_resolution_links_with_kd_tree():
    # Distinct positions 1e-9 apart near the origin plus one point 1e5 away: with tol 1e-12 a
    # hash grid over the extent would need > 2^52 cells an axis; the k-d tree links instead.
    pts, expected = _twins_and_strangers(1e-7, 1e-12, 4)
    pts = np.vstack([pts, [[1e5, 0.0, 0.0]]])
    expected = np.append(expected, expected.max() + 1)
    ids = compute_vertex_ids(pts, options=VertexIdOptions(tolerance=1e-12, coarse_factor=16))
    assert same_partition(ids, expected)
    assert ids[-1] == ids.max()


def _contract_violation(p: np.ndarray, ids: np.ndarray, tol: float) -> str | None:
    """Brute-force check of the module contract with a k-d tree (independent of the hash grid)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    tree = cKDTree(p.astype(np.float64) + 0.0)
    close = tree.query_pairs(tol * (1 - 1e-9), p=np.inf, output_type="ndarray")
    if len(close) and (ids[close[:, 0]] != ids[close[:, 1]]).any():
        return "a pair closer than tol got different IDs"
    far = tree.query_pairs(3 * tol * (1 + 1e-6), p=np.inf, output_type="ndarray")
    n = len(p)
    graph = coo_matrix((np.ones(len(far)), (far[:, 0], far[:, 1])), shape=(n, n))
    comp = connected_components(graph, directed=False)[1]
    pairs = np.unique(np.stack([ids, comp], axis=1), axis=0)
    if len(np.unique(pairs[:, 0])) != len(pairs):
        return "an ID joins positions with no chain of steps <= 3 tol"
    first = np.unique(ids, return_index=True)[1]
    if not (np.all(np.diff(first) > 0) and ids.max() + 1 == len(first)):
        return "not numbered by first appearance"
    return None


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 6, 29])
def test_contract_on_random_clouds_with_near_twins(seed):
    # Clouds with twins jittered up to 2 tol (the ambiguous band included), some snapped onto the
    # grid, float32 and float64, several coarse factors: the contract must hold on every one.
    # Seeds 1, 3, 6 and 29 hold clouds where an earlier implementation split pairs closer than
    # tol (cells refined below the top level).
    rng = np.random.default_rng(seed)
    for _ in range(15):
        n = int(rng.integers(1, 3000))
        base = rng.normal(size=(n, 3)) * rng.choice([1e-3, 1.0, 1e3])
        tol = float(rng.choice([1e-7, 1e-5, 1e-3, 1e-2, 0.1])) * np.abs(base).max()
        k = int(rng.integers(0, n + 1))
        jitter = rng.uniform(-1, 1, (k, 3)) * tol * rng.choice([0.05, 0.4, 0.9, 2.0])
        p = np.vstack([base, base[rng.integers(0, n, k)] + jitter])
        if rng.random() < 0.3:
            p = np.round(p / tol) * tol
        if rng.random() < 0.5:
            p = p.astype(np.float32)
        opts = VertexIdOptions(tolerance=tol, coarse_factor=rng.choice([None, 16.0, 100.0, 1024.0]))
        ids = compute_vertex_ids(p, options=opts)
        assert _contract_violation(p, ids, tol) is None, (n, tol, p.dtype, opts)
