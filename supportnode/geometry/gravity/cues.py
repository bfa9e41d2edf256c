"""Evidence that a plane family is the up axis, and the sign it implies."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from supportnode.geometry.gravity.families import Family, inside_extent, parallel_planes

_STAND_HEIGHT = 0.5  # m: points this far on either side of a plane count as resting on/under it


@dataclass
class Evidence:
    """What the cloud says about one family, for +axis as up.

    planes: [(offset m from the sensor along the axis, member mask)]; sensor_vote: member
    area below the sensor minus above it, over both, in [-1, 1] (0 when no sensor is known);
    on / under: downsampled points just above / below a plane and inside its extent;
    oblique: mean sine of the angle between viewing rays and the axis (1: seen at a graze);
    perp: share of all normals perpendicular to the axis (walls, box and can sides)."""

    planes: list[tuple[float, np.ndarray]]
    sensor_vote: float
    on: int
    under: int
    oblique: float
    perp: float

    @property
    def rest_vote(self) -> float:
        """(on - under) / (on + under), in [-1, 1]; 0 when nothing rests either side."""
        return (self.on - self.under) / max(self.on + self.under, 1)


def plane_basis(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane perpendicular to the unit axis ``a`` (3,)."""
    e1 = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(a, e1)


def gather(
    fam: Family, ds: np.ndarray, normals: np.ndarray, sensor: np.ndarray, voxel: float
) -> Evidence:
    """Evidence for ``fam`` (+axis up) from the downsampled points ``ds`` (V, 3) m, their
    normals (V, 3), where the sensor was (3,) m, and the voxel edge m."""
    a = fam.axis
    t_all = (ds - sensor) @ a
    t = t_all[fam.members]
    planes = parallel_planes(t, voxel, ds.shape[0])
    margin = 2.0 * voxel
    sensor_vote = 0.0
    if planes:
        largest = max(planes, key=lambda pm: int(pm[1].sum()))[0]
        # No sensor stands inside its largest plane: then the origin is not where a sensor
        # was (a world-frame cloud with the origin on the floor, a mesh sampling). No vote.
        if abs(largest) >= margin:
            below = int((t < -margin).sum())
            above = int((t > margin).sum())
            sensor_vote = (below - above) / max(below + above, 1)

    # Things resting on a plane lie just above it and inside its extent.
    e1, e2 = plane_basis(a)
    uv_all = np.stack([ds @ e1, ds @ e2], axis=1)
    on, under = 0, 0
    for offset, m in planes:  # a handful of planes
        dt = t_all - offset
        gap = max(voxel, 2.0 * float(np.std(t[m])))  # clear of the plane's own noise
        near = np.flatnonzero((np.abs(dt) > gap) & (np.abs(dt) < _STAND_HEIGHT))
        inside = inside_extent(uv_all[fam.members[m]], uv_all[near], voxel)
        up_side = dt[near[inside]] > 0
        on += int(up_side.sum())
        under += int((~up_side).sum())

    # Obliquity: planes seen from the sensor at a slant (floor, table) rather than face-on
    # (a wall ahead): the sine of the angle between each viewing ray and the axis, averaged.
    rays = ds[fam.members] - sensor
    rn = np.linalg.norm(rays, axis=1)
    ok = rn > 1e-9
    sin_view = np.linalg.norm(np.cross(rays[ok], a), axis=1) / rn[ok]
    oblique = float(sin_view.mean()) if sin_view.size else 0.5

    perp = float((np.abs(normals @ a) < np.sin(np.radians(10.0))).mean())
    return Evidence(planes, sensor_vote, on, under, oblique, perp)
