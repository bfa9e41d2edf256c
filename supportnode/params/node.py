"""Parameters of the ZeroMQ node: endpoints, topics, rates, input limits, and its map.

The ``node`` section of the configuration (see `supportnode.params`); ``node.map`` is `MapParams`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from supportnode.params.base import param


@dataclass(frozen=True)
class MapParams:
    """The node's incremental voxel map: posed scans merged, aged, cropped around the sensor."""

    radius: float = param(
        20.0, "keep only voxels within this horizontal distance of the sensor", "m", min=0.1
    )
    max_age: float = param(
        10.0, "forget voxels not seen for this long (0: never by age)", "s", min=0.0
    )
    max_voxels: int = param(
        2_000_000, "cap on stored voxels; the oldest go first beyond it", min=1000
    )
    voxel_size: float = param(0.05, "edge of the map's voxels", "m", min=1e-3, max=1.0)
    clear_free_space: bool = param(
        True, "erase voxels that a new ray passes through (moved or removed objects)"
    )


@dataclass(frozen=True)
class NodeParams:
    """The ZeroMQ node: endpoints, topics, rates, input limits and its map.

    Endpoints are ZeroMQ addresses (tcp://host:port, ipc://path, inproc://name). Like a ROS
    topic fed by a sensor driver, the driver (or replay) binds its PUB socket and the node
    connects to it (scan_bind: false); the node binds the PUB socket its results go out on, and
    planners connect to it.
    """

    name: str = param("supportnode", "node name used in logs and diagnostics")
    scan_endpoint: str = param(
        "tcp://127.0.0.1:5555", "where the node subscribes to scans (a driver's PUB socket)"
    )
    scan_bind: bool = param(
        False, "bind the scan socket instead of connecting (when drivers connect to the node)"
    )
    scan_topic: str = param("scan", "topic of incoming PointCloud messages")
    pub_endpoint: str = param(
        "tcp://127.0.0.1:5556", "where the node publishes results (planners connect here)"
    )
    pub_bind: bool = param(True, "bind the result socket (false: connect to a forwarder)")
    surfaces_topic: str = param("surfaces", "topic of outgoing SupportSurfaces messages")
    obstacles_topic: str = param("obstacles", "topic of outgoing ObstacleClusters messages")
    diagnostics_topic: str = param("diagnostics", "topic of outgoing Diagnostics messages")
    detection_rate: float = param(
        0.0,
        "largest detection rate; scans in between only update the map (0: every scan)",
        "Hz",
        min=0.0,
        max=1000.0,
    )
    diagnostics_period: float = param(
        1.0, "time between Diagnostics messages", "s", min=0.01, max=3600.0
    )
    map_topic: str = param(
        "map", "topic of the map as a PointCloud (one point per voxel, results' frame)"
    )
    map_period: float = param(
        1.0, "time between map messages (0: never publish the map)", "s", min=0.0, max=3600.0
    )
    threads: int = param(
        0,
        "threads of the compiled kernels' parallel loops (0: numba's default, every core; the "
        "node shares the cores with SLAM and the driver)",
        min=0,
        max=256,
    )
    safe_min_hits: int = param(
        2,
        "a surface is safe only once seen in this many detections in a row under one id "
        "(and the safe section's rules hold)",
        min=1,
    )
    max_points: int = param(4_000_000, "scans with more points are rejected", min=1)
    max_message_bytes: int = param(
        64 * 1024 * 1024, "messages larger than this many bytes are rejected", min=1024
    )
    reject_log_period: float = param(
        5.0,
        "at most one log line per this period about rejected messages (and per kind of "
        "internal error)",
        "s",
        min=0.0,
    )
    max_stamp_jump: float = param(
        30.0,
        "a scan stamped more than this after the previous one, or before it, is rejected "
        "(stamp_jump) unless the next scan continues its timeline (a source that restarted)",
        "s",
        min=0.001,
        max=1e9,
    )
    gravity_max_angle_deg: float = param(
        15.0,
        "a scan's gravity (or IMU orientation) farther than this from the map's up is an "
        "outlier: counted, not used",
        "deg",
        min=0.1,
        max=90.0,
    )
    gravity_min_agreeing: int = param(
        3,
        "scans whose gravity agree (within gravity_max_angle_deg) before it replaces an "
        "assumed or estimated up",
        min=2,
        max=100,
    )
    map: MapParams = field(default_factory=MapParams)
    frame_id: str = param(
        "map",
        "frame of published results for scans with a pose: the map frame, rotated to gravity "
        "when a correction applies (scans without a pose: their own frame_id)",
    )
    curve_enabled: bool = param(
        False,
        "encrypt and authenticate the node's sockets with ZeroMQ CURVE (keys in curve_keys_dir)",
    )
    curve_keys_dir: str = param(
        "",
        "CURVE key folder: this node's server.key_secret, the scan driver's public key "
        "scan_server.key (the node connects for scans), subscribers/*.key (clients allowed "
        "to subscribe to results), drivers/*.key (drivers allowed to publish scans when "
        "scan_bind)",
    )
