"""The map's up direction, from the scans' gravity (or IMU orientation) or estimated.

The map has one up direction, so a scan's ``gravity`` or ``imu_orientation`` is an observation
of it, taken to the map frame through the scan's pose, and fused with the others: no single
message sets it, and none is kept as node state. Until ``node.gravity_min_agreeing``
observations agree within ``node.gravity_max_angle_deg``, the up in use is assumed (+z) or
estimated from the scans' normals (``gravity.enabled``); when they do, their mean becomes the
up (source "given") and later observations within the angle are averaged in, with a memory of
a few hundred scans. An observation farther than the angle from the up in use is an outlier:
counted; while the up is only assumed or estimated it still waits in a short window, so that a
sensor whose frame really differs (a camera frame, y down) is followed after a few scans,
but once the up is given no number of outliers moves it.

Pure numpy: no logging (the node logs the first outlier) and no sockets.
"""

from __future__ import annotations

import collections
import logging
import math
from enum import Enum
from typing import Any

import numpy as np

from supportnode.errors import AlignmentError
from supportnode.geometry.gravity import estimate_gravity, rotation_to_z
from supportnode.geometry.transform import quaternion_matrix
from supportnode.msgs import PointCloud
from supportnode.params import DetectParams

__all__ = ["SOURCES", "Gravity", "Verdict", "observed_up", "report_verdict"]

#: The gauge ``gravity_source`` is the index into this.
SOURCES = ("none", "given", "estimated")
# Gravity estimation without an IMU: every scan at first, then every this many scans.
_ESTIMATE_WARMUP = 5
_ESTIMATE_EVERY = 10
# Weight kept by the fused up per observation: about 256 scans of memory, so that a pose's
# slow rotational drift is followed while one scan moves it by 1/256 of its angle at most.
_DECAY = 1.0 - 1.0 / 256
# Observations kept while no up is given (beyond the ones that agree, bad ones linger).
_WINDOW_PER_VOTE = 3


class Verdict(Enum):
    """What one scan's gravity observation did."""

    NONE = "none"  # the scan gave none
    PENDING = "pending"  # waits for agreeing observations
    INLIER = "inlier"  # averaged into the given up
    ADOPTED = "adopted"  # it and the ones that agree with it became the up
    OUTLIER = "outlier"  # farther than the angle from the up in use


def observed_up(cloud: PointCloud) -> np.ndarray | None:
    """(3,) unit up in the cloud frame from ``imu_orientation`` or ``gravity``, or None.
    (The decoder has checked both: a unit quaternion, a gravity of sane magnitude.)"""
    if cloud.imu_orientation is not None:
        return quaternion_matrix(cloud.imu_orientation).T @ np.array([0.0, 0.0, 1.0])
    if cloud.gravity is not None:
        g = np.asarray(cloud.gravity, dtype=np.float64)
        return -g / np.linalg.norm(g)
    return None


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.acos(max(-1.0, min(1.0, float(a @ b))))


class Gravity:
    """The up direction in the map frame and the correction rotation it implies (see the
    module docstring). ``up`` (3,) unit; ``source`` one of `SOURCES`; counters ``outliers``
    (observations rejected) and ``failures`` (estimations that found no up)."""

    def __init__(self, params: DetectParams) -> None:
        self.params = params.gravity
        self.max_angle = math.radians(params.node.gravity_max_angle_deg)
        self.min_agreeing = int(params.node.gravity_min_agreeing)
        self.up = np.array([0.0, 0.0, 1.0])
        self.source = "none"
        self.outliers = 0
        self.failures = 0
        self._given = np.zeros(3)  # decayed sum of the inliers of the given up
        self._waiting: collections.deque[np.ndarray] = collections.deque(
            maxlen=_WINDOW_PER_VOTE * self.min_agreeing
        )
        self._estimated = np.zeros(3)  # inlier-weighted sum of the estimates
        self._estimates = 0
        self._scans = 0

    def update(self, cloud: PointCloud, rotation: np.ndarray, points: np.ndarray) -> Verdict:
        """Take one scan into account; ``rotation``: (3, 3) cloud-to-map, ``points``: (N, 3)
        cloud frame (for the estimate). Returns what its own gravity observation did."""
        self._scans += 1
        up_cloud = observed_up(cloud)
        verdict = Verdict.NONE if up_cloud is None else self._observe(rotation @ up_cloud)
        if self.params.enabled and self.source != "given":
            self._estimate(rotation, points)
        return verdict

    def _observe(self, v: np.ndarray) -> Verdict:
        v = v / np.linalg.norm(v)
        beyond = _angle(v, self.up) > self.max_angle
        if beyond:
            self.outliers += 1
        if self.source == "given":
            if beyond:
                return Verdict.OUTLIER
            self._given = self._given * _DECAY + v
            self.up = self._given / np.linalg.norm(self._given)
            return Verdict.INLIER
        self._waiting.append(v)
        agree = [w for w in self._waiting if _angle(w, v) <= self.max_angle]
        if len(agree) < self.min_agreeing:
            return Verdict.OUTLIER if beyond else Verdict.PENDING
        self._given = np.sum(agree, axis=0)
        self.up, self.source = self._given / np.linalg.norm(self._given), "given"
        self._waiting.clear()
        return Verdict.ADOPTED

    def _estimate(self, rotation: np.ndarray, points: np.ndarray) -> None:
        due = self._estimates < _ESTIMATE_WARMUP or self._scans % _ESTIMATE_EVERY == 0
        if not due:
            return
        try:
            est = estimate_gravity(points, self.params)
        except AlignmentError:
            self.failures += 1
            return
        self._estimates += 1
        self._estimated += max(est.inliers, 1) * (rotation @ est.up)
        self.up = self._estimated / np.linalg.norm(self._estimated)
        self.source = "estimated"

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) map frame -> detection frame (z up)."""
        return rotation_to_z(self.up)

    @property
    def tilt_deg(self) -> float:
        return float(np.degrees(np.arccos(np.clip(self.up[2], -1.0, 1.0))))


def report_verdict(
    log: logging.Logger,
    cfg: Any,
    gravity: Gravity,
    counters: dict[str, int],
    seq: int,
    verdict: Verdict,
) -> None:
    """Count a scan's gravity outlier in ``counters``; log the first one and every new up
    adopted. cfg: the node's parameters (name, gravity_max_angle_deg, gravity_min_agreeing)."""
    if verdict is Verdict.OUTLIER:
        counters["gravity_outliers"] += 1
        if counters["gravity_outliers"] == 1:
            log.warning(
                "%s: scan seq %d: its gravity is more than %g deg from the map's up %s "
                "(%s): not used (logged once; counted in gravity_outliers)",
                cfg.name,
                seq,
                cfg.gravity_max_angle_deg,
                np.round(gravity.up, 3).tolist(),
                gravity.source,
            )
    elif verdict is Verdict.ADOPTED:
        log.info(
            "%s: the map's up is %s, from %d scans' gravity that agree",
            cfg.name,
            np.round(gravity.up, 3).tolist(),
            cfg.gravity_min_agreeing,
        )
