"""The node: scans in, support surfaces and the obstacles on them out, with diagnostics.

Data path of one scan: socket -> decode and validate -> gravity (given or estimated) -> voxel map
merge through the pose -> detection on the region the scan touched -> stable ids -> encode ->
socket. `Node.process` is that path without sockets (tests and embedding); `Node.spin` adds the
sockets, keep-newest input, the diagnostics timer and clean shutdown on SIGINT/SIGTERM.

`spin` is pipelined (``node.pipeline``): the receiving thread decodes and merges every scan into
the map as it arrives; a detection thread runs on the newest map state and publishes. When
detection is slower than the scans, it skips to the newest scan (counted), but the map still
has every scan; a scan that arrived while detection was busy gives way to the next one when
that is due within a scan period (see `_detect_loop`). The detection thread hands the map's
points to a worker process (``node.detect_process``, `supportnode.node.worker`), so that the
merge and the detection do not take turns at one interpreter lock. If the worker dies, the
thread detects by itself meanwhile and the worker is restarted (at most _WORKER_RESTARTS times).
With ``node.defer_clear`` the receiving thread only merges a scan, and its free-space clearing
(and forgetting) waits until the detection of that scan has the map's points: it runs in the
detection thread once the worker has them, while it detects, or after the detection when no
worker took them. A scan that no detection takes at once (the detector busy, or none due) is
cleared by the receiving thread right after its merge, and any clearing still pending runs
before the next merge: the map goes through the same states as without, and a detection sees
the clearing of the scans before its own.
With ``node.surfaces_first`` a detection's surfaces and their free space go out as soon as they
are known, and its obstacles (same ``seq``) once their hulls and boxes are computed.

    with Node(load_config("config/default.yaml")) as node:
        out = node.process(cloud)            # NodeOutput: SupportSurfaces, ObstacleClusters
    with Node(params) as node:
        node.spin()                          # until SIGINT/SIGTERM or node.stop()

Frames: a scan's points are in its cloud frame; its ``pose`` takes them to the map frame (no
pose: the cloud frame is the map frame, a static sensor). Results are published in the map frame
rotated by the gravity correction (identity when the map frame is already z-up), named
``NodeParams.frame_id`` (the cloud's ``frame_id`` for scans without a pose).

A surface is ``safe`` by `supportnode.detection.policy.is_safe` (the ``safe`` section: area,
flatness, tilt) once seen in ``node.safe_min_hits`` detections in a row under the same id (one
scan's glimpse is not enough to put something down on).
"""

from __future__ import annotations

import logging
import math
import os
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Protocol

import numpy as np
import zmq

from supportnode import bus
from supportnode._closing import Closing
from supportnode.curve import NodeKeys, node_keys
from supportnode.detection.policy import is_safe
from supportnode.errors import InputError, SupportNodeError
from supportnode.geometry.memo import Memo
from supportnode.geometry.transform import quaternion_matrix, transform_points
from supportnode.msgs import (
    Diagnostics,
    ObstacleClusters,
    PointCloud,
    SupportSurfaces,
)
from supportnode.node import incremental
from supportnode.node.gravity import SOURCES, Gravity, Verdict
from supportnode.node.incremental import Items
from supportnode.node.intake import BACKWARD_S, Intake, Reject, scan_problem
from supportnode.node.latency import LatencyWindow, RateLimitedLog
from supportnode.map import VoxelMap
from supportnode.node.tracking import ClusterTracker, SurfaceTracker
from supportnode.node.worker import DetectionWorker, WorkerError
from supportnode.params import DetectParams

__all__ = ["MapLike", "Node", "NodeOutput", "quaternion_matrix"]

log = logging.getLogger("supportnode.node")

# Horizontal planes less than this below the sensor, or above it, are ceilings and
# undersides, not supports: the node publishes only surfaces lower than sensor z minus this, m.
_UNDER_SENSOR_M = 0.05
# A scan stamped this much before the previous one means the source restarted (a replay that
# loops, a driver restart; on the wire, `Intake` admits such a scan only once the next one
# confirms the new timeline): the map and ids start over rather than mixing two timelines.
_TIME_JUMP = BACKWARD_S
# How long one wait for a scan lasts in spin: bounds the reaction time to a stop request.
_POLL_S = 0.05
# A scan handed to detection while it was busy waits at most this long for a newer one.
_FRESH_WAIT_MAX_S = 0.5
# A detection worker that died is restarted after this long, this many times at most.
_WORKER_RESTART_S = 5.0
_WORKER_RESTARTS = 3
# Points of the published map at most (3 MB a message): a map of millions of voxels is thinned.
MAP_MAX_POINTS = 262_144


class MapLike(Protocol):
    """What the node needs of a map (`supportnode.node.map.VoxelMap`). A map may also have
    an int ``version`` that changes whenever its points may have: the node then skips the
    detection of a map unchanged since the previous one (its result is the same)."""

    def integrate(self, points: np.ndarray, pose: np.ndarray, stamp: float) -> Any: ...
    def points(self) -> np.ndarray: ...
    def stats(self) -> dict[str, int]: ...


# A map may also defer a scan's clearing: ``integrate(..., defer_clear=True)`` then only merges,
# ``finish()`` runs the clearing (returning what it removed, a Touched-like ``removed``) and
# ``clear_pending`` says whether one waits (`VoxelMap`). Maps without ``finish`` never defer.


