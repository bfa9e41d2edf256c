"""The node's core: one scan in (`NodeCore.ingest`), its results out (`NodeCore.detect`).

No threads, no locks, no sockets. The two calls split the work by who owns what:

- `ingest` (the receiving side) owns the map, the gravity estimate and the scan timeline: it
  merges the scan and, when a detection is due, returns a `Job` holding everything the
  detection needs (a snapshot of the map's points in the detection frame, the region the
  scans changed, the map's identity and version), so the detection never reads the map;
  `settle` then clears along the scan's rays, once the job is out (the node: once its
  surfaces are): the job has the map's points from before, the next job sees the clearing;
- `detect` (the detecting side) owns the trackers and the previous detection: it detects on
  the job's points (only on the changed region when that equals a full recompute, or the
  previous result when the map did not change), assigns stable ids and makes the messages.

A map reset (a source that restarted) starts a new map *generation* on the receiving side;
the detecting side resets its trackers when it first sees a job of a newer generation, so
neither side writes the other's state. `Node.process` is `ingest`, `detect`, then `settle`.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable

import numpy as np

from supportnode.detection.policy import is_safe
from supportnode.errors import InputError
from supportnode.geometry.transform import quaternion_matrix, transform_points
from supportnode.map import VoxelMap
from supportnode.msgs import ObstacleClusters, PointCloud, SupportSurfaces
from supportnode.node import incremental
from supportnode.node.gravity import Gravity, report_verdict
from supportnode.node.incremental import Items
from supportnode.node.intake import BACKWARD_S
from supportnode.node.job import Job, MapLike, NodeOutput, Partial
from supportnode.node.latency import RateLimitedLog
from supportnode.node.tracking import ClusterTracker, SurfaceTracker
from supportnode.params import DetectParams

__all__ = [
    "DETECT_COUNTERS",
    "INGEST_COUNTERS",
    "Job",
    "MapLike",
    "NodeCore",
    "NodeOutput",
    "Partial",
]

# Horizontal planes less than this below the sensor, or above it, are ceilings and
# undersides, not supports: the node publishes only surfaces lower than sensor z minus this, m.
_UNDER_SENSOR_M = 0.05
# A scan stamped this much before the previous one means the source restarted: the map and
# ids start over rather than mixing two timelines.
_TIME_JUMP = BACKWARD_S
# Each side's counters: a fixed key set, so that a copy taken by another thread never sees
# the dict change size (only values change, in place).
INGEST_COUNTERS = (
    "scans_processed",
    "time_jumps",
    "points_nonfinite",
    "gravity_failures",
    "gravity_outliers",
)
DETECT_COUNTERS = ("detections", "incremental_detections", "detections_reused")


def _empty_box() -> tuple[np.ndarray, np.ndarray]:
    return np.full(2, np.inf), np.full(2, -np.inf)


class NodeCore:
    """Gravity, map and detection of a scan stream (see the module docstring).

    params: the whole configuration. map_factory: makes the map (default: `VoxelMap` of
    ``node.map``), again at each reset. incremental: detect only on the region the scans
    touched when that equals a full recompute. logger: for the stream's warnings.
    """

    def __init__(
        self,
        params: DetectParams | None = None,
        *,
        map_factory: Callable[[], MapLike] | None = None,
        incremental: bool = True,
        logger: logging.Logger | None = None,
    ) -> None:
        self.params = params or DetectParams()
        self.cfg = self.params.node
        self.incremental = incremental
        self.log = logger or logging.getLogger("supportnode.node")
        self._map_factory = map_factory or (lambda: VoxelMap(self.cfg.map))
        self._stream_log = RateLimitedLog(self.log, self.cfg.reject_log_period)
        self.gravity = Gravity(self.params)
        self.ingest_counters = dict.fromkeys(INGEST_COUNTERS, 0)
        self.detect_counters = dict.fromkeys(DETECT_COUNTERS, 0)
        self.generation = 0
        self.posed, self.frame = False, "map"
        self.last_counts = (0, 0)  # surfaces, obstacles of the last detection (a gauge)
        self._seen_generation = 0  # the detecting side's: its trackers are of this one
        self.reset()
        self._reset_detection()

    # ---------------------------------------------------------------- receiving side

    def reset(self) -> None:
        """Forget the map (a new generation: the detecting side then forgets its ids and
        previous detection). The map frame's up direction stays."""
        self.map: MapLike = self._map_factory()
        self.last_stamp: float | None = None
        self._last_detect: float | None = None
        self._pending = _empty_box()
        self.generation += 1

    def ingest(self, cloud: PointCloud) -> Job | None:
        """Merge one admitted scan into the map; the `Job` of its detection when one is due
        (``node.detection_rate``), else None. Raises InputError for a scan without points."""
        if cloud.count == 0:
            raise InputError("scan has no finite points")
        timings: dict[str, float] = {}
        stamp = float(cloud.stamp)
        c = self.ingest_counters
        if self.last_stamp is not None and stamp < self.last_stamp - _TIME_JUMP:
            c["time_jumps"] += 1
            self._stream_log.warning(
                f"scan stamp {stamp:.3f} is before the previous {self.last_stamp:.3f}: "
                "source restarted, map reset"
            )
            self.reset()
        c["points_nonfinite"] += int(cloud.dropped_nonfinite)
        pose = np.eye(4)
        if cloud.pose is not None:
            pose[:3, :3] = quaternion_matrix(cloud.pose.rotation)
            pose[:3, 3] = cloud.pose.translation
        t = time.perf_counter()
        failures = self.gravity.failures
        verdict = self.gravity.update(cloud, pose[:3, :3], cloud.points)
        c["gravity_failures"] += self.gravity.failures - failures
        report_verdict(self.log, self.cfg, self.gravity, c, cloud.seq, verdict)
        timings["gravity"] = time.perf_counter() - t
        t = time.perf_counter()
        self.settle()  # the previous scan's clearing, if nobody ran it yet
        touched = self.map.merge(cloud.points, pose, stamp)
        self.last_stamp = stamp
        rotation = self.gravity.rotation
        self._widen_pending(touched.lo, touched.hi, touched.removed, rotation)
        timings["map"] = time.perf_counter() - t
        c["scans_processed"] += 1
        self.posed, self.frame = cloud.pose is not None, cloud.frame_id
        if not self._detection_due(stamp):
            return None
        t = time.perf_counter()
        raw = self.map.points()
        # Scans with gravity in their pose (and no correction yet): the map frame is level.
        points = raw if np.array_equal(rotation, np.eye(3)) else transform_points(raw, rotation)
        timings["points"] = time.perf_counter() - t
        region, self._pending = self._pending, _empty_box()
        frame = self.cfg.frame_id if cloud.pose is not None else cloud.frame_id
        return Job(
            points=points,
            rotation=rotation,
            sensor_z=float((rotation @ pose[:3, 3])[2]),
            stamp=stamp,
            frame=frame,
            generation=self.generation,
            source=(self.generation, self.map.version),
            region=region,
            timings=timings,
        )

    def map_cloud(self, max_points: int, seq: int) -> PointCloud | None:
        """The map as a PointCloud in the results' frame: one point per voxel (its points'
        mean; at most ``max_points``, every k-th); None before the first scan."""
        if self.last_stamp is None:
            return None
        pts = transform_points(self.map.centroids(max_points), self.gravity.rotation)
        frame = self.cfg.frame_id if self.posed else self.frame
        return PointCloud.from_xyz(pts.astype(np.float32), self.last_stamp, frame, seq)

    def _detection_due(self, stamp: float) -> bool:
        rate = self.cfg.detection_rate
        due = (
            rate <= 0 or self._last_detect is None or stamp - self._last_detect >= 1.0 / rate - 1e-6
        )
        if due:
            self._last_detect = stamp
        return due

    def settle(self) -> float:
        """The last ingested scan's clearing (`VoxelMap.settle`); what it removes joins the
        next detection's region. Call once the scan's job is out (the job holds the map's
        points from before: the clearing shows in the next scan's detection). Returns the
        seconds it took."""
        t = time.perf_counter()
        removed = self.map.settle()
        if len(removed):
            no_box = np.full(3, np.inf), np.full(3, -np.inf)
            self._widen_pending(*no_box, removed, self.gravity.rotation)
        return time.perf_counter() - t

    def _widen_pending(
        self, lo: np.ndarray, hi: np.ndarray, removed: np.ndarray, rotation: np.ndarray
    ) -> None:
        """Add the x, y box (detection frame) of a scan's box lo, hi (3,) and the voxels
        ``removed`` (R, 3) (map frame) to the next detection's region."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        corners = []
        if np.all(lo <= hi):
            corners.append(np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(3, -1).T)
        removed = np.asarray(removed, float)
        if len(removed):
            size = float(self.cfg.map.voxel_size)
            rlo, rhi = removed.min(axis=0) * size, (removed.max(axis=0) + 1) * size
            corners.append(np.array(np.meshgrid(*zip(rlo, rhi, strict=True))).reshape(3, -1).T)
        if corners:
            c = np.concatenate(corners) @ rotation.T
            lo2, hi2 = c[:, :2].min(axis=0), c[:, :2].max(axis=0)
            self._pending = (np.minimum(self._pending[0], lo2), np.maximum(self._pending[1], hi2))

    # ---------------------------------------------------------------- detecting side

    def _reset_detection(self) -> None:
        self.surface_tracker = SurfaceTracker(min_iou=0.2, height_tolerance=0.05, max_misses=3)
        self.cluster_tracker = ClusterTracker(cell_size=0.02, min_iou=0.2, max_misses=3)
        self._items: Items | None = None
        self._items_rotation: np.ndarray | None = None
        self._items_source: tuple[int, int | None] | None = None
        self._out_seq = 0
        self._seen_generation = self.generation

    def detect(self, job: Job) -> NodeOutput:
        """Detection, stable ids and messages of one job: `detect_surfaces` then
        `detect_objects` (see the module docstring)."""
        return self.detect_objects(self.detect_surfaces(job))

    def detect_surfaces(self, job: Job) -> Partial:
        """A detection's first phase: surfaces, their free space, stable ids and ``safe``;
        ``out.surfaces`` is final (publish it), `detect_objects` continues."""
        if job.generation != self._seen_generation:
            self._reset_detection()  # the map was reset: ids and previous detection go
            self._seen_generation = job.generation
        timings = dict(job.timings)
        below = job.sensor_z - _UNDER_SENSOR_M  # surfaces from here up are not published
        prev = self._items
        same_frame = self._items_rotation is not None and np.allclose(
            self._items_rotation, job.rotation, atol=1e-9
        )
        # Detection is a function of the map's points alone: on an unchanged map the previous
        # one is the answer, unless the sensor rose and surfaces it left without free space
        # are now below it.
        reused = bool(
            same_frame
            and prev is not None
            and prev.has_free_space_below(below)
            and job.source[1] is not None
            and self._items_source == job.source
        )
        phase = incremental.Phase.done(prev) if reused and prev is not None else None
        if phase is None and self.incremental and prev is not None and same_frame:
            lo, hi = job.region
            phase = incremental.begin_regional(
                job.points, prev, lo, hi, self.params, free_below=below
            )
        if phase is None:
            phase = incremental.begin_full(job.points, self.params, free_below=below)
        t = time.perf_counter()
        # Horizontal planes above the sensor are ceilings and undersides, not supports.
        keep = [s for s in phase.surfaces if s.height < below]
        kept_ids = {s.id for s in keep}
        s_up = self.surface_tracker.update_surfaces(keep)
        sid = {s.id: int(i) for s, i in zip(keep, s_up.ids, strict=True)}
        tracks = self.surface_tracker.tracks
        safe = [
            is_safe(
                s, self.params.safe, tracks.get(int(i), {}).get("hits", 0), self.cfg.safe_min_hits
            )
            for s, i in zip(keep, s_up.ids, strict=True)
        ]
        self._out_seq += 1
        free = [f for f in phase.free if f.surface_id in kept_ids]
        surfaces = SupportSurfaces.from_detection(
            keep,
            free,
            job.stamp,
            job.frame,
            self._out_seq,
            ids=[int(i) for i in s_up.ids],
            safe=safe,
        )
        timings["track"] = time.perf_counter() - t
        out = NodeOutput(surfaces, None, timings, reused=reused)
        out.new_ids, out.gone_ids = {"surfaces": list(s_up.new)}, {"surfaces": list(s_up.gone)}
        return Partial(out, job, phase, sid)

    def detect_objects(self, part: Partial) -> NodeOutput:
        """A detection's second phase: objects, their stable ids, ObstacleClusters of the
        same seq; the whole `NodeOutput` (``out.surfaces`` as `detect_surfaces` made it)."""
        out, job = part.out, part.job
        items = part.phase.finish()
        if not out.reused:
            out.timings.update(items.timings)
        self._items, self._items_rotation, self._items_source = items, job.rotation, job.source
        out.incremental = not out.reused and items.region is not None
        c = self.detect_counters
        c["detections"] += 1
        c["incremental_detections"] += int(out.incremental)
        c["detections_reused"] += int(out.reused)
        t = time.perf_counter()
        sid = part.sid
        surface_of = np.array(
            [sid.get(c.surface_id, -1) if c.surface_id is not None else -1 for c in items.clusters],
            dtype=np.int64,
        )
        c_up = self.cluster_tracker.update_clusters(items.clusters, surface_of)
        out.timings["track"] += time.perf_counter() - t
        t = time.perf_counter()
        clusters = [
            c
            if c.surface_id is None or c.surface_id in sid
            else dataclasses.replace(c, surface_id=None)
            for c in items.clusters
        ]
        out.obstacles = ObstacleClusters.from_detection(
            clusters,
            job.stamp,
            job.frame,
            self._out_seq,
            ids=[int(i) for i in c_up.ids],
            surface_ids=sid,
            points=items.cluster_points,
        )
        out.timings["messages"] = time.perf_counter() - t
        out.new_ids["obstacles"], out.gone_ids["obstacles"] = list(c_up.new), list(c_up.gone)
        self.last_counts = (len(sid), len(clusters))
        out.items = items
        return out
