"""Support surfaces on clouds built in the test: heights, areas, what must not be a surface."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_points, plane_points, table_legs
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.errors import InputError
from supportnode.geometry.surfaces import cells_outline, detect_surfaces
from supportnode.params import SurfaceParams


def _by_height(result, z, tol=0.01):
    return [s for s in result.surfaces if abs(s.height - z) < tol]


def test_floor_and_table_found_with_height_and_area(room):
    pts, truth = room
    res = detect_surfaces(pts)
    assert len(res.surfaces) == 2
    floor, table = res.surfaces  # largest first
    assert floor.height == pytest.approx(0.0, abs=1e-6)
    assert table.height == pytest.approx(0.73, abs=1e-6)
    assert floor.area == pytest.approx(4.04 * 4.07, rel=0.03)
    assert table.area == pytest.approx(1.0 * 0.7, rel=0.05)
    assert table.normal[2] == pytest.approx(1.0, abs=1e-6)
    assert [floor.id, table.id] == [0, 1]
    # Point labels: precise (nothing from walls, legs or the box) and nearly complete.
    on = res.labels >= 0
    assert on[truth == 3].mean() < 0.002  # wall: at most a few points at its very foot
    # Only the rim of the box and the leg tops within the 1 cm point tolerance of the table.
    assert on[truth == 2].mean() < 0.05 and on[truth == 4].mean() < 0.01
    assert np.isin(truth[on], [0, 1]).mean() > 0.995  # precision
    assert on[truth == 1].mean() > 0.97
    assert on[truth == 0].mean() > 0.97
    assert (res.labels == table.id).sum() == table.point_count


def test_wall_legs_and_object_top_are_not_surfaces(room):
    pts, _ = room
    res = detect_surfaces(pts)
    heights = sorted(round(s.height, 2) for s in res.surfaces)
    assert heights == [0.0, 0.73]  # no 0.93 box top, no wall rings, no leg tops


def test_seed_method_reproduces_the_report_false_positives(room):
    """Algorithm 1 as published has no flatness test: wall voxels of one layer grow into
    'surfaces'. This is the report's known error that the planar default removes."""
    pts, _ = room
    res = detect_surfaces(pts, SurfaceParams(method="seed", psi_min=10))
    assert len(_by_height(res, 0.0, 0.03)) >= 1
    assert len([s for s in _by_height(res, 0.73, 0.03) if s.normal[2] > 0.9]) == 1
    wall_like = [s for s in res.surfaces if abs(s.normal[2]) < 0.5]
    assert len(wall_like) >= 3


def test_seed_psi_min_and_p_min(rng):
    pts = plane_points(rng, 0, 0.5, 0, 0.5, 1.0, 5000)  # 25 voxels of 0.1 m
    assert len(detect_surfaces(pts, SurfaceParams(method="seed", psi_min=25)).surfaces) == 1
    assert len(detect_surfaces(pts, SurfaceParams(method="seed", psi_min=37)).surfaces) == 0
    assert len(detect_surfaces(pts, SurfaceParams(method="seed", p_min=1000)).surfaces) == 0


def test_seed_connectivity_4_vs_8(rng):
    # Two squares touching only at a corner: one region with 8-neighbours, two with 4.
    a = plane_points(rng, 0.0, 0.3, 0.0, 0.3, 0.5, 3000)
    b = plane_points(rng, 0.3, 0.6, 0.3, 0.6, 0.5, 3000)
    pts = np.vstack([a, b]) + [0.001, 0.001, 0.0]
    r8 = detect_surfaces(pts, SurfaceParams(method="seed", psi_min=5, connectivity=8))
    r4 = detect_surfaces(pts, SurfaceParams(method="seed", psi_min=5, connectivity=4))
    assert len(r8.surfaces) == 1 and len(r4.surfaces) == 2


def test_table_with_dip_is_one_surface(rng):
    """The report's table with a 2 cm dip in its middle gave false negatives; growing across
    height layers within max_step keeps it one surface."""
    frame = plane_points(rng, 0, 1.2, 0, 0.8, 0.75, 20000)
    inner = (np.abs(frame[:, 0] - 0.6) < 0.3) & (np.abs(frame[:, 1] - 0.4) < 0.2)
    frame[inner, 2] -= 0.02
    res = detect_surfaces(frame)
    assert len(res.surfaces) == 1
    assert (res.labels >= 0).mean() > 0.97


