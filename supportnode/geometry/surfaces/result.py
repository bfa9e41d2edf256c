"""What surface detection returns: :class:`Surface` and :class:`SurfaceResult`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def _r(value):
    """Round a float or array to 7 decimals for JSON (plain Python types)."""
    if np.ndim(value):
        return [round(float(v), 7) + 0.0 for v in value]
    return round(float(value), 7) + 0.0


@dataclass
class Surface:
    """One support surface. Lengths in metres, z up."""

    id: int
    height: float  # median z of the surface points
    area: float  # footprint area, m^2
    centroid: np.ndarray  # (3,) float64
    normal: np.ndarray  # (3,) float64 unit, z >= 0, from a plane fit to the surface points
    flatness: float  # rms distance of the surface points to that plane
    bbox_min: np.ndarray  # (3,) float64
    bbox_max: np.ndarray  # (3,) float64
    outline: list[np.ndarray]  # 2-D polygons (K, 2) float64 in x, y: [outer, hole, hole, ...]
    point_count: int
    voxel_count: int
    cells: np.ndarray  # (C, 2) int64 footprint cells (ix, iy) on the grid of size cell_size
    cell_size: tuple[float, float]  # (vx, vy) of the footprint grid; cell (i, j) spans
    # x in [i*vx, (i+1)*vx), y in [j*vy, (j+1)*vy)
    width: float = 0.0  # largest inscribed square-ish width of the footprint, m
    # Measured noise: sigma(r) = sqrt(a^2 + (b r^2)^2) m at range r m from the sensor, (a, b);
    # and the band that labelled its points: (sigmas, minimum m). Zeros: not measured.
    noise: tuple[float, float] = (0.0, 0.0)
    band: tuple[float, float] = (0.0, 0.0)

    def band_width(self, r: np.ndarray | float) -> np.ndarray:
        """The half-width of the surface's noise band at range ``r`` m, metres."""
        r2 = np.asarray(r, dtype=np.float64) ** 2
        return np.maximum(self.band[0] * np.hypot(self.noise[0], self.noise[1] * r2), self.band[1])

    def to_dict(self) -> dict:
        """JSON-ready dictionary (no numpy types). Floats are rounded to 1e-7 (0.1 um, 1e-7 of
        a unit normal) so that the output does not depend on summation order."""
        return {
            "id": int(self.id),
            "height": _r(self.height),
            "area": _r(self.area),
            "width": _r(self.width),
            "centroid": _r(self.centroid),
            "normal": _r(self.normal),
            "flatness": _r(self.flatness),
            "bbox_min": _r(self.bbox_min),
            "bbox_max": _r(self.bbox_max),
            "outline": [np.round(p, 6).tolist() for p in self.outline],
            "point_count": int(self.point_count),
            "voxel_count": int(self.voxel_count),
            "noise": {"sigma": _r(self.noise[0]), "sigma_per_m2": _r(self.noise[1])},
        }


@dataclass
class SurfaceResult:
    """Surfaces sorted largest first (ids 0, 1, ... in that order) and a label per point."""

    surfaces: list[Surface]
    labels: np.ndarray  # (N,) int32: surface id of each input point, -1 when on none
    stats: dict = field(default_factory=dict)  # counts for diagnostics (voxels, candidates, ...)
    # Rows (ascending) of raised patches in a surface's noise band (a pot's inner bottom a few
    # millimetres above the table): labelled none, and not the surface's noise either.
    raised: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
