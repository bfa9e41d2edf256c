"""Faces joined by their boundaries' votes (votes.py): long creases are not crossed by chains."""

from __future__ import annotations

import numpy as np

from supportnode.geometry.objects.votes import vote_segments


def _vote(boundaries, n):
    a, b, links, concave = (np.array(v) for v in zip(*boundaries, strict=True))
    return vote_segments(n, a, b, links, concave.astype(float))


def test_convex_boundaries_join_and_a_crease_parts():
    # 0-1 convex (one object's lid and side), 1-2 a long concave crease.
    seg = _vote([(0, 1, 40, 2), (1, 2, 30, 25)], 3)
    assert seg[0] == seg[1] != seg[2]


def test_a_sliver_in_the_cusp_does_not_chain_two_objects():
    # Faces 0 (can a) and 1 (can b) meet in a crease of 40 links; slivers 2 and 3 in the cusp
    # between them meet a and b convexly and each other by 2 links. Joining every convex pair
    # at once would join a and b through 2-3.
    boundaries = [(0, 1, 40, 38), (0, 2, 15, 0), (1, 3, 11, 0), (2, 3, 2, 0), (1, 2, 3, 3)]
    seg = _vote(boundaries, 4)
    assert seg[0] == seg[2] and seg[1] == seg[3] and seg[0] != seg[1]


def test_chains_without_a_crease_still_join():
    # One object's faces meeting only through small faces (a cylinder's noisy side).
    seg = _vote([(0, 2, 6, 0), (2, 3, 3, 0), (3, 1, 5, 0), (0, 1, 6, 2)], 4)
    assert len(set(seg.tolist())) == 1


def test_no_boundaries():
    np.testing.assert_array_equal(_vote([(0, 0, 0, 0)], 3)[1:], [1, 2])
