"""The simulator's output: a point cloud where every point knows what it is (ground truth)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

# Point roles. A `surface` primitive's top face is ROLE_SURFACE; its other faces are STRUCTURE.
ROLE_SURFACE, ROLE_STRUCTURE, ROLE_OBJECT, ROLE_OUTLIER = 0, 1, 2, 3
ROLE_NAMES: dict[int, str] = {
    ROLE_SURFACE: "surface",
    ROLE_STRUCTURE: "structure",
    ROLE_OBJECT: "object",
    ROLE_OUTLIER: "outlier",
}


def rotate(points: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(N, 3) `points` rotated by the (3, 3) matrix `rot` (each row p -> rot @ p).

    np.dot on contiguous operands: numpy's `@` falls back to a slow non-BLAS loop (tens of times
    slower) when an operand is a strided view such as pose[:3, :3]. May return `points` itself.
    """
    if np.array_equal(rot, np.eye(3)):  # most scene parts are axis-aligned
        return points
    return np.dot(points, np.ascontiguousarray(rot.T))


def _identity3() -> np.ndarray:
    return np.eye(3)


@dataclass
class SimCloud:
    """A labelled cloud.

    points: (N, 3) float32, metres, in world (z up) or in the sensor frame (see `frame`).
    role: (N,) int8, one of ROLE_*.
    primitive: (N,) int32, index into `Scene.primitives` of the primitive hit (-1 for outliers).
    object: (N,) int32, object id (-1 if none); parts of one object share it.
    surface: (N,) int32, surface id 0..S-1 per scene (-1 if none).
    sensor_pose: (4, 4) float64 sensor-to-world transform (identity for sampled clouds).
    stamp: seconds.
    tilt_rotation: (3, 3) float64 rotation applied by the `tilt` noise: points = R @ untilted
        (identity when no tilt). Undo with R.T.
    frame: "world" or "sensor" (the frame of `points`). `sensor_pose` is always the true pose;
        with a tilt, the untilted points are tilt_rotation.T @ p, in the same frame.
    """

    points: np.ndarray
    role: np.ndarray
    primitive: np.ndarray
    object: np.ndarray
    surface: np.ndarray
    sensor_pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    stamp: float = 0.0
    tilt_rotation: np.ndarray = field(default_factory=_identity3)
    frame: str = "world"

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def select(self, mask: np.ndarray) -> SimCloud:
        """The points where `mask` ((N,) bool or index array) holds, same pose and stamp."""
        return replace(
            self,
            points=self.points[mask],
            role=self.role[mask],
            primitive=self.primitive[mask],
            object=self.object[mask],
            surface=self.surface[mask],
        )

    def to_frame(self, frame: str) -> SimCloud:
        """The same cloud expressed in `frame` ("world" or "sensor")."""
        if frame not in ("world", "sensor"):
            raise ValueError(f"frame must be 'world' or 'sensor', not {frame!r}")
        if frame == self.frame:
            return self
        pose, tilt = self.sensor_pose, self.tilt_rotation
        pts = rotate(self.points.astype(np.float64), tilt.T)  # undo the tilt
        if frame == "sensor":  # p_s = R^T (p_w - t)
            pts = rotate(pts - pose[:3, 3], pose[:3, :3].T)
        else:
            pts = rotate(pts, pose[:3, :3]) + pose[:3, 3]
        pts = rotate(pts, tilt)  # the tilt is about the origin of whichever frame the points are in
        return replace(self, points=pts.astype(np.float32), frame=frame)

    def arrays(self) -> dict[str, np.ndarray]:
        """NPZ-ready arrays: points, role, primitive, object, surface, sensor_pose, stamp,
        tilt_rotation, frame."""
        return {
            "points": self.points,
            "role": self.role,
            "primitive": self.primitive,
            "object": self.object,
            "surface": self.surface,
            "sensor_pose": self.sensor_pose,
            "stamp": np.float64(self.stamp),
            "tilt_rotation": self.tilt_rotation,
            "frame": np.str_(self.frame),
        }


def empty_cloud(n: int = 0) -> SimCloud:
    """A cloud of `n` uninitialised points (float32 points, int8/int32 labels)."""
    return SimCloud(
        points=np.empty((n, 3), np.float32),
        role=np.empty(n, np.int8),
        primitive=np.empty(n, np.int32),
        object=np.empty(n, np.int32),
        surface=np.empty(n, np.int32),
    )


def concatenate(clouds: list[SimCloud]) -> SimCloud:
    """Points of all `clouds` in order; pose, stamp, tilt and frame from the first one."""
    first = clouds[0]
    return replace(
        first,
        points=np.concatenate([c.points for c in clouds]),
        role=np.concatenate([c.role for c in clouds]),
        primitive=np.concatenate([c.primitive for c in clouds]),
        object=np.concatenate([c.object for c in clouds]),
        surface=np.concatenate([c.surface for c in clouds]),
    )
