"""Binary searches on ascending arrays inside compiled kernels: ``np.searchsorted`` from a
starting row, without leaving compiled code (used by `kernels.layers`, `kernels.overlap`)."""

from __future__ import annotations

from numba import njit

__all__ = ["first_above", "first_at"]


@njit(cache=True, nogil=True)
def first_above(a, v, lo):
    """The first row from ``lo`` of ascending ``a`` whose value > v (searchsorted "right")."""
    hi = a.size
    while lo < hi:
        mid = (lo + hi) >> 1
        if a[mid] <= v:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True)
def first_at(a, v, lo):
    """The first row from ``lo`` of ascending ``a`` whose value >= v (searchsorted "left")."""
    hi = a.size
    while lo < hi:
        mid = (lo + hi) >> 1
        if a[mid] < v:
            lo = mid + 1
        else:
            hi = mid
    return lo
