"""Typed parameters of the geometry, one frozen dataclass per stage.

Each field carries metadata used by `supportnode.config` to document, parse and range-check it:
``unit`` (SI unit or ``""``), ``help`` (one line), and optional ``min`` / ``max`` (inclusive) or
``choices``. Defaults here are the built-in defaults (lowest precedence: defaults < YAML < --set).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


def param(default: Any, help: str, unit: str = "", **limits: Any) -> Any:
    """A dataclass field with documentation and limits for the configuration loader."""
    meta = {"help": help, "unit": unit, **limits}
    if isinstance(default, (list, tuple)):
        return field(default_factory=lambda: tuple(default), metadata=meta)
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class SurfaceParams:
    """Support-surface detection (Algorithm 1 of the report and the planar default)."""

    method: str = param(
        "planar",
        "'seed': the report's Algorithm 1 as published; 'planar': per-voxel plane fits, "
        "growth across height layers, area and width limits",
        choices=("seed", "planar"),
    )
    voxel_size: tuple[float, float, float] = param(
        (0.1, 0.1, 0.05), "voxel edge lengths vx, vy, vz", "m", min=1e-3, max=10.0
    )
    p_min: int = param(2, "a voxel counts only if it holds MORE than p_min points", min=0)
    psi_min: int = param(
        10, "seed method: a region is a surface only with at least psi_min voxels", min=1
    )
    connectivity: int = param(
        8, "horizontal neighbourhood for region growing: 4 or 8", choices=(4, 8)
    )
    max_tilt_deg: float = param(
        10.0,
        "planar: a voxel's fitted normal may deviate from +z by at most this",
        "deg",
        min=0.0,
        max=89.0,
    )
    max_roughness: float = param(
        0.012, "planar: largest rms distance of a voxel's points to its plane", "m", min=0.0
    )
    max_step: float = param(
        0.03,
        "planar: largest height change between adjacent voxels of one surface",
        "m",
        min=0.0,
    )
    min_area: float = param(0.08, "planar: smallest surface footprint area", "m^2", min=0.0)
    min_width: float = param(
        0.15,
        "planar: narrowest a surface may be (a rail or wall top is not a surface)",
        "m",
        min=0.0,
    )
    point_tolerance: float = param(
        0.01,
        "planar: a point is on a surface if this close to the surface's local plane "
        "(widened to 3x the surface's median voxel roughness on noisy clouds); a depth "
        "camera's surfaces use their noise band instead (band_sigmas), at most this wide",
        "m",
        min=0.0,
    )
    band_sigmas: float = param(
        3.5,
        "planar: a point is on a surface within this many sigma of its plane, sigma the "
        "surface's own noise at the point's range (measured on it; 0: point_tolerance alone)",
        min=0.0,
    )
    band_min: float = param(
        0.003,
        "planar: the noise band is never thinner than this (noise-free clouds)",
        "m",
        min=0.0,
    )
    bridge_cells: int = param(
        1,
        "planar: empty cells a surface may span between level voxels of the same plane "
        "(gaps between a lidar's rings far away); 0: only adjacent voxels join",
        min=0,
        max=5,
    )
    absorb_steps: int = param(
        3,
        "planar: rings of cluttered voxels (a board's edge by a panel, the foot of an "
        "object) a surface may grow into when part of their points lie on its plane",
        min=0,
        max=50,
    )
    absorb_min_fraction: float = param(
        0.2,
        "planar: share of a cluttered voxel's points that must lie on the plane for it to join",
        min=0.0,
        max=1.0,
    )
    clutter_normal_k: int = param(
        10,
        "planar: neighbours for the normals that vet surface points in cluttered voxels "
        "(tilted by more than normal_filter_max_tilt_deg: not on the surface); 0: no vetting",
        min=0,
        max=100,
    )
    normal_filter: bool = param(
        False,
        "the report's option: drop points whose k-NN normal is not vertical before "
        "growing (only candidate points are tested)",
    )
    normal_filter_k: int = param(30, "neighbours for the normal filter", min=3, max=500)
    normal_filter_max_tilt_deg: float = param(
        20.0,
        "normal filter: largest angle between a point normal and +z",
        "deg",
        min=0.0,
        max=90.0,
    )
    object_top_max_area: float = param(
        0.5,
        "planar: a level face smaller than this that stands on a lower surface which is "
        "hidden under it (the top of a box on a worktop) and holds nothing is an object's "
        "top, not a surface; 0: off",
        "m^2",
        min=0.0,
    )
    object_top_max_height: float = param(
        0.5,
        "planar: such a face is an object's top only this close above the surface around it",
        "m",
        min=0.0,
    )
    plateau_min_step: float = param(
        0.012,
        "planar: a part of a surface that rises by a step at least this high (and at least "
        "the point tolerance) above the rest around it is a flat object lying on it (a "
        "cutting board, a plate), not surface; smooth slopes and warps are no steps; 0: off",
        "m",
        min=0.0,
    )
    plateau_max_area: float = param(
        0.3,
        "planar: such a raised part is an object only up to this footprint area",
        "m^2",
        min=0.0,
    )


@dataclass(frozen=True)
class ObjectParams:
    """Supported-object segmentation (Algorithm 2 of the report and the voxel default)."""

    method: str = param(
        "convex",
        "'knn': the report's Algorithm 2 (sampled k-NN graph); 'voxel': connected "
        "occupied voxels of a fine grid, no sampling; 'convex': as voxel, then the densely "
        "sampled groups (a depth camera's) split into smooth faces joined where they meet "
        "convexly, cut at concave creases (touching and stacked objects)",
        choices=("knn", "voxel", "convex"),
    )
    k: int = param(20, "knn: neighbours linked per sampled point", min=1, max=500)
    sample_fraction: float = param(
        0.3, "knn: fraction s of the non-surface points sampled", min=1e-4, max=1.0
    )
    seed: int = param(0, "random seed for sampling", min=0)
    label_radius: float = param(
        0.05,
        "knn: unsampled points take the label of the nearest sampled point within this",
        "m",
        min=0.0,
    )
    voxel_size: float = param(0.03, "voxel: edge of the fine grid", "m", min=1e-3, max=1.0)
    min_points: int = param(30, "smallest cluster kept (smaller ones are noise)", min=1)
    support_tolerance: float = param(
        0.05,
        "a cluster stands on a surface when its lowest points are this close above it",
        "m",
        min=0.0,
    )
    split_touching: bool = param(
        True, "split clusters whose footprint has separate parts joined by a thin neck"
    )
    split_neck_width: float = param(
        0.04, "footprint necks narrower than this separate two objects", "m", min=0.0
    )
    split_concave: bool = param(
        False,
        "split clusters that fall apart into parts standing side by side on the surface when "
        "the voxels along concave creases are removed (touching convex objects)",
    )
    convex_cell: float = param(
        0.005,
        "convex: points in 26-adjacent cells this wide are linked (wider gaps cut); grown "
        "until a typical cell holds a few points (sparse clouds, maps)",
        "m",
        min=1e-3,
        max=0.1,
    )
    convex_normal_cells: int = param(
        2,
        "convex: a cell's normal comes from the cells within this many cells of it (a "
        "depth camera's noise and depth steps scatter a one-cell normal)",
        min=1,
        max=6,
    )
    convex_smooth_deg: float = param(
        25.0,
        "convex: faces whose normals differ by less than this stay joined where they meet "
        "concavely (a bowl's inside)",
        "deg",
        min=0.0,
        max=90.0,
    )
    foot_reach: float = param(
        0.015,
        "the points of a surface's noise band under an object go to the object where the "
        "object comes down to within this of the surface over them (its foot); 0: none",
        "m",
        min=0.0,
    )
    concave_tolerance: float = param(
        0.1,
        "a link between neighbouring voxels is concave when their normals converge by more "
        "than this (normal difference along the centroid offset, per unit offset)",
        min=0.0,
        max=2.0,
    )


@dataclass(frozen=True)
class FreeSpaceParams:
    """Free (unoccupied) part of each support surface."""

    cell_size: float = param(0.02, "2-D grid cell for the free-space map", "m", min=1e-3)
    margin: float = param(0.05, "clearance kept around each object footprint", "m", min=0.0)


@dataclass(frozen=True)
class GravityParams:
    """Gravity alignment when no IMU gives the up direction."""

    enabled: bool = param(False, "estimate the rotation to gravity from normals")
    up_hint: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0),
        "approximate up vector in the cloud frame (the plane family nearest it is up, never "
        "a refusal); zeros: decide from the scene",
    )
    hint_cone_deg: float = param(
        60.0,
        "up_hint: plane families within this angle of it compete (the nearest wins); none: "
        "up is refined on the planar normals within it, or is the hint itself",
        "deg",
        min=1.0,
        max=90.0,
    )
    voxel_size: float = param(0.05, "grid for the normals used by alignment", "m", min=1e-3)
    inlier_angle_deg: float = param(
        10.0, "normals within this of the up direction refine it", "deg", min=0.1, max=45.0
    )


@dataclass(frozen=True)
class SafeParams:
    """When a surface is ``safe`` for a planner to put something down on (all must hold)."""

    min_area: float = param(0.10, "smallest footprint area", "m^2", min=0.0)
    max_flatness: float = param(
        0.01, "largest rms distance of its points to its plane", "m", min=0.0
    )
    max_tilt_deg: float = param(
        5.0, "largest angle between its normal and up", "deg", min=0.0, max=90.0
    )


@dataclass(frozen=True)
class DetectParams:
    """Everything `supportnode detect` and the node's detection stage use."""

    surfaces: SurfaceParams = field(default_factory=SurfaceParams)
    objects: ObjectParams = field(default_factory=ObjectParams)
    freespace: FreeSpaceParams = field(default_factory=FreeSpaceParams)
    gravity: GravityParams = field(default_factory=GravityParams)
    safe: SafeParams = field(default_factory=SafeParams)
    # A lambda because NodeParams is defined below (appended sections keep this file's order).
    node: NodeParams = field(default_factory=lambda: NodeParams())


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
