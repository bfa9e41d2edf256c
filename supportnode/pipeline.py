"""One cloud in; support surfaces, the objects on them and their free space out.

The single entry used by `supportnode detect` and by the node. Pure: arrays and parameters in,
dataclasses out, no files or printing.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from supportnode.errors import InputError
from supportnode.geometry.freespace import FreeSpace, free_space_all
from supportnode.geometry.memo import Memo
from supportnode.geometry.objects import (
    Components,
    ObjectResult,
    Segmentation,
    cluster_objects,
    convex_components,
    describe_objects,
    split_objects,
)
from supportnode.geometry.surfaces import SurfaceResult, detect_surfaces
from supportnode.params import DetectParams

if TYPE_CHECKING:  # the estimator is imported only when alignment runs
    from supportnode.geometry.gravity import GravityEstimate


@dataclass
class Detection:
    """Everything found in one cloud. Coordinates are in the detection frame: the input frame,
    or the gravity-aligned frame ``rotation @ p`` when alignment ran."""

    surfaces: SurfaceResult
    objects: ObjectResult | None
    free_space: list[FreeSpace]
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage
    rotation: np.ndarray | None = None  # (3, 3) applied to the input, None when not aligned
    gravity: GravityEstimate | None = None  # when alignment ran

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no per-point arrays)."""
        out: dict[str, Any] = {
            "timings": {k: round(v, 6) for k, v in self.timings.items()},
            "surfaces": [s.to_dict() for s in self.surfaces.surfaces],
            "objects": [c.to_dict() for c in self.objects.clusters] if self.objects else [],
            "free_space": [f.to_dict() for f in self.free_space],
            "stats": {"surfaces": self.surfaces.stats, "objects": self.objects.stats}
            if self.objects
            else {"surfaces": self.surfaces.stats},
        }
        if self.rotation is not None:
            out["gravity"] = {
                "rotation": np.round(self.rotation, 9).tolist(),
                **_gravity_summary(self.gravity),
            }
        return out


def _gravity_summary(g: GravityEstimate | None) -> dict[str, Any]:
    if g is None:
        return {}
    return {
        "up_in_input_frame": [float(v) for v in g.up],
        "tilt_deg": float(g.tilt_deg),
        "inliers": int(g.inliers),
        "residual_deg": float(g.residual_deg),
        "reason": g.reason,
        **({"warning": g.warning} if g.warning else {}),
    }


@dataclass
class Early:
    """A detection's first phase (`surfaces_stage`): its surfaces are final and have their
    free space; the objects (`objects_stage`) continue from the components."""

    surfaces: SurfaceResult
    free: list[FreeSpace]
    components: Components
    timings: dict[str, float]  # seconds: objects (so far), free_space; objects_stage adds
    # (points, sensor origin) when the objects' own components are still to be found: the
    # convex segmentation, deferred past the surfaces (see surfaces_stage).
    pending: tuple[np.ndarray, np.ndarray | None] | None = None


def surfaces_stage(
    pts: np.ndarray,
    surfaces: SurfaceResult,
    params: DetectParams,
    free_below: float | None = None,
    timings: dict[str, float] | None = None,
    sensor_origin: np.ndarray | None = None,
) -> Early:
    """Components of the (N, 3) float64 points on no surface, and the free space of the
    surfaces lower than ``free_below`` (m; None: all). Free space needs only the connected
    components standing on each surface (a pile occupies its surface however it is split into
    objects): after this the surfaces are complete, and can go out, before touching objects
    are split and described. ``timings`` (seconds) is updated in place. ``sensor_origin``: (3,)
    in the detection frame when known (the convex method's noise band follows its range)."""
    timings = {} if timings is None else timings
    t = time.perf_counter()
    pending = None
    objects = params.objects
    if objects.method == "convex" and not any(s.band[0] > 0 for s in surfaces.surfaces):
        # No surface with a noise band (a lidar's, a map's): no object claims its feet from
        # a surface, so the surfaces are final now, and free space needs only the connected
        # voxels (what the convex segmentation parts stays on the same surface). The
        # segmentation, tens of ms on a dense view, waits for objects_stage.
        pending = (pts, sensor_origin)
        objects = replace(objects, method="voxel")
    components = cluster_objects(pts, surfaces, objects, sensor_origin=sensor_origin)
    if len(components.claimed):
        # An object's foot is the object's, no longer the surface's.
        labels = surfaces.labels.copy()
        labels[components.claimed] = -1
        surfaces = replace(surfaces, labels=labels)
    timings["objects"] = time.perf_counter() - t
    t = time.perf_counter()
    below = surfaces
    if free_below is not None:
        below = replace(surfaces, surfaces=[s for s in surfaces.surfaces if s.height < free_below])
    free = free_space_all(below, components.segmentation, pts, params.freespace)
    timings["free_space"] = time.perf_counter() - t
    return Early(surfaces, free, components, timings, pending)


