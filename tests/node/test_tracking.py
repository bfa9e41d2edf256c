"""Stable ids by footprint overlap: jitter, new, gone, order independence, stacked boards."""

from __future__ import annotations

import numpy as np
import pytest

from supportnode.errors import InputError
from supportnode.node.tracking import (
    ClusterTracker,
    OverlapTracker,
    overlap_matrix,
    pack_cells,
    polygon_cells,
    polygons_cells_packed,
    unpack_cells,
)


def _rect(x0, y0, nx, ny):
    gx, gy = np.meshgrid(np.arange(x0, x0 + nx), np.arange(y0, y0 + ny), indexing="ij")
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def test_overlap_matrix_counts_shared_cells():
    a = [pack_cells(_rect(0, 0, 10, 10)), pack_cells(_rect(100, 0, 2, 2))]
    b = [pack_cells(_rect(5, 0, 10, 10)), pack_cells(_rect(0, 0, 10, 10))]
    iou = overlap_matrix(a, b)
    assert iou[0, 0] == pytest.approx(50 / 150)
    assert iou[0, 1] == 1.0
    assert (iou[1] == 0).all()


def test_ids_stable_under_jitter_and_new_one_gets_new_id():
    rng = np.random.default_rng(0)
    tr = OverlapTracker(max_misses=3)
    floor, table = _rect(-20, -20, 40, 40), _rect(0, 0, 16, 9)
    first = tr.update([floor, table], [0.0, 0.75])
    assert list(first.ids) == [0, 1] and first.new == [0, 1]
    for _ in range(10):
        dx = rng.integers(-1, 2, 2)
        keep = rng.random(len(table)) > 0.2  # parts occluded
        up = tr.update([floor + dx, table[keep] + dx], [rng.normal(0, 0.005), 0.75])
        assert list(up.ids) == [0, 1] and not up.new and not up.gone
    seat = _rect(30, 30, 4, 4)
    up = tr.update([floor, table, seat], [0.0, 0.75, 0.45])
    assert list(up.ids) == [0, 1, 2] and up.new == [2]


def test_vanished_surface_is_gone_after_n_misses():
    tr = OverlapTracker(max_misses=3)
    floor, table = _rect(-20, -20, 40, 40), _rect(0, 0, 16, 9)
    tr.update([floor, table], [0.0, 0.75])
    gone = [tr.update([floor], [0.0]).gone for _ in range(4)]
    assert gone == [[], [], [1], []]
    # Back after a short absence (fewer misses than the limit): the same id.
    tr2 = OverlapTracker(max_misses=3)
    tr2.update([floor, table], [0.0, 0.75])
    tr2.update([floor], [0.0])
    assert list(tr2.update([floor, table], [0.0, 0.75]).ids) == [0, 1]
    # Back after it was reported gone: a new id, never a reused one.
    assert list(tr.update([floor, table], [0.0, 0.75]).ids) == [0, 2]


def test_order_independent_and_stacked_boards_kept_apart():
    """Three shelf boards share one footprint; height keeps them apart whatever the order."""
    board = _rect(0, 0, 12, 4)
    tr = OverlapTracker()
    ids0 = tr.update([board, board, board], [0.4, 0.8, 1.2]).ids
    perm = [2, 0, 1]
    ids1 = tr.update([board[:-3], board[3:], board], np.array([0.4, 0.8, 1.2])[perm]).ids
    assert list(ids1) == list(ids0[perm])
    # Swapped order of two side-by-side surfaces at one height.
    a, b = _rect(0, 0, 5, 5), _rect(10, 0, 5, 5)
    tr2 = OverlapTracker()
    first = tr2.update([a, b], [0.7, 0.7]).ids
    assert list(tr2.update([b, a], [0.7, 0.7]).ids) == [first[1], first[0]]


