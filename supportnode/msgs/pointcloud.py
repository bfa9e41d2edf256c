"""``PointCloud``: one scan as named per-point fields (x, y, z required), each its own buffer."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from supportnode.errors import InputError
from supportnode.geometry.transform import is_rotation, pose_matrix, quaternion_from_matrix
from supportnode.msgs._wire import (
    FLOAT_DTYPES,
    Check,
    Header,
    Limits,
    encode_frames,
    expect_type,
    parse_frames,
)

__all__ = ["PointCloud", "Pose"]

XYZ = ("x", "y", "z")
# Per-point vector fields (e.g. rgb as (N, 3) uint8) may have at most this many columns.
MAX_FIELD_COLUMNS = 64
#: Magnitudes a ``gravity`` vector may have (any unit: only its direction is used).
GRAVITY_NORM = (1e-3, 1e3)


@dataclass(eq=False)
class Pose:
    """Rigid transform from the cloud's frame to the map frame (the sensor's pose in the map).

    p_map = R(rotation) @ p_cloud + translation.
    """

    translation: np.ndarray  # (3,) float64, metres
    rotation: np.ndarray  # (4,) float64 unit quaternion x, y, z, w

    def __post_init__(self) -> None:
        self.translation = np.asarray(self.translation, dtype=np.float64).reshape(3)
        self.rotation = np.asarray(self.rotation, dtype=np.float64).reshape(4)

    @classmethod
    def from_matrix(cls, matrix: Any) -> Pose:
        """Pose of a (4, 4) homogeneous transform (rotation part orthonormal); `InputError`
        when it is not one."""
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape != (4, 4) or not np.isfinite(m).all():
            raise InputError(f"pose must be a finite 4x4 matrix, got shape {m.shape}")
        if not is_rotation(m[:3, :3]):
            raise InputError("pose: the 3x3 rotation part is not a rotation")
        return cls(m[:3, 3].copy(), quaternion_from_matrix(m[:3, :3]))

    def matrix(self) -> np.ndarray:
        """(4, 4) float64 homogeneous transform cloud frame -> map frame."""
        return pose_matrix(self.translation, self.rotation)


@dataclass(eq=False)
class PointCloud:
    """A point cloud on the wire.

    fields: name -> (N,) or (N, K) array, in wire order. x, y, z (metres, float32 or float64,
    shape (N,)) are required; anything else (intensity, ring, time, rgb, ...) is optional, of any
    dtype in `DTYPES`. gravity: (3,) float64, the direction gravity pulls in the cloud frame (e.g.
    (0, 0, -9.81) for a level sensor; only its direction is used). imu_orientation: (4,) float64
    unit quaternion x, y, z, w rotating cloud-frame vectors into a gravity-aligned frame (z up).
    dropped_nonfinite: set by `decode` only (rows removed because x, y or z was NaN/Inf).
    """

    TYPE: ClassVar[str] = "PointCloud"

    stamp: float  # seconds
    frame_id: str
    fields: dict[str, np.ndarray]
    seq: int = 0
    pose: Pose | None = None
    gravity: np.ndarray | None = None
    imu_orientation: np.ndarray | None = None
    dropped_nonfinite: int = field(default=0, compare=False)

    @property
    def count(self) -> int:
        """Number of points N."""
        return len(self.fields["x"])

    @property
    def points(self) -> np.ndarray:
        """(N, 3) float64 x, y, z (a new array)."""
        return np.stack([np.asarray(self.fields[k], dtype=np.float64) for k in XYZ], axis=1)

    @classmethod
    def from_xyz(
        cls,
        points: np.ndarray,
        stamp: float,
        frame_id: str,
        seq: int = 0,
        fields: dict[str, np.ndarray] | None = None,
        pose: Pose | tuple[np.ndarray, np.ndarray] | None = None,
        gravity: np.ndarray | None = None,
        imu_orientation: np.ndarray | None = None,
    ) -> PointCloud:
        """Cloud from (N, 3) float32/float64 points (other floats become float64) and optional
        extra per-point ``fields`` (name -> (N,) or (N, K)). ``pose``: a `Pose` or
        (translation (3,), quaternion x y z w (4,))."""
        pts = np.asarray(points)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InputError(f"points must be an (N, 3) array, got shape {pts.shape}")
        if pts.dtype not in (np.float32, np.float64):
            pts = pts.astype(np.float64)
        # Contiguous columns now, so that encode() can send them without another copy.
        cols = {k: np.ascontiguousarray(pts[:, i]) for i, k in enumerate(XYZ)}
        for name, values in (fields or {}).items():
            if name in cols:
                raise InputError(f"field '{name}' given twice (x, y, z come from points)")
            cols[name] = np.asarray(values)
        if pose is not None and not isinstance(pose, Pose):
            pose = Pose(*pose)
        return cls(
            stamp=float(stamp),
            frame_id=frame_id,
            fields=cols,
            seq=seq,
            pose=pose,
            gravity=None if gravity is None else np.asarray(gravity, dtype=np.float64),
            imu_orientation=(
                None if imu_orientation is None else np.asarray(imu_orientation, dtype=np.float64)
            ),
        )

    def encode(self, topic: str | bytes) -> list[bytes | memoryview]:
        """``[topic, header, x, y, z, *other fields]``; contiguous little-endian fields are sent
        without a copy (the frames view this cloud's arrays: do not modify them until sent)."""
        chk = Check(topic if isinstance(topic, str) else topic.decode("utf-8", "replace"))
        missing = [k for k in XYZ if k not in self.fields]
        if missing:
            chk.fail(f"cannot encode: PointCloud without field(s) {', '.join(missing)}")
        n = len(self.fields["x"])
        order = list(XYZ) + [k for k in self.fields if k not in XYZ]
        arrays = []
        for name in order:
            a = np.asarray(self.fields[name])
            ok = a.ndim == 1 if name in XYZ else a.ndim in (1, 2)
            if not ok or len(a) != n:
                chk.fail(f"cannot encode: field '{name}' has shape {a.shape}, expected ({n},)")
            if name in XYZ and a.dtype.kind != "f":
                chk.fail(f"cannot encode: field '{name}' must be float32 or float64")
            arrays.append((name, a))
        extra: dict[str, Any] = {}
        if self.pose is not None:
            extra["pose"] = {
                "translation": _floats(chk, self.pose.translation, "pose.translation", 3),
                "rotation": _quaternion(chk, self.pose.rotation, "pose.rotation"),
            }
        if self.gravity is not None:
            extra["gravity"] = _floats(chk, self.gravity, "gravity", 3)
        if self.imu_orientation is not None:
            extra["imu_orientation"] = _quaternion(chk, self.imu_orientation, "imu_orientation")
        return encode_frames(topic, self.TYPE, self.stamp, self.frame_id, self.seq, arrays, extra)

    @classmethod
    def decode(
        cls, frames: Any, limits: Limits | None = None, *, drop_nonfinite: bool = True
    ) -> PointCloud:
        """Validated cloud from ``[topic, header, *buffers]``; any problem is a ProtocolError.

        drop_nonfinite: remove rows whose x, y or z is NaN/Inf (organised clouds carry them
        legitimately) and count them in ``dropped_nonfinite``; False rejects such clouds.
        The field arrays view the frames (read-only) unless rows were dropped.
        """
        limits = limits or Limits()
        header, buffers = parse_frames(frames, limits)
        return cls._from_parsed(header, buffers, limits, drop_nonfinite)

    @classmethod
    def _from_parsed(
        cls,
        header: Header,
        buffers: dict[str, np.ndarray],
        limits: Limits,
        drop_nonfinite: bool = True,
    ) -> PointCloud:
        chk = Check(header.topic)
        expect_type(chk, header, cls.TYPE)
        x = chk.array(buffers, "x", FLOAT_DTYPES)
        n = len(x)
        if n > limits.max_points:
            chk.fail(f"{n} points exceeds max_points {limits.max_points}", "too_many_points")
        cols: dict[str, np.ndarray] = {}
        for name in XYZ:
            cols[name] = chk.array(buffers, name, FLOAT_DTYPES)
            chk.length(cols[name], name, n, "x")
        for name, a in buffers.items():
            if name in XYZ:
                continue
            if a.ndim not in (1, 2) or (a.ndim == 2 and not 1 <= a.shape[1] <= MAX_FIELD_COLUMNS):
                chk.fail(
                    f"field '{name}' has shape {a.shape}, expected (N,) or (N, K), "
                    f"K <= {MAX_FIELD_COLUMNS}"
                )
            chk.length(a, name, n, "x")
            cols[name] = a
        raw = header.raw
        pose = None
        if raw.get("pose") is not None:
            p = chk.as_map(raw["pose"], "header key 'pose'")
            pose = Pose(
                chk.as_vector(chk.key(p, "translation", "pose"), "pose.translation", 3),
                chk.unit_quaternion(chk.key(p, "rotation", "pose"), "pose.rotation"),
            )
        gravity = None
        if raw.get("gravity") is not None:
            gravity = _gravity(chk, chk.as_vector(raw["gravity"], "gravity", 3))
        imu = None
        if raw.get("imu_orientation") is not None:
            imu = chk.unit_quaternion(raw["imu_orientation"], "imu_orientation")
        good = np.isfinite(cols["x"]) & np.isfinite(cols["y"]) & np.isfinite(cols["z"])
        dropped = n - int(np.count_nonzero(good))
        if dropped:
            if not drop_nonfinite:
                bad = sum(int(np.count_nonzero(~np.isfinite(cols[k]))) for k in XYZ)
                chk.fail(f"{bad} NaN/Inf values in x,y,z", "nonfinite")
            cols = {k: v[good] for k, v in cols.items()}
        return cls(
            stamp=header.stamp,
            frame_id=header.frame_id,
            fields=cols,
            seq=header.seq,
            pose=pose,
            gravity=gravity,
            imu_orientation=imu,
            dropped_nonfinite=dropped,
        )


def _gravity(chk: Check, g: np.ndarray) -> np.ndarray:
    """``g`` when it has a direction: a magnitude within `GRAVITY_NORM` (m/s^2, g or a unit
    vector all qualify), so that normalising it is exact; else a ``bad_gravity`` failure.
    (1e308 components overflow the norm, 1e-320 ones underflow it: both normalise to NaN.)"""
    scale = float(np.max(np.abs(g)))
    norm = scale * float(np.linalg.norm(g / scale)) if scale > 0 else 0.0
    lo, hi = GRAVITY_NORM
    if not lo <= norm <= hi:
        chk.fail(
            f"gravity {g.tolist()} has magnitude {norm:.6g}, not in [{lo:g}, {hi:g}]", "bad_gravity"
        )
    return g


def _floats(chk: Check, v: Any, what: str, n: int) -> list[float]:
    """``v`` as a list of n finite Python floats for the header."""
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (n,) or not np.isfinite(a).all():
        chk.fail(f"cannot encode: {what} must be {n} finite numbers, got {a.tolist()}")
    return [float(x) for x in a]


def _quaternion(chk: Check, v: Any, what: str) -> list[float]:
    """A unit quaternion for the header; receivers reject others, so senders must not send them."""
    q = _floats(chk, v, what, 4)
    if abs(float(np.linalg.norm(q)) - 1.0) > 1e-3:
        chk.fail(f"cannot encode: {what} is not a unit quaternion x, y, z, w: {q}")
    return q
