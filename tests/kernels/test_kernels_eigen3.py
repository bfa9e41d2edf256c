"""The compiled 3x3 eigen solver against the numpy closed form (to the bit) and eigh."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.geometry.linalg import sym3_eigen_entries
from supportnode.kernels import runtime
from supportnode.kernels.eigen3 import _warm, sym3_eigen_columns

PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _entries(cov: np.ndarray) -> list[np.ndarray]:
    return [np.ascontiguousarray(cov[:, i, j]) for i, j in PAIRS]


def _numpy_closed_form(*entries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The closed form as numpy ufuncs, as the package computed it before the kernel; the
    entries a00, a11, a22, a01, a02, a12 (M,) each."""
    a00, a11, a22, a01, a02, a12 = entries
    # Trigonometric solution (Smith 1961) on the shifted, scaled matrix B = (A - qI) / p.
    q = (a00 + a11 + a22) / 3.0
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    d0, d1, d2 = a00 - q, a11 - q, a22 - q
    p2 = d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1
    p = np.sqrt(p2 / 6.0)
    safe_p = np.where(p > 0, p, 1.0)
    b00, b11, b22 = d0 / safe_p, d1 / safe_p, d2 / safe_p
    b01, b02, b12 = a01 / safe_p, a02 / safe_p, a12 / safe_p
    det_b = (
        b00 * (b11 * b22 - b12 * b12)
        - b01 * (b01 * b22 - b12 * b02)
        + b02 * (b01 * b12 - b11 * b02)
    )
    r = np.clip(det_b / 2.0, -1.0, 1.0)
    phi = np.arccos(r) / 3.0
    e_max = q + 2.0 * p * np.cos(phi)
    e_min = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    e_mid = 3.0 * q - e_max - e_min
    evals = np.stack([e_min, e_mid, e_max], axis=1)

    # Eigenvector of e_min: the largest cross product of two rows of (A - e_min I), with rows
    # r0 = (m00, a01, a02), r1 = (a01, m11, a12), r2 = (a02, a12, m22).
    m00, m11, m22 = a00 - e_min, a11 - e_min, a22 - e_min
    c01 = (a01 * a12 - a02 * m11, a02 * a01 - m00 * a12, m00 * m11 - a01 * a01)  # r0 x r1
    c02 = (a01 * m22 - a02 * a12, a02 * a02 - m00 * m22, m00 * a12 - a01 * a02)  # r0 x r2
    c12 = (m11 * m22 - a12 * a12, a12 * a02 - a01 * m22, a01 * a12 - m11 * a02)  # r1 x r2
    n01, n02, n12 = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2] for c in (c01, c02, c12))
    # Ties go to the first, as argmax over (n01, n02, n12) would.
    use01 = (n01 >= n02) & (n01 >= n12)
    use02 = ~use01 & (n02 >= n12)
    vec = np.empty((len(q), 3), dtype=np.float64)
    for i in range(3):  # three components, not a loop over matrices
        vec[:, i] = np.where(use01, c01[i], np.where(use02, c02[i], c12[i]))
    norm = np.sqrt(np.maximum(np.maximum(np.maximum(n01, n02), n12), 0.0))
    # Degenerate cases (two or three equal small eigenvalues, e.g. collinear points): the
    # cross products vanish and any vector orthogonal to the dominant direction is an
    # eigenvector; report +z there and let callers judge with the eigenvalues.
    scale = np.maximum(np.maximum(np.abs(e_min), np.abs(e_mid)), np.abs(e_max))
    degenerate = norm <= 1e-12 * np.maximum(scale, 1e-300)
    vec[degenerate] = (0.0, 0.0, 1.0)
    norm[degenerate] = 1.0
    vec /= norm[:, None]
    return evals, vec


@settings(max_examples=60, deadline=None)
@given(m=st.integers(0, 400), scale=st.floats(1e-8, 1e3), seed=st.integers(0, 10_000))
def test_compiled_equals_numpy_bit_for_bit(m, scale, seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(m, 3, 6)) * scale
    pts[: m // 4, 2] *= 1e-6  # flat ones (a plane's voxels)
    pts[m // 4 : m // 3, 1:] = 0.0  # lines (one lidar ring): degenerate
    cov = pts @ pts.transpose(0, 2, 1)
    cov[m // 3 : m // 3 + 2] = 0.0  # empty spread
    got, want = sym3_eigen_entries(*_entries(cov)), _numpy_closed_form(*_entries(cov))
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
