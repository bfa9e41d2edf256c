"""k-NN normals: planes, orientation, curvature, the candidate-only vertical filter."""

from __future__ import annotations

import numpy as np
import pytest

from supportnode.errors import InputError
from supportnode.geometry.normals import estimate_normals, filter_vertical_normals


def _plane(rng: np.random.Generator, n: int, normal: np.ndarray, offset: np.ndarray) -> np.ndarray:
    normal = normal / np.linalg.norm(normal)
    e1 = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    uv = rng.uniform(-1, 1, (n, 2))
    return offset + uv[:, :1] * e1 + uv[:, 1:] * e2


def test_tilted_plane_normals_and_curvature() -> None:
    rng = np.random.default_rng(0)
    n_true = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    # far from the origin: centring on each query point keeps the covariance exact
    pts = _plane(rng, 5000, n_true, np.array([1e4, -2e4, 50.0]))
    normals, curvature = estimate_normals(pts, k=20)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    assert (normals[:, 2] >= 0).all()  # default orientation: +z
    assert np.degrees(np.arccos(np.clip(normals @ n_true, -1, 1))).max() < 0.01
    assert curvature.max() < 1e-6 and normals.dtype == np.float64


def test_orientation_toward_viewpoint() -> None:
    rng = np.random.default_rng(1)
    pts = _plane(rng, 2000, np.array([1.0, 0, 0]), np.array([2.0, 0, 0]))  # wall at x = 2
    normals, _ = estimate_normals(pts, k=10, viewpoint=np.zeros(3))
    np.testing.assert_allclose(normals, np.tile([-1.0, 0, 0], (2000, 1)), atol=1e-9)


def test_scatter_has_high_curvature() -> None:
    pts = np.random.default_rng(2).normal(size=(3000, 3))
    _, curvature = estimate_normals(pts, k=30)
    assert np.median(curvature) > 0.15  # isotropic scatter: close to 1/3


def test_chunking_matches_one_pass(monkeypatch: pytest.MonkeyPatch) -> None:
    import supportnode.geometry.normals as mod

    pts = np.random.default_rng(3).normal(size=(2000, 3)) * [1, 1, 0.05]
    a, ca = estimate_normals(pts, k=15)
    monkeypatch.setattr(mod, "_CHUNK_VALUES", 15 * 7)  # 7 points per chunk
    b, cb = estimate_normals(pts, k=15)
    np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(ca, cb, atol=1e-12)


def test_filter_vertical_only_candidates() -> None:
    rng = np.random.default_rng(4)
    floor = np.column_stack([rng.uniform(-1, 1, (4000, 2)), np.zeros(4000)])
    wall = np.column_stack([np.full(2000, 1.5), rng.uniform(-1, 1, 2000), rng.uniform(0, 1, 2000)])
    pts = np.concatenate([floor, wall])
    cand = np.ones(6000, dtype=bool)
    cand[:100] = False  # floor points that are not candidates are never kept
    keep = filter_vertical_normals(pts, cand, k=20, max_tilt_deg=20.0)
    assert not keep[:100].any() and keep[100:4000].all() and not keep[4000:].any()
    assert not filter_vertical_normals(pts, np.zeros(6000, bool)).any()


def test_bad_input() -> None:
    with pytest.raises(InputError, match="shape"):
        estimate_normals(np.zeros((10, 2)))
    bad = np.zeros((10, 3))
    bad[3] = np.nan
    with pytest.raises(InputError, match="not finite"):
        estimate_normals(bad)
    with pytest.raises(InputError, match="candidate_mask"):
        filter_vertical_normals(np.random.default_rng(0).random((10, 3)), np.ones(9, bool))


def test_bounded_search_matches_plain_search(monkeypatch: pytest.MonkeyPatch) -> None:
    """The search radius from a sample only prunes: same neighbours, same normals, also
    where a cloud's density varies (sparse points need the unbounded fallback)."""
    import supportnode.geometry.normals as mod

    rng = np.random.default_rng(5)
    dense = rng.normal(size=(30000, 3)) * [1, 1, 0.02]
    sparse = rng.uniform(-20, 20, (2000, 3))
    pts = np.concatenate([dense, sparse])
    a, ca = estimate_normals(pts, k=30)
    monkeypatch.setattr(mod, "_BOUND_MIN_QUERIES", 10**9)
    b, cb = estimate_normals(pts, k=30)
    np.testing.assert_allclose(a, b, atol=1e-9)
    np.testing.assert_allclose(ca, cb, atol=1e-12)


