"""Union-find components against scipy's csgraph on random graphs, and bad edges."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from supportnode.kernels.components import label_edges, label_voxel_grid


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(0, 60),
    edges=st.lists(st.tuples(st.integers(0, 59), st.integers(0, 59)), max_size=120),
)
def test_same_components_and_numbering_as_scipy(n, edges):
    e = np.array([(a, b) for a, b in edges if a < n and b < n], dtype=np.int64).reshape(-1, 2)
    got = label_edges(n, e[:, 0], e[:, 1])
    assert got.dtype == np.int64 and got.shape == (n,)
    if n == 0:
        return
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    _, want = connected_components(graph, directed=False)
    np.testing.assert_array_equal(got, want)


def test_no_edges_gives_singletons_and_self_loops_are_harmless():
    np.testing.assert_array_equal(label_edges(4, np.array([2]), np.array([2])), [0, 1, 2, 3])


@pytest.mark.parametrize(
    ("n", "src", "dst", "message"),
    [
        (3, [0, 1], [1], "differ in length"),
        (3, [0], [3], r"in \[0, 3\)"),
        (3, [-1], [0], r"in \[0, 3\)"),
        (-1, [], [], ">= 0"),
    ],
)
def test_bad_edges_are_refused_before_the_kernel(n, src, dst, message):
    with pytest.raises(ValueError, match=message):
        label_edges(n, np.array(src, dtype=np.int64), np.array(dst, dtype=np.int64))


@settings(max_examples=100, deadline=None)
@given(
    dims=st.tuples(st.integers(1, 6), st.integers(1, 6), st.integers(1, 6)),
    fill=st.floats(0.0, 1.0),
    n_support=st.integers(0, 3),
    seed=st.integers(0, 10_000),
)
def test_voxel_grid_components_equal_the_edge_list_ones(dims, fill, n_support, seed):
    """label_voxel_grid == label_edges over the 26-neighbour links, support cuts included."""
    rng = np.random.default_rng(seed)
    inner = rng.random(dims) < fill
    grid = np.pad(inner, 1)  # the empty border the kernel relies on
    shape = np.array(grid.shape)
    strides = np.array([shape[1] * shape[2], shape[2], 1])
    offsets = (
        np.array([o for o in np.ndindex(3, 3, 3) if o > (1, 1, 1)], dtype=np.int64) - 1
    )  # the 13 forward offsets
    flat_offsets = offsets @ strides
    occupied = grid.ravel()
    vkeys = np.flatnonzero(occupied)
    vid = np.zeros(occupied.size, np.int64)
    vid[vkeys] = np.arange(len(vkeys))
    support = rng.integers(-1, n_support, len(vkeys)) if n_support else None
    rows, cols = [], []
    for off in flat_offsets:
        hit = np.flatnonzero(occupied[vkeys + off])
        rows.append(hit)
        cols.append(vid[vkeys[hit] + off])
    r, c = np.concatenate(rows), np.concatenate(cols)
    cuts = 0
    if support is not None:
        same = support[r] == support[c]
        cuts = int((~same).sum())
        r, c = r[same], c[same]
    labels, got_cuts = label_voxel_grid(vkeys, occupied, vid, flat_offsets, support)
    np.testing.assert_array_equal(labels, label_edges(len(vkeys), r, c))
    assert got_cuts == cuts


def test_voxel_grid_without_border_or_with_wrong_support_is_refused():
    occupied = np.array([True, True, False])
    vid = np.array([0, 1, 0])
    with pytest.raises(ValueError, match="empty border"):
        label_voxel_grid(np.array([0, 1]), occupied[:2], vid[:2], np.array([1]))
    with pytest.raises(ValueError, match="one label per voxel"):
        label_voxel_grid(np.array([1]), occupied, vid, np.array([1]), np.array([0, 1]))
