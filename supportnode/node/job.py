"""What passes between the node's sides: the map a core needs (`MapLike`), a merged scan due
for detection (`Job`), a detection half done (`Partial`) and what a scan produced
(`NodeOutput`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from supportnode.map import Touched
from supportnode.msgs import ObstacleClusters, SupportSurfaces
from supportnode.node import incremental
from supportnode.node.incremental import Items

__all__ = ["Job", "MapLike", "NodeOutput", "Partial"]


class MapLike(Protocol):
    """What the core needs of a map (`supportnode.map.VoxelMap`): ``version`` changes
    whenever its points may have (the core reuses the previous detection of an unchanged
    map: its result is the same); ``merge`` says what a scan changed (`Touched`: the
    detection then looks again there only) and ``settle`` what its clearing removed, (R, 3)
    voxel keys; ``centroids`` is the map as published."""

    version: int

    def merge(self, points: np.ndarray, pose: np.ndarray, stamp: float) -> Touched: ...
    def settle(self) -> np.ndarray: ...
    def points(self) -> np.ndarray: ...
    def centroids(self, max_points: int | None = None) -> np.ndarray: ...
    def stats(self) -> dict[str, int]: ...


@dataclass
class NodeOutput:
    """What one scan produced.

    surfaces, obstacles: the messages to publish; None when the scan only updated the map
    (``node.detection_rate``). timings: seconds per stage (gravity, map, points, surfaces,
    objects, free_space, track, messages, total). new_ids / gone_ids: stable ids that appeared /
    vanished, per kind ("surfaces", "obstacles"). incremental: detection ran on a crop of the map.
    reused: the map had not changed since the previous detection, whose result this is.
    items: the detection behind the messages (detection ids, not stable ids).
    """

    surfaces: SupportSurfaces | None
    obstacles: ObstacleClusters | None
    timings: dict[str, float] = field(default_factory=dict)
    new_ids: dict[str, list[int]] = field(default_factory=dict)
    gone_ids: dict[str, list[int]] = field(default_factory=dict)
    incremental: bool = False
    items: Items | None = None
    reused: bool = False


@dataclass
class Job:
    """A merged scan due for detection, with what its detection needs (no map access).

    points: (P, 3) float64 detection-frame points of the map after the scan, metres.
    region: x, y box (lo, hi) in the detection frame of what changed since the previous
    job handed over (`merged_with` widens it when a job replaces an untaken one).
    """

    points: np.ndarray
    rotation: np.ndarray  # (3, 3) map -> detection frame (gravity correction)
    sensor_z: float  # the sensor's height in the detection frame, m
    stamp: float
    frame: str
    generation: int  # of the map it went into (a reset starts a new one)
    source: tuple[int, int | None]  # (generation, map version): equal sources, equal points
    region: tuple[np.ndarray, np.ndarray]
    timings: dict[str, float] = field(default_factory=dict)  # of its ingest
    t_recv: float = 0.0  # perf_counter when it was received (spin)

    def merged_with(self, older: Job) -> Job:
        """This job, its region widened by an older one that no detection took."""
        lo = np.minimum(self.region[0], older.region[0])
        hi = np.maximum(self.region[1], older.region[1])
        return dataclasses.replace(self, region=(lo, hi))


@dataclass
class Partial:
    """A detection half done (`NodeCore.detect_surfaces`): ``out.surfaces`` is final,
    `NodeCore.detect_objects` adds ``out.obstacles``. sid: detection -> stable surface id."""

    out: NodeOutput
    job: Job
    phase: incremental.Phase
    sid: dict[int, int]