@dataclass
class NodeOutput:
    """What one scan produced.

    surfaces, obstacles: the messages to publish; None when the scan only updated the map
    (``node.detection_rate``). timings: seconds per stage (gravity, map, points, surfaces,
    objects, free_space, track, messages, total). new_ids / gone_ids: stable ids that appeared /
    vanished, per kind ("surfaces", "obstacles"). incremental: detection ran on a crop of the map.
    reused: the map had not changed since the previous detection, whose result this is.
    items: the detection behind the messages (detection ids, not stable ids).
    """

    surfaces: SupportSurfaces | None
    obstacles: ObstacleClusters | None
    timings: dict[str, float] = field(default_factory=dict)
    new_ids: dict[str, list[int]] = field(default_factory=dict)
    gone_ids: dict[str, list[int]] = field(default_factory=dict)
    incremental: bool = False
    items: Items | None = None
    reused: bool = False
    surfaces_sent: bool = False  # published already, ahead of the obstacles (surfaces_first)


class _Decoded(NamedTuple):
    """A scan decoded as it came off the socket (``Subscriber``'s check), and how long that
    took, s."""

    cloud: PointCloud
    seconds: float


@dataclass
class _SurfaceOut:
    """The surfaces' part of a detection's output (see Node._surface_message)."""

    message: SupportSurfaces
    kept_ids: set[int]  # detection ids of the surfaces kept (below the sensor)
    sid: dict[int, int]  # detection id -> stable id of the kept surfaces
    new: list[int]  # stable ids that appeared
    gone: list[int]  # stable ids that vanished


@dataclass
class _Job:
    """The newest scan ingested into the map, waiting for detection."""

    pose: np.ndarray  # (4, 4) sensor -> map
    stamp: float
    frame: str
    generation: int  # of the map it went into (a reset starts a new one)
    t_recv: float = 0.0  # perf_counter when it was received (threaded spin)
    t_ready: float = 0.0  # perf_counter when it was merged and handed to detection
    merge: int = 0  # number of its merge into the map (Node._merges after it)