def test_slightly_sloped_table_is_a_surface_and_a_ramp_is_not(rng):
    def tilted(deg, n):
        p = plane_points(rng, 0, 1.0, 0, 1.0, 0.0, n)
        p[:, 2] = 0.7 + np.tan(np.radians(deg)) * p[:, 0]
        return p

    assert len(detect_surfaces(tilted(3, 20000)).surfaces) == 1
    assert len(detect_surfaces(tilted(15, 20000)).surfaces) == 0
    assert len(detect_surfaces(tilted(15, 20000), SurfaceParams(max_tilt_deg=20)).surfaces) == 1


def test_thin_rail_is_rejected_by_min_width(rng):
    rail = plane_points(rng, 0, 3.0, 0, 0.06, 0.9, 6000)  # 3 m long wall top, 6 cm wide
    seat = plane_points(rng, 5, 5.45, 0, 0.45, 0.45, 6000)
    res = detect_surfaces(np.vstack([rail, seat]))
    assert [round(s.height, 2) for s in res.surfaces] == [0.45]
    loose = detect_surfaces(np.vstack([rail, seat]), SurfaceParams(min_width=0.0))
    assert len(loose.surfaces) == 2


def test_min_area_in_square_metres(rng):
    small = plane_points(rng, 0, 0.25, 0, 0.25, 0.4, 3000)
    assert len(detect_surfaces(small, SurfaceParams(min_area=0.05)).surfaces) == 1
    assert len(detect_surfaces(small, SurfaceParams(min_area=0.1)).surfaces) == 0


def test_stacked_shelf_boards_are_separate(rng):
    boards = [plane_points(rng, 0, 0.8, 0, 0.35, z, 6000) for z in (0.3, 0.6, 0.9)]
    res = detect_surfaces(np.vstack(boards))
    assert sorted(round(s.height, 2) for s in res.surfaces) == [0.3, 0.6, 0.9]


def test_invariant_to_point_order(room):
    pts, _ = room
    perm = np.random.default_rng(7).permutation(len(pts))
    a = detect_surfaces(pts)
    b = detect_surfaces(pts[perm])
    assert np.array_equal(a.labels[perm], b.labels)
    assert [s.to_dict() for s in a.surfaces] == [s.to_dict() for s in b.surfaces]


@pytest.mark.parametrize("shift", [(0.037, -0.013), (10.5, 3.25), (-101.01, 55.555)])
def test_invariant_to_horizontal_translation(room, shift):
    pts, _ = room
    a = detect_surfaces(pts)
    b = detect_surfaces(pts + [shift[0], shift[1], 0.0])
    assert len(a.surfaces) == len(b.surfaces)
    for sa, sb in zip(a.surfaces, b.surfaces, strict=True):
        assert sb.height == pytest.approx(sa.height, abs=1e-6)
        assert sb.area == pytest.approx(sa.area, rel=0.05)
        assert sb.centroid[:2] == pytest.approx(sa.centroid[:2] + shift, abs=0.03)
    agree = (a.labels >= 0) == (b.labels >= 0)
    assert agree.mean() > 0.98


def test_outline_of_table_and_hole():
    # 5x5 cells with the middle cell missing: one CCW outer ring and one CW hole.
    cells = np.array([(i, j) for i in range(5) for j in range(5) if (i, j) != (2, 2)])
    rings = cells_outline(cells, (0.1, 0.1))
    assert len(rings) == 2
    outer, hole = rings
    assert sorted(map(tuple, np.round(outer, 6))) == [(0, 0), (0, 0.5), (0.5, 0), (0.5, 0.5)]

    def area(r):
        x, y = r[:, 0], r[:, 1]
        return 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))

    assert area(outer) == pytest.approx(0.25)
    assert area(hole) == pytest.approx(-0.01)


