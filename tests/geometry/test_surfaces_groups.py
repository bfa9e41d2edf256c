"""Per-group counts of the surfaces' helpers equal their plain numpy reference."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from supportnode.geometry.surfaces.groups import columns_per_group


def _reference(group: np.ndarray, keys: np.ndarray, n: int) -> np.ndarray:
    sv = np.flatnonzero(group >= 0)
    if len(sv) == 0:
        return np.zeros(n, np.int64)
    rows = np.unique(np.stack([group[sv], keys[sv, 0], keys[sv, 1]], 1), axis=0)
    return np.bincount(rows[:, 0], minlength=n)


@given(
    st.integers(1, 5),
    st.lists(st.tuples(st.integers(-1, 4), st.integers(-6, 6), st.integers(-6, 6)), max_size=80),
    st.sampled_from([1, 2**40]),
)
def test_columns_per_group_counts_each_groups_distinct_columns(n, rows, spread):
    group = np.array([min(g, n - 1) for g, _, _ in rows], dtype=np.int64)
    # spread 2**40: keys so far apart that the packed key would overflow (the rows' path)
    keys = np.array([[x * spread, y * spread, 0] for _, x, y in rows], dtype=np.int64)
    keys = keys.reshape(-1, 3)
    got = columns_per_group(group, keys, n)
    np.testing.assert_array_equal(got, _reference(group, keys, n))


def test_columns_per_group_ignores_height_and_ungrouped_voxels():
    keys = np.array([[0, 0, 0], [0, 0, 5], [1, 0, 0], [1, 0, 0]])
    group = np.array([0, 0, 0, -1])
    np.testing.assert_array_equal(columns_per_group(group, keys, 2), [2, 0])
