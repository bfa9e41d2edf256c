"""The sparse cell grid: window sums and adjacent pairs against brute force, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels import runtime
from supportnode.kernels.cellgraph import MOMENTS, CellGrid, _warm, bin_points


def _cells(seed: int, n: int, span: int, pad: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    ijk = np.unique(rng.integers(pad, pad + span, (n, 3)), axis=0)
    dims = np.full(3, span + 2 * pad)
    return ijk, dims


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(0, 60),
    span=st.integers(1, 6),
    w=st.integers(0, 2),
    labelled=st.booleans(),
    seed=st.integers(0, 10_000),
)
def test_window_sums_match_brute_force(n, span, w, labelled, seed):
    ijk, dims = _cells(seed, n, span, 2)
    rng = np.random.default_rng(seed + 1)
    mom = rng.normal(size=(len(ijk), 4))
    label = rng.integers(0, 3, len(ijk)) if labelled else None
    got = CellGrid(ijk, dims, 2).window_sums(mom, w, label)
    want = np.zeros_like(mom)
    for c in range(len(ijk)):
        near = np.abs(ijk - ijk[c]).max(axis=1) <= w
        if label is not None:
            near &= label == label[c]
        want[c] = mom[near].sum(axis=0)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 80), span=st.integers(1, 6), seed=st.integers(0, 10_000))
def test_adjacent_pairs_are_every_26_neighbour_pair_once(n, span, seed):
    ijk, dims = _cells(seed, n, span, 1)
    src, dst = CellGrid(ijk, dims, 1).adjacent_pairs()
    got = {(min(a, b), max(a, b)) for a, b in zip(src.tolist(), dst.tolist(), strict=True)}
    assert len(got) == len(src)  # each pair once
    d = np.abs(ijk[:, None, :] - ijk[None, :, :]).max(axis=2)
    want = {(a, b) for a, b in zip(*np.nonzero(np.triu(d == 1)), strict=True)}
    assert got == want


@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 60), sparse=st.booleans(), w=st.integers(0, 3), seed=st.integers(0, 10_000))
def test_window_sums_of_moments_in_window_order_to_the_bit(n, sparse, w, seed):
    # MOMENTS columns (summed in registers), on a dense box and on a sparse one (two
    # clusters far apart: the hashed column lookups), each cell's window in lookup order.
    ijk, dims = _cells(seed, n, 4, 3)
    if sparse:
        ijk[::2] += 5000
        dims = dims + 5000
    rng = np.random.default_rng(seed + 1)
    mom = rng.normal(size=(len(ijk), MOMENTS))
    label = rng.integers(0, 2, len(ijk))
    got = CellGrid(ijk, dims, 3).window_sums(mom, w, label)
    where = {tuple(c): i for i, c in enumerate(ijk.tolist())}
    for c in range(len(ijk)):
        acc = np.zeros(MOMENTS)
        for dx in range(-w, w + 1):
            for dy in range(-w, w + 1):
                for dz in range(-w, w + 1):
                    j = where.get((ijk[c, 0] + dx, ijk[c, 1] + dy, ijk[c, 2] + dz))
                    if j is not None and label[j] == label[c]:
                        acc += mom[j]
        np.testing.assert_array_equal(got[c], acc)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 60), span=st.integers(1, 5), seed=st.integers(0, 10_000))
def test_window_sums_add_in_window_order_to_the_bit(n, span, seed):
    # The column walk adds the cells in the order of the (2w + 1)^3 single lookups it
    # replaced (dx, dy, dz ascending): the normals downstream keep their bits.
    ijk, dims = _cells(seed, n, span, 2)
    mom = np.random.default_rng(seed + 1).normal(size=(len(ijk), 3))
    got = CellGrid(ijk, dims, 2).window_sums(mom, 2)
    where = {tuple(c): i for i, c in enumerate(ijk.tolist())}
    for c in range(len(ijk)):
        acc = np.zeros(3)
        for dx in range(-2, 3):
            for dy in range(-2, 3):
                for dz in range(-2, 3):
                    j = where.get((ijk[c, 0] + dx, ijk[c, 1] + dy, ijk[c, 2] + dz))
                    if j is not None:
                        acc += mom[j]
        np.testing.assert_array_equal(got[c], acc)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 80), span=st.integers(1, 6), seed=st.integers(0, 10_000))
def test_adjacent_pairs_within_a_distance_are_those_numpy_keeps(n, span, seed):
    ijk, dims = _cells(seed, n, span, 1)
    grid = CellGrid(ijk, dims, 1)
    centroid = ijk + np.random.default_rng(seed).uniform(0.0, 1.0, (len(ijk), 3))
    src, dst = grid.adjacent_pairs()
    near = np.linalg.norm(centroid[src] - centroid[dst], axis=1) <= 1.25
    got = grid.adjacent_pairs(centroid, 1.25)
    np.testing.assert_array_equal(got[0], src[near])
    np.testing.assert_array_equal(got[1], dst[near])
    with pytest.raises(ValueError, match="centroids must be"):
        grid.adjacent_pairs(centroid[:, :2], 1.0)


def test_empty_and_one_cell():
    g = CellGrid(np.zeros((0, 3), np.int64), np.array([3, 3, 3]), 1)
    assert g.window_sums(np.zeros((0, 10)), 1).shape == (0, 10)
    assert all(len(x) == 0 for x in g.adjacent_pairs())
    g = CellGrid(np.array([[1, 1, 1]]), np.array([3, 3, 3]), 1)
    np.testing.assert_array_equal(g.window_sums(np.ones((1, 2)), 1), [[1.0, 1.0]])
    assert all(len(x) == 0 for x in g.adjacent_pairs())


def test_coordinates_at_the_packing_limits():
    """Cells at the padded grid's extreme corners find each other and nothing beyond."""
    dims = np.array([9, 7, 5])
    ijk = np.array([[2, 2, 2], [6, 4, 2], [5, 3, 1 + 1]])
    g = CellGrid(ijk, dims, 2)
    s = g.window_sums(np.eye(3), 2)
    np.testing.assert_array_equal(s.diagonal(), [1, 1, 1])
    assert s[1, 2] == 1 and s[2, 1] == 1 and s[0, 1] == 0