def test_height_gate_and_clusters():
    tr = OverlapTracker(height_tolerance=0.05)
    tr.update([_rect(0, 0, 5, 5)], [0.40])
    up = tr.update([_rect(0, 0, 5, 5)], [0.60])  # same footprint, 20 cm higher: not the same
    assert up.new == [1]

    class C:  # the fields of Cluster the tracker reads
        def __init__(self, x, z, top=None):
            self.footprint = np.array([[x, 0.0], [x + 0.2, 0.0], [x + 0.2, 0.1], [x, 0.1]])
            self.bbox_min = np.array([x, 0.0, z])
            self.bbox_max = np.array([x + 0.2, 0.1, z + 0.1 if top is None else top])

    ct = ClusterTracker(cell_size=0.02, match_groups=True)
    ids = ct.update_clusters([C(0.0, 0.75), C(0.5, 0.75)], np.array([1, 1])).ids
    again = ct.update_clusters([C(0.51, 0.75), C(0.01, 0.75)], np.array([1, 1])).ids
    assert list(again) == [ids[1], ids[0]]
    moved = ct.update_clusters([C(0.0, 0.75)], np.array([2])).ids  # now on another surface
    assert moved[0] not in ids
    # A lamp first seen by its shade over what hides its stem, then whole: its bottom drops
    # 18 cm, its top stays: the same object. Both ends moved: another one.
    ct = ClusterTracker(cell_size=0.02)
    first = ct.update_clusters([C(0.0, 0.98, top=1.09)]).ids[0]
    assert ct.update_clusters([C(0.0, 0.80, top=1.09)]).ids[0] == first
    assert ct.update_clusters([C(0.0, 0.60, top=0.70)]).ids[0] != first


def test_polygon_cells_and_bad_input():
    sq = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.1], [0.0, 0.1]])
    assert len(polygon_cells(sq, 0.02)) == 36  # 5 x 5 centres inside, the outline's cells
    # A sliver (a box's side seen alone) covers the cells along it, not only its centroid's.
    sliver = np.array([[0.0, 0.0], [0.3, 0.001], [0.3, 0.002]])
    assert len(polygon_cells(sliver, 0.02)) >= 15
    assert len(polygon_cells(np.array([[0.001, 0.001]]), 0.02)) == 1
    with pytest.raises(InputError):
        OverlapTracker().update([_rect(0, 0, 2, 2)], [0.0, 1.0])


def _cells_brute(poly: np.ndarray, c: float) -> set:
    """Reference: cell centres inside (every edge's cross product >= -1e-12), the outline's
    cells sampled every half cell, and the centroid's cell."""
    lo = np.floor(poly.min(axis=0) / c).astype(int)
    hi = np.floor(poly.max(axis=0) / c).astype(int)
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1))
    xc, yc = (gx.ravel() + 0.5) * c, (gy.ravel() + 0.5) * c
    inside = np.ones(len(xc), bool)
    if len(poly) >= 3:
        for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
            inside &= (b[0] - a[0]) * (yc - a[1]) - (b[1] - a[1]) * (xc - a[0]) >= -1e-12
    else:
        inside[:] = False
    cells = {(int(i), int(j)) for i, j in zip(gx.ravel()[inside], gy.ravel()[inside], strict=True)}
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        n = max(int(np.ceil(np.hypot(*(b - a)) / (0.5 * c))), 1)
        for t in np.arange(n) / n:
            cells.add(tuple(np.floor((a + t * (b - a)) / c).astype(int).tolist()))
    cells.add(tuple(np.floor(poly.mean(axis=0) / c).astype(int).tolist()))
    return cells


def test_polygons_cells_in_one_pass_match_each_polygon():
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(3)
    polys = [np.zeros((0, 2)), np.array([[0.011, 0.013]]), np.array([[0.0, 0.0], [0.1, 0.0]])]
    polys.append(np.array([[0.0, 0.0], [0.2, 0.0], [0.2, 0.1], [0.0, 0.1]]))  # vertical edges
    for _ in range(40):
        pts = rng.normal(size=(8, 2)) * rng.uniform(0.01, 0.3) + rng.uniform(-2, 2, 2)
        polys.append(pts[ConvexHull(pts).vertices])
    batch = polygons_cells_packed(polys, 0.02)
    assert len(batch) == len(polys) and len(batch[0]) == 0
    for poly, packed in zip(polys[1:], batch[1:], strict=True):
        assert np.all(np.diff(packed) > 0)  # sorted, distinct
        assert {tuple(c) for c in unpack_cells(packed).tolist()} == _cells_brute(poly, 0.02)
        assert np.array_equal(polygon_cells(poly, 0.02), unpack_cells(packed))
