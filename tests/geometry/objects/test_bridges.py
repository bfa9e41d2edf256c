"""A face bridging a concave crease is parted between its two sides (bridges.py)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from shadows import seen

from supportnode.geometry.objects.bridges import split_bridges, split_necks


def _graph(concave_crease: bool):
    """Face 0: a chain of 6 cells; face 1 (10 cells) touches its first cell, face 2 (10 cells)
    its last; faces 1 and 2 meet along 25 links, concave or not."""
    face = np.r_[np.zeros(6), np.ones(10), np.full(10, 2)].astype(np.int64)
    a_cells, b_cells = np.arange(6, 16), np.arange(16, 26)
    chain = [(i, i + 1) for i in range(5)]
    to_a = [(int(c), 0) for c in a_cells]
    to_b = [(int(c), 5) for c in b_cells]
    crease = [(int(a_cells[k % 10]), int(b_cells[(k * 3) % 10])) for k in range(25)]
    links = np.array(chain + to_a + to_b + crease)
    concave = np.zeros(len(links), bool)
    concave[-25:] = concave_crease
    return face, links[:, 0], links[:, 1], concave


def test_a_face_bridging_a_crease_is_parted_by_nearness():
    face, src, dst, concave = _graph(True)
    out = split_bridges(face, src, dst, concave, 0.3)
    assert (out[:3] == 0).all()  # the half nearer face 1 keeps the label
    assert len(set(out[3:6].tolist())) == 1 and out[3] == 3  # the other half: a new face
    np.testing.assert_array_equal(out[6:], face[6:])  # the sides are untouched


def test_without_a_crease_nothing_changes():
    face, src, dst, concave = _graph(False)
    np.testing.assert_array_equal(split_bridges(face, src, dst, concave, 0.3), face)


def test_no_faces_no_links():
    face = np.full(4, -1, np.int64)
    empty = np.zeros(0, np.int64)
    out = split_bridges(face, empty, empty, np.zeros(0, bool), 0.3)
    np.testing.assert_array_equal(out, face)


def _lids(centres, radius=0.033, spacing=0.002):
    """Points of level discs at z = 0 (lids seen from above), one label per disc; radius, metres,
    one for all or one per disc."""
    pts = []
    for c, r in zip(centres, np.broadcast_to(radius, len(centres)), strict=True):
        g = np.arange(-r, r + 1e-9, spacing)
        x, y = np.meshgrid(g, g)
        disc = np.column_stack([x.ravel(), y.ravel()])
        disc = disc[(disc**2).sum(axis=1) <= r**2]
        pts.append(np.column_stack([disc + c, np.zeros(len(disc))]))
    return np.concatenate(pts), np.repeat(np.arange(len(centres)), [len(p) for p in pts])


def _necks(points, above_points=None, origin=None, height=None):
    from supportnode.geometry.objects.faces import make_cells

    all_pts = points if above_points is None else np.concatenate([points, above_points])
    cells = make_cells(all_pts, 0.0075, 3)
    face = np.full(len(cells.centroid), -1, np.int64)
    face[cells.of_point[: len(points)]] = 0  # the lids: one level face
    src, dst = cells.grid.adjacent_pairs()
    above = None if height is None else np.full(len(face), height)
    out, cut = split_necks(cells, face, np.array([1.0]), src, dst, origin, above)
    return out[cells.of_point[: len(points)]], cut


def test_two_lids_touching_part_at_their_neck():
    pts, truth = _lids([(0.0, -0.033), (0.0, 0.033)])
    part, cut = _necks(pts)
    for k in (0, 1):
        assert np.bincount(part[truth == k]).max() >= 0.9 * (truth == k).sum()
    assert part[truth == 0][0] != part[truth == 1][0]
    assert cut.any()


def test_three_lids_in_a_row_part_at_both_necks():
    # Lids of two sizes: the necks part at different depths, one after the other.
    pts, truth = _lids([(0.0, -0.08), (0.0, 0.0), (0.0, 0.06)], radius=[0.05, 0.03, 0.03])
    part, _ = _necks(pts)
    assert len(np.unique(part)) == 3
    for k in (0, 1, 2):
        assert np.bincount(part[truth == k]).max() >= 0.9 * (truth == k).sum()


def test_flat_things_are_not_parted():
    # Two sheets touching, 5 mm above the table: no sides to tell them by; lids 12 cm up are.
    pts, _ = _lids([(0.0, -0.033), (0.0, 0.033)])
    assert len(np.unique(_necks(pts, height=0.005)[0])) == 1
    assert len(np.unique(_necks(pts, height=0.12)[0])) == 2


def test_one_lid_or_a_box_top_stays_one_face():
    pts, _ = _lids([(0.0, 0.0)], radius=0.05)
    assert len(np.unique(_necks(pts)[0])) == 1
    g = np.arange(0.0, 0.2, 0.002)
    x, y = np.meshgrid(g, g[:60])
    top = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    assert len(np.unique(_necks(top)[0])) == 1


def test_a_notch_under_what_stands_on_the_face_is_no_neck():
    # A book's top with a box standing on it across most of its depth: the visible top is two
    # lobes joined by a strip, but the box above fills the notch.
    g = np.arange(0.0, 0.24, 0.002)
    x, y = np.meshgrid(g, g[:85])
    top = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    box = (np.abs(top[:, 0] - 0.12) < 0.04) & (top[:, 1] > 0.03)
    part, _ = _necks(top[~box])
    assert len(np.unique(part)) == 2  # without the box: a neck
    lid = top[box] + [0.0, 0.0, 0.05]  # the box's top, 5 cm above the book
    part, _ = _necks(top[~box], lid, origin=np.array([0.12, -0.6, 0.6]))
    assert len(np.unique(part)) == 1


def test_a_shadow_across_a_top_is_no_neck():
    # A tall block in front of a book hides a band across most of the book's top from the
    # sensor: what the sensor sees of the top is two lobes joined by a strip.
    origin = np.array([-0.45, 0.085, 0.45])
    lo, hi = np.array([-0.06, 0.03, -0.035]), np.array([-0.02, 0.14, 0.3])
    g = np.arange(0.0, 0.24, 0.002)
    x, y = np.meshgrid(g, g[:85])
    top = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    top = top[seen(top, origin, lo, hi)]
    f = np.arange(0.03, 0.14, 0.002)
    yy, zz = np.meshgrid(f, np.arange(0.0, 0.3, 0.002))
    front = np.column_stack([np.full(yy.size, -0.06), yy.ravel(), zz.ravel()])
    assert len(np.unique(_necks(top, front)[0])) == 2  # the sensor unknown: a neck
    assert len(np.unique(_necks(top, front, origin=origin)[0])) == 1


def test_level_faces_of_one_top_without_a_neck_become_one_face():
    # A block in front of a book (24 x 30 cm) hides a band across most of its top: what is
    # seen is two lobes joined by a strip at the far end, here two faces, one per side. At
    # one height, with no neck once the hidden band is filled, they are one top.
    from supportnode.geometry.objects.faces import make_cells

    origin = np.array([-0.6, 0.15, 0.6])
    lo, hi = np.array([-0.06, 0.1, -0.035]), np.array([-0.02, 0.2, 0.165])
    x, y = np.meshgrid(np.arange(0.0, 0.24, 0.002), np.arange(0.0, 0.3, 0.002))
    top = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    top = top[seen(top, origin, lo, hi)]
    yy, zz = np.meshgrid(np.arange(0.1, 0.2, 0.002), np.arange(0.0, 0.165, 0.002))
    front = np.column_stack([np.full(yy.size, -0.06), yy.ravel(), zz.ravel()])
    cells = make_cells(np.concatenate([top, front]), 0.0075, 3)
    face = np.full(len(cells.centroid), -1, np.int64)
    of_top = cells.of_point[: len(top)]
    face[of_top] = (top[:, 1] > 0.15).astype(np.int64)  # two faces, one per side
    src, dst = cells.grid.adjacent_pairs()
    out, _ = split_necks(cells, face, np.array([1.0, 1.0]), src, dst, origin)
    assert len(np.unique(out[of_top])) == 1
    out, _ = split_necks(cells, face, np.array([1.0, 1.0]), src, dst, None)
    assert len(np.unique(out[of_top])) >= 2  # the sensor unknown: a neck between them


def test_an_l_shaped_top_has_one_bay_and_stays_whole():
    # An L (one bay in its outline) and two boxes of one height side by side, one set back
    # (a step in the outline on both sides): the first is one top, the second two.
    g = np.arange(0.0, 0.2, 0.002)
    x, y = np.meshgrid(g, g)
    top = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    ell = top[(top[:, 0] < 0.08) | (top[:, 1] < 0.08)]
    assert len(np.unique(_necks(ell)[0])) == 1
    a = top[(top[:, 0] < 0.12) & (top[:, 1] < 0.1)]
    b = top[(top[:, 0] < 0.12) & (top[:, 1] < 0.1)] + [0.04, 0.1, 0.0]
    part, _ = _necks(np.concatenate([a, b]))
    assert len(np.unique(part)) == 2
    assert part[0] != part[-1]


@settings(max_examples=200, deadline=None)
@given(
    pts=st.lists(st.tuples(st.integers(-6, 6), st.integers(-6, 6)), min_size=1, max_size=9),
    line=st.booleans(),
)
def test_collinear_is_a_rank_below_two(pts, line):
    from supportnode.geometry.objects.bridges import _collinear

    p = np.array(pts, dtype=float)
    if line:  # points on one lattice line through the first
        p = p[0] + np.arange(len(p))[:, None] * (p[-1] - p[0])
    assert _collinear(p) == (np.linalg.matrix_rank(p - p[0]) < 2)
