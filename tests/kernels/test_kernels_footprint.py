"""Footprint rasters: closing and hole filling against scipy.ndimage, rasterising, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.ndimage as ndi
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels.footprint import close3, fill_holes, footprint_raster, label8


def _holes_up_to(mask: np.ndarray, max_cells: int) -> np.ndarray:
    """Reference: binary_fill_holes, then only the holes of at most max_cells cells kept."""
    holes = ndi.binary_fill_holes(mask) & ~mask
    lab, n = ndi.label(holes)
    sizes = np.bincount(lab.ravel(), minlength=n + 1)
    small = (sizes <= max_cells) & (np.arange(n + 1) > 0)
    return mask | small[lab]


@settings(max_examples=120, deadline=None)
@given(
    h=st.integers(1, 30),
    w=st.integers(1, 30),
    fill=st.floats(0.0, 1.0),
    max_cells=st.integers(0, 12),
    seed=st.integers(0, 10_000),
)
def test_close_and_fill_match_scipy(h, w, fill, max_cells, seed):
    mask = np.random.default_rng(seed).random((h, w)) < fill
    closed = ndi.binary_closing(mask, np.ones((3, 3), bool), border_value=0)
    np.testing.assert_array_equal(close3(mask), closed)
    np.testing.assert_array_equal(fill_holes(mask), ndi.binary_fill_holes(mask))
    np.testing.assert_array_equal(fill_holes(mask, max_cells), _holes_up_to(mask, max_cells))


def test_empty_and_one_cell_rasters():
    for shape in [(0, 0), (0, 4), (1, 1), (2, 2)]:
        mask = np.ones(shape, bool)
        assert close3(mask).shape == shape and not close3(mask).any()  # edge cells never close
        np.testing.assert_array_equal(fill_holes(mask), mask)


def test_ring_is_filled_unless_its_hole_is_too_big():
    ring = np.zeros((7, 7), bool)
    ring[1:6, 1:6] = True
    ring[2:5, 2:5] = False  # a hole of 9 cells
    assert fill_holes(ring)[1:6, 1:6].all()
    assert fill_holes(ring, 9)[1:6, 1:6].all()
    np.testing.assert_array_equal(fill_holes(ring, 8), ring)
    open_ring = ring.copy()
    open_ring[3, 1] = open_ring[3, 0] = False  # the hole reaches the edge: outside
    np.testing.assert_array_equal(fill_holes(open_ring), open_ring)


def test_footprint_raster_of_points():
    # Two points 2 cells apart on a row: closing bridges the gap between them.
    occ = footprint_raster(np.array([0.2, 0.7, 0.9]), np.array([0.5, 2.4, 0.0]), (4, 6), 10)
    expected = np.zeros((4, 6), bool)
    expected[1, 1:4] = True
    np.testing.assert_array_equal(occ, expected)
    assert footprint_raster(np.zeros(0), np.zeros(0), (3, 3), 10).sum() == 0
    with pytest.raises(ValueError, match="raster coordinates"):
        footprint_raster(np.array([np.nan]), np.array([0.0]), (3, 3), 10)
    with pytest.raises(ValueError, match="raster coordinates"):
        footprint_raster(np.array([1.5]), np.array([0.0]), (3, 3), 10)


@settings(max_examples=120, deadline=None)
@given(
    h=st.integers(1, 30),
    w=st.integers(1, 30),
    fill=st.floats(0.0, 1.0),
    seed=st.integers(0, 10_000),
)
def test_labels_match_scipy_numbering_and_all(h, w, fill, seed):
    mask = np.random.default_rng(seed).random((h, w)) < fill
    got, n = label8(mask)
    want, n_want = ndi.label(mask, structure=np.ones((3, 3), bool))
    assert n == n_want and got.dtype == want.dtype
    np.testing.assert_array_equal(got, want)
