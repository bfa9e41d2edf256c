"""The compiled 3-D hull's volume is Qhull's, on general, degenerate and sensor-like sets."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull, QhullError

from supportnode.kernels.hull3d import FAILED, hull_volume


def qhull_volume(p: np.ndarray) -> float:
    try:
        return float(ConvexHull(p).volume)
    except (QhullError, ValueError):
        return 0.0


def cloud(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    if kind == "normal":
        return rng.normal(size=(n, 3))
    if kind == "sphere":  # every point a hull vertex
        v = rng.normal(size=(n, 3))
        return v / np.linalg.norm(v, axis=1, keepdims=True)
    if kind == "quantised":  # a depth camera's mm steps: many coplanar, repeated points
        return np.round(rng.uniform(0, 0.2, (n, 3)), 3)
    if kind == "box":  # points on a box's faces: coplanar by the hundred
        size = np.array([0.3, 0.2, 0.1])
        p = rng.uniform(0, 1, (n, 3)) * size
        axis = rng.integers(0, 3, n)
        p[np.arange(n), axis] = np.where(rng.random(n) < 0.5, 0.0, size[axis])
        return p
    g = np.stack(np.meshgrid(*[np.arange(4.0)] * 3), -1).reshape(-1, 3)  # a lattice, twice
    return np.concatenate([g, g])[: max(n, 4)] * 0.01


@settings(max_examples=120, deadline=None)
@given(
    kind=st.sampled_from(["normal", "sphere", "quantised", "box", "lattice"]),
    n=st.integers(4, 400),
    offset=st.floats(-100, 100),
    seed=st.integers(0, 10_000),
)
def test_volume_is_qhulls(kind, n, offset, seed):
    p = cloud(kind, n, np.random.default_rng(seed)) + offset
    got = hull_volume(np.ascontiguousarray(p))
    assert got != FAILED
    assert got == pytest.approx(qhull_volume(p), rel=1e-9, abs=1e-12)


def test_degenerate_sets_have_no_volume():
    rng = np.random.default_rng(3)
    assert hull_volume(np.zeros((0, 3))) == 0.0
    assert hull_volume(rng.normal(size=(3, 3))) == 0.0  # too few for a solid
    assert hull_volume(np.zeros((10, 3))) == 0.0  # one point, repeated
    line = np.outer(rng.uniform(size=20), [1.0, 2.0, 3.0])
    assert hull_volume(line) == 0.0
    flat = np.c_[rng.uniform(size=(50, 2)), np.full(50, 0.7)]
    assert hull_volume(flat) == 0.0


def test_unit_cube_and_tetrahedron():
    cube = np.stack(np.meshgrid(*[[0.0, 1.0]] * 3), -1).reshape(-1, 3)
    inner = np.random.default_rng(0).uniform(0.1, 0.9, (100, 3))
    assert hull_volume(np.concatenate([cube, inner])) == pytest.approx(1.0, rel=1e-12)
    tetra = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    assert hull_volume(tetra) == pytest.approx(1 / 6, rel=1e-12)


def test_room_for_faces_doubles_keeping_the_faces_so_far():
    from supportnode.kernels.hull3d import _faces, _grow

    faces = _faces(4)
    faces[0][:] = np.arange(12).reshape(4, 3)
    faces[3][:] = [5, -1, 7, -1]
    faces[6][:] = [True, False, True, True]
    grown = _grow(*faces)
    assert len(grown[0]) == 8
    np.testing.assert_array_equal(grown[0][:4], faces[0])
    np.testing.assert_array_equal(grown[3], [5, -1, 7, -1, -1, -1, -1, -1])
    np.testing.assert_array_equal(grown[6], [True, False, True, True] + [False] * 4)
