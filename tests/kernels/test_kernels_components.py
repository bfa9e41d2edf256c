"""Union-find components against scipy's csgraph on random graphs, and bad edges."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from supportnode.kernels.components import label_edges


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