def test_bad_input_is_refused_before_the_kernel():
    with pytest.raises(ValueError, match="inside the grid"):
        CellGrid(np.array([[0, 1, 1]]), np.array([3, 3, 3]), 1)
    with pytest.raises(ValueError, match="too large"):
        CellGrid(np.array([[1, 1, 1]]), np.array([2**21, 2**21, 2**21]), 1)
    g = CellGrid(np.array([[2, 2, 2]]), np.array([5, 5, 5]), 2)
    with pytest.raises(ValueError, match="padding"):
        g.window_sums(np.ones((1, 2)), 3)
    with pytest.raises(ValueError, match="a row per cell"):
        g.window_sums(np.ones((2, 2)), 1)
    with pytest.raises(ValueError, match="one per cell"):
        g.window_sums(np.ones((1, 2)), 1, np.zeros(3))


def test_warm_up_is_registered():
    assert _warm in runtime._WARMERS
    runtime.warm(["cellgraph"])


@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 400), size=st.sampled_from([0.005, 0.02, 0.1]), seed=st.integers(0, 9999))
def test_bin_points_matches_numpy_grouping(n, size, seed):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-0.1, 0.2, (n, 3))
    grid, of_point, mom, base = bin_points(pts, size, 2)
    assert len(of_point) == n and mom.shape == (len(grid.ijk), 10)
    if n:
        np.testing.assert_array_equal(base, pts.min(axis=0))
        assert (grid.dims > grid.ijk.max(axis=0) + 1).all()  # the pad on the far side too
    rel = pts - base
    ijk = np.floor(rel / size).astype(np.int64) + 2
    np.testing.assert_array_equal(grid.ijk[of_point], ijk)  # each point in its cell
    assert len(np.unique(grid.ijk, axis=0)) == len(grid.ijk)
    for c in range(len(grid.ijk)):
        p = rel[of_point == c]
        want = [len(p), *p.sum(0), *(p * p).sum(0), *(p[:, [0, 0, 1]] * p[:, [1, 2, 2]]).sum(0)]
        np.testing.assert_allclose(mom[c], want, rtol=1e-12, atol=1e-14)
    # the grid's lookup finds every cell
    if len(grid.ijk):
        s = grid.window_sums(np.eye(len(grid.ijk)), 0)
        np.testing.assert_array_equal(s, np.eye(len(grid.ijk)))


def test_bin_points_refuses_nan_and_a_bad_size():
    with pytest.raises(ValueError, match="finite"):
        bin_points(np.array([[0.0, 0.0, np.nan]]), 0.01, 1)
    with pytest.raises(ValueError, match="size"):
        bin_points(np.zeros((2, 3)), 0.0, 1)
    grid, of_point, mom, _ = bin_points(np.zeros((0, 3)), 0.01, 1)
    assert len(grid.ijk) == 0 and len(of_point) == 0 and mom.shape == (0, 10)


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 60),
    span=st.integers(1, 6),
    w=st.integers(0, 2),
    labelled=st.booleans(),
    dup=st.booleans(),
    seed=st.integers(0, 10_000),
)
def test_window_sums_of_some_cells_are_their_rows_to_the_bit(n, span, w, labelled, dup, seed):
    # Cells asked for in any order (column by column inside), or some twice (cell by cell):
    # each row exactly the row of all cells' sums.
    ijk, dims = _cells(seed, n, span, 2)
    rng = np.random.default_rng(seed + 2)
    mom = rng.normal(size=(len(ijk), MOMENTS))
    label = rng.integers(0, 3, len(ijk)) if labelled else None
    g = CellGrid(ijk, dims, 2)
    every = g.window_sums(mom, w, label)
    at = rng.permutation(len(ijk))[: rng.integers(0, len(ijk) + 1)]
    if dup and len(at):
        at = np.r_[at, at[:1]]
    np.testing.assert_array_equal(g.window_sums(mom, w, label, at), every[at])
