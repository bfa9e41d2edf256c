"""An object's foot taken from the table's band, raised patches given out, stacks cut."""

from __future__ import annotations

import numpy as np

from supportnode.geometry.objects.feet import claim_feet, claim_raised
from supportnode.geometry.objects.stacks import cut_stacks


def _grid(lo, hi, step, z):
    x, y = np.meshgrid(np.arange(lo[0], hi[0], step), np.arange(lo[1], hi[1], step))
    return np.c_[x.ravel(), y.ravel(), np.full(x.size, z)]


def test_band_points_under_an_object_s_foot_go_to_it():
    """A box's front face comes down to the table at x = 0: the band points in its columns
    are its foot; the table in front of it (x < 0) and far from it stays the table's."""
    face = _grid([0.0, 0.0], [0.002, 0.1], 0.002, 0.0)
    face = np.concatenate([face + [0, 0, z] for z in np.arange(0.004, 0.1, 0.002)])
    band = _grid([-0.05, 0.0], [0.01, 0.1], 0.002, 0.001)
    height = np.array([0.0])
    owner = claim_feet(
        band, np.zeros(len(band), np.int64), height, face, np.zeros(len(face), np.int64),
        np.zeros(len(face), np.int64), height, 0.005, 0.015,
    )  # fmt: skip
    under = band[:, 0] >= 0.0
    assert (owner[under & (band[:, 0] < 0.004)] == 0).all()
    assert (owner[band[:, 0] < -0.01] == -1).all()


def test_no_foot_where_the_object_stays_high_above_the_table():
    """A chair seat 45 cm up does not take the floor under it."""
    seat = _grid([0.0, 0.0], [0.4, 0.4], 0.01, 0.45)
    floor = _grid([0.0, 0.0], [0.4, 0.4], 0.01, 0.0)
    height = np.array([0.0])
    owner = claim_feet(
        floor, np.zeros(len(floor), np.int64), height, seat, np.zeros(len(seat), np.int64),
        np.zeros(len(seat), np.int64), height, 0.01, 0.015,
    )  # fmt: skip
    assert (owner == -1).all()
    assert (claim_feet(floor, np.zeros(len(floor), np.int64), height, seat[:0],
                       np.zeros(0, np.int64), np.zeros(0, np.int64), height, 0.01, 0.015)
            == -1).all()  # fmt: skip


def test_a_raised_patch_goes_to_the_object_ringing_it_or_stands_alone():
    """A pot's inner bottom (a raised patch ringed by its wall) goes to the pot; a sheet
    lying alone is an object of its own; a few raised points alone stay none."""
    angles = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    wall = np.c_[0.08 * np.cos(angles), 0.08 * np.sin(angles), np.full(200, 0.01)]
    wall = np.concatenate([wall + [0, 0, z] for z in (0.0, 0.02, 0.04)])
    bottom = _grid([-0.06, -0.06], [0.06, 0.06], 0.004, 0.005)
    bottom = bottom[np.hypot(bottom[:, 0], bottom[:, 1]) < 0.06]
    sheet = _grid([0.5, 0.5], [0.6, 0.6], 0.004, 0.003)
    specks = np.array([[1.0, 1.0, 0.003], [1.0, 1.004, 0.003]])
    xyz = np.concatenate([bottom, sheet, specks])
    owner = np.full(len(xyz), -1, np.int64)
    out = claim_raised(
        xyz, owner, np.ones(len(xyz), bool), wall, np.full(len(wall), 3, np.int64),
        0.01, 0.045, 30,
    )  # fmt: skip
    nb, ns = len(bottom), len(sheet)
    assert (out[:nb] == 3).all()
    assert (out[nb : nb + ns] == 4).all()  # a new object, after the labels given
    assert (out[nb + ns :] == -1).all()


def _box_cells(lo, hi, step):
    """Cell centroids on the visible faces (top, front -y, side -x) of a box."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    top = _grid(lo[:2], hi[:2], step, hi[2])
    xs, zs = np.meshgrid(np.arange(lo[0], hi[0], step), np.arange(lo[2], hi[2], step))
    front = np.c_[xs.ravel(), np.full(xs.size, lo[1]), zs.ravel()]
    ys, zs = np.meshgrid(np.arange(lo[1], hi[1], step), np.arange(lo[2], hi[2], step))
    side = np.c_[np.full(ys.size, lo[0]), ys.ravel(), zs.ravel()]
    return [top, front, side]


def _stack_inputs(upper_lo, upper_hi):
    """One segment holding a 10 cm box and a box standing on it (faces numbered)."""
    faces = _box_cells([0, 0, 0], [0.2, 0.16, 0.1], 0.01) + _box_cells(upper_lo, upper_hi, 0.01)
    centroid = np.concatenate(faces)
    face = np.concatenate([np.full(len(f), k) for k, f in enumerate(faces)])
    up = np.array([1.0, 0, 0, 1.0, 0, 0])
    # Adjacent cells: within one cell and a half.
    d = np.linalg.norm(centroid[:, None] - centroid[None], axis=2)
    src, dst = np.nonzero(np.triu((d > 0) & (d <= 0.015)))
    return centroid, face, up, src, dst


def test_a_box_standing_on_a_box_is_cut_from_it():
    centroid, face, up, src, dst = _stack_inputs([0.04, 0.04, 0.1], [0.16, 0.13, 0.18])
    n = len(centroid)
    seg = cut_stacks(
        centroid, np.full(n, 10.0), centroid[:, 2], face, up, np.zeros(n, np.int64),
        src, dst, 0.006, 30,
    )  # fmt: skip
    upper = face >= 3
    assert len(np.unique(seg[upper & (centroid[:, 2] > 0.11)])) == 1
    assert seg[upper & (centroid[:, 2] > 0.11)][0] != seg[face == 0][0]
    assert (seg[face < 3] == 0).all()


def test_a_taller_box_beside_a_lower_one_is_not_cut():
    """A 14 cm box touching a 10 cm one from the side, fronts flush (one face): it goes on
    down beside the lower box's top, so nothing stands on that top."""
    faces = _box_cells([0, 0, 0], [0.1, 0.16, 0.1], 0.01)
    tall = _box_cells([0.1, 0.0, 0.0], [0.22, 0.16, 0.14], 0.01)
    tall[1] = np.concatenate([tall[1], faces[1]])  # the fronts flush: one face
    faces[1] = faces[1][:0]
    centroid = np.concatenate(faces + tall)
    face = np.concatenate([np.full(len(f), k) for k, f in enumerate(faces + tall)])
    up = np.array([1.0, 0, 0, 1.0, 0, 0])
    d = np.linalg.norm(centroid[:, None] - centroid[None], axis=2)
    src, dst = np.nonzero(np.triu((d > 0) & (d <= 0.015)))
    n = len(centroid)
    seg = cut_stacks(
        centroid, np.full(n, 10.0), centroid[:, 2], face, up, np.zeros(n, np.int64),
        src, dst, 0.006, 30,
    )  # fmt: skip
    assert (seg == 0).all()
