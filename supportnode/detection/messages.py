"""A detection as the node's result messages: geometry dataclasses in, wire messages out.

The wire (`supportnode.msgs`) knows no geometry, so the conversion from `Surface`, `FreeSpace`
and `Cluster` lives here, beside the pipeline that makes them; the node and the offline CLI
both call it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from supportnode.detection.policy import is_safe
from supportnode.errors import InputError
from supportnode.geometry.freespace import FreeSpace
from supportnode.geometry.objects import Cluster
from supportnode.geometry.surfaces import Surface
from supportnode.msgs import ObstacleCluster, ObstacleClusters, SupportSurface, SupportSurfaces
from supportnode.params import SafeParams
from supportnode.pipeline import Detection

__all__ = ["detection_messages", "obstacles_message", "surfaces_message"]


def surfaces_message(
    surfaces: Sequence[Surface],
    free: Sequence[FreeSpace],
    stamp: float,
    frame_id: str,
    seq: int = 0,
    ids: Sequence[int] | None = None,
    safe: Sequence[bool] | None = None,
) -> SupportSurfaces:
    """Message from `detect_surfaces` results and `free_space_all` (matched by surface id;
    surfaces without one get NaN free space). ids: stable ids parallel to ``surfaces``
    (default: the detection ids); safe: flags parallel to ``surfaces`` (default False)."""
    by_id = {f.surface_id: f for f in free}
    for what, seq_ in (("ids", ids), ("safe", safe)):
        if seq_ is not None and len(seq_) != len(surfaces):
            raise InputError(f"{what} has {len(seq_)} entries for {len(surfaces)} surfaces")
    out = []
    for i, s in enumerate(surfaces):
        f = by_id.get(s.id)
        out.append(
            SupportSurface(
                id=int(s.id if ids is None else ids[i]),
                height=float(s.height),
                normal=np.asarray(s.normal, dtype=np.float64),
                area=float(s.area),
                outline=[np.asarray(r, dtype=np.float64) for r in s.outline],
                free_area=math.nan if f is None else float(f.free_area),
                disc_center=np.full(2, np.nan) if f is None else np.array(f.disc_center, float),
                disc_radius=math.nan if f is None else float(f.disc_radius),
                flatness=float(s.flatness),
                point_count=int(s.point_count),
                safe=False if safe is None else bool(safe[i]),
            )
        )
    return SupportSurfaces(stamp=float(stamp), frame_id=frame_id, seq=seq, surfaces=out)


def obstacles_message(
    clusters: Sequence[Cluster],
    stamp: float,
    frame_id: str,
    seq: int = 0,
    ids: Sequence[int] | None = None,
    surface_ids: Mapping[int, int] | None = None,
    points: Sequence[np.ndarray] | None = None,
    max_points_per_cluster: int | None = None,
) -> ObstacleClusters:
    """Message from `detect_objects` clusters.

    ids: stable ids parallel to ``clusters`` (default: detection ids). surface_ids: detection
    surface id -> stable surface id (default: unchanged). points: each cluster's (M, 3) points,
    parallel to ``clusters``, kept as float32 and evenly subsampled to at most
    ``max_points_per_cluster``; None sends no points.
    """
    for what, seq_ in (("ids", ids), ("points", points)):
        if seq_ is not None and len(seq_) != len(clusters):
            raise InputError(f"{what} has {len(seq_)} entries for {len(clusters)} clusters")
    # supported_by names a detection id: it goes out as the stable id of that cluster
    stable = {c.id: int(c.id if ids is None else ids[i]) for i, c in enumerate(clusters)}
    out = []
    for i, c in enumerate(clusters):
        sid = c.surface_id
        if sid is not None and surface_ids is not None:
            sid = surface_ids.get(sid, sid)
        pts = None
        if points is not None:
            pts = np.asarray(points[i], dtype=np.float32).reshape(-1, 3)
            if max_points_per_cluster is not None and len(pts) > max_points_per_cluster:
                keep = np.linspace(0, len(pts) - 1, max_points_per_cluster).round()
                pts = pts[keep.astype(np.int64)]
        out.append(
            ObstacleCluster(
                id=int(c.id if ids is None else ids[i]),
                surface_id=None if sid is None else int(sid),
                centroid=np.asarray(c.centroid, dtype=np.float64),
                bbox_min=np.asarray(c.bbox_min, dtype=np.float64),
                bbox_max=np.asarray(c.bbox_max, dtype=np.float64),
                obb_center=np.asarray(c.obb_center, dtype=np.float64),
                obb_size=np.asarray(c.obb_size, dtype=np.float64),
                obb_yaw=float(c.obb_yaw),
                height=float(c.height),
                point_count=int(c.point_count),
                points=pts,
                supported_by=stable.get(getattr(c, "supported_by", -1), -1),
            )
        )
    return ObstacleClusters(stamp=float(stamp), frame_id=frame_id, seq=seq, clusters=out)


def detection_messages(
    detection: Detection, safe: SafeParams, stamp: float, frame_id: str, seq: int = 0
) -> tuple[SupportSurfaces, ObstacleClusters | None]:
    """SupportSurfaces (``safe`` by `is_safe`, one detection: no hits to count) and
    ObstacleClusters (None when objects were not detected) of one detection."""
    surfaces = detection.surfaces.surfaces
    msg_s = surfaces_message(
        surfaces,
        detection.free_space,
        stamp,
        frame_id,
        seq,
        safe=[is_safe(s, safe) for s in surfaces],
    )
    if detection.objects is None:
        return msg_s, None
    return msg_s, obstacles_message(detection.objects.clusters, stamp, frame_id, seq)