def objects_stage(
    early: Early, params: DetectParams, memo: Memo | None = None, volumes: bool = True
) -> ObjectResult:
    """The objects of `surfaces_stage`'s components: touching objects split, then described
    (hulls, boxes; volumes False: no convex-hull volumes, NaN); adds its time to
    ``early.timings["objects"]``."""
    t = time.perf_counter()
    components = early.components
    if early.pending is not None:
        pts, origin = early.pending
        components = convex_components(components, pts, early.surfaces, params.objects, origin)
    segmentation = split_objects(components, params.objects, memo)
    result = describe_objects(segmentation, memo, volumes)
    early.timings["objects"] = early.timings.get("objects", 0.0) + time.perf_counter() - t
    return result


def detect(
    points: np.ndarray,
    params: DetectParams | None = None,
    *,
    align: bool = False,
    objects: bool = True,
    sensor_origin: np.ndarray | None = None,
    memo: Memo | None = None,
    on_surfaces: Callable[[SurfaceResult, list[FreeSpace], Segmentation], None] | None = None,
    free_below: float | None = None,
    origin_assumed: bool = False,
) -> Detection:
    """Run the detection stages on (N, 3) float points, metres.

    align: estimate the rotation to gravity from normals first (no IMU); raises
    AlignmentError when the cloud shows no horizontal surface. objects: also segment the
    supported objects and compute free space. sensor_origin: (3,) sensor position in the input
    frame when known (planes above it are undersides, not surfaces). memo: per-item results
    kept between calls on a changing map (see `supportnode.geometry.memo`); the same result.
    on_surfaces: called with the surfaces, their free space and the connected components of
    the points on no surface (a Segmentation) as soon as those are known, before touching
    objects are split and the objects described (hulls, boxes), so that a node can publish the
    surfaces first; only when objects is true. free_below: free space only for the surfaces
    lower than this height, metres, in the output frame (a node publishes no surface at or
    above its sensor: the ceiling's free space would be work thrown away); None: all.
    origin_assumed: sensor_origin is an assumption (the cloud is taken to be in its sensor's
    frame), dropped when alignment finds it on the support plane itself (a world-frame cloud
    with its origin on the floor): no sensor stands inside its floor.
    """
    params = params or DetectParams()
    if free_below is not None and math.isnan(free_below):
        # Every comparison with NaN is false: the result would hold no free space at all.
        raise InputError("free_below must be a height in metres or None, got nan")
    timings: dict[str, float] = {}
    pts = np.asarray(points, dtype=np.float64)
    rotation = None
    gravity = None
    if align:
        # Imported here: `runtime.warm` loads the kernels of every imported kernel module.
        from supportnode.kernels.rotate import transform_points_fast

        t = time.perf_counter()
        gravity = _estimate_gravity(pts, params, sensor_origin)
        rotation = gravity.rotation
        if origin_assumed and not _sensor_off_the_plane(gravity, params):
            sensor_origin = None
        pts = transform_points_fast(pts, rotation)  # compiled: ~3x numpy's 9 passes
        timings["gravity"] = time.perf_counter() - t
    t = time.perf_counter()
    origin = _in_detection_frame(sensor_origin, rotation)
    surfaces = detect_surfaces(pts, params.surfaces, sensor_origin=origin)
    timings["surfaces"] = time.perf_counter() - t
    object_result = None
    free: list[FreeSpace] = []
    if objects:
        if memo is not None:
            memo.next_round()
        early = surfaces_stage(pts, surfaces, params, free_below, timings, sensor_origin=origin)
        surfaces, free = early.surfaces, early.free
        if on_surfaces is not None:
            on_surfaces(surfaces, free, early.components.segmentation)
        object_result = objects_stage(early, params, memo)
    return Detection(surfaces, object_result, free, timings, rotation, gravity)


def _estimate_gravity(
    pts: np.ndarray, params: DetectParams, sensor_origin: np.ndarray | None
) -> GravityEstimate:
    """The gravity estimate of the cloud (imported here: only alignment needs that module)."""
    from supportnode.geometry.gravity import estimate_gravity

    return estimate_gravity(pts, params.gravity, sensor_origin=sensor_origin)


def _in_detection_frame(
    sensor_origin: np.ndarray | None, rotation: np.ndarray | None
) -> np.ndarray | None:
    """The sensor origin (3,) m rotated as the points were (None stays None)."""
    if sensor_origin is None:
        return None
    origin = np.asarray(sensor_origin, dtype=np.float64)
    return origin if rotation is None else rotation @ origin


def _sensor_off_the_plane(gravity: GravityEstimate, params: DetectParams) -> bool:
    """Whether the assumed sensor origin stands clear of the support plane alignment found
    (more than two downsampling voxels from it)."""
    return abs(gravity.sensor_height) > 2.0 * params.gravity.downsample_voxel