def test_surface_to_dict_is_json_ready(room):
    import json

    res = detect_surfaces(room[0])
    d = json.loads(json.dumps(res.surfaces[1].to_dict()))
    for key in (
        "id",
        "height",
        "area",
        "centroid",
        "normal",
        "flatness",
        "bbox_min",
        "bbox_max",
        "outline",
        "point_count",
        "voxel_count",
    ):
        assert key in d


@pytest.mark.parametrize(
    "bad", [np.zeros((10, 2)), np.array([[0.0, 0.0, np.nan]]), np.zeros((3, 3, 3))]
)
def test_bad_points_raise_input_error(bad):
    with pytest.raises(InputError):
        detect_surfaces(bad)


def test_empty_cloud_gives_no_surfaces():
    res = detect_surfaces(np.zeros((0, 3)))
    assert res.surfaces == [] and res.labels.shape == (0,)


def test_box_on_floor_top_not_surface_but_floor_is(rng):
    floor = plane_points(rng, 0, 2, 0, 2, 0.0, 30000)
    box = box_points(rng, (1.0, 1.0, 0.15), (0.2, 0.2, 0.3), 4000)
    res = detect_surfaces(np.vstack([floor, box]))
    assert [round(s.height, 3) for s in res.surfaces] == [0.0]


def test_underside_seen_from_below_is_not_a_surface(rng):
    board = plane_points(rng, 0, 1.0, 0, 0.4, 1.6, 8000)  # a high shelf board
    floor = plane_points(rng, -1, 2, -1, 2, 0.0, 30000)
    pts = np.vstack([board, floor])
    assert len(detect_surfaces(pts).surfaces) == 2  # no sensor given: cannot tell
    res = detect_surfaces(pts, sensor_origin=np.array([0.5, -1.0, 1.2]))
    assert [round(s.height, 2) for s in res.surfaces] == [0.0]
    assert (res.labels[: len(board)] == -1).all()


def test_sparse_scan_lines_on_a_ramp_are_not_a_surface():
    """One lidar ring per voxel on a 15 degree ramp looks level voxel by voxel; the plane fitted
    to the whole region does not."""
    x = np.linspace(0, 2.0, 400)
    rings = []
    for y in np.arange(0.0, 1.5, 0.11):  # rings 11 cm apart, each along a contour
        rings.append(np.c_[x, np.full_like(x, y), np.full_like(x, np.tan(np.radians(15)) * y)])
    assert detect_surfaces(np.vstack(rings), SurfaceParams(max_step=0.04)).surfaces == []


def test_outline_rings_corner_touching_and_l_shape():
    rings = cells_outline(np.array([[0, 0], [1, 1]]), (1.0, 1.0))
    assert len(rings) == 2  # cells meeting at a corner: two separate rings
    (l_shape,) = cells_outline(np.array([[0, 0], [1, 0], [0, 1]]), (0.5, 0.5))
    assert len(l_shape) == 6
    x, y = l_shape[:, 0], l_shape[:, 1]
    assert 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) == pytest.approx(0.75)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(st.integers(-3, 40), st.integers(-50, 300)), min_size=1, max_size=120),
)
def test_outline_rings_enclose_exactly_the_cells(cell_list):
    """Signed ring areas add up to the cells' area for any footprint: boundaries minus holes,
    corner-touching cells, tall and wide shapes alike."""
    cells = np.unique(np.array(cell_list, dtype=np.int64), axis=0)
    rings = cells_outline(cells, (0.1, 0.2))

    def area(r):
        x, y = r[:, 0], r[:, 1]
        return 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))

    assert sum(area(r) for r in rings) == pytest.approx(len(cells) * 0.02)
    assert all(len(r) >= 4 for r in rings)


def test_normal_filter_removes_the_seed_methods_false_positives(room):
    """The report's option: with normals checked (on candidate points only), Algorithm 1 no
    longer reports wall strips or leg tops, and still finds floor and table."""
    pts, truth = room
    plain = detect_surfaces(pts, SurfaceParams(method="seed"))
    filtered = detect_surfaces(pts, SurfaceParams(method="seed", normal_filter=True))
    assert filtered.stats["normal_filter_removed"] > 0
    assert (filtered.labels[truth == 3] >= 0).mean() < 0.2 * (plain.labels[truth == 3] >= 0).mean()
    heights = sorted(round(s.height, 2) for s in filtered.surfaces if s.point_count > 1000)
    assert heights == [0.0, 0.73]


