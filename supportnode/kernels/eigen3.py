"""Symmetric 3x3 eigen solver, the closed form of `geometry.linalg`, one pass per matrix.

`geometry.linalg.sym3_eigen_entries` in two compiled passes around numpy's arccos and cos:
the same floating-point operations in the same order as its numpy expressions, and the two
transcendental steps left to numpy (whose SIMD implementations may round differently from
the C library's), so the results are the same bits. Each numpy step there made an (M,)
temporary; here each matrix is done in registers. Releases the interpreter lock.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

__all__ = ["sym3_eigen_columns"]


@njit(cache=True, nogil=True)
def _shifted(a00, a11, a22, a01, a02, a12):
    """Per matrix: the mean eigenvalue q, the scale p and r = det(B) / 2 clipped to [-1, 1]
    of B = (A - qI) / p (Smith 1961)."""
    m = a00.size
    q = np.empty(m)
    p = np.empty(m)
    r = np.empty(m)
    for i in range(m):
        qi = (a00[i] + a11[i] + a22[i]) / 3.0
        p1 = a01[i] * a01[i] + a02[i] * a02[i] + a12[i] * a12[i]
        d0, d1, d2 = a00[i] - qi, a11[i] - qi, a22[i] - qi
        pi = math.sqrt((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1) / 6.0)
        safe = pi if pi > 0 else 1.0
        b00, b11, b22 = d0 / safe, d1 / safe, d2 / safe
        b01, b02, b12 = a01[i] / safe, a02[i] / safe, a12[i] / safe
        det = (
            b00 * (b11 * b22 - b12 * b12)
            - b01 * (b01 * b22 - b12 * b02)
            + b02 * (b01 * b12 - b11 * b02)
        )
        h = det / 2.0
        # np.clip(h, -1, 1), NaN kept
        r[i] = -1.0 if h < -1.0 else (1.0 if h > 1.0 else h)
        q[i], p[i] = qi, pi
    return q, p, r


@njit(cache=True, nogil=True)
def _vectors(a00, a11, a22, a01, a02, a12, q, p, cos_max, cos_min):
    """Eigenvalues (M, 3) ascending and the unit eigenvector of the smallest (M, 3)."""
    m = a00.size
    evals = np.empty((m, 3))
    vec = np.empty((m, 3))
    for i in range(m):
        e_max = q[i] + 2.0 * p[i] * cos_max[i]
        e_min = q[i] + 2.0 * p[i] * cos_min[i]
        e_mid = 3.0 * q[i] - e_max - e_min
        evals[i, 0], evals[i, 1], evals[i, 2] = e_min, e_mid, e_max
        x01, x02, x12 = a01[i], a02[i], a12[i]
        m00, m11, m22 = a00[i] - e_min, a11[i] - e_min, a22[i] - e_min
        c01 = (x01 * x12 - x02 * m11, x02 * x01 - m00 * x12, m00 * m11 - x01 * x01)
        c02 = (x01 * m22 - x02 * x12, x02 * x02 - m00 * m22, m00 * x12 - x01 * x02)
        c12 = (m11 * m22 - x12 * x12, x12 * x02 - x01 * m22, x01 * x12 - m11 * x02)
        n01 = c01[0] * c01[0] + c01[1] * c01[1] + c01[2] * c01[2]
        n02 = c02[0] * c02[0] + c02[1] * c02[1] + c02[2] * c02[2]
        n12 = c12[0] * c12[0] + c12[1] * c12[1] + c12[2] * c12[2]
        if n01 >= n02 and n01 >= n12:  # ties to the first, as argmax would
            c = c01
        elif n02 >= n12:
            c = c02
        else:
            c = c12
        norm = math.sqrt(max(max(max(n01, n02), n12), 0.0))
        scale = max(max(abs(e_min), abs(e_mid)), abs(e_max))
        if norm <= 1e-12 * max(scale, 1e-300):  # degenerate: +z, judged by the eigenvalues
            vec[i, 0], vec[i, 1], vec[i, 2] = 0.0, 0.0, 1.0
        else:
            vec[i, 0], vec[i, 1], vec[i, 2] = c[0] / norm, c[1] / norm, c[2] / norm
    return evals, vec


def sym3_eigen_columns(*entries: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (M, 3) ascending and the smallest eigenvector (M, 3) of the symmetric
    matrices with entries a00, a11, a22, a01, a02, a12, each (M,) float64 (finite)."""
    if len(entries) != 6:
        raise ValueError(f"six entries (a00, a11, a22, a01, a02, a12), got {len(entries)}")
    cols = [np.ascontiguousarray(e, dtype=np.float64).reshape(-1) for e in entries]
    if len({c.size for c in cols}) != 1:
        raise ValueError("the six entries must have one length")
    a00, a11, a22, a01, a02, a12 = cols
    q, p, r = _shifted(a00, a11, a22, a01, a02, a12)
    phi = np.arccos(r) / 3.0
    cos_max, cos_min = np.cos(phi), np.cos(phi + 2.0 * np.pi / 3.0)
    return _vectors(a00, a11, a22, a01, a02, a12, q, p, cos_max, cos_min)


@warmer
def _warm() -> None:
    one = np.ones(2)
    sym3_eigen_columns(2 * one, one, 0.5 * one, 0.1 * one, 0.0 * one, 0.2 * one)
