"""Ray clearing's march beside the merge gives the map a march after the merge gives."""

from __future__ import annotations

import numpy as np

from supportnode.kernels.rays import ray_voxels
from supportnode.map import VoxelMap
from supportnode.map.clearing import _SHIFT_ARR
from supportnode.map.keys import _OFFS
from supportnode.params import MapParams


class _Afterwards:
    """A march run when its pairs are asked for, on the map as it is then."""

    def __init__(self, m: VoxelMap, origin, u, n, pts) -> None:
        self.m, self.origin, self.u, self.n, self.pts = m, origin, u, n, pts

    def pairs(self):
        m = self.m
        table, scan = m._hash.table, m._scans
        return ray_voxels(self.origin, self.u, self.n, m.size, table, _OFFS, _SHIFT_ARR,
                          m._last_scan, scan)  # fmt: skip


class _MarchAfterMerge(VoxelMap):
    """The order before the march ran beside the merge: the scan's rays sampled, its
    voxels merged (new keys in the table), then the march on that table."""

    def _begin_clear(self, cols, origin):
        return _Afterwards(self, origin, *self._sample_rays(cols, origin))

    def _merge(self, cols, stamp, origin, march=None):
        return super()._merge(cols, stamp, origin, None)


def _state(m: VoxelMap) -> dict:
    v = m.voxels()
    order = np.lexsort(v["keys"].T[::-1])
    out = {k: a[order] for k, a in v.items()}
    out["points"] = m.points(out["keys"])
    return out


def test_march_beside_the_merge_equals_march_after_it():
    from supportnode.sim import Lidar, load_scene, poses_for
    from supportnode.sim.noise import NoiseSpec
    from supportnode.sim.simulate import scans

    scene = load_scene("kitchen")
    lidar = Lidar(32, -22.5, 22.5, 512, 0.3, 30.0, 10.0)
    clouds = scans(scene, lidar, poses_for(scene, 6), seed=1, noise=NoiseSpec(gauss=0.01))
    params = MapParams(radius=30.0, max_age=0.0)
    beside, after = VoxelMap(params), _MarchAfterMerge(params)
    for i, c in enumerate(clouds):
        pts = c.points.astype(np.float64)
        a = beside.integrate(pts, c.sensor_pose, 0.1 * i, in_map_frame=True)
        b = after.integrate(pts, c.sensor_pose, 0.1 * i, in_map_frame=True)
        assert np.array_equal(a.removed, b.removed) and np.array_equal(a.keys, b.keys)
        sa, sb = _state(beside), _state(after)
        for k in sa:
            assert np.array_equal(sa[k], sb[k]), (i, k)
    assert beside.stats() == after.stats()
    assert beside.stats()["cleared"] > 0  # the rays did clear: the comparison means something