def _without(pts, x0, x1, y0, y1):
    """Points outside the horizontal rectangle: what a solid box standing there hides."""
    inside = (pts[:, 0] > x0) & (pts[:, 0] < x1) & (pts[:, 1] > y0) & (pts[:, 1] < y1)
    return pts[~inside]


def test_top_of_a_box_on_a_table_is_an_object_not_a_surface(rng):
    """A microwave-sized box (0.5 x 0.4 m, 0.3 m tall) on a table: its top is flat and big
    enough for min_area, but the table is hidden under it and it is low above the table."""
    floor = plane_points(rng, -1.5, 2.5, -1.5, 2.0, 0.0, 60000)
    table = _without(plane_points(rng, 0, 1.2, 0, 0.8, 0.75, 24000), 0.3, 0.8, 0.2, 0.6)
    box = box_points(rng, (0.55, 0.4, 0.9), (0.5, 0.4, 0.3), 12000)
    legs = table_legs(rng, [(0.05, 0.05), (1.15, 0.05), (0.05, 0.75), (1.15, 0.75)], 0.73)
    pts = np.vstack([floor, table, box, legs])
    res = detect_surfaces(pts)
    assert sorted(round(s.height, 2) for s in res.surfaces) == [0.0, 0.75]
    top = np.arange(len(pts))[len(floor) + len(table) : len(floor) + len(table) + len(box)]
    assert (res.labels[top[pts[top, 2] > 1.0]] == -1).all()
    off = detect_surfaces(pts, SurfaceParams(object_top_max_area=0.0))
    assert sorted(round(s.height, 2) for s in off.surfaces) == [0.0, 0.75, 1.05]
    # Higher above the table than object_top_max_height: a surface again.
    low = detect_surfaces(pts, SurfaceParams(object_top_max_height=0.25))
    assert sorted(round(s.height, 2) for s in low.surfaces) == [0.0, 0.75, 1.05]


def test_small_low_table_with_floor_seen_under_it_is_a_surface(rng):
    """A side table (0.45 x 0.45 m at 0.45 m) is as small and low as a box top, but the floor
    shows under it between its legs."""
    floor = plane_points(rng, -1, 1.5, -1, 1.5, 0.0, 40000)
    top = plane_points(rng, 0, 0.45, 0, 0.45, 0.45, 6000)
    legs = table_legs(rng, [(0.03, 0.03), (0.42, 0.03), (0.03, 0.42), (0.42, 0.42)], 0.43)
    res = detect_surfaces(np.vstack([floor, top, legs]))
    assert sorted(round(s.height, 2) for s in res.surfaces) == [0.0, 0.45]


def test_low_shelf_board_with_floor_partly_seen_below_is_a_surface(rng):
    """A bench or bottom shelf board (1.0 x 0.35 m at 0.4 m) between side panels, in front of
    a wall: a sensor in front sees the floor under its front half only."""
    floor = _without(plane_points(rng, -1, 2, -1.5, 0.35, 0.0, 50000), 0, 1.0, 0.17, 0.35)
    board = plane_points(rng, 0, 1.0, 0, 0.35, 0.4, 8000)
    sides = [
        np.c_[np.full(3000, x), rng.uniform(0, 0.35, 3000), rng.uniform(0, 0.8, 3000)]
        for x in (-0.01, 1.01)
    ]
    wall = np.c_[rng.uniform(-1, 2, 8000), np.full(8000, 0.36), rng.uniform(0, 1.5, 8000)]
    res = detect_surfaces(np.vstack([floor, board, *sides, wall]))
    assert sorted(round(s.height, 2) for s in res.surfaces) == [0.0, 0.4]