def test_sym3_eigen_matches_eigh() -> None:
    from supportnode.geometry.linalg import sym3_eigen

    rng = np.random.default_rng(6)
    a = rng.normal(size=(500, 3, 3))
    cov = a @ a.transpose(0, 2, 1)
    v = rng.normal(size=(100, 3))
    cov[:100] = v[:, :, None] * v[:, None, :] + np.eye(3) * 1e-3  # two equal eigenvalues
    evals, vec = sym3_eigen(cov)
    ref_vals, ref_vec = np.linalg.eigh(cov)
    # The trigonometric form loses digits at repeated eigenvalues: ~1e-8 of the largest.
    np.testing.assert_allclose(evals, ref_vals, atol=1e-6 * np.abs(ref_vals).max())
    cos = np.abs(np.einsum("ij,ij->i", vec, ref_vec[:, :, 0]))
    assert cos[100:].min() > 1 - 1e-9  # the smallest eigenvalue is simple there
    e0, n0 = sym3_eigen(np.zeros((2, 3, 3)))
    np.testing.assert_array_equal(n0, [[0, 0, 1.0], [0, 0, 1.0]])
    assert (e0 == 0).all()


def test_grid_search_gives_the_k_d_trees_normals_bit_for_bit(monkeypatch: pytest.MonkeyPatch):
    """Clouds of 1k points and more search their neighbours through a grid of cells: the same
    normals and curvature, and the same filter decisions, as the k-d tree's."""
    from supportnode.geometry import normals as mod

    rng = np.random.default_rng(5)
    floor = np.c_[rng.uniform(-2, 2, (15000, 2)), rng.normal(0, 0.002, 15000)]
    box = rng.uniform(-0.2, 0.2, (6000, 3)) + [0.5, 0.5, 0.2]
    pts = np.concatenate([floor, box])
    mask = pts[:, 2] < 0.05
    assert mod._grid(pts, 30) is not None  # the grid path is the one taken
    got = mod.estimate_normals(pts, k=30, viewpoint=np.array([0.0, 0.0, 2.0]))
    kept = mod.filter_vertical_normals(pts, mask)
    monkeypatch.setattr(mod, "_grid", lambda p, k: None)
    want = mod.estimate_normals(pts, k=30, viewpoint=np.array([0.0, 0.0, 2.0]))
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    np.testing.assert_array_equal(kept, mod.filter_vertical_normals(pts, mask))


def test_grid_normals_of_queries_in_any_order_match_the_k_d_tree():
    """Through a grid of cells, queries in any order (not only the cloud's own points, far
    from the origin as in a map frame) get the k-d tree's normals and curvature; clouds too
    small for a grid are left to the tree."""
    from scipy.spatial import cKDTree

    from supportnode.geometry import normals as mod

    rng = np.random.default_rng(6)
    walls = [_plane(rng, 3000, rng.normal(size=3), rng.uniform(-1, 1, 3)) for _ in range(3)]
    pts = np.concatenate(walls) + 1e3
    grid = mod._grid(pts, 20)
    assert grid is not None
    tree = cKDTree(pts)
    for query in (pts, pts[rng.permutation(len(pts))[:2000]] + rng.normal(0, 0.01, (2000, 3))):
        got = mod._grid_normals_any(grid, query, 20)
        want = mod.normals_at(tree, pts, query, 20)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    assert mod._grid(pts[:100], 20) is None


def test_normals_among_any_cell_spacing_are_the_k_d_trees(monkeypatch: pytest.MonkeyPatch):
    """`normals_among` (the surfaces' clutter filter) searches through cells of any spacing,
    or a k-d tree where the cells would not fit: the same normals and curvature either way."""
    from scipy.spatial import cKDTree

    from supportnode.geometry import normals as mod

    rng = np.random.default_rng(8)
    pts = np.concatenate(
        [_plane(rng, 2000, rng.normal(size=3), rng.uniform(-1, 1, 3)) for _ in range(2)]
    )
    query = pts[rng.permutation(len(pts))[:300]]
    want = mod.normals_at(cKDTree(pts), pts, query, 10)
    for spacing in (0.01, 0.1, 1.0, 1e-9):  # the last: too many cells, the tree's path
        got = mod.normals_among(pts, query, 10, spacing)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    # A big query with workers goes to the tree's threads (no grid built), the same normals.
    from supportnode.kernels import knn

    monkeypatch.setattr(knn, "_PARALLEL_MIN_QUERIES", 100)
    monkeypatch.setattr(knn.KnnGrid, "build", lambda *a: pytest.fail("grid built"))
    got = mod.normals_among(pts, query, 10, 0.1, workers=-1)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
