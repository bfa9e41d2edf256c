"""The object code's array helpers give the plain numpy call's values."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from supportnode.geometry.objects.arrays import ranks


@given(st.lists(st.integers(0, 40), max_size=200), st.integers(0, 20))
def test_ranks_are_np_uniques_inverse(values, spare):
    v = np.array(values, dtype=np.int64)
    n = int(v.max()) + 1 + spare if len(v) else spare
    got = ranks(v, n)
    want = np.unique(v, return_inverse=True)[1].reshape(-1)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, want)


def test_ranks_close_the_gaps_in_order():
    np.testing.assert_array_equal(ranks(np.array([7, 2, 7, 9]), 10), [1, 0, 1, 2])
    assert ranks(np.array([], dtype=np.int64), 0).shape == (0,)
