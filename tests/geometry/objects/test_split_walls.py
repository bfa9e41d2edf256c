"""Touching objects of one height parted where their walls meet in a crease (a sparse cloud:
split_concave._split_walls), and single objects left whole."""

from __future__ import annotations

import numpy as np
import pytest
from sparse_scenes import box_faces, detect_parts, table_surface, whole

TABLE = 0.75


def _can(cx: float, cy: float, r: float, h: float, spacing: float, rng) -> np.ndarray:
    """(P, 3) points uniformly on the side and top of an upright cylinder on the table,
    about one per spacing^2 (m)."""
    n_side = rng.poisson(2 * np.pi * r * h / spacing**2)
    a = rng.uniform(0, 2 * np.pi, n_side)
    side = np.c_[cx + r * np.cos(a), cy + r * np.sin(a), TABLE + rng.uniform(0, h, n_side)]
    n_top = rng.poisson(np.pi * r * r / spacing**2)
    rho, b = r * np.sqrt(rng.uniform(0, 1, n_top)), rng.uniform(0, 2 * np.pi, n_top)
    top = np.c_[cx + rho * np.cos(b), cy + rho * np.sin(b), np.full(n_top, TABLE + h)]
    return np.concatenate([side, top])


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("gap", [0.003, 0.01])
def test_two_cans_a_few_mm_apart_are_two(seed, gap):
    """Cans 6.6 cm wide, 3 mm or 1 cm apart, sampled every ~8 mm: the footprint raster closes
    the gap (no neck), both tops are at one height (no step), the tops join across it."""
    rng = np.random.default_rng(seed)
    r = 0.033
    a = _can(0.0, 0.0, r, 0.12, 0.008, rng)
    b = _can(0.0, 2 * r + gap, r, 0.12, 0.008, rng)
    res, labs = detect_parts([a, b], table_surface(TABLE))
    assert res.stats["wall_splits"] == 1
    owners = [np.bincount(lab[lab >= 0]).argmax() for lab in labs]
    assert owners[0] != owners[1]
    # Where the walls meet, points go to the nearest wall seed: most of each can is its own.
    for lab, k in zip(labs, owners, strict=True):
        assert np.mean(lab == k) > 0.65


@pytest.mark.parametrize("seed", range(4))
def test_three_barrels_in_a_triangle_in_a_sparse_cloud_are_three(seed):
    rng = np.random.default_rng(seed)
    r = 0.06
    centres = [(-r, 0.0), (r, 0.0), (0.0, r * np.sqrt(3.0))]
    barrels = [_can(x, y, r, 0.18, 0.014, rng) for x, y in centres]
    _, labs = detect_parts(barrels, table_surface(TABLE))
    owners = [np.bincount(lab[lab >= 0]).argmax() for lab in labs]
    assert len(set(owners)) == 3
    for lab, k in zip(labs, owners, strict=True):  # most of each barrel is its own
        assert np.mean(lab == k) > 0.75


def _ell(rng) -> np.ndarray:
    """An L-shaped box (two 40 x 15 cm arms, 20 cm tall) without the faces hidden inside it."""
    parts = [
        ((0.0, 0.0, TABLE), (0.4, 0.15, TABLE + 0.2)),
        ((0.0, 0.0, TABLE), (0.15, 0.4, TABLE + 0.2)),
    ]
    pts = np.concatenate([box_faces(lo, hi, rng, 0.014) for lo, hi in parts])
    hidden = np.zeros(len(pts), dtype=bool)
    for lo, hi in parts:
        hidden |= ((pts > np.add(lo, 1e-3)) & (pts < np.subtract(hi, 1e-3))).all(axis=1)
    return pts[~hidden]


@pytest.mark.parametrize("seed", range(6))
def test_single_sparse_objects_stay_whole(seed):
    """A box, a can, a wide drum and an L-shaped box, sampled every 1.4-2 cm: sparse voxels
    and noisy normals break their walls, but the pieces meet in no crease."""
    rng = np.random.default_rng(seed)
    objects = [
        box_faces((-0.6, -0.1, TABLE), (-0.4, 0.1, TABLE + 0.25), rng, 0.02),
        _can(0.0, -0.5, 0.033, 0.12, 0.014, rng),
        _can(0.5, 0.5, 0.15, 0.3, 0.014, rng),
        _ell(rng) + [0.0, 0.0, 0.0],
    ]
    res, labs = detect_parts(objects, table_surface(TABLE))
    assert len({whole(lab) for lab in labs}) == 4
    assert res.stats["wall_splits"] == 0


@pytest.mark.parametrize("seed", range(3))
def test_a_sparse_chair_and_a_person_are_not_cut_at_their_legs(seed):
    """Legs are walls that stand on the floor apart from each other, joined above by a seat
    or a torso: they meet in no crease, so no part is cut off."""
    rng = np.random.default_rng(seed)
    legs = [
        box_faces((x, y, 0.0), (x + 0.03, y + 0.03, 0.43), rng, 0.02)
        for x in (0.0, 0.42)
        for y in (0.0, 0.42)
    ]
    seat = box_faces((0.0, 0.0, 0.43), (0.45, 0.45, 0.47), rng, 0.02)
    back = box_faces((0.0, 0.42, 0.47), (0.45, 0.45, 0.9), rng, 0.02)
    chair = np.concatenate([*legs, seat, back])
    person_legs = [_can(1.0, y, 0.07, 0.8, 0.025, rng) - [0.0, 0.0, TABLE] for y in (0.0, 0.18)]
    torso = box_faces((0.9, -0.08, 0.8), (1.1, 0.26, 1.5), rng, 0.025)
    res, (a, b) = detect_parts([chair, np.concatenate([*person_legs, torso])], table_surface(0.0))
    assert res.stats["wall_splits"] == 0 and res.stats["merged_splits"] == 0
    assert whole(a) != np.bincount(b[b >= 0]).argmax()
