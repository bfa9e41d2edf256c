"""Things lying on a surface, and what they leave of it: a cutting board or a plate (a raised
plateau, not the table), the foot of a small shelf unit (the board around it stays board)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_points, plane_points, table_legs

from supportnode.geometry.surfaces import detect_surfaces
from supportnode.params import SurfaceParams


def _flat_object(rng, shape, centre, height, top, density=25000.0):
    """A thin object lying on a surface at ``top``: a board (0.4 x 0.25 m, turned 10 deg) or
    a plate (radius 0.12 m), ``height`` thick; its top and rim at ``density`` points/m^2.
    Returns (points on it, a function telling which (P, 2) xy lie under it)."""
    if shape == "board":
        half, turn = np.array([0.2, 0.125]), np.radians(10.0)
        rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])

        def under(xy):
            return np.all(np.abs((xy - centre) @ rot) <= half, axis=1)

        u = rng.uniform(-1, 1, (int(density * 4 * half.prod()), 2)) * half
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
        rim = []
        for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True):
            k = int(density * np.linalg.norm(b - a) * height)
            rim.append(a + rng.uniform(0, 1, (k, 1)) * (b - a))
        top_xy, side_xy = u @ rot.T, np.vstack(rim) @ rot.T
    else:
        radius = 0.12

        def under(xy):
            return np.hypot(*(xy - centre).T) <= radius

        r = radius * np.sqrt(rng.uniform(0, 1, int(density * np.pi * radius**2)))
        a = rng.uniform(0, 2 * np.pi, len(r))
        top_xy = np.c_[r * np.cos(a), r * np.sin(a)]
        a = rng.uniform(0, 2 * np.pi, int(density * 2 * np.pi * radius * height))
        side_xy = radius * np.c_[np.cos(a), np.sin(a)]
    pts = np.vstack(
        [
            np.c_[top_xy + centre, np.full(len(top_xy), top + height)],
            np.c_[side_xy + centre, rng.uniform(top, top + height, len(side_xy))],
        ]
    )
    return pts, under


@pytest.mark.parametrize("shape", ["board", "plate"])
@pytest.mark.parametrize("top", [0.73, 0.75, 0.765])
def test_board_or_plate_lying_on_a_table_is_not_part_of_it(rng, shape, top):
    """A cutting board or a plate, 2 cm high, lies on a table: growth across height layers
    (within max_step) joins it to the table, but it is a raised plateau, not table."""
    floor = plane_points(rng, -1, 2.2, -1, 1.8, 0.0, 80000)
    table = plane_points(rng, 0, 1.2, 0, 0.8, top, 24000)
    centre = np.array([0.45, 0.4])
    obj, under = _flat_object(rng, shape, centre, 0.02, top)
    table = table[~under(table[:, :2])]
    legs = table_legs(rng, [(0.05, 0.05), (1.15, 0.05), (0.05, 0.75), (1.15, 0.75)], top - 0.02)
    pts = np.vstack([floor, table, obj, legs])
    on_obj = np.arange(len(floor) + len(table), len(floor) + len(table) + len(obj))
    on_table = np.arange(len(floor), len(floor) + len(table))
    res = detect_surfaces(pts)
    assert sorted(round(s.height, 2) for s in res.surfaces) == [0.0, round(top, 2)]
    assert res.stats["plateau_voxels"] > 0
    top_of_obj = on_obj[pts[on_obj, 2] > top + 0.015]
    assert (res.labels[top_of_obj] >= 0).mean() < 0.02
    assert (res.labels[on_table] >= 0).mean() > 0.97
    # Without the plateau test the object's top is table.
    joined = detect_surfaces(pts, SurfaceParams(plateau_min_step=0.0))
    assert (joined.labels[top_of_obj] >= 0).mean() > 0.5


@pytest.mark.parametrize("seed", range(12))
def test_a_plank_on_a_board_leaves_the_board_around_it_on_the_board(seed):
    """A small shelf unit's foot (a 1 cm plank, a panel on its edge) on a board: the voxels
    holding the board and the plank's edge fit planes tilted 5-9 deg, and the cluttered
    voxels beside them once took those planes, leaving the board 5-10 cm away unlabelled
    (and free to join the objects on it into one)."""
    rng = np.random.default_rng(seed)
    board = plane_points(rng, -0.6, 0.6, -0.2, 0.2, 0.8, 60000)
    cx, cy = 0.01 * seed, 0.01 + 0.01 * (seed % 5)  # across the voxel grid
    under = (np.abs(board[:, 0] - cx) <= 0.1) & (np.abs(board[:, 1] - cy) <= 0.075)
    board = board[~under]
    plank = box_points(rng, (cx, cy, 0.805), (0.2, 0.15, 0.01), 4000)
    panel = box_points(rng, (cx + 0.095, cy, 0.92), (0.01, 0.15, 0.22), 6000)
    res = detect_surfaces(np.r_[board, plank, panel], SurfaceParams())
    assert len(res.surfaces) == 1
    away = np.maximum(np.abs(board[:, 0] - cx) - 0.1, np.abs(board[:, 1] - cy) - 0.075) > 0.05
    assert (res.labels[: len(board)][away] == 0).all()
    assert (res.labels[len(board) + len(plank) :] < 0).mean() > 0.9  # the panel is no board
