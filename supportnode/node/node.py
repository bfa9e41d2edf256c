"""The node: scans in, support surfaces and the obstacles on them out, with diagnostics.

Who runs what (`spin`)::

    receiving thread                         mailbox            detecting thread
    subscriber -> intake (decode, checks)    (latest job)       NodeCore.detect
      -> NodeCore.ingest (gravity, map) ---> put / take ------>   detect_surfaces -> outbox
      -> diagnostics, map messages                                detect_objects -> outbox
                     \\------------------> outbox (owns the publishing socket) <-/

The receiving thread owns the subscriber, the intake, the gravity estimate and the map; the
detecting thread owns the trackers and the previous detection (both inside `NodeCore`). The
only hand-off is the one-job `Mailbox`: a scan merged while the detector is busy replaces the
waiting one (counted in ``detections_skipped``; the map has every scan); a detector behind
the sensor skips a scan's obstacles for a newer scan's surfaces (`supportnode.node.detector`).
Each side writes its own counters; `diagnostics` reads copies. `Node.process` is the same two
calls without threads or sockets (tests and embedding): its results equal the published ones
on the same scans.

    with Node(load_config("config/default.yaml")) as node:
        out = node.process(cloud)            # NodeOutput: SupportSurfaces, ObstacleClusters
    with Node(params) as node:
        node.spin()                          # until SIGINT/SIGTERM or node.stop()

Frames: a scan's ``pose`` takes its points to the map frame (none: the cloud's frame is the
map's). Results are in the map frame rotated by the gravity correction, named
``NodeParams.frame_id``. A surface is ``safe`` (`detection.policy.is_safe`) once seen in
``node.safe_min_hits`` detections in a row under one id."""

from __future__ import annotations

import logging
import signal
import threading
import time
from collections.abc import Callable
from typing import Any

import zmq

from supportnode import bus
from supportnode._closing import Closing
from supportnode.errors import InputError, SupportNodeError
from supportnode.geometry.transform import quaternion_matrix
from supportnode.msgs import Diagnostics, PointCloud
from supportnode.node.admission import Admission
from supportnode.node.core import MapLike, NodeCore, NodeOutput
from supportnode.node.detector import Detector
from supportnode.node.diagnostics import diagnostics_message
from supportnode.node.gravity import Gravity
from supportnode.node.intake import scan_problem
from supportnode.node.latency import LatencyWindow
from supportnode.node.mailbox import Doorbell, Mailbox
from supportnode.node.outbox import Outbox
from supportnode.node.receiver import POLL_S, Receiver
from supportnode.node.rehearsal import warm_up
from supportnode.node.sockets import NodeSockets
from supportnode.params import DetectParams

__all__ = ["MapLike", "Node", "NodeOutput", "quaternion_matrix"]

log = logging.getLogger("supportnode.node")

# Points of the published map at most (3 MB a message): a map of millions of voxels is thinned.
MAP_MAX_POINTS = 262_144
Hook = Callable[[], None] | None  # `Node.spin`'s on_ready
# The receiving thread's own counters (fixed keys: see `supportnode.node.diagnostics`).
_OWN = ("diagnostics_sent", "diagnostics_failures", "maps_sent", "map_failures")


