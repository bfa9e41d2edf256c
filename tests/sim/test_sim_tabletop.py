"""The tabletop test cases object segmentation is tested on: each is what its name says, seen
as a Kinect sees it, with ground truth (objects, support) and reproducible by seed."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from supportnode.sim.cloud import ROLE_NONE
from supportnode.sim.sensors import DepthCamera
from supportnode.sim.tabletop import CASES, TABLE_TOP, case, touching_boxes, two_cans, view


@pytest.mark.parametrize("name", sorted(CASES))
def test_every_case_is_an_organised_noisy_table_view(name):
    c = case(name)
    cloud = c.cloud
    assert cloud.image_shape == (480, 640) and len(cloud) == 480 * 640
    holes = ~np.isfinite(cloud.points[:, 0])
    assert 0.02 < holes.mean() < 0.4 and (cloud.role[holes] == ROLE_NONE).all()
    table = c.scene.surface_names.index("table")
    on_table = cloud.surface == table
    assert on_table.mean() > 0.3
    assert np.abs(np.median(cloud.points[on_table, 2]) - TABLE_TOP) < 0.002
    for o, obj in enumerate(c.scene.object_names):
        mine = cloud.object == o
        assert mine.sum() > 300, obj  # every object is in view
        assert np.isfinite(cloud.points[mine]).all()
        assert (cloud.support_surface[mine] == table).all()


def test_gaps_between_touching_boxes():
    for gap in (0.0, 0.001, 0.01, 0.03):
        cloud = view(touching_boxes(gap), noise=0.0, azimuth_deg=-30.0)
        a = cloud.points[cloud.object == 0].astype(np.float64)
        b = cloud.points[cloud.object == 1].astype(np.float64)
        nearest = cKDTree(a).query(b)[0].min()
        assert gap - 1e-4 <= nearest <= gap + 0.004, gap  # pixel spacing ~2 mm at 1 m


def test_stack_mug_and_book_ground_truth():
    c = case("box_on_box")
    upper, lower = (c.scene.object_names.index(n) for n in ("upper", "lower"))
    assert (c.cloud.supported_by[c.cloud.object == upper] == lower).all()
    assert (c.cloud.supported_by[c.cloud.object == lower] == -1).all()
    mug = case("mug")
    handle = [p.index for p in mug.scene.primitives if p.name == "handle"]
    parts = np.unique(mug.cloud.primitive[mug.cloud.object == 0])
    assert handle[0] in parts and len(parts) == 2  # body and handle: one object
    book = case("flat_book", noise=0.0).cloud
    top = book.points[book.object == 0, 2].max()
    assert top == pytest.approx(TABLE_TOP + 0.035, abs=1e-4)


def test_near_and_far_views_and_frames():
    for name, distance in (("boxes_at_0.5m", 0.5), ("boxes_at_1.5m", 1.5)):
        c = case(name, frame="optical")
        on = c.cloud.object >= 0
        depth = c.cloud.points[on, 2]  # optical z: depth ahead of the camera
        assert np.median(depth) == pytest.approx(distance, abs=0.15)
    small = DepthCamera(160, 120, 58.0, 0.45, 4.5, 30.0, 0.075)
    a, b, other = (view(two_cans(), seed=s, camera=small) for s in (3, 3, 4))
    assert np.array_equal(a.points, b.points, equal_nan=True)
    assert not np.array_equal(a.points, other.points, equal_nan=True)
    with pytest.raises(ValueError, match="unknown tabletop case 'nope'"):
        case("nope")