class Node(Closing):
    """The support-surface node (see the module docstring).

    params: the whole configuration (`DetectParams`; its ``node`` section for the node).
    map_factory: makes the map (default: `VoxelMap` of ``node.map``); called again by `reset`
    (a source that restarted), so it is a factory, not a map.
    incremental: detect only on the region a scan touched when that equals a full recompute.
    context: ZeroMQ context for the sockets (default: the shared instance).
    """

    def __init__(
        self,
        params: DetectParams | None = None,
        *,
        map_factory: Callable[[], MapLike] | None = None,
        incremental: bool = True,
        context: zmq.Context | None = None,
        logger: logging.Logger | None = None,
    ) -> None:
        self.params = params or DetectParams()
        self.cfg = self.params.node
        self.incremental = incremental
        self.log = logger or log
        self._map_factory = map_factory or (lambda: VoxelMap(self.cfg.map))
        self._context = context
        self.latency = LatencyWindow()
        self.counters: dict[str, int] = {
            "scans_received": 0,
            "scans_processed": 0,
            "scans_dropped": 0,
            "scans_rejected": 0,
            "detections": 0,
            "incremental_detections": 0,
            "detections_reused": 0,
            "time_jumps": 0,
            "points_nonfinite": 0,
            "gravity_failures": 0,
            "gravity_outliers": 0,
            "diagnostics_sent": 0,
            "diagnostics_failures": 0,
            "maps_sent": 0,
            "map_failures": 0,
            "detections_skipped": 0,
            "worker_detections": 0,
            "worker_failures": 0,
        }
        self.rejects: dict[str, int] = {}
        self.last_reject = ""
        self._reject_log = RateLimitedLog(self.log, self.cfg.reject_log_period)
        # Its own limit: a flood of rejects must not hide an internal error, nor the reverse.
        self._error_log = RateLimitedLog(self.log, self.cfg.reject_log_period)
        self._stream_log = RateLimitedLog(self.log, self.cfg.reject_log_period)
        self._intake = Intake(self.cfg)  # the scan stream's checks: receiving thread
        self._sub: bus.Subscriber | None = None
        self._pub: bus.Publisher | None = None
        self._stop = threading.Event()
        self._diag_seq = 0
        self._map_seq = 0
        self._posed, self._frame = False, "map"
        # Guards the map, the pending region and the gravity estimate between the receiving
        # thread and the detection thread of a pipelined spin (uncontended in process()).
        self._lock = threading.RLock()
        # Guards the trackers and the previous detection against a reset. Not the map lock:
        # a detection finishing while the next scan merges (20-30 ms under the map lock)
        # would wait for it.
        self._track_lock = threading.Lock()
        self._pub_lock = threading.Lock()
        self._job_ready = threading.Condition()
        self._job: _Job | None = None
        self._detecting = False  # the detection thread has taken a job and works on it
        self._scan_period: float | None = None  # running mean of the time between scans, s
        self._last_recv: float | None = None
        self._ingest_time: float | None = None  # running mean of receive to merged, s
        self._generation = 0
        self._merges = 0  # scans merged into the map (any map: not reset)
        self._worker: DetectionWorker | None = None
        self._worker_restart_at: float | None = None  # monotonic time of the next start
        self._worker_starts = 0
        self._worker_logged: int | None = None  # pid of the worker announced in the log
        self.reset()

    # ------------------------------------------------------------------ state

    def reset(self) -> None:
        """Forget the map, the ids and the previous detection. The map frame's up direction
        (fused from the scans' gravity or estimated) stays, as do the scan stream's
        checks (its timeline and seq): a source that restarted keeps its frames."""
        with self._track_lock:
            self._reset()

    def _reset(self) -> None:
        self.map: MapLike = self._map_factory()
        self.surface_tracker = SurfaceTracker(min_iou=0.2, height_tolerance=0.05, max_misses=3)
        self.cluster_tracker = ClusterTracker(cell_size=0.02, min_iou=0.2, max_misses=3)
        if not hasattr(self, "gravity"):
            self.gravity = Gravity(self.params)
        self._items: Items | None = None
        self._items_rotation: np.ndarray | None = None
        self._items_source: tuple[object, int | None] = (None, None)  # map and its version
        self._memo = Memo()  # per-cluster results of the previous detection
        self._last_stamp: float | None = None
        self._last_detect: float | None = None
        self._out_seq = 0
        self._last_counts = (0, 0)
        self._pending: tuple[np.ndarray, np.ndarray] | None = None
        self._generation += 1

    # ------------------------------------------------------------------ in-process

    def process(self, cloud: PointCloud) -> NodeOutput:
        """Run one scan through gravity, map, detection and tracking; returns the messages.

        Raises InputError for a scan the node cannot use (no finite points, out of the map's
        range: `supportnode.node.intake.scan_problem`); the map is then unchanged.
        """
        problem = scan_problem(cloud, self._intake.limit)
        if problem is not None:
            raise InputError(f"scan seq {cloud.seq}: {problem.text}")
        return self._process(cloud)

    def _process(self, cloud: PointCloud) -> NodeOutput:
        """`process` of a scan the intake admitted."""
        t_start = time.perf_counter()
        timings: dict[str, float] = {}
        job = self._ingest(cloud, timings)
        if not self._detection_due(job.stamp):
            timings["total"] = time.perf_counter() - t_start
            self.latency.add_all(timings)
            return NodeOutput(None, None, timings)
        out = self._detect_job(job, timings)
        assert out is not None  # one thread: no reset can happen during the detection
        timings["total"] = time.perf_counter() - t_start
        self.latency.add_all(timings)
        return out

    def _ingest(self, cloud: PointCloud, timings: dict[str, float], defer: bool = False) -> _Job:
        """Gravity and map update of one scan; the region it touched joins the pending region
        that the next detection recomputes. Holds the map lock. defer: leave the scan's
        clearing pending in the map (see `_finish_map`), when the map can."""
        if cloud.count == 0:
            raise InputError("scan has no finite points")  # admitted scans have some
        with self._lock:
            stamp = float(cloud.stamp)
            if self._last_stamp is not None and stamp < self._last_stamp - _TIME_JUMP:
                self.counters["time_jumps"] += 1
                self._stream_log.warning(
                    f"scan stamp {stamp:.3f} is before the previous {self._last_stamp:.3f}: "
                    "source restarted, map reset"
                )
                self.reset()
            self.counters["points_nonfinite"] += int(cloud.dropped_nonfinite)
            pose = np.eye(4)
            if cloud.pose is not None:
                pose[:3, :3] = quaternion_matrix(cloud.pose.rotation)
                pose[:3, 3] = cloud.pose.translation

            t = time.perf_counter()
            failures = self.gravity.failures
            verdict = self.gravity.update(cloud, pose[:3, :3], cloud.points)
            self.counters["gravity_failures"] += self.gravity.failures - failures
            self._gravity_verdict(cloud, verdict)
            timings["gravity"] = time.perf_counter() - t

            t = time.perf_counter()
            # The previous scan's clearing, when nothing ran it yet: before this merge.
            self._finish_map()
            if defer and hasattr(self.map, "finish"):
                touched = self.map.integrate(cloud.points, pose, stamp, defer_clear=True)
            else:
                touched = self.map.integrate(cloud.points, pose, stamp)
            self._last_stamp = stamp
            self._merges += 1
            self._pending_region(touched)
            timings["map"] = time.perf_counter() - t
            self.counters["scans_processed"] += 1
            frame = self.cfg.frame_id if cloud.pose is not None else cloud.frame_id
            self._posed, self._frame = cloud.pose is not None, cloud.frame_id
            return _Job(pose, stamp, frame, self._generation, merge=self._merges)

    def _gravity_verdict(self, cloud: PointCloud, verdict: Verdict) -> None:
        """Count a scan's gravity outlier; log the first one and every new up adopted."""
        if verdict is Verdict.OUTLIER:
            self.counters["gravity_outliers"] += 1
            if self.counters["gravity_outliers"] == 1:
                self.log.warning(
                    "%s: scan seq %d: its gravity is more than %g deg from the map's up %s "
                    "(%s): not used (logged once; counted in gravity_outliers)",
                    self.cfg.name,
                    cloud.seq,
                    self.cfg.gravity_max_angle_deg,
                    np.round(self.gravity.up, 3).tolist(),
                    self.gravity.source,
                )
        elif verdict is Verdict.ADOPTED:
            self.log.info(
                "%s: the map's up is %s, from %d scans' gravity that agree",
                self.cfg.name,
                np.round(self.gravity.up, 3).tolist(),
                self.cfg.gravity_min_agreeing,
            )

    def _detection_due(self, stamp: float) -> bool:
        rate = self.cfg.detection_rate
        due = (
            rate <= 0 or self._last_detect is None or stamp - self._last_detect >= 1.0 / rate - 1e-6
        )
        if due:
            self._last_detect = stamp
        return due

    def _touched_box(self, touched: Any, rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """x, y box in the detection frame of what ``touched`` (map frame) changed."""
        lo, hi = np.asarray(touched.lo, float), np.asarray(touched.hi, float)
        corners = []
        if np.all(lo <= hi):
            corners.append(np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(3, -1).T)
        removed = np.asarray(getattr(touched, "removed", np.zeros((0, 3))), float)
        if len(removed):
            size = float(self.cfg.map.voxel_size)
            rlo, rhi = removed.min(axis=0) * size, (removed.max(axis=0) + 1) * size
            corners.append(np.array(np.meshgrid(*zip(rlo, rhi, strict=True))).reshape(3, -1).T)
        if not corners:
            return np.full(2, np.inf), np.full(2, -np.inf)
        c = np.concatenate(corners) @ rotation.T
        return c[:, :2].min(axis=0), c[:, :2].max(axis=0)

    def _pending_region(self, touched: Any) -> None:
        lo, hi = self._touched_box(touched, self.gravity.rotation)
        if self._pending is not None:
            lo, hi = np.minimum(lo, self._pending[0]), np.maximum(hi, self._pending[1])
        self._pending = (lo, hi)

    def _finish_map(self, merge: int | None = None) -> None:
        """Run the clearing that the map's last merge left pending (``node.defer_clear``), if
        any; what it removed joins the pending region, so the next detection recomputes there
        (the map's version changed with it, so no detection is reused across it). merge: only
        if the last merge is still that one (`_Job.merge`: a detection's scan; a newer one is
        the receiving thread's to clear, and after a reset the pending clearing went with the
        old map). Call with the map lock held."""
        m = self.map
        if (merge is not None and merge != self._merges) or not getattr(m, "clear_pending", False):
            return
        t = time.perf_counter()
        done = m.finish()
        if len(done.removed):
            self._pending_region(done)
        self.latency.add("clear", time.perf_counter() - t)

    def _detect_job(
        self,
        job: _Job,
        timings: dict[str, float],
        publish_surfaces: Callable[[SupportSurfaces], None] | None = None,
    ) -> NodeOutput | None:
        """Detection on the map as it is now, for the newest ingested scan ``job``.

        publish_surfaces: when given, a full detection calls it with the SupportSurfaces
        message as soon as the surfaces and their free space are known (the obstacles are
        still being described); the result then has ``surfaces_sent``."""
        with self._lock:
            rotation = self.gravity.rotation
            region, self._pending = self._pending, None
            source = (self.map, getattr(self.map, "version", None))
        lo, hi = region if region is not None else (np.full(2, np.inf), np.full(2, -np.inf))
        # Not the sensor origin: the map holds points seen from many places, and the rule
        # "planes above the sensor are undersides" is applied below to every surface alike.
        items = None
        same_frame = self._items_rotation is not None and np.allclose(
            self._items_rotation, rotation, atol=1e-9
        )
        fetch_time = [0.0]
        # Scans with gravity in their pose (and no correction yet): the map frame is level.
        level = bool(np.array_equal(rotation, np.eye(3)))

        def fetch(blo: np.ndarray, bhi: np.ndarray, max_share: float) -> np.ndarray | None:
            t = time.perf_counter()
            with self._lock:
                pts = self.map.points_in_box(blo, bhi, rotation, max_share)
            if pts is not None:
                pts = pts if level else transform_points(pts, rotation)
                pts = pts[np.all((pts[:, :2] >= blo) & (pts[:, :2] <= bhi), axis=1)]
            fetch_time[0] += time.perf_counter() - t
            return pts

        sensor_z = float((rotation @ job.pose[:3, 3])[2])
        # Surfaces from here up are not published (see _surface_message): no free space.
        below = sensor_z - _UNDER_SENSOR_M
        # Detection is a function of the map's points alone: on an unchanged map (a robot
        # standing before a static scene) the previous one is the answer, unless the sensor
        # rose and surfaces that it left without free space are now below it.
        reused = (
            same_frame
            and self._items is not None
            and self._items.has_free_space_below(below)
            and source[1] is not None
            and self._items_source[0] is source[0]
            and self._items_source[1] == source[1]
        )
        if reused:
            items = self._items
        elif self.incremental and self._items is not None and same_frame:
            items = incremental.regional_from(
                fetch, self._items, lo, hi, self.params, free_below=below
            )
        is_incremental = items is not None and not reused
        early: list[_SurfaceOut] = []
        if items is None:
            t = time.perf_counter()
            with self._lock:
                raw = self.map.points()
                deferred = bool(getattr(self.map, "clear_pending", False))
            points = raw if level else transform_points(raw, rotation)
            fetch_time[0] += time.perf_counter() - t
            on_surfaces = None
            if publish_surfaces is not None:

                def on_surfaces(part: Items) -> None:
                    if early:  # a worker that died after sending them: redone in this thread
                        return
                    with self._track_lock:
                        if job.generation != self._generation:
                            return  # reset meanwhile: the final result is dropped too
                        early.append(
                            self._surface_message(part, sensor_z, job.stamp, job.frame, timings)
                        )
                    publish_surfaces(early[0].message)

            after_send = None
            if deferred:

                def after_send() -> None:
                    # The map's points are with the worker: its clearing now, beside the
                    # detection, not before the next merge.
                    self._finish_map_safely(job.merge, wait=False)

            items = self._full(points, on_surfaces, after_send, below)
            if items is None:
                return None  # stopped while the worker was detecting
        if not reused:
            timings["points"] = fetch_time[0]
            timings.update({k: v for k, v in items.timings.items()})
        with self._track_lock:  # a reset (source restarted) must not interleave with this
            if job.generation != self._generation:
                return None  # the map was reset while this ran: the result is stale
            self._items, self._items_rotation, self._items_source = items, rotation, source
            self.counters["detections"] += 1
            self.counters["incremental_detections"] += int(is_incremental)
            self.counters["detections_reused"] += int(reused)
            out = self._messages(
                items,
                sensor_z,
                job.stamp,
                job.frame,
                timings,
                is_incremental,
                early[0] if early else None,
            )
            out.reused = reused
            out.surfaces_sent = bool(early)
            return out

    def _full(
        self,
        points: np.ndarray,
        on_surfaces: Callable[[Items], None] | None = None,
        after_send: Callable[[], None] | None = None,
        free_below: float | None = None,
    ) -> Items | None:
        """Full detection on (N, 3) detection-frame points: in the worker process when it
        is up, else in this thread. None when the node stopped during the detection.
        on_surfaces, free_below: see `incremental.full`. after_send: called once the worker has the
        points, while it detects (`DetectionWorker.detect`'s on_sent); not called when the
        detection runs in this thread."""
        self._start_worker_when_due()
        w = self._worker
        try:
            if w is not None and w.ready():
                if self._worker_logged != w.pid:
                    self._worker_logged = w.pid
                    self.log.info("detection worker ready (pid %d)", w.pid)
                items = w.detect(
                    points, self._stop, on_surfaces, on_sent=after_send, free_below=free_below
                )
                self.counters["worker_detections"] += 1
                return items
        except WorkerError as err:
            if self._stop.is_set():
                return None
            self._worker = None
            w.close()
            self.counters["worker_failures"] += 1
            again = self._worker_starts <= _WORKER_RESTARTS
            self.log.warning(
                "%s; detecting in the node's thread%s",
                err,
                f", restart in {_WORKER_RESTART_S:g} s" if again else " from now on",
            )
            if again:
                self._worker_restart_at = time.monotonic() + _WORKER_RESTART_S
        return incremental.full(
            points, self.params, memo=self._memo, on_surfaces=on_surfaces, free_below=free_below
        )

    def _start_worker_when_due(self) -> None:
        due = self._worker_restart_at
        if due is None or time.monotonic() < due or self._stop.is_set():
            return
        self._worker_restart_at = None
        self._worker_starts += 1
        try:
            self._worker = DetectionWorker.start(self.params)
        except WorkerError as err:
            self.log.warning("%s; detecting in the node's thread", err)

    def _surface_message(
        self, items: Items, sensor_z: float, stamp: float, frame: str, timings: dict[str, float]
    ) -> _SurfaceOut:
        """Stable ids and the SupportSurfaces message of a detection's surfaces (its clusters
        are not needed: free space is in ``items.free``). Call with the track lock held."""
        t = time.perf_counter()
        # Horizontal planes above the sensor are ceilings and undersides, not supports.
        keep = [s for s in items.surfaces if s.height < sensor_z - _UNDER_SENSOR_M]
        kept_ids = {s.id for s in keep}
        s_up = self.surface_tracker.update_surfaces(keep)
        sid = {s.id: int(i) for s, i in zip(keep, s_up.ids, strict=True)}
        timings["track"] = timings.get("track", 0.0) + time.perf_counter() - t

        t = time.perf_counter()
        tracks = self.surface_tracker.tracks
        safe = [
            is_safe(
                s, self.params.safe, tracks.get(int(i), {}).get("hits", 0), self.cfg.safe_min_hits
            )
            for s, i in zip(keep, s_up.ids, strict=True)
        ]
        self._out_seq += 1
        free = [f for f in items.free if f.surface_id in kept_ids]
        message = SupportSurfaces.from_detection(
            keep, free, stamp, frame, self._out_seq, ids=[int(i) for i in s_up.ids], safe=safe
        )
        timings["messages"] = timings.get("messages", 0.0) + time.perf_counter() - t
        return _SurfaceOut(message, kept_ids, sid, list(s_up.new), list(s_up.gone))

    def _messages(
        self,
        items: Items,
        sensor_z: float,
        stamp: float,
        frame: str,
        timings: dict[str, float],
        is_incremental: bool,
        surface_out: _SurfaceOut | None = None,
    ) -> NodeOutput:
        """Both messages of a detection; surface_out: its surfaces' part, when already made."""
        so = surface_out or self._surface_message(items, sensor_z, stamp, frame, timings)
        t = time.perf_counter()
        surface_of = np.array(
            [
                so.sid.get(c.surface_id, -1) if c.surface_id is not None else -1
                for c in items.clusters
            ],
            dtype=np.int64,
        )
        c_up = self.cluster_tracker.update_clusters(items.clusters, surface_of)
        timings["track"] = timings.get("track", 0.0) + time.perf_counter() - t

        t = time.perf_counter()
        clusters = [
            c if c.surface_id is None or c.surface_id in so.kept_ids else _unsupported(c)
            for c in items.clusters
        ]
        obstacles = ObstacleClusters.from_detection(
            clusters,
            stamp,
            frame,
            self._out_seq,
            ids=[int(i) for i in c_up.ids],
            surface_ids=so.sid,
            points=items.cluster_points,
        )
        timings["messages"] = timings.get("messages", 0.0) + time.perf_counter() - t
        self._last_counts = (len(so.kept_ids), len(clusters))
        return NodeOutput(
            so.message,
            obstacles,
            timings,
            new_ids={"surfaces": so.new, "obstacles": list(c_up.new)},
            gone_ids={"surfaces": so.gone, "obstacles": list(c_up.gone)},
            incremental=is_incremental,
            items=items,
        )

    # ------------------------------------------------------------------ wire

    def handle(self, frames: Any) -> NodeOutput | None:
        """Decode one received message and process it; a message the node cannot use is
        counted in ``rejects`` by reason, logged (rate-limited) and None is returned."""
        msg, decode = self._decoded(frames)
        if msg is None:
            return None
        try:
            out = self._process(msg)
        except SupportNodeError as err:
            self._reject("unusable", f"scan seq {msg.seq}: {err}")
            return None
        except Exception as err:
            self._internal_error(f"scan seq {msg.seq}", err)
            return None
        out.timings["decode"] = decode
        self.latency.add("decode", decode)
        return out

    def _check_scan(self, frames: Any) -> _Decoded | None:
        """The scan subscriber's check: a message is decoded as it comes off the socket, so
        that only usable scans take a place in the newest-scans queue (a malformed message
        after a scan must not push it out)."""
        t = time.perf_counter()
        try:
            msg = self._decode(frames)
        except Exception as err:  # a decoder bug must not end the node's receiving loop
            self._internal_error("decoding", err)
            return None
        return None if msg is None else _Decoded(msg, time.perf_counter() - t)

    def _decoded(self, frames: Any) -> tuple[PointCloud | None, float]:
        """(scan or None, seconds it took to decode) of raw frames or a `_Decoded`."""
        if isinstance(frames, _Decoded):
            return frames.cloud, frames.seconds
        t = time.perf_counter()
        msg = self._decode(frames)
        return msg, time.perf_counter() - t

    def _decode(self, frames: Any) -> PointCloud | None:
        """The scan in ``frames``, or None (counted and logged) when the intake rejects it."""
        got = self._intake.admit(frames)
        if isinstance(got, Reject):
            self._reject(got.reason, got.text)
            return None
        return got

    def _reject(self, reason: str, text: str, log: RateLimitedLog | None = None) -> None:
        """Count a scan not used under ``reason``; log it (rate-limited)."""
        self.counters["scans_rejected"] += 1
        self.rejects[reason] = self.rejects.get(reason, 0) + 1
        self.last_reject = text
        if log is None:
            self._reject_log.warning(f"{self.cfg.name}: rejected a scan ({reason}): {text}")
        else:
            log.warning(f"{self.cfg.name}: internal error, {text}", exc_info=True)

    def _internal_error(self, where: str, err: Exception) -> None:
        """A bug met while handling a scan: counted as an internal_error reject, logged with
        its traceback at most once per ``node.reject_log_period``. Call from an except block."""
        self._reject("internal_error", f"{where}: {type(err).__name__}: {err}", self._error_log)

    def open(self) -> None:
        """Create the sockets (done by `spin`; in-process use needs none)."""
        if self._sub is not None:
            return
        curve = self._curve_keys()
        self._pub = bus.Publisher(
            self.cfg.pub_endpoint,
            bind=self.cfg.pub_bind,
            context=self._context,
            hwm=10,
            curve=None if curve is None else curve.results,
            watch=self._handshake_report("results"),
        )
        try:
            self._sub = bus.Subscriber(
                self.cfg.scan_endpoint,
                self.cfg.scan_topic,
                bind=self.cfg.scan_bind,
                keep_newest=self.cfg.queue,
                context=self._context,
                max_message_bytes=self.cfg.max_message_bytes,
                curve=None if curve is None else curve.scans,
                check=self._check_scan,
                watch=self._handshake_report("scans"),
            )
        except BaseException:
            self._pub.close()
            self._pub = None
            raise

    def _handshake_report(self, socket: str) -> Callable[[str], None]:
        """How a socket reports a failed handshake (`supportnode.handshake`): a log line."""
        return lambda line: self.log.warning("%s: %s %s", self.cfg.name, socket, line)

    def _handshake_counters(self) -> dict[str, int]:
        """Failed handshakes of the node's sockets, by socket and kind."""
        out = {}
        for name, sock in (("scans", self._sub), ("results", self._pub)):
            if sock is not None:
                for kind, n in sock.handshake_failures().items():
                    out[f"handshake_failures_{name}_{kind}"] = n
        return out

    def _curve_keys(self) -> NodeKeys | None:
        """CURVE keys of both sockets from ``curve_keys_dir`` when ``curve_enabled`` (the
        folder's layout: `supportnode.curve`)."""
        if not self.cfg.curve_enabled:
            return None
        return node_keys(self.cfg.curve_keys_dir, self.cfg.scan_bind)

    @property
    def pub_endpoint(self) -> str:
        """Resolved result endpoint (the real port after binding ``tcp://host:*``)."""
        return self._pub.endpoint if self._pub is not None else self.cfg.pub_endpoint

    @property
    def scan_endpoint(self) -> str:
        """Resolved scan endpoint."""
        return self._sub.endpoint if self._sub is not None else self.cfg.scan_endpoint

    def stop(self) -> None:
        """Ask `spin` to return (thread-safe, and safe from a signal handler)."""
        self._stop.set()

    def spin(self, duration: float | None = None, handle_signals: bool = True) -> None:
        """Receive scans and publish results until `stop`, SIGINT/SIGTERM or ``duration`` s.

        Keeps only the newest ``node.queue`` scans when processing falls behind; publishes
        Diagnostics every ``node.diagnostics_period`` seconds. Signal handlers are installed
        only from the main thread, and restored on return.
        """
        self.open()
        assert self._sub is not None and self._pub is not None
        restore: dict[int, Any] = {}
        if handle_signals and threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                restore[sig] = signal.signal(sig, lambda *_: self._stop.set())
        self._stop.clear()
        end = None if duration is None else time.monotonic() + duration
        period = self.cfg.diagnostics_period
        next_diag = time.monotonic() + period
        next_map = time.monotonic() + self.cfg.map_period
        self.log.info(
            "%s: scans from %s (topic %s), results on %s",
            self.cfg.name,
            self.scan_endpoint,
            self.cfg.scan_topic,
            self.pub_endpoint,
        )
        worker = None
        if self.cfg.pipeline:
            self._job = None
            self._detecting = False
            if self.cfg.detect_process:
                self._worker_restart_at, self._worker_starts = time.monotonic(), 0
                self._start_worker_when_due()  # the worker imports while scans arrive
            worker = threading.Thread(target=self._detect_loop, name="detect", daemon=True)
            worker.start()
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                if end is not None and now >= end:
                    break
                wait = min(_POLL_S, max(0.0, next_diag - now))
                oversized = self._sub.oversized
                frames = self._sub.recv(wait)
                if self._sub.oversized != oversized:
                    for _ in range(self._sub.oversized - oversized):
                        size = self._sub.last_oversized[1] if self._sub.last_oversized else 0
                        self._reject(
                            "oversized",
                            f"message of {size} bytes exceeds max_message_bytes "
                            f"{self.cfg.max_message_bytes}",
                        )
                if frames is not None:
                    # Received when decoding began: the subscriber's check decoded it (a
                    # _Decoded) as it came off the socket.
                    t_recv = time.perf_counter() - frames.seconds
                    if worker is not None:
                        self._ingest_for_detection(frames, t_recv)
                    else:
                        out = self.handle(frames)
                        if out is not None and out.surfaces is not None:
                            self._publish(out, t_recv)
                if time.monotonic() >= next_diag:
                    self._publish_safely("diagnostics", self.publish_diagnostics)
                    next_diag = time.monotonic() + period
                if self.cfg.map_period > 0 and time.monotonic() >= next_map:
                    self._publish_safely("map", self.publish_map)
                    next_map = time.monotonic() + self.cfg.map_period
        finally:
            self._stop.set()
            if worker is not None:
                with self._job_ready:
                    self._job_ready.notify_all()
                worker.join(5.0)
                self._finish_map_safely()  # the map as integrate would leave it
            if self._worker is not None:
                self._worker.close()
                self._worker = None
            self._worker_restart_at = None
            for sig, old in restore.items():
                signal.signal(sig, old)

    # ------------------------------------------------------------------ pipelined spin

    def _ingest_for_detection(self, frames: Any, t_recv: float) -> None:
        """Receiving thread: decode, merge into the map, hand the newest scan to detection."""
        msg, decode = self._decoded(frames)
        if msg is None:
            return
        timings: dict[str, float] = {"decode": decode}
        try:
            job = self._ingest(msg, timings, defer=self.cfg.defer_clear)
        except SupportNodeError as err:
            self._reject("unusable", f"scan seq {msg.seq}: {err}")
            return
        except Exception as err:
            self._internal_error(f"scan seq {msg.seq}", err)
            return
        self.latency.add_all(timings)
        if not self._detection_due(job.stamp):
            self._finish_map_safely()  # no detection takes this scan: its clearing now
            return
        job.t_recv, job.t_ready = t_recv, time.perf_counter()
        if self._last_recv is not None:
            dt = t_recv - self._last_recv
            self._scan_period = (
                dt if self._scan_period is None else 0.8 * self._scan_period + 0.2 * dt
            )
        self._last_recv = t_recv
        took = job.t_ready - t_recv
        self._ingest_time = (
            took if self._ingest_time is None else 0.8 * self._ingest_time + 0.2 * took
        )
        with self._job_ready:
            if self._job is not None:
                # Detection is still busy with an older scan: that one's region stays pending,
                # and the next detection covers both (the map has every scan either way).
                self.counters["detections_skipped"] += 1
            self._job = job
            busy = self._detecting
            self._job_ready.notify()
        if busy:
            # The detector is busy: this scan's clearing now, before the next scan comes and
            # while the detector could not take this one anyway (it takes the map's state as
            # it is when it gets to it).
            self._finish_map_safely()

    def _detect_loop(self) -> None:
        """Detection thread: detect on the newest ingested scan, publish, repeat.

        A scan that was merged while the previous detection ran has waited for the detector
        and is old; when scans come regularly, the next one is due within a scan period, and
        detecting that one instead gives results that are as frequent but fresher (latency =
        merge + detection, with no wait for a busy detector in it). So the detector waits for
        it, up to one and a half periods after the old one arrived, or one period and one and a
        half merges when merging takes longer than a third of a period (at most
        ``_FRESH_WAIT_MAX_S``), and takes the old scan if none comes: the last scan of a stream
        is always detected. A scan merged after the detector became free has not waited (it
        arrived during the detection, but its merge took longer): it is taken at once."""
        done_at = 0.0
        while True:
            with self._job_ready:
                while self._job is None and not self._stop.is_set():
                    self._job_ready.wait(_POLL_S)
                if self._stop.is_set():
                    return
                job = self._job
                period, ingest = self._scan_period, self._ingest_time or 0.0
                if job.t_ready < done_at and period is not None:
                    # The next scan is due a period after this one and ready a merge later.
                    # A fixed 1.5 periods missed it whenever the merge took half a period,
                    # and the latency jumped by a period.
                    wait = max(1.5 * period, period + 1.5 * ingest)
                    deadline = job.t_recv + min(wait, _FRESH_WAIT_MAX_S)
                    while self._job is job and not self._stop.is_set():
                        left = deadline - time.perf_counter()
                        if left <= 0:
                            break
                        self._job_ready.wait(min(left, _POLL_S))
                    if self._stop.is_set():
                        return
                job, self._job = self._job, None
                self._detecting = True
            timings: dict[str, float] = {}
            t = time.perf_counter()
            early = None
            if self.cfg.surfaces_first:

                def early(msg: SupportSurfaces, t_recv: float = job.t_recv) -> None:
                    self._publish_surfaces(msg, t_recv)

            try:
                out = self._detect_job(job, timings, early)
            except Exception as err:
                self._internal_error(f"detection of the scan at {job.stamp:.3f}", err)
                out = None
            done_at = time.perf_counter()
            if out is not None:
                timings["detect"] = time.perf_counter() - t
                timings["total"] = time.perf_counter() - job.t_recv  # receive to results, in node
                self.latency.add_all(timings)
                self._publish(out, job.t_recv)
            # The scan's clearing if no detection ran it beside the worker (detection reused,
            # regional or in this thread): now, rather than before the next merge. (A scan
            # merged meanwhile had its clearing run by the receiving thread, and one being
            # merged runs it first.)
            self._finish_map_safely(job.merge, wait=False)
            with self._job_ready:
                self._detecting = False

    def _finish_map_safely(self, merge: int | None = None, wait: bool = True) -> None:
        """`_finish_map` from spin's threads, taking the map lock; an error is logged and
        counted, not raised (the clearing is not retried). wait: False gives up when the
        lock is taken (the receiving thread merging the next scan, which runs the pending
        clearing first: the detection thread does not wait for a merge)."""
        if not self._lock.acquire(blocking=wait):
            return
        try:
            self._finish_map(merge)
        except Exception as err:
            self._internal_error("clearing", err)
        finally:
            self._lock.release()

    def _publish(self, out: NodeOutput, t_recv: float) -> None:
        """Send a detection's messages: obstacles then surfaces, or with node.surfaces_first
        surfaces (unless they went out ahead, ``surfaces_sent``) then obstacles."""
        assert self._pub is not None and out.surfaces is not None and out.obstacles is not None
        t = time.perf_counter()
        obstacles = out.obstacles.encode(self.cfg.obstacles_topic)
        surfaces = None if out.surfaces_sent else out.surfaces.encode(self.cfg.surfaces_topic)
        with self._pub_lock:  # ZeroMQ sockets are not thread-safe
            if surfaces is not None and self.cfg.surfaces_first:
                self._pub.send(surfaces)  # a reused or regional detection: one order always
                surfaces = None
            # Else surfaces last: a planner that reacts to surfaces has their obstacles.
            self._pub.send(obstacles)
            if surfaces is not None:
                self._pub.send(surfaces)
        out.timings["publish"] = time.perf_counter() - t
        self.latency.add("publish", out.timings["publish"])
        done = time.perf_counter() - t_recv
        self.latency.add("receive_to_publish", done)
        if surfaces is not None:
            self.latency.add("receive_to_surfaces", done)

    def _publish_surfaces(self, msg: SupportSurfaces, t_recv: float) -> None:
        """Send a SupportSurfaces message ahead of its obstacles (node.surfaces_first)."""
        assert self._pub is not None
        frames = msg.encode(self.cfg.surfaces_topic)
        with self._pub_lock:
            self._pub.send(frames)
        self.latency.add("receive_to_surfaces", time.perf_counter() - t_recv)

    def diagnostics(self) -> Diagnostics:
        """The current Diagnostics message (counters, latencies, gauges, status)."""
        if self._sub is not None:
            self.counters["scans_received"] = self._sub.received
            self.counters["scans_dropped"] = self._sub.dropped
        counters = dict(self.counters)
        counters.update(self._intake.counters())
        counters.update(self._handshake_counters())
        counters.update({f"rejected_{k}": v for k, v in self.rejects.items()})
        stats = self.map.stats()
        counters.update({f"map_{k}": int(v) for k, v in stats.items()})
        up = self.gravity.up
        gauges = {
            "map_voxels": float(stats.get("voxels", 0)),
            "surfaces": float(self._last_counts[0]),
            "obstacles": float(self._last_counts[1]),
            "gravity_tilt_deg": self.gravity.tilt_deg,
            "gravity_up_x": float(up[0]),
            "gravity_up_y": float(up[1]),
            "gravity_up_z": float(up[2]),
            "gravity_source": float(SOURCES.index(self.gravity.source)),
            "rss_mb": _rss_mb(),
            "rss_mb_worker": self._worker.rss_mb() if self._worker is not None else math.nan,
        }
        level, message = "ok", ""
        if self.counters["scans_processed"] == 0:
            level, message = "warn", f"no scans processed yet on topic {self.cfg.scan_topic}"
        if self.last_reject:
            level, message = "warn", f"last reject: {self.last_reject}"[:500]
        self._diag_seq += 1
        return Diagnostics(
            stamp=time.time(),
            node=self.cfg.name,
            level=level,
            message=message,
            counters=counters,
            latencies=self.latency.stats(),
            gauges={k: v for k, v in gauges.items() if math.isfinite(v)},
            seq=self._diag_seq,
        )

    def _publish_safely(self, what: str, publish: Callable[[], object]) -> None:
        """`publish_diagnostics` or `publish_map` from spin: an error is counted
        (``<what>_failures``) and logged (rate-limited), never the end of the node."""
        try:
            publish()
        except Exception as err:
            self.counters[f"{what}_failures"] += 1
            self._error_log.warning(
                f"{self.cfg.name}: {what} not sent: {type(err).__name__}: {err}",
                exc_info=not isinstance(err, SupportNodeError),
            )

    def publish_diagnostics(self) -> Diagnostics:
        """Send the current Diagnostics (sockets must be open); returns it."""
        if self._pub is None:
            raise InputError("publish_diagnostics needs open sockets (call open() or spin())")
        msg = self.diagnostics()
        with self._pub_lock:
            self._pub.send(msg.encode(self.cfg.diagnostics_topic))
        self.counters["diagnostics_sent"] += 1
        self.last_reject = ""
        return msg

    def map_cloud(self) -> PointCloud | None:
        """The map as a PointCloud: one point per voxel (its points' mean, at most
        MAP_MAX_POINTS), in the results' frame; None before the first scan. A clearing the
        last merge left pending (``node.defer_clear``) runs first: the map a subscriber sees
        has every merged scan's free space cleared. Call with the map lock held."""
        if self._last_stamp is None or not hasattr(self.map, "centroids"):
            return None
        self._finish_map()
        pts = transform_points(self.map.centroids(MAP_MAX_POINTS), self.gravity.rotation)
        frame = self.cfg.frame_id if self._posed else self._frame
        self._map_seq += 1
        return PointCloud.from_xyz(pts.astype(np.float32), self._last_stamp, frame, self._map_seq)

    def publish_map(self) -> PointCloud | None:
        """Send `map_cloud` on ``node.map_topic`` (sockets must be open); returns it."""
        if self._pub is None:
            raise InputError("publish_map needs open sockets (call open() or spin())")
        with self._lock:
            msg = self.map_cloud()
        if msg is not None and msg.count:
            frames = msg.encode(self.cfg.map_topic)
            with self._pub_lock:
                self._pub.send(frames)
            self.counters["maps_sent"] += 1
        return msg

    def close(self) -> None:
        """Close the sockets (idempotent)."""
        for s in (self._sub, self._pub):
            if s is not None:
                s.close()
        self._sub = self._pub = None


def _unsupported(c: Any) -> Any:
    import dataclasses

    return dataclasses.replace(c, surface_id=None)


def _rss_mb() -> float:
    """Resident memory of this process in MiB (Linux /proc; peak RSS elsewhere)."""
    try:
        with open(f"/proc/{os.getpid()}/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
