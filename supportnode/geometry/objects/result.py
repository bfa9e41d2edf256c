"""Result types of object detection: a described object (Cluster), the detection result
(ObjectResult), objects segmented but not yet described (Segmentation) and the connected
components before touching objects are split (Components).

Lengths in metres, z up; N is the number of input points, M of candidates (points on no
surface), C of clusters.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from supportnode.geometry.objects.support_lookup import _SupportLookup


@dataclass
class Cluster:
    """One supported object (or piece of structure). Lengths in metres, z up."""

    id: int  # 0 = largest by point count, then descending
    surface_id: int | None  # surface directly under the lowest points, None when on none
    point_count: int
    centroid: np.ndarray  # (3,) float64
    bbox_min: np.ndarray  # (3,) float64, axis-aligned box
    bbox_max: np.ndarray  # (3,) float64
    obb_center: np.ndarray  # (3,) float64, oriented box (yaw only)
    obb_size: np.ndarray  # (3,) float64: length >= width, height
    obb_yaw: float  # radians in (-pi/2, pi/2], direction of the length axis
    height: float  # top above the surface height (above its own bottom when surface_id is None)
    footprint: np.ndarray  # (K, 2) float64 convex hull in x, y, counter-clockwise
    volume: float  # convex-hull volume, m^3 (0 for degenerate sets; NaN: not computed)
    supported_by: int = -1  # id of the cluster it stands on, -1 when on its surface (or none)

    def to_dict(self) -> dict:
        """JSON-ready dictionary (no numpy types)."""
        return {
            "id": int(self.id),
            "surface_id": None if self.surface_id is None else int(self.surface_id),
            "point_count": int(self.point_count),
            "centroid": [float(v) for v in self.centroid],
            "bbox_min": [float(v) for v in self.bbox_min],
            "bbox_max": [float(v) for v in self.bbox_max],
            "obb_center": [float(v) for v in self.obb_center],
            "obb_size": [float(v) for v in self.obb_size],
            "obb_yaw": float(self.obb_yaw),
            "height": float(self.height),
            "footprint": np.round(self.footprint, 4).tolist(),
            "volume": float(self.volume),
            "supported_by": int(self.supported_by),
        }


@dataclass
class ObjectResult:
    """Clusters sorted largest first (ids 0, 1, ... in that order) and a label per input point."""

    clusters: list[Cluster]
    labels: np.ndarray  # (N,) int32: cluster id of each input point, -1 for none
    stats: dict = field(default_factory=dict)


@dataclass
class Segmentation:
    """Objects segmented but not yet described: what free space needs, before the hulls.

    labels: (N,) int32 cluster id of each input point, -1 for none; ids are the final ones
    (largest first), so :func:`describe_objects` only adds the clusters' geometry.
    surface_ids: (C,) int64 surface under each cluster, -1 for none. bbox_min, bbox_max:
    (C, 3) float64 axis-aligned boxes of the clusters' points, metres.
    """

    labels: np.ndarray
    surface_ids: np.ndarray
    bbox_min: np.ndarray
    bbox_max: np.ndarray
    stats: dict = field(default_factory=dict)
    # For describe_objects: the clustered points grouped by cluster (old order) and the run
    # [start, end) of each cluster in the new order.
    _grouped: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    _runs: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64), repr=False)
    _heights: dict = field(default_factory=dict, repr=False)
    # `kernels.groups.group_rows` of the labels the clusters were ordered from (their old
    # ids): start, rows, points, lo, hi; None when not kept.
    _groups: tuple | None = field(default=None, repr=False)


@dataclass
class Components:
    """Connected components of the points on no surface, before touching objects are split:
    what free space needs (a pile of objects occupies its surface however it is split), and
    what :func:`split_objects` continues from.

    segmentation: the components as a Segmentation (labels (N,), largest first, their
    supporting surfaces and boxes). The other fields are for split_objects.
    """

    segmentation: Segmentation
    _points: np.ndarray = field(repr=False)  # (M, 3) float64 candidate points
    _candidates: np.ndarray = field(repr=False)  # (M,) int64 their rows in the input
    _labels: np.ndarray = field(repr=False)  # (M,) int64 component of each candidate, -1: none
    _supports: np.ndarray = field(repr=False)  # (C,) int64 surface of each component by label
    # The surfaces' footprint lookups, plain and dilated (see support_lookup._lookups).
    _lookups: tuple[list[_SupportLookup], list[_SupportLookup]] = field(repr=False)
    _n_points: int = 0
    _stats: dict = field(default_factory=dict, repr=False)
    # Rows the objects took from the surfaces' noise band (their feet): no longer surface.
    claimed: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64), repr=False)
    # (M,) each candidate's voxel of the clustering grid (voxel method, no feet claimed).
    _voxels: np.ndarray | None = field(default=None, repr=False)
    # (3,) the sensor in the points' frame, when known (what it cannot see fills footprints).
    _origin: np.ndarray | None = field(default=None, repr=False)
    # (M,) bool: the candidates the convex method left whole (too sparse for convexity);
    # None for the other methods. Their stacks are cut by layers (see layers.cut_layers).
    _sparse: np.ndarray | None = field(default=None, repr=False)
    # (K,) int64: the last K candidates lie at their surface's level (see level.set_aside),
    # segmented without them; each goes with the candidate at its row here (-1: none).
    _level_near: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64), repr=False)
