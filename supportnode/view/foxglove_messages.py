"""Each of our messages as Foxglove message objects (pure): scans, surfaces, obstacles,
diagnostics. `supportnode.view.foxglove_bridge.Bridge` calls these and keeps the per-topic state.
Lengths are metres, angles radians, times seconds (Foxglove: sec + nsec).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    KeyValuePair,
    LinePrimitive,
    LinePrimitiveLineType,
    Log,
    LogLevel,
    PackedElementField,
    PackedElementFieldNumericType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    TextPrimitive,
    Timestamp,
    Vector3,
)
from foxglove.messages import PointCloud as FoxPointCloud

from supportnode.geometry.transform import quaternion_from_yaw
from supportnode.msgs import (
    Diagnostics,
    ObstacleCluster,
    ObstacleClusters,
    PointCloud,
    SupportSurface,
)
from supportnode.view.style import (
    DISC_COLOR,
    LOOSE_OBSTACLE_COLOR,
    OBSTACLE_COLOR,
    SAFE_COLOR,
    UNSAFE_COLOR,
)

__all__ = [
    "DIAGNOSTICS_SCHEMA",
    "cluster_entity",
    "cluster_points",
    "diagnostics_json",
    "diagnostics_log",
    "quaternion_from_yaw",
    "scan_pointcloud",
    "scan_transform",
    "surface_entity",
    "timestamp",
]

TEXT_COLOR = (1.0, 1.0, 1.0, 1.0)
LINE_PIXELS = 2.0  # outline thickness, screen pixels (scale invariant: readable at any zoom)
FONT_PIXELS = 14.0
DISC_THICKNESS = 0.01  # m; the disc is drawn just above its surface so it is not z-fighting
LABEL_LIFT = 0.05  # m above a surface or box top

_LEVELS = {"ok": LogLevel.Info, "warn": LogLevel.Warning, "error": LogLevel.Error}
# numpy dtype -> Foxglove packed field type; other dtypes (int64, bool, ...) go as float64.
_NUMERIC = {
    "u1": PackedElementFieldNumericType.Uint8,
    "i1": PackedElementFieldNumericType.Int8,
    "u2": PackedElementFieldNumericType.Uint16,
    "i2": PackedElementFieldNumericType.Int16,
    "u4": PackedElementFieldNumericType.Uint32,
    "i4": PackedElementFieldNumericType.Int32,
    "f4": PackedElementFieldNumericType.Float32,
    "f8": PackedElementFieldNumericType.Float64,
}

#: JSON Schema of the diagnostics JSON channel (times in seconds, as on the wire).
DIAGNOSTICS_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": "supportnode.Diagnostics",
    "properties": {
        "stamp": {"type": "number", "description": "seconds since the epoch"},
        "node": {"type": "string"},
        "level": {"type": "string", "enum": ["ok", "warn", "error"]},
        "message": {"type": "string"},
        "counters": {"type": "object", "additionalProperties": {"type": "integer"}},
        "latencies": {
            "type": "object",
            "description": "per stage, seconds",
            "additionalProperties": {
                "type": "object",
                "properties": {"p50": {"type": "number"}, "p99": {"type": "number"}},
            },
        },
        "gauges": {"type": "object", "additionalProperties": {"type": "number"}},
    },
}


# ----------------------------------------------------------------------------- small pieces


def timestamp(stamp: float) -> Timestamp:
    """Foxglove timestamp of ``stamp`` seconds since the epoch (negative stamps clamp to 0:
    Foxglove timestamps are unsigned)."""
    sec = max(0.0, float(stamp))
    whole = math.floor(sec)
    return Timestamp(int(whole), min(999_999_999, round((sec - whole) * 1e9)))


def _color(rgba: Sequence[float]) -> Color:
    r, g, b, a = rgba
    return Color(r=r, g=g, b=b, a=a)


def _pose(position: Sequence[float], q: Sequence[float] = (0.0, 0.0, 0.0, 1.0)) -> Pose:
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in q)
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def _label(text: str, position: Sequence[float]) -> TextPrimitive:
    return TextPrimitive(
        pose=_pose(position),
        billboard=True,  # faces the camera
        font_size=FONT_PIXELS,
        scale_invariant=True,
        color=_color(TEXT_COLOR),
        text=text,
    )


def _packed(
    columns: Sequence[tuple[str, np.ndarray]],
) -> tuple[list[PackedElementField], int, bytes]:
    """Fields, stride (bytes) and data of equal-length 1-D ``columns`` packed point by point
    (one numpy structured array: no Python loop per point)."""
    dtypes = []
    for name, a in columns:
        key = a.dtype.newbyteorder("<").str[1:]
        dtypes.append((name, "<" + (key if key in _NUMERIC else "f8")))
    rows = np.empty(len(columns[0][1]), dtype=np.dtype(dtypes))  # packed, no padding
    for name, a in columns:
        rows[name] = a
    layout = rows.dtype.fields
    assert layout is not None  # a structured dtype, built just above
    fields = [
        PackedElementField(name=name, offset=layout[name][1], type=_NUMERIC[dt[1:]])
        for name, dt in dtypes
    ]
    return fields, rows.dtype.itemsize, rows.tobytes()


# ------------------------------------------------------------------------------------ scans


def _point_cloud(
    stamp: float, frame_id: str, columns: list[tuple[str, np.ndarray]]
) -> FoxPointCloud:
    """A Foxglove PointCloud at the frame's origin from (name, (N,) array) columns."""
    fields, stride, data = _packed(columns)
    return FoxPointCloud(
        timestamp=timestamp(stamp),
        frame_id=frame_id,
        pose=_pose((0.0, 0.0, 0.0)),
        point_stride=stride,
        fields=fields,
        data=data,
    )


