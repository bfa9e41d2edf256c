"""The compiled support look-up against the numpy one it replaced; bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.geometry.objects.support_lookup import _SupportTable
from supportnode.kernels import runtime
from supportnode.kernels.lookup import _warm, table_lookup


@settings(max_examples=80, deadline=None)
@given(
    m=st.integers(0, 400),
    s=st.integers(0, 4),
    shape=st.tuples(st.integers(1, 30), st.integers(1, 30)),
    seed=st.integers(0, 10_000),
)
def test_lookup_matches_numpy(m, s, shape, seed):
    rng = np.random.default_rng(seed)
    cell = rng.uniform(0.02, 0.2, 2)
    origin = rng.integers(-20, 20, 2)
    best = rng.integers(-1, s + 1, (s + 1, *shape)).astype(np.int32)
    threshold = np.sort(rng.uniform(-1, 2, s))
    table = _SupportTable(cell, origin, best, threshold)
    span = (origin + np.array(shape) / 2) * cell
    cp = np.column_stack(
        [rng.normal(span, 2.0 * cell * np.array(shape), (m, 2)), rng.uniform(-1.5, 2.5, m)]
    )
    cp[: m // 5, 2] = np.resize(threshold, m // 5) if s else cp[: m // 5, 2]  # ties: side right
    assert np.array_equal(table.lookup(cp), table.lookup_numpy(cp))


def test_bad_input_and_warm_up():
    best = np.zeros((2, 3, 3), np.int32)
    cp = np.zeros((1, 3))
    with pytest.raises(ValueError, match="S \\+ 1"):
        table_lookup(cp, np.zeros(2), np.ones(2), np.zeros(2), best)
    with pytest.raises(ValueError, match="ascend"):
        table_lookup(cp, np.array([1.0, 0.0]), np.ones(2), np.zeros(2), np.zeros((3, 3, 3)))
    assert _warm in runtime._WARMERS
