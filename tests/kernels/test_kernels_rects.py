"""Minimum-area yaw boxes in one compiled pass against the per-polygon numpy reference."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.geometry.objects.hull import _oriented_rect, _oriented_rects
from supportnode.kernels.rects import min_area_boxes


@settings(max_examples=40, deadline=None)
@given(n_polys=st.integers(0, 12), seed=st.integers(0, 10_000))
def test_boxes_of_many_polygons_equal_one_at_a_time(n_polys, seed):
    # Convex polygons of 1 to 200 vertices (ellipses sampled at random angles, far from the
    # origin as a map's): the same centre, length, width and yaw, bit for bit.
    rng = np.random.default_rng(seed)
    polys = []
    for _ in range(n_polys):
        t = np.sort(rng.uniform(0, 2 * np.pi, int(rng.integers(1, 200))))
        r = rng.uniform(0.01, 2.0, 2)
        polys.append(np.c_[r[0] * np.cos(t), r[1] * np.sin(t)] + rng.normal(0, 100, 2))
    for got, poly in zip(_oriented_rects(polys), polys, strict=True):
        want = _oriented_rect(poly)
        np.testing.assert_array_equal(got[0], want[0])
        assert got[1:] == want[1:]


def test_a_square_takes_its_first_edge_and_bad_input_is_refused():
    x, y = np.array([0.0, 1.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0, 1.0])
    zero = np.zeros(4)
    best, ext = min_area_boxes(x, y, np.array([0, 4]), zero, zero + 1.0, zero)
    assert best.tolist() == [0]  # four equal areas: the first direction
    np.testing.assert_array_equal(ext, [[1.0, 0.0, 1.0, 0.0]])
    with pytest.raises(ValueError, match="starts"):
        min_area_boxes(x, y, np.array([0, 2, 2, 4]), zero, zero, zero)  # an empty polygon
    with pytest.raises(ValueError, match="min_area_boxes"):
        min_area_boxes(x, y[:3], np.array([0, 4]), zero, zero, zero)
