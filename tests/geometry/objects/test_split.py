"""Clusters split at the necks of their footprints (split.py), and what stands on them."""

from __future__ import annotations

import numpy as np
import pytest
from shadows import seen
from sparse_scenes import box_faces, detect_parts, table_surface, whole

from supportnode.geometry.objects.split import _split_touching
from supportnode.params import ObjectParams

TABLE = 0.75


def _book_with_a_box(box_on_top: bool):
    """A book's visible top (24 x 17 cm, 3.5 cm up) notched across most of its depth where a
    box stands on it: two lobes joined by a strip. Label 0: the book; 1: the box's points
    (its top and sides, from 3.5 to 8.5 cm), when ``box_on_top``."""
    g = np.arange(0.0, 0.24, 0.004)
    x, y = np.meshgrid(g, g[:43])
    top = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, 0.035)])
    under = (np.abs(top[:, 0] - 0.12) < 0.04) & (top[:, 1] > 0.03)
    book = top[~under]
    if not box_on_top:
        return book, np.zeros(len(book), np.int64)
    box = np.concatenate([top[under] + [0.0, 0.0, 0.05], top[under] + [0.0, 0.0, 0.002]])
    pts = np.concatenate([book, box])
    return pts, np.r_[np.zeros(len(book)), np.ones(len(box))].astype(np.int64)


def _parts_of_book(box_on_top: bool) -> int:
    pts, lab = _book_with_a_box(box_on_top)
    stats = {"merged_splits": 0, "split_parts": 0, "step_splits": 0, "concave_splits": 0}
    out = _split_touching(pts, lab, ObjectParams(), stats)
    return len(np.unique(out[lab == 0]))


def test_a_notch_is_a_neck_when_nothing_stands_in_it():
    assert _parts_of_book(False) == 2


def test_what_stands_on_a_cluster_fills_its_notch():
    assert _parts_of_book(True) == 1


def _parts_of_shadowed_book(origin):
    """A block in front of a book (24 x 30 cm) hides a band across most of the book's top
    from the sensor at (-0.6, 0.15, 0.6): the top seen is two lobes joined by a 4 cm strip at
    its far end. Label 0: the book; 1: the block's front face."""
    sensor = np.array([-0.6, 0.15, 0.6])
    lo, hi = np.array([-0.06, 0.1, -0.035]), np.array([-0.02, 0.2, 0.165])
    x, y = np.meshgrid(np.arange(0.0, 0.24, 0.004), np.arange(0.0, 0.3, 0.004))
    top = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    top = top[seen(top, sensor, lo, hi)]
    yy, zz = np.meshgrid(np.arange(0.1, 0.2, 0.004), np.arange(-0.03, 0.165, 0.004))
    front = np.column_stack([np.full(yy.size, -0.06), yy.ravel(), zz.ravel()])
    pts = np.concatenate([top, front])
    lab = np.r_[np.zeros(len(top)), np.ones(len(front))].astype(np.int64)
    stats = {"merged_splits": 0, "split_parts": 0, "step_splits": 0, "concave_splits": 0}
    out = _split_touching(pts, lab, ObjectParams(), stats, origin=origin)
    return len(np.unique(out[lab == 0]))


def test_a_shadow_across_a_flat_top_is_no_neck():
    assert _parts_of_shadowed_book(None) == 2  # the sensor unknown: a neck
    assert _parts_of_shadowed_book(np.array([-0.6, 0.15, 0.6])) == 1


@pytest.mark.parametrize("seed", range(4))
def test_a_box_sides_go_with_its_top_at_a_step(seed):
    """Boxes 14 and 10 cm tall face to face, sampled every ~1.4 cm (a sampled map): a fine
    cell of the tall box's far side holds no top, and its highest side point may match the
    low box's level; it goes with the box whose top its coarse cell holds."""
    rng = np.random.default_rng(seed)
    tall = box_faces((-0.5, -0.24, TABLE), (-0.34, -0.12, TABLE + 0.14), rng, 0.014)
    low = box_faces((-0.5, -0.12, TABLE), (-0.34, -0.02, TABLE + 0.10), rng, 0.014)
    low = low[low[:, 1] > -0.12 + 1e-9]
    # The faces in contact are hidden; the tall box's face shows above the low box.
    tall = tall[(tall[:, 1] < -0.12 - 1e-9) | (tall[:, 2] > TABLE + 0.10)]
    res, (a, b) = detect_parts([tall, low], table_surface(TABLE))
    assert res.stats["step_splits"] == 1
    assert whole(a) != whole(b)
    assert np.mean(a == whole(a)) > 0.96 and np.mean(b == whole(b)) > 0.9
