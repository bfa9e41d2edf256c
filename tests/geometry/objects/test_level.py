"""Points at a table's own level (level.py): a sparse cloud's table points left beside the
objects' feet never join two objects, and go back to the object they lie against."""

from __future__ import annotations

import numpy as np
import pytest
from sparse_scenes import box_faces, detect_parts, table_surface, whole

from supportnode.geometry.objects.level import LEVEL, nearest_object_point, set_aside
from supportnode.geometry.surfaces import Surface

TABLE = 0.75
SPACING = 0.012  # a sparsely sampled scene: a handful of points per 3 cm voxel


def _table(normal=(0.0, 0.0, 1.0), band=(0.0, 0.01)) -> Surface:
    return table_surface(TABLE, normal, band)


def _box(lo, hi, rng) -> np.ndarray:
    return box_faces(lo, hi, rng, SPACING)


def _table_around(boxes, width: float, rng, dz: float = 0.0) -> np.ndarray:
    """Table points within ``width`` of the boxes' feet, not under them: the surface leaves
    them out (their voxels hold the boxes' feet), so they reach the objects as candidates."""
    lo = np.min([b[0][:2] for b in boxes], axis=0) - width
    hi = np.max([b[1][:2] for b in boxes], axis=0) + width
    xy = rng.uniform(lo, hi, (rng.poisson(np.prod(hi - lo) / SPACING**2), 2))
    under = np.zeros(len(xy), bool)
    for b_lo, b_hi in boxes:
        under |= np.all((xy >= np.asarray(b_lo[:2])) & (xy <= np.asarray(b_hi[:2])), axis=1)
    xy = xy[~under]
    return np.c_[xy, TABLE + rng.uniform(-dz, dz, len(xy))]


def _detect(parts: list[np.ndarray], table: Surface):
    return detect_parts(parts, table)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_table_between_two_boxes_does_not_join_them(seed):
    # 5 cm apart, the table between them left to the objects: the 3 cm voxels chain
    # through it and, filled in, it leaves their joint footprint no neck to cut.
    rng = np.random.default_rng(seed)
    boxes = [
        ((-0.1, -0.05, TABLE), (0.0, 0.05, TABLE + 0.1)),
        ((0.05, -0.05, TABLE), (0.15, 0.05, TABLE + 0.1)),
    ]
    table = _table_around(boxes, 0.04, rng, dz=0.002)
    res, (a, b, t) = _detect([*(_box(lo, hi, rng) for lo, hi in boxes), table], _table())
    ia, ib = whole(a), whole(b)
    assert ia != ib
    assert len(res.clusters) == 2
    # A table point goes to a box it lies against (beside one box, that one), or to none.
    given = t >= 0
    assert 0 < given.sum() < len(t)
    assert set(t[given & (table[:, 0] < 0.0)]) == {ia}
    assert set(t[given & (table[:, 0] > 0.05)]) == {ib}
    assert res.stats["level_points"] >= len(table)  # and the boxes' lowest 3 mm


def test_over_a_depth_cameras_band_nothing_is_set_aside():
    rng = np.random.default_rng(2)
    box = ((-0.05, -0.05, TABLE), (0.05, 0.05, TABLE + 0.1))
    parts = [_box(*box, rng), _table_around([box], 0.03, rng)]
    res, _ = _detect(parts, _table(band=(2.5, 0.002)))
    assert res.stats["level_points"] == 0


def test_a_small_objects_feet_count_towards_its_size():
    # 25 points above the table's level and 10 at it: 35 >= min_points (30), one object.
    rng = np.random.default_rng(3)
    above = np.c_[rng.uniform(-0.02, 0.02, (25, 2)), rng.uniform(TABLE + 0.01, TABLE + 0.05, 25)]
    feet = np.c_[rng.uniform(-0.02, 0.02, (10, 2)), np.full(10, TABLE + 0.001)]
    res, (a, f) = _detect([above, feet], _table())
    assert len(res.clusters) == 1
    assert (a == 0).all() and (f == 0).all()


def test_the_level_follows_a_tilted_plane():
    table = _table(normal=(0.1, 0.0, 1.0))
    x = np.array([-0.5, 0.0, 0.5, 0.5, 0.3])
    plane = TABLE - 0.1 * x
    cp = np.c_[x, np.zeros(5), plane + np.array([0.0, 0.002, 0.01, -0.001, 0.02])]
    support = np.array([0, 0, 0, -1, 0])
    kept, kept_cp, kept_support, bottom, level = set_aside(
        np.arange(5), cp, support, [table], 0.015
    )
    assert level.tolist() == [0, 1]  # within LEVEL of the plane, over the table
    assert kept.tolist() == [2, 3, 4] and np.array_equal(kept_cp, cp[2:])
    assert kept_support.tolist() == [0, -1, 0]
    assert bottom.tolist() == [0]  # 1 cm up: an object's bottom; 2 cm: beyond LEVEL + reach
    assert LEVEL < 0.01


def test_nearest_object_point_within_reach_only():
    obj = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    q = np.array([[0.02, 0.0, 0.0], [1.0, 0.0, 0.0], [1.97, 0.0, 0.0], [5.0, 0.0, 0.0]])
    assert nearest_object_point(q, obj, 0.05).tolist() == [0, -1, 1, -1]
    assert nearest_object_point(q[:0], obj, 0.05).shape == (0,)
    assert nearest_object_point(q, obj[:0], 0.05).tolist() == [-1] * 4


def test_candidates_all_at_the_tables_level_make_no_object():
    # A sheet of paper on the table, left out by the surface: nothing to stand, no error.
    rng = np.random.default_rng(4)
    sheet = np.c_[rng.uniform(-0.1, 0.1, (200, 2)), TABLE + rng.uniform(-0.002, 0.002, 200)]
    res, (lab,) = _detect([sheet], _table())
    assert res.clusters == [] and (lab == -1).all()
    assert res.stats["level_points"] == len(sheet)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_box_past_the_end_of_the_grown_table_is_one_object_on_it(seed):
    # The table's region growing stopped at x = 0 (a strip of it beside clutter), but the
    # table goes on at its level to x = 0.4, and a box stands across that end, 20 cm past it:
    # over the table throughout, not cut in two where the grown footprint ends.
    import dataclasses

    rng = np.random.default_rng(seed)
    grown = _table(band=(0.0, 0.0))
    grown = dataclasses.replace(grown, cells=grown.cells[grown.cells[:, 0] < 0])
    box = ((-0.1, -0.05, TABLE), (0.2, 0.05, TABLE + 0.1))
    table = _table_around([box], 0.2, rng)
    table = table[table[:, 0] >= 0.0]  # the table left to the objects: past the grown part
    res, (b, t) = _detect([_box(*box, rng), table], grown)
    ib = whole(b)
    assert len(res.clusters) == 1
    assert res.clusters[ib].surface_id == 0
    assert (t == -1).mean() > 0.5  # the table's own points are no object
