"""The simulator's output: a point cloud where every point knows what it is (ground truth)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

# Point roles. A `surface` primitive's top face is ROLE_SURFACE; its other faces are STRUCTURE.
# ROLE_NONE marks the NaN rows of an organised cloud (a pixel with no return).
ROLE_NONE, ROLE_SURFACE, ROLE_STRUCTURE, ROLE_OBJECT, ROLE_OUTLIER = -1, 0, 1, 2, 3
ROLE_NAMES: dict[int, str] = {
    ROLE_NONE: "none",
    ROLE_SURFACE: "surface",
    ROLE_STRUCTURE: "structure",
    ROLE_OBJECT: "object",
    ROLE_OUTLIER: "outlier",
}
FRAMES = ("world", "sensor", "optical")
# Rotation taking body (x fwd, y left, z up) vectors to optical (z fwd, x right, y down) ones.
OPTICAL_FROM_BODY = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


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

    points: (N, 3) float32, metres, in world (z up) or in the sensor frame (see `frame`); NaN
        rows in an organised cloud where a pixel has no return.
    role: (N,) int8, one of ROLE_*.
    primitive: (N,) int32, index into `Scene.primitives` of the primitive hit (-1 for outliers).
    object: (N,) int32, object id (-1 if none); parts of one object share it.
    surface: (N,) int32, surface id 0..S-1 per scene (-1 if none).
    supported_by: (N,) int32, for a point of an object: the object id that object stands on
        (-1 when it stands on a surface or on nothing, and for points of no object).
    support_surface: (N,) int32, for a point of an object: the surface under the object or
        under its stack (-1 when none, and for points of no object).
    sensor_pose: (4, 4) float64 sensor-to-world transform (identity for sampled clouds).
    stamp: seconds.
    tilt_rotation: (3, 3) float64 rotation applied by the `tilt` noise: points = R @ untilted
        (identity when no tilt). Undo with R.T.
    frame: "world", "sensor" (the sensor's body: x forward, z up) or "optical" (a camera's:
        z forward, x right, y down), the frame of `points`. `sensor_pose` is always the true
        pose; with a tilt, the untilted points are tilt_rotation.T @ p, in the same frame.
    image_shape: (rows, columns) of an organised cloud (a depth image: N = rows * columns,
        row-major from the top-left pixel), None for an unorganised one.
    """

    points: np.ndarray
    role: np.ndarray
    primitive: np.ndarray
    object: np.ndarray
    surface: np.ndarray
    supported_by: np.ndarray
    support_surface: np.ndarray
    sensor_pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    stamp: float = 0.0
    tilt_rotation: np.ndarray = field(default_factory=_identity3)
    frame: str = "world"
    image_shape: tuple[int, int] | None = None

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def select(self, mask: np.ndarray) -> SimCloud:
        """The points where `mask` ((N,) bool or index array) holds, same pose and stamp;
        no longer organised."""
        return replace(
            self,
            image_shape=None,
            points=self.points[mask],
            role=self.role[mask],
            primitive=self.primitive[mask],
            object=self.object[mask],
            surface=self.surface[mask],
            supported_by=self.supported_by[mask],
            support_surface=self.support_surface[mask],
        )

    def without_returns(self, mask: np.ndarray) -> SimCloud:
        """The cloud with the rows where `mask` ((N,) bool) holds turned into pixels that
        returned nothing: NaN point, role ROLE_NONE, every label -1; order and shape kept."""

        def none(labels: np.ndarray) -> np.ndarray:
            return np.where(mask, -1, labels).astype(np.int32)

        return replace(
            self,
            points=np.where(mask[:, None], np.float32(np.nan), self.points).astype(np.float32),
            role=np.where(mask, ROLE_NONE, self.role).astype(np.int8),
            primitive=none(self.primitive),
            object=none(self.object),
            surface=none(self.surface),
            supported_by=none(self.supported_by),
            support_surface=none(self.support_surface),
        )

    def to_frame(self, frame: str) -> SimCloud:
        """The same cloud expressed in `frame` (one of FRAMES)."""
        if frame not in FRAMES:
            raise ValueError(f"frame must be one of {', '.join(FRAMES)}, not {frame!r}")
        if frame == self.frame:
            return self
        pose, tilt = self.sensor_pose, self.tilt_rotation
        pts = rotate(self.points.astype(np.float64), tilt.T)  # undo the tilt
        if self.frame == "optical":
            pts = rotate(pts, OPTICAL_FROM_BODY.T)
        if self.frame != "world":
            pts = rotate(pts, pose[:3, :3]) + pose[:3, 3]
        if frame != "world":  # p_s = R^T (p_w - t)
            pts = rotate(pts - pose[:3, 3], pose[:3, :3].T)
        if frame == "optical":
            pts = rotate(pts, OPTICAL_FROM_BODY)
        pts = rotate(pts, tilt)  # the tilt is about the origin of whichever frame the points are in
        return replace(self, points=pts.astype(np.float32), frame=frame)

    def arrays(self) -> dict[str, np.ndarray]:
        """NPZ-ready arrays: points, role, primitive, object, surface, supported_by,
        support_surface, sensor_pose, stamp, tilt_rotation, frame, and image_shape (2,) for an
        organised cloud."""
        shape = {} if self.image_shape is None else {"image_shape": np.array(self.image_shape)}
        return {
            **shape,
            "points": self.points,
            "role": self.role,
            "primitive": self.primitive,
            "object": self.object,
            "surface": self.surface,
            "supported_by": self.supported_by,
            "support_surface": self.support_surface,
            "sensor_pose": self.sensor_pose,
            "stamp": np.array(self.stamp, dtype=np.float64),
            "tilt_rotation": self.tilt_rotation,
            "frame": np.array(self.frame),
        }


def empty_cloud(n: int = 0) -> SimCloud:
    """A cloud of `n` uninitialised points (float32 points, int8/int32 labels)."""
    return SimCloud(
        points=np.empty((n, 3), np.float32),
        role=np.empty(n, np.int8),
        primitive=np.empty(n, np.int32),
        object=np.empty(n, np.int32),
        surface=np.empty(n, np.int32),
        supported_by=np.empty(n, np.int32),
        support_surface=np.empty(n, np.int32),
    )


def concatenate(clouds: list[SimCloud]) -> SimCloud:
    """Points of all `clouds` in order; pose, stamp, tilt and frame from the first one; not
    organised."""
    first = clouds[0]
    return replace(
        first,
        image_shape=None,
        points=np.concatenate([c.points for c in clouds]),
        role=np.concatenate([c.role for c in clouds]),
        primitive=np.concatenate([c.primitive for c in clouds]),
        object=np.concatenate([c.object for c in clouds]),
        surface=np.concatenate([c.surface for c in clouds]),
        supported_by=np.concatenate([c.supported_by for c in clouds]),
        support_surface=np.concatenate([c.support_surface for c in clouds]),
    )
