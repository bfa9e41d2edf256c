"""A scan's merge and its clearing apart (`VoxelMap.merge`, `settle`) make the map
`integrate` makes; between the two the map has the scan and not yet its clearing."""

from __future__ import annotations

import numpy as np
import pytest

from supportnode.map import VoxelMap
from supportnode.params import MapParams


def _state(m: VoxelMap) -> dict:
    v = m.voxels()
    order = np.lexsort(v["keys"].T[::-1])
    out = {k: a[order] for k, a in v.items()}
    out["points"] = m.points(out["keys"])
    return out


@pytest.fixture(scope="module")
def clouds():
    from supportnode.sim import Lidar, load_scene, poses_for
    from supportnode.sim.noise import NoiseSpec
    from supportnode.sim.simulate import scans

    scene = load_scene("kitchen")
    lidar = Lidar(32, -22.5, 22.5, 512, 0.3, 30.0, 10.0)
    return scans(scene, lidar, poses_for(scene, 6), seed=1, noise=NoiseSpec(gauss=0.01))


def test_merge_then_settle_equals_integrate(clouds):
    params = MapParams(radius=30.0, max_age=0.0)
    whole, halves = VoxelMap(params), VoxelMap(params)
    grew = 0
    for i, c in enumerate(clouds):
        pts = c.points.astype(np.float64)
        a = whole.integrate(pts, c.sensor_pose, 0.1 * i, in_map_frame=True)
        b = halves.merge(pts, c.sensor_pose, 0.1 * i, in_map_frame=True)
        before = len(halves.points())
        assert len(b.removed) == 0 and np.array_equal(a.lo, b.lo) and np.array_equal(a.hi, b.hi)
        removed = halves.settle()
        assert np.array_equal(removed, a.removed)
        # Clearing only takes away: the map between the halves held the cleared voxels too.
        grew += before - len(halves.points())
        assert before >= len(halves.points())
        sa, sb = _state(whole), _state(halves)
        for k in sa:
            assert np.array_equal(sa[k], sb[k]), (i, k)
        assert len(halves.settle()) == 0  # nothing left to settle
    assert whole.stats() == halves.stats()
    assert whole.stats()["cleared"] > 0 and grew > 0  # the comparison means something


def test_a_merge_settles_the_scan_before_it(clouds):
    """A scan merged while the previous one is unsettled: that one's clearing runs first."""
    params = MapParams(radius=30.0, max_age=0.0)
    whole, merged = VoxelMap(params), VoxelMap(params)
    for i, c in enumerate(clouds):
        pts = c.points.astype(np.float64)
        whole.integrate(pts, c.sensor_pose, 0.1 * i, in_map_frame=True)
        merged.merge(pts, c.sensor_pose, 0.1 * i, in_map_frame=True)
    merged.settle()
    sa, sb = _state(whole), _state(merged)
    for k in sa:
        assert np.array_equal(sa[k], sb[k]), k
    assert whole.stats() == merged.stats()