def scan_pointcloud(cloud: PointCloud) -> FoxPointCloud:
    """The scan as a Foxglove PointCloud in its own frame: x, y, z as float32 at offsets 0, 4, 8,
    then the cloud's other 1-D numeric fields (intensity, ring, time, ...) in wire order, so
    Foxglove can colour by them; (N, K) fields (e.g. rgb) are left out."""
    columns = [(k, np.asarray(cloud.fields[k], dtype=np.float32)) for k in ("x", "y", "z")]
    for name, a in cloud.fields.items():
        a = np.asarray(a)
        if name not in ("x", "y", "z") and a.ndim == 1 and a.dtype.kind in "uif":
            columns.append((name, a))
    return _point_cloud(cloud.stamp, cloud.frame_id, columns)


def scan_transform(cloud: PointCloud, map_frame: str) -> FrameTransform | None:
    """Transform map frame -> the scan's frame from the scan's pose (None without a pose, or
    when the scan is already in the map frame)."""
    if cloud.pose is None or cloud.frame_id == map_frame:
        return None
    t, q = cloud.pose.translation, cloud.pose.rotation
    return FrameTransform(
        timestamp=timestamp(cloud.stamp),
        parent_frame_id=map_frame,
        child_frame_id=cloud.frame_id,
        translation=Vector3(x=float(t[0]), y=float(t[1]), z=float(t[2])),
        rotation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
    )


# --------------------------------------------------------------------------------- surfaces


def surface_entity(s: SupportSurface, stamp: float, frame_id: str) -> SceneEntity:
    """Entity ``surface/<id>``: each outline ring a closed line at ``s.height`` (green when
    safe, else orange), the largest free disc (when there is one) a thin cylinder lying on the
    surface, and the label "id height area"."""
    color = _color(SAFE_COLOR if s.safe else UNSAFE_COLOR)
    z = float(s.height)
    lines = [
        LinePrimitive(
            type=LinePrimitiveLineType.LineLoop,
            pose=_pose((0.0, 0.0, 0.0)),
            thickness=LINE_PIXELS,
            scale_invariant=True,
            # Outline vertices are few (bounded by max_polygon_vertices); the SDK takes objects.
            points=[Point3(x=x, y=y, z=z) for x, y in np.asarray(ring, dtype=float).tolist()],
            color=color,
        )
        for ring in s.outline
        if len(ring) >= 2
    ]
    cylinders = []
    r, c = float(s.disc_radius), np.asarray(s.disc_center, dtype=float)
    if math.isfinite(r) and r > 0 and bool(np.isfinite(c).all()):
        cylinders.append(
            CylinderPrimitive(
                pose=_pose((c[0], c[1], z + DISC_THICKNESS / 2)),
                size=Vector3(x=2 * r, y=2 * r, z=DISC_THICKNESS),
                bottom_scale=1.0,
                top_scale=1.0,
                color=_color(DISC_COLOR),
            )
        )
    anchor = _label_anchor(s)
    text = f"{s.id}  {s.height:.2f} m  {s.area:.2f} m²"
    return SceneEntity(
        timestamp=timestamp(stamp),
        frame_id=frame_id,
        id=f"surface/{s.id}",
        metadata=[
            KeyValuePair(key="id", value=str(s.id)),
            KeyValuePair(key="safe", value="yes" if s.safe else "no"),
            KeyValuePair(key="free_area", value=f"{s.free_area:.3f}"),
            KeyValuePair(key="points", value=str(s.point_count)),
        ],
        lines=lines,
        cylinders=cylinders,
        texts=[_label(text, (anchor[0], anchor[1], z + LABEL_LIFT))],
    )


