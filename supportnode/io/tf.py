"""A transform tree over time, as ROS's tf keeps it: static and moving edges parent -> child,
looked up between any two connected frames at a time (interpolated; extrapolated at most a
tolerance past the samples). Pure numpy; fed from ``/tf`` and ``/tf_static`` by io.rosbag."""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field

import numpy as np

from supportnode.errors import SupportNodeError
from supportnode.geometry.transform import pose_matrix, slerp

__all__ = ["TfBuffer", "TfError"]


class TfError(SupportNodeError):
    """No transform: ``reason`` is "tf missing" (frames not connected) or "tf late" (the time
    is farther than the tolerance from the samples of an edge on the path)."""

    def __init__(self, reason: str, text: str) -> None:
        super().__init__(text)
        self.reason = reason


@dataclass
class _Edge:
    parent: str
    times: list[float] = field(default_factory=list)  # s, ascending
    translations: list[np.ndarray] = field(default_factory=list)
    rotations: list[np.ndarray] = field(default_factory=list)  # quaternions x, y, z, w
    static: bool = False

    def at(self, t: float, tolerance: float, child: str) -> np.ndarray:
        """(4, 4) parent <- child at ``t``."""
        if self.static:
            return pose_matrix(self.translations[0], self.rotations[0])
        ts = self.times
        if len(ts) == 1 or t <= ts[0] or t >= ts[-1]:
            end = 0 if t <= ts[0] else len(ts) - 1
            if abs(t - ts[end]) > tolerance:
                raise TfError(
                    "tf late",
                    f"{self.parent} -> {child}: no transform within {tolerance:g} s of "
                    f"{t:.3f} (samples {ts[0]:.3f} .. {ts[-1]:.3f})",
                )
            if len(ts) == 1:
                return pose_matrix(self.translations[0], self.rotations[0])
            i = 0 if end == 0 else len(ts) - 2  # extrapolate along the end segment
        else:
            i = bisect.bisect_right(ts, t) - 1
        s = (t - ts[i]) / (ts[i + 1] - ts[i]) if ts[i + 1] > ts[i] else 0.0
        tr = self.translations[i] + s * (self.translations[i + 1] - self.translations[i])
        return pose_matrix(tr, slerp(self.rotations[i], self.rotations[i + 1], s))


def _name(frame: str) -> str:
    return frame.lstrip("/")  # ROS 1 frames may start with "/"


class TfBuffer:
    """Edges by child frame (a frame has one parent, as in tf)."""

    def __init__(self) -> None:
        self._edges: dict[str, _Edge] = {}

    def add(
        self,
        parent: str,
        child: str,
        stamp: float,
        translation: np.ndarray,
        rotation: np.ndarray,
        static: bool = False,
    ) -> None:
        """One transform parent <- child (translation (3,) m, quaternion x, y, z, w) at ``stamp``
        s. Samples may come in any order."""
        parent, child = _name(parent), _name(child)
        edge = self._edges.get(child)
        if edge is None or edge.parent != parent or static != edge.static:
            edge = self._edges[child] = _Edge(parent, static=static)
        if static:
            edge.times, edge.translations, edge.rotations = [stamp], [], []
        i = bisect.bisect_right(edge.times, stamp) if not static else 0
        if not static:
            edge.times.insert(i, stamp)
        edge.translations.insert(i, np.asarray(translation, dtype=np.float64))
        edge.rotations.insert(i, np.asarray(rotation, dtype=np.float64))

    def frames(self) -> set[str]:
        return set(self._edges) | {e.parent for e in self._edges.values()}

    def _chain(self, frame: str) -> list[str]:
        """frame, its parent, ... up to its root."""
        chain = [frame]
        while chain[-1] in self._edges and len(chain) <= len(self._edges):
            chain.append(self._edges[chain[-1]].parent)
        return chain

    def root(self, frame: str) -> str:
        """The root of ``frame``'s tree."""
        return self._chain(_name(frame))[-1]

    def lookup(self, target: str, source: str, t: float, tolerance: float) -> np.ndarray:
        """(4, 4) taking points in ``source`` to ``target`` at time ``t`` s; raises TfError."""
        target, source = _name(target), _name(source)
        unknown = [f for f in (source, target) if f not in self.frames()]
        if unknown:
            raise TfError("tf missing", f"frame {unknown[0]!r} is not in the tf tree")
        up_s, up_t = self._chain(source), self._chain(target)
        common = next((f for f in up_s if f in up_t), None)
        if common is None:
            raise TfError(
                "tf missing",
                f"no transform from {source!r} to {target!r} (their trees' roots: "
                f"{up_s[-1]!r}, {up_t[-1]!r})",
            )
        m: np.ndarray = np.linalg.inv(self._to(up_t, common, t, tolerance)) @ self._to(
            up_s, common, t, tolerance
        )
        return m

    def _to(self, chain: list[str], ancestor: str, t: float, tolerance: float) -> np.ndarray:
        m = np.eye(4)
        for child in chain[: chain.index(ancestor)]:
            m = self._edges[child].at(t, tolerance, child) @ m
        return m
