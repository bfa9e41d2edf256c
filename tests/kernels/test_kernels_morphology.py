"""Distance transform and binary morphology against scipy.ndimage: the same arrays, bit for
bit, including the nearest cell chosen among equally near ones, on random and tied rasters,
empty ones, one cell, no background and bad input."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.ndimage as ndi
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels.morphology import (
    binary_closing,
    binary_dilation,
    binary_erosion,
    binary_opening,
    distance_transform,
    feature_transform,
    squared_distance_transform,
)

_SQUARE3, _SQUARE5 = np.ones((3, 3), bool), np.ones((5, 5), bool)
_CROSS = ndi.generate_binary_structure(2, 1)


def _disc(ri: int, rj: int) -> np.ndarray:
    ii, jj = np.mgrid[-ri : ri + 1, -rj : rj + 1]
    return (ii / ri) ** 2 + (jj / rj) ** 2 <= 1.0


def _raster(h: int, w: int, fill: float, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).random((h, w)) < fill


def _assert_transforms_match(mask: np.ndarray) -> None:
    dist, ft = ndi.distance_transform_edt(mask, return_indices=True)
    got = feature_transform(mask)
    assert got.dtype == ft.dtype == np.int32
    np.testing.assert_array_equal(got, ft)  # the same nearest cell, ties included
    np.testing.assert_array_equal(distance_transform(mask), dist)  # bits: no tolerance
    np.testing.assert_array_equal(squared_distance_transform(mask), np.round(dist**2))


@settings(max_examples=200, deadline=None)
@given(
    h=st.integers(1, 40),
    w=st.integers(1, 40),
    fill=st.floats(0.0, 1.0),
    seed=st.integers(0, 10_000),
)
def test_distance_and_feature_transforms_match_scipy(h, w, fill, seed):
    _assert_transforms_match(_raster(h, w, fill, seed))


@settings(max_examples=60, deadline=None)
@given(h=st.integers(1, 60), w=st.integers(1, 60), seed=st.integers(0, 10_000))
def test_ties_on_sparse_lattices_match_scipy(h, w, seed):
    # Background on a coarse lattice: many cells are equally near several of its points.
    rng = np.random.default_rng(seed)
    mask = np.ones((h, w), bool)
    step = int(rng.integers(2, 7))
    mask[int(rng.integers(0, step)) :: step, int(rng.integers(0, step)) :: step] = False
    _assert_transforms_match(mask)


def test_transform_edge_cases_match_scipy():
    for mask in [
        np.zeros((1, 1), bool),
        np.ones((1, 1), bool),  # no background: scipy's placeholders
        np.ones((3, 5), bool),
        np.ones((1, 7), bool),
        np.eye(6, dtype=bool),
        ~np.eye(6, dtype=bool),
    ]:
        _assert_transforms_match(mask)
    for shape in [(0, 0), (0, 3), (4, 0)]:
        assert feature_transform(np.zeros(shape, bool)).shape == (2, *shape)
        assert distance_transform(np.zeros(shape, bool)).shape == shape
    # nonzero is True, as scipy reads it
    np.testing.assert_array_equal(
        distance_transform(np.array([[0.0, 2.5], [np.nan, 0.0]])),
        ndi.distance_transform_edt(np.array([[0.0, 2.5], [np.nan, 0.0]])),
    )


@settings(max_examples=200, deadline=None)
@given(
    h=st.integers(1, 30),
    w=st.integers(1, 30),
    fill=st.floats(0.0, 1.0),
    seed=st.integers(0, 10_000),
    which=st.sampled_from(["cross", "square3", "square5", "disc"]),
    border=st.booleans(),
)
def test_morphology_matches_scipy(h, w, fill, seed, which, border):
    mask = _raster(h, w, fill, seed)
    s = {"cross": _CROSS, "square3": _SQUARE3, "square5": _SQUARE5, "disc": _disc(2, 3)}[which]
    np.testing.assert_array_equal(
        binary_dilation(mask, s, border), ndi.binary_dilation(mask, s, border_value=border)
    )
    np.testing.assert_array_equal(
        binary_erosion(mask, s, border), ndi.binary_erosion(mask, s, border_value=border)
    )
    np.testing.assert_array_equal(binary_closing(mask, s), ndi.binary_closing(mask, s))
    np.testing.assert_array_equal(binary_opening(mask, s), ndi.binary_opening(mask, s))


@settings(max_examples=80, deadline=None)
@given(
    h=st.integers(1, 20),
    w=st.integers(1, 20),
    fill=st.floats(0.0, 1.0),
    seed=st.integers(0, 10_000),
    shape=st.tuples(st.sampled_from([1, 3, 5]), st.sampled_from([1, 3, 5])),
)
def test_asymmetric_structures_are_reflected_as_scipy_does(h, w, fill, seed, shape):
    mask = _raster(h, w, fill, seed)
    s = np.random.default_rng(seed + 1).random(shape) < 0.5
    np.testing.assert_array_equal(binary_dilation(mask, s), ndi.binary_dilation(mask, s))
    np.testing.assert_array_equal(binary_erosion(mask, s), ndi.binary_erosion(mask, s))


def test_default_structure_is_the_cross_and_edge_cases():
    mask = np.zeros((5, 5), bool)
    mask[2, 2] = True
    np.testing.assert_array_equal(binary_dilation(mask), ndi.binary_dilation(mask))
    one = np.ones((1, 1), bool)
    assert not binary_erosion(one).any() and binary_erosion(one, border_value=True).all()
    assert binary_dilation(np.zeros((1, 1), bool), border_value=True).all()
    for shape in [(0, 0), (0, 3), (2, 0)]:
        assert binary_dilation(np.zeros(shape, bool), _SQUARE3).shape == shape
        assert binary_closing(np.zeros(shape, bool)).shape == shape


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="2-D raster"):
        feature_transform(np.zeros(4, bool))
    with pytest.raises(ValueError, match="odd sides"):
        binary_dilation(np.zeros((3, 3), bool), np.ones((2, 3), bool))
    with pytest.raises(ValueError, match="2-D raster"):
        binary_erosion(np.zeros((2, 2, 2), bool))
