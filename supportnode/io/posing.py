"""Poses and gravity for ROS scans from the bag's ``/tf``, ``/tf_static`` and IMU messages."""

from __future__ import annotations

import bisect
import dataclasses
from dataclasses import dataclass, field

import numpy as np

from supportnode.io.tf import TfBuffer, TfError
from supportnode.msgs import PointCloud, Pose

__all__ = ["ImuSample", "ScanPoser"]

STANDARD_GRAVITY = 9.80665  # m/s^2
# An IMU reads |a| = g only at rest (or constant velocity): farther than this from g, the
# robot accelerates and the reading is no gravity direction, m/s^2.
_REST_TOLERANCE = 0.3


@dataclass(frozen=True)
class ImuSample:
    """One ``sensor_msgs/Imu``: stamp s, frame, linear acceleration (3,) m/s^2 (points up at
    rest: the accelerometer measures the support's push, not the pull)."""

    stamp: float
    frame_id: str
    acceleration: np.ndarray


@dataclass
class ScanPoser:
    """Gives a scan its pose in ``fixed_frame`` (None: the root of the scan frame's tree) at
    its stamp, and its gravity from the IMU sample nearest in time when the robot is near
    rest. ``tolerance``: s a transform or IMU sample may be away from the scan's stamp."""

    tf: TfBuffer
    fixed_frame: str | None = None
    tolerance: float = 0.1
    imu: list[ImuSample] = field(default_factory=list)  # by stamp

    def __post_init__(self) -> None:
        self.imu.sort(key=lambda s: s.stamp)
        self._imu_times = [s.stamp for s in self.imu]

    def apply(self, cloud: PointCloud) -> PointCloud:
        """``cloud`` with ``pose`` (and ``gravity`` when an IMU says it); raises TfError."""
        fixed = self.fixed_frame or self.tf.root(cloud.frame_id)
        pose = self.tf.lookup(fixed, cloud.frame_id, cloud.stamp, self.tolerance)
        return dataclasses.replace(cloud, pose=Pose.from_matrix(pose), gravity=self._gravity(cloud))

    def _gravity(self, cloud: PointCloud) -> np.ndarray | None:
        """The pull direction in the cloud frame, or None (no IMU near the stamp, moving)."""
        sample = self._nearest_imu(cloud.stamp)
        if sample is None:
            return None
        a = sample.acceleration
        if abs(float(np.linalg.norm(a)) - STANDARD_GRAVITY) > _REST_TOLERANCE:
            return None
        try:
            m = self.tf.lookup(cloud.frame_id, sample.frame_id, cloud.stamp, self.tolerance)
        except TfError:
            return None
        up: np.ndarray = m[:3, :3] @ (-a / np.linalg.norm(a))
        return up

    def _nearest_imu(self, t: float) -> ImuSample | None:
        i = bisect.bisect_left(self._imu_times, t)
        near = [j for j in (i - 1, i) if 0 <= j < len(self.imu)]
        if not near:
            return None
        j = min(near, key=lambda k: abs(self._imu_times[k] - t))
        return self.imu[j] if abs(self._imu_times[j] - t) <= self.tolerance else None