def test_box_top_that_holds_something_stays_a_surface(rng):
    """The same box with a tin standing on it, beside a wall taller than the box: something
    stands there, so it is a place to put things (a cabinet on a desk); the wall rising beside
    a bare box does not count as a load."""
    floor = plane_points(rng, -1.5, 2.5, -1.5, 2.0, 0.0, 60000)
    table = _without(plane_points(rng, 0, 1.2, 0, 0.8, 0.75, 24000), 0.3, 0.8, 0.2, 0.6)
    box = box_points(rng, (0.55, 0.4, 0.9), (0.5, 0.4, 0.3), 12000)
    legs = table_legs(rng, [(0.05, 0.05), (1.15, 0.05), (0.05, 0.75), (1.15, 0.75)], 0.73)
    wall = np.c_[rng.uniform(-0.5, 1.7, 15000), np.full(15000, 0.61), rng.uniform(0.75, 2.0, 15000)]
    bare = detect_surfaces(np.vstack([floor, table, box, legs, wall]))
    assert sorted(round(s.height, 2) for s in bare.surfaces) == [0.0, 0.75]
    t = rng.uniform(0, 2 * np.pi, 1500)
    tin = np.c_[0.5 + 0.04 * np.cos(t), 0.4 + 0.04 * np.sin(t), rng.uniform(1.06, 1.2, 1500)]
    loaded = detect_surfaces(np.vstack([floor, table, box, legs, wall, tin]))
    assert sorted(round(s.height, 2) for s in loaded.surfaces) == [0.0, 0.75, 1.05]


def test_box_top_with_a_box_on_it_is_no_surface(rng):
    """A 12 cm box on a table with a smaller box standing on it (a stack, as mOSD labels
    it): two objects, so neither top is a surface; the loaded-top rule is furniture's."""
    floor = plane_points(rng, -1.5, 2.5, -1.5, 2.0, 0.0, 60000)
    table = _without(plane_points(rng, 0, 1.2, 0, 0.8, 0.75, 24000), 0.4, 0.7, 0.25, 0.55)
    legs = table_legs(rng, [(0.05, 0.05), (1.15, 0.05), (0.05, 0.75), (1.15, 0.75)], 0.73)
    lower = box_points(rng, (0.55, 0.4, 0.81), (0.3, 0.3, 0.12), 12000)
    upper = box_points(rng, (0.55, 0.4, 0.91), (0.15, 0.12, 0.08), 4000)
    upper = upper[upper[:, 2] > 0.872]  # its bottom face lies on the lower box, hidden
    res = detect_surfaces(np.vstack([floor, table, legs, lower, upper]))
    assert sorted(round(s.height, 2) for s in res.surfaces) == [0.0, 0.75]


def test_warped_table_and_table_with_small_dip_stay_whole(rng):
    """Smooth warps predict their neighbours: no step, nothing cut out. A dip is lower than
    the table around it: not an object lying on it."""
    warped = plane_points(rng, 0, 1.2, 0, 0.8, 0.75, 24000)
    warped[:, 2] += 0.02 * np.sin(np.pi * warped[:, 0] / 1.2) * np.sin(np.pi * warped[:, 1] / 0.8)
    dipped = plane_points(rng, 3, 4.2, 0, 0.8, 0.75, 24000)
    dip = np.hypot(dipped[:, 0] - 3.6, dipped[:, 1] - 0.4) < 0.15
    dipped[dip, 2] -= 0.02
    for pts in (warped, dipped):
        res = detect_surfaces(pts)
        assert len(res.surfaces) == 1
        assert (res.labels >= 0).mean() > 0.97


@pytest.mark.parametrize(("deg", "max_tilt"), [(6, 10.0), (8, 10.0), (10, 20.0)])
def test_gentle_ramp_joined_to_a_floor_stays_whole(rng, deg, max_tilt):
    """A ramp up to a landing: its voxels are tilted but each predicts the next; the landing
    at its top is no plateau lying on it."""
    floor = plane_points(rng, -1, 0, 0, 1.0, 0.0, 25000)
    ramp = plane_points(rng, 0, 1.2, 0, 1.0, 0.0, 30000)
    ramp[:, 2] = np.tan(np.radians(deg)) * ramp[:, 0]
    landing = plane_points(rng, 1.2, 1.45, 0, 1.0, np.tan(np.radians(deg)) * 1.2, 6000)
    pts = np.vstack([floor, ramp, landing])
    res = detect_surfaces(pts, SurfaceParams(max_tilt_deg=max_tilt))
    assert len(res.surfaces) == 1
    assert (res.labels >= 0).mean() > 0.97
