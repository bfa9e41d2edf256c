"""Clusters split at the necks of their footprints (split.py), and what stands on them."""

from __future__ import annotations

import numpy as np

from supportnode.geometry.objects.split import _split_touching
from supportnode.params import ObjectParams


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