def _label_anchor(s: SupportSurface) -> np.ndarray:
    """x, y for a surface's label: the free disc's centre when known (inside the surface), else
    the mean of the outer ring's vertices."""
    c = np.asarray(s.disc_center, dtype=float)
    if bool(np.isfinite(c).all()):
        return c
    if s.outline and len(s.outline[0]):
        mean: np.ndarray = np.asarray(s.outline[0], dtype=float).mean(axis=0)
        return mean
    return np.zeros(2)


# -------------------------------------------------------------------------------- obstacles


def cluster_entity(c: ObstacleCluster, stamp: float, frame_id: str) -> SceneEntity:
    """Entity ``obstacle/<id>``: the oriented box (centre, size length x width x height, yaw
    about z) as a cube, translucent red on a surface, grey on none; label "id" or "id on s"."""
    size = np.asarray(c.obb_size, dtype=float)
    center = np.asarray(c.obb_center, dtype=float)
    on = c.surface_id is not None
    text = f"{c.id} on {c.surface_id}" if on else f"{c.id}"
    return SceneEntity(
        timestamp=timestamp(stamp),
        frame_id=frame_id,
        id=f"obstacle/{c.id}",
        metadata=[
            KeyValuePair(key="id", value=str(c.id)),
            KeyValuePair(key="surface_id", value="-" if not on else str(c.surface_id)),
            KeyValuePair(key="height", value=f"{c.height:.3f}"),
            KeyValuePair(key="points", value=str(c.point_count)),
        ],
        cubes=[
            CubePrimitive(
                pose=_pose(center.tolist(), quaternion_from_yaw(c.obb_yaw)),
                size=Vector3(x=float(size[0]), y=float(size[1]), z=float(size[2])),
                color=_color(OBSTACLE_COLOR if on else LOOSE_OBSTACLE_COLOR),
            )
        ],
        texts=[_label(text, (center[0], center[1], center[2] + size[2] / 2 + LABEL_LIFT))],
    )


def cluster_points(msg: ObstacleClusters) -> FoxPointCloud | None:
    """The clusters' subsampled points as one PointCloud (float32 x, y, z, int32 ``cluster``
    id per point), or None when no cluster carries points."""
    parts = [(c.id, c.points) for c in msg.clusters if c.points is not None and len(c.points)]
    if not parts:
        return None
    pts = np.concatenate([np.asarray(p, dtype=np.float32) for _, p in parts])
    ids = np.repeat(np.array([i for i, _ in parts], dtype=np.int32), [len(p) for _, p in parts])
    columns = [("x", pts[:, 0]), ("y", pts[:, 1]), ("z", pts[:, 2]), ("cluster", ids)]
    return _point_cloud(msg.stamp, msg.frame_id, columns)


# ------------------------------------------------------------------------------ diagnostics


def diagnostics_log(msg: Diagnostics) -> Log:
    """A Foxglove Log line: level ok/warn/error -> Info/Warning/Error, the node as ``name``,
    the status message and the counters as text."""
    counters = " ".join(f"{k}={v}" for k, v in msg.counters.items())
    text = " | ".join(t for t in (msg.message or msg.level, counters) if t)
    return Log(
        timestamp=timestamp(msg.stamp),
        level=_LEVELS.get(msg.level, LogLevel.Unknown),
        message=text,
        name=msg.node,
    )


def diagnostics_json(msg: Diagnostics) -> dict[str, Any]:
    """The diagnostics as a JSON-ready dict (`DIAGNOSTICS_SCHEMA`): Foxglove's Plot panel plots
    e.g. ``latencies.total.p99`` or ``counters.scans_dropped``."""
    return {
        "stamp": float(msg.stamp),
        "node": msg.node,
        "level": msg.level,
        "message": msg.message,
        "counters": {k: int(v) for k, v in msg.counters.items()},
        "latencies": {k: {"p50": v.p50, "p99": v.p99} for k, v in msg.latencies.items()},
        "gauges": {k: float(v) for k, v in msg.gauges.items()},
    }
