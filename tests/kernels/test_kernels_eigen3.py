"""The compiled 3x3 eigen solver against the numpy closed form (to the bit) and eigh."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.geometry.linalg import sym3_eigen_entries, sym3_eigen_entries_numpy
from supportnode.kernels import runtime
from supportnode.kernels.eigen3 import _warm, sym3_eigen_columns

PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _entries(cov: np.ndarray) -> list[np.ndarray]:
    return [np.ascontiguousarray(cov[:, i, j]) for i, j in PAIRS]


@settings(max_examples=60, deadline=None)
@given(m=st.integers(0, 400), scale=st.floats(1e-8, 1e3), seed=st.integers(0, 10_000))
def test_compiled_equals_numpy_bit_for_bit(m, scale, seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(m, 3, 6)) * scale
    pts[: m // 4, 2] *= 1e-6  # flat ones (a plane's voxels)
    pts[m // 4 : m // 3, 1:] = 0.0  # lines (one lidar ring): degenerate
    cov = pts @ pts.transpose(0, 2, 1)
    cov[m // 3 : m // 3 + 2] = 0.0  # empty spread
    got, want = sym3_eigen_entries(*_entries(cov)), sym3_eigen_entries_numpy(*_entries(cov))
    for g, w in zip(got, want, strict=True):
        assert g.shape == w.shape == (m, 3)
        assert np.array_equal(g, w)


def test_eigenvalues_agree_with_eigh_and_the_normal_is_the_smallest():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(500, 3, 3))
    cov = a @ a.transpose(0, 2, 1)
    evals, vec = sym3_eigen_columns(*_entries(cov))
    np.testing.assert_allclose(evals, np.linalg.eigh(cov)[0], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(vec, axis=1), 1.0, rtol=1e-12)
    residual = np.einsum("mij,mj->mi", cov, vec) - evals[:, :1] * vec
    assert np.abs(residual).max() < 1e-8


def test_bad_input_and_warm_up():
    one = np.ones(3)
    with pytest.raises(ValueError, match="six entries"):
        sym3_eigen_columns(one, one)
    with pytest.raises(ValueError, match="one length"):
        sym3_eigen_columns(one, one, one, one, one, np.ones(2))
    assert _warm in runtime._WARMERS