class Node(Closing):
    """The support-surface node (see the module docstring).

    params: the whole configuration (`DetectParams`; its ``node`` section for the node).
    map_factory: makes the map (default: `VoxelMap` of ``node.map``), again at each reset.
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
        self.log = logger or log
        self.core = NodeCore(
            self.params, map_factory=map_factory, incremental=incremental, logger=self.log
        )
        self.latency = LatencyWindow()
        self._wire = Admission(self.cfg, self.log)
        self._rejects = self._wire.rejects
        self._own = dict.fromkeys(_OWN, 0)
        self._sockets = NodeSockets(
            self.cfg,
            context,
            self._wire.check,
            lambda sock, line: self.log.warning("%s: %s %s", self.cfg.name, sock, line),
        )
        self._outbox: Outbox | None = None
        self._bell: Doorbell | None = None  # spin's: rung by the detector when surfaces are out
        self._mailbox = Mailbox()
        self._stop = threading.Event()
        self._ready = False  # kernels warmed, subscribed: the `ready` gauge
        self._diag_seq = 0
        self._map_seq = 0

    # ------------------------------------------------------------------ state

    @property
    def map(self) -> MapLike:
        return self.core.map

    @property
    def gravity(self) -> Gravity:
        return self.core.gravity

    @property
    def rejects(self) -> dict[str, int]:
        """Messages not used, by reason (a copy)."""
        return self._rejects.counts()

    @property
    def counters(self) -> dict[str, int]:
        """Both sides' counters, copied (what Diagnostics reports, without the map's)."""
        c = {
            "scans_received": self._sub.received if self._sub is not None else 0,
            "scans_dropped": self._sub.dropped if self._sub is not None else 0,
            "scans_rejected": self._rejects.total,
            "detections_skipped": self._mailbox.skipped,
            "obstacles_skipped": self._mailbox.obstacles_skipped,
        }
        for part in (self.core.ingest_counters, self.core.detect_counters, self._own):
            c.update(part.copy())  # fixed keys: a copy never meets a resize
        return c

    def reset(self) -> None:
        """Forget the map, the ids and the previous detection (the map frame's up and the
        scan stream's checks stay). In-process use; `spin` resets from its receiving thread."""
        self.core.reset()

    # ------------------------------------------------------------------ in-process

    def process(self, cloud: PointCloud) -> NodeOutput:
        """Run one scan through gravity, map, detection and tracking; returns the messages.

        Raises InputError for a scan the node cannot use (no finite points, out of the map's
        range: `supportnode.node.intake.scan_problem`); the map is then unchanged."""
        problem = scan_problem(cloud, self._wire.intake.limit)
        if problem is not None:
            raise InputError(f"scan seq {cloud.seq}: {problem.text}")
        return self._process(cloud)

    def _process(self, cloud: PointCloud) -> NodeOutput:
        """`process` of a scan the intake admitted: `ingest`, `settle`, then `detect`."""
        t_start = time.perf_counter()
        job = self.core.ingest(cloud)
        clear = self.core.settle()
        out = NodeOutput(None, None, {} if job is None else job.timings)
        out.timings["clear"] = clear
        if job is not None:
            out = self.core.detect(job)
        out.timings["total"] = time.perf_counter() - t_start
        self.latency.add_all(out.timings)
        return out

    # ------------------------------------------------------------------ wire

    def handle(self, frames: Any) -> NodeOutput | None:
        """Decode one received message and process it; a message the node cannot use is
        counted in ``rejects`` by reason, logged (rate-limited) and None is returned."""
        msg, decode = self._wire.decoded(frames)
        if msg is None:
            return None
        try:
            out = self._process(msg)
        except SupportNodeError as err:
            self._wire.reject("unusable", f"scan seq {msg.seq}: {err}")
            return None
        except Exception as err:
            self._wire.internal_error(f"scan seq {msg.seq}", err)
            return None
        out.timings["decode"] = decode
        self.latency.add("decode", decode)
        return out

    def open(self) -> None:
        """Create the sockets (done by `spin`; in-process use needs none)."""
        if self._sockets.open():
            assert self._sockets.pub is not None
            topics = (self.cfg.surfaces_topic, self.cfg.obstacles_topic)
            self._outbox = Outbox(self._sockets.pub, topics, self.latency)

    @property
    def _sub(self) -> bus.Subscriber | None:
        return self._sockets.sub

    @property
    def pub_endpoint(self) -> str:  # resolved: the real port after binding tcp://host:*
        return self._sockets.pub_endpoint

    @property
    def scan_endpoint(self) -> str:  # resolved
        return self._sockets.scan_endpoint

    def stop(self) -> None:
        """Ask `spin` to return (thread-safe, and safe from a signal handler)."""
        self._stop.set()

    # ------------------------------------------------------------------ spin

    def spin(
        self, duration: float | None = None, handle_signals: bool = True, on_ready: Hook = None
    ) -> None:
        """Receive scans and publish results until `stop`, SIGINT/SIGTERM or ``duration`` s.

        Compiles (or loads) the detection's kernels before subscribing, so the first scan is
        not slow, then calls ``on_ready`` (`supportnode run`: see `cli._process`); publishes
        Diagnostics every ``node.diagnostics_period`` seconds. Signal handlers are installed
        only from the main thread, and restored on return."""
        restore: dict[signal.Signals, Any] = {}
        if handle_signals and threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                restore[sig] = signal.signal(sig, lambda *_: self._stop.set())
        self._stop.clear()
        try:
            self._warm()
            self.open()
            if on_ready is not None:
                on_ready()
            self._ready = True
            self._bell = Doorbell()
            self._mailbox = Mailbox(on_sent=self._bell.ring)
            assert self._outbox is not None
            detecting = Detector(
                self.core, self._mailbox, self._outbox, self.latency, self._wire, POLL_S
            )
            detector = threading.Thread(
                target=detecting.run, args=(self._stop,), name="detect", daemon=True
            )
            detector.start()
            try:
                self._receive(duration)
            finally:
                self._stop.set()
                self._mailbox.close()
                detector.join(5.0)
                self._bell.close()
                self._bell = None
        finally:
            self._ready = False
            for sig, old in restore.items():
                signal.signal(sig, old)

    def _warm(self) -> None:
        """Compile (a fresh install: ~25 s on two cores) or load the kernels, saying so."""
        self.log.info(
            "%s: preparing kernels (the first run after an install compiles them: ~25 s on two cores)",
            self.cfg.name,
        )
        took = warm_up(self.params, self.cfg.threads or None)
        self.log.info("%s: kernels ready in %.2f s", self.cfg.name, took)

    def _receive(self, duration: float | None) -> None:
        """The receiving thread's loop (`Receiver`), diagnostics and the map when due."""
        assert self._sub is not None and self._bell is not None
        self.log.info(
            "%s: scans from %s (topic %s), results on %s",
            self.cfg.name,
            self.scan_endpoint,
            self.cfg.scan_topic,
            self.pub_endpoint,
        )
        receiver = Receiver(
            self.core, self._sub, self._wire, self._mailbox, self._bell, self.latency, self.cfg
        )
        start = time.monotonic()
        due = {"diag": start + self.cfg.diagnostics_period, "map": start + self.cfg.map_period}

        def periodic(now: float) -> float:
            if now >= due["diag"]:
                self._publish_safely("diagnostics", self.publish_diagnostics)
                due["diag"] = time.monotonic() + self.cfg.diagnostics_period
            if self.cfg.map_period > 0 and now >= due["map"]:
                self._publish_safely("map", self.publish_map)
                due["map"] = time.monotonic() + self.cfg.map_period
            return due["diag"]

        receiver.run(self._stop, None if duration is None else start + duration, periodic)

    # ------------------------------------------------------------------ diagnostics, map

    def diagnostics(self, last_reject: str | None = None) -> Diagnostics:
        """The current Diagnostics message (counters, latencies, gauges, status); the last
        reject's text in its message unless ``last_reject`` is given."""
        counters = self.counters
        counters.update(self._wire.intake.counters())
        counters.update(self._sockets.handshake_counters())
        self._diag_seq += 1
        surfaces, obstacles = self.core.last_counts
        return diagnostics_message(
            node=self.cfg.name,
            seq=self._diag_seq,
            counters=counters,
            rejects=self._rejects,
            map_stats=self.map.stats(),
            gravity=self.core.gravity,
            latency=self.latency,
            gauges={"surfaces": surfaces, "obstacles": obstacles, "ready": float(self._ready)},
            topic=self.cfg.scan_topic,
            last_reject=self._rejects.last if last_reject is None else last_reject,
        )

    def _publish_safely(self, what: str, publish: Callable[[], object]) -> None:
        """`publish_diagnostics` or `publish_map` from spin: an error is counted
        (``<what>_failures``) and logged (rate-limited), never the end of the node."""
        try:
            publish()
        except Exception as err:
            self._own[f"{what}_failures"] += 1
            self._wire.error_log.warning(
                f"{self.cfg.name}: {what} not sent: {type(err).__name__}: {err}",
                exc_info=not isinstance(err, SupportNodeError),
            )

    def publish_diagnostics(self) -> Diagnostics:
        """Send the current Diagnostics (sockets must be open); returns it."""
        if self._outbox is None:
            raise InputError("publish_diagnostics needs open sockets (call open() or spin())")
        msg = self.diagnostics(self._rejects.take_last())
        self._outbox.send(msg.encode(self.cfg.diagnostics_topic))
        self._own["diagnostics_sent"] += 1
        return msg

    def map_cloud(self) -> PointCloud | None:
        """The map as a PointCloud (`NodeCore.map_cloud`, at most MAP_MAX_POINTS); None
        before the first scan. Receiving side."""
        msg = self.core.map_cloud(MAP_MAX_POINTS, self._map_seq + 1)
        self._map_seq += msg is not None
        return msg

    def publish_map(self) -> PointCloud | None:
        """Send `map_cloud` on ``node.map_topic`` (sockets must be open); returns it."""
        if self._outbox is None:
            raise InputError("publish_map needs open sockets (call open() or spin())")
        msg = self.map_cloud()
        if msg is not None and msg.count:
            self._outbox.send(msg.encode(self.cfg.map_topic))
            self._own["maps_sent"] += 1
        return msg

    def close(self) -> None:
        """Close the sockets (idempotent)."""
        self._sockets.close()
        self._outbox = None
