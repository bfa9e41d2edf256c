"""A face bridging a concave crease is parted between its two sides (bridges.py)."""

from __future__ import annotations

import numpy as np

from supportnode.geometry.objects.bridges import split_bridges


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
