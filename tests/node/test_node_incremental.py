"""Incremental detection (the changed region, or the previous result of an unchanged map)
equals a full recompute scan by scan, on moving, standing and noisy sequences."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import box_points, plane_points

from supportnode.client import pose_from_matrix
from supportnode.msgs import PointCloud
from supportnode.node.node import Node


def _board(rng, cx, n=4000, noise=0.0):
    pts = plane_points(rng, cx - 0.6, cx + 0.6, -0.4, 0.4, 0.5, n)
    return pts + rng.normal(0, noise, pts.shape) if noise else pts


def _sequence(rng, kind: str) -> list[PointCloud]:
    """Two boards 4 m apart seen in the first scan; then scans of the first board only, a box
    put on it from the third scan and taken away at the sixth. moving: the sensor slides
    along x; standing: it stays; noisy: standing, 5 mm of gaussian noise on every point."""
    noise = 0.005 if kind == "noisy" else 0.0
    out = []
    for i in range(8):
        x = 0.04 * i if kind == "moving" else 0.0
        pose = np.eye(4)
        pose[:3, 3] = (x, 0.0, 1.5)
        parts = [_board(rng, 0.0, noise=noise)]
        if i == 0:
            parts.append(_board(rng, 4.0, noise=noise))
        if 2 <= i < 5:
            box = box_points(rng, (0.2, 0.1, 0.6), (0.2, 0.2, 0.2), 2000)
            parts.append(box + rng.normal(0, noise, box.shape) if noise else box)
        pts = np.vstack(parts) - pose[:3, 3]
        out.append(
            PointCloud.from_xyz(pts, 1.0 + 0.1 * i, "lidar", seq=i + 1, pose=pose_from_matrix(pose))
        )
    return out


def _summary(out):
    """The surfaces and obstacles by id (a regional detection lists the unchanged items
    first: the same items under the same ids, another order in the message)."""
    s = sorted(
        (x.id, round(x.height, 6), round(x.area, 6), x.point_count, x.safe)
        for x in out.surfaces.surfaces
    )
    c = sorted(
        (tuple(np.round(x.centroid, 6)), x.point_count, x.id) for x in out.obstacles.clusters
    )
    f = sorted((x.id, round(x.free_area, 6)) for x in out.surfaces.surfaces)
    return s, c, f


@pytest.mark.parametrize("kind", ["moving", "standing", "noisy"])
def test_incremental_equals_full_recompute_scan_by_scan(rng, kind):
    clouds = _sequence(rng, kind)
    outs = {}
    for inc in (True, False):
        with Node(incremental=inc) as node:
            outs[inc] = [node.process(c) for c in clouds]
    for i, (a, b) in enumerate(zip(outs[True], outs[False], strict=True)):
        assert _summary(a) == _summary(b), f"scan {i}"
    assert not any(o.incremental for o in outs[False])
    # The shortcuts really ran somewhere in these sequences (else the test proves nothing).
    shortcuts = sum(o.incremental or o.reused for o in outs[True])
    assert shortcuts >= 1, [(o.incremental, o.reused) for o in outs[True]]


def _inside_one_by_one(boxes, lo, hi, margin):
    """The region's closure as first written: box by box, the region grown at each."""
    inside = np.zeros(len(boxes), bool)
    grew = True
    while grew:
        grew = False
        for i, (blo, bhi) in enumerate(boxes):
            meets = np.all(blo <= hi + margin) and np.all(bhi >= lo - margin)
            if not inside[i] and meets:
                inside[i] = True
                lo, hi = np.minimum(lo, blo), np.maximum(hi, bhi)
                grew = True
    return inside, lo, hi


@pytest.mark.parametrize("seed", range(20))
def test_region_closure_equals_growing_box_by_box(seed):
    """The closure over the items' boxes is unique: all boxes at once per round give the
    same boxes and region as one box at a time (chains of boxes reached in several rounds)."""
    from supportnode.node.incremental import _inside

    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 40))
    lo_b = rng.uniform(-5, 5, (n, 2))
    boxes = [(b, b + rng.uniform(0.05, 1.5, 2)) for b in lo_b]
    lo = rng.uniform(-1, 0, 2)
    hi = lo + rng.uniform(0, 1, 2)
    got = _inside(boxes, lo, hi, 0.5)
    want = _inside_one_by_one(boxes, lo, hi, 0.5)
    assert np.array_equal(got[0], want[0])
    assert np.array_equal(got[1], want[1]) and np.array_equal(got[2], want[2])
    if n and seed == 0:
        assert 0 < got[0].sum()  # the case is not vacuous
