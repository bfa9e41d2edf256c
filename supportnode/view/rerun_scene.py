"""The scene in Rerun: a scan or cloud, the surfaces (outlines at their height, free disc,
safe in green), the obstacles (oriented boxes with their ids) and what holds what (an arrow
from each object down to its surface), timed by the messages' stamps.

Shown in Rerun's native viewer (spawned), served to a browser (Rerun's web viewer, from this
machine), or saved to an ``.rrd`` file. Needs the ``rerun`` extra (``rerun-sdk``), imported
only here. Entities: ``world/scan``, ``world/surfaces/<id>`` (and ``.../free_disc``),
``world/objects/<id>``, ``world/support/<id>``; a new detection clears the previous one's.
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from supportnode._closing import Closing
from supportnode.geometry.transform import quaternion_from_yaw
from supportnode.msgs import ObstacleClusters, PointCloud, SupportSurfaces
from supportnode.view import ViewError
from supportnode.view.style import (
    DISC_COLOR,
    LOOSE_OBSTACLE_COLOR,
    OBSTACLE_COLOR,
    SAFE_COLOR,
    UNSAFE_COLOR,
)

__all__ = ["INSTALL_HINT", "RerunScene"]

INSTALL_HINT = "install the Rerun extra: pip install 'supportnode[rerun]'"
_DISC_SEGMENTS = 48
_SCAN_COLOR = (0.55, 0.55, 0.55)


def _rerun() -> Any:
    try:
        import rerun
    except ImportError as err:
        raise ViewError(f"the Rerun view needs rerun-sdk: {INSTALL_HINT}") from err
    return rerun


def _rgba(c: tuple[float, ...]) -> list[int]:
    return [round(255 * v) for v in c]


class RerunScene(Closing):
    """One Rerun recording. ``mode``: "save" (to ``path``), "spawn" (the native viewer) or
    "web" (serve the web viewer on ``web_port``, its gRPC data on ``grpc_port``)."""

    def __init__(
        self,
        mode: str,
        path: str | os.PathLike[str] | None = None,
        web_port: int = 9090,
        grpc_port: int = 9876,
    ) -> None:
        rr = _rerun()
        self.rr = rr
        self.rec = rr.RecordingStream("supportnode")
        self.url: str | None = None
        self._heights: dict[int, float] = {}  # surface id -> height, of the last detection
        if mode == "save":
            if path is None:
                raise ViewError("saving a Rerun scene needs a file name")
            self.rec.save(os.fspath(path))
        elif mode == "spawn":
            self.rec.spawn()
        elif mode == "web":
            uri = self.rec.serve_grpc(grpc_port=grpc_port)
            rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=uri)
            self.url = f"http://127.0.0.1:{web_port}/?url={uri}"
        else:
            raise ViewError(f"unknown Rerun mode {mode!r} (save, spawn or web)")
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    def _time(self, stamp: float) -> None:
        if stamp > 1e8:  # wall-clock time since the epoch
            self.rec.set_time("stamp", timestamp=stamp)
        else:  # simulated or relative time
            self.rec.set_time("stamp", duration=stamp)

    def log_points(
        self, stamp: float, points: np.ndarray, colors: np.ndarray | None = None
    ) -> None:
        """(N, 3) metres in the world frame; colors (N, 3) uint8 or None (grey)."""
        self._time(stamp)
        c = colors if colors is not None else np.array(_rgba(_SCAN_COLOR), np.uint8)
        self.rec.log("world/scan", self.rr.Points3D(np.asarray(points, np.float32), colors=c))

    def log_scan(self, scan: PointCloud) -> None:
        """A scan, moved into the world frame by its pose when it has one."""
        from supportnode.geometry.transform import transform_points

        points = scan.points
        if scan.pose is not None:
            m = scan.pose.matrix()
            points = transform_points(points, m[:3, :3], m[:3, 3])
        self.log_points(scan.stamp, points)

    def log_surfaces(self, msg: SupportSurfaces) -> None:
        rr = self.rr
        self._time(msg.stamp)
        self.rec.log("world/surfaces", rr.Clear(recursive=True))
        for s in msg.surfaces:
            color = _rgba(SAFE_COLOR if s.safe else UNSAFE_COLOR)
            strips = [
                np.c_[np.vstack([r, r[:1]]), np.full(len(r) + 1, s.height)] for r in s.outline
            ]
            label = f"S{s.id} {s.height:.2f} m {s.area:.2f} m²" + ("" if s.safe else " (not safe)")
            path = f"world/surfaces/{s.id}"
            self.rec.log(
                path,
                rr.LineStrips3D(strips, colors=color, labels=[label] + [""] * (len(strips) - 1)),
                rr.AnyValues(height=s.height, area=s.area, safe=bool(s.safe)),
            )
            if math.isfinite(s.disc_radius) and s.disc_radius > 0:
                a = np.linspace(0, 2 * math.pi, _DISC_SEGMENTS + 1)
                ring = np.c_[
                    s.disc_center[0] + s.disc_radius * np.cos(a),
                    s.disc_center[1] + s.disc_radius * np.sin(a),
                    np.full(len(a), s.height + 0.005),
                ]
                self.rec.log(f"{path}/free_disc", rr.LineStrips3D([ring], colors=_rgba(DISC_COLOR)))
        self._heights = {s.id: s.height for s in msg.surfaces}

    def log_obstacles(self, msg: ObstacleClusters) -> None:
        """Oriented boxes labelled with their ids, and an arrow from each supported one down
        to its surface (after `log_surfaces` of the same detection, for the heights)."""
        rr = self.rr
        self._time(msg.stamp)
        self.rec.log("world/objects", rr.Clear(recursive=True))
        self.rec.log("world/support", rr.Clear(recursive=True))
        heights = self._heights
        for c in msg.clusters:
            on = c.surface_id is not None
            yaw = float(c.obb_yaw)
            self.rec.log(
                f"world/objects/{c.id}",
                rr.Boxes3D(
                    centers=[c.obb_center],
                    half_sizes=[np.asarray(c.obb_size) / 2],
                    quaternions=[rr.Quaternion(xyzw=quaternion_from_yaw(yaw))],
                    colors=_rgba(OBSTACLE_COLOR if on else LOOSE_OBSTACLE_COLOR),
                    labels=[f"#{c.id}"],
                ),
                rr.AnyValues(surface_id=-1 if c.surface_id is None else int(c.surface_id)),
            )
            if on and c.surface_id in heights:
                base = np.array([c.centroid[0], c.centroid[1], c.bbox_min[2]])
                down = heights[c.surface_id] - base[2]
                self.rec.log(
                    f"world/support/{c.id}",
                    rr.Arrows3D(
                        origins=[base],
                        vectors=[[0, 0, min(down, -0.02)]],
                        labels=[f"#{c.id} on S{c.surface_id}"],
                    ),
                )

    def log_message(self, topic: str, msg: Any) -> None:
        """A decoded message off the node's topics (others are left out)."""
        if isinstance(msg, SupportSurfaces):
            self.log_surfaces(msg)
        elif isinstance(msg, ObstacleClusters):
            self.log_obstacles(msg)
        elif isinstance(msg, PointCloud) and topic != "map":
            self.log_scan(msg)

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()
