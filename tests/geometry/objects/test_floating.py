"""Nothing floats (floating.py): a segment held by nothing level joins what it stands on."""

from __future__ import annotations

import numpy as np

from supportnode.geometry.objects.floating import join_floating


def _scene(lower_face_level: bool, upper_low: float = 0.2):
    """Two segments of cells in a column: a lower one (cells 0-4, z 0 to 0.16, its top cell on
    face 1) and an upper one (cells 5-9, from ``upper_low`` up, face 2). The upper segment's
    lowest cells meet cell 4 along five links. Face 1 is level or sloped."""
    z = np.r_[np.linspace(0.0, 0.16, 5), upper_low + np.linspace(0.0, 0.04, 5)]
    centroid = np.column_stack([np.zeros(10), np.zeros(10), z])
    above = z.copy()  # the surface at z = 0
    face = np.r_[0, 0, 0, 0, 1, 2, 2, 2, 2, 2].astype(np.int64)
    face_up = np.array([0.0, 1.0 if lower_face_level else 0.6, 0.0])
    seg = np.r_[np.zeros(5), np.ones(5)].astype(np.int64)
    chain = [(i, i + 1) for i in range(9)]
    src, dst = (np.array(v) for v in zip(*(chain + [(4, 5), (4, 6)] * 2), strict=True))
    return centroid, above, face, face_up, seg, src, dst


def test_a_neck_on_a_sloped_shoulder_joins_it():
    out = join_floating(*_scene(lower_face_level=False))
    assert len(set(out.tolist())) == 1


def test_a_box_on_a_level_top_stays_apart():
    out = join_floating(*_scene(lower_face_level=True))
    assert out[0] != out[9]


def test_what_reaches_the_surface_stands_by_itself():
    centroid, above, face, face_up, seg, src, dst = _scene(lower_face_level=False)
    above[5] = 0.005  # the upper segment comes down to the surface somewhere
    out = join_floating(centroid, above, face, face_up, seg, src, dst)
    assert out[0] != out[9]


def test_what_stands_beside_is_not_joined():
    # The upper segment's lowest cell lies below the lower one's top: beside it, not on it.
    out = join_floating(*_scene(lower_face_level=False, upper_low=0.1))
    assert out[0] != out[9]


def test_over_no_surface_nothing_is_known():
    centroid, above, face, face_up, seg, src, dst = _scene(lower_face_level=False)
    above[:] = np.inf
    np.testing.assert_array_equal(join_floating(centroid, above, face, face_up, seg, src, dst), seg)
