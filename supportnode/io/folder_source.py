"""A folder as a scan source: cloud files in name order, or simulator frames at their stamps."""

from __future__ import annotations

import os
import re
from collections.abc import Collection, Iterator
from pathlib import Path

import numpy as np

from supportnode.errors import CloudFormatError, SupportNodeError
from supportnode.io.clouds import READ_EXTENSIONS
from supportnode.io.source_base import Source, SourceMessage
from supportnode.msgs import PointCloud, Pose

__all__ = ["CLOUD_EXTENSIONS", "FolderSource"]

CLOUD_EXTENSIONS = READ_EXTENSIONS


def _natural_key(p: Path) -> list[object]:
    """frame_2 before frame_10."""
    return [int(s) if s.isdigit() else s.lower() for s in re.split(r"(\d+)", p.name)]


class FolderSource(Source):
    """A folder of cloud files (name order, ``hz`` per second from time 0) or of simulator
    frames ``frame_*.npz`` (their stamps). ``topic``: what the clouds are published on;
    ``frame_id``: of cloud files (simulator frames are converted to the sensor frame, ``lidar``,
    and carry the sensor pose)."""

    kind = "folder"

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        topic: str = "scan",
        hz: float = 10.0,
        frame_id: str = "map",
    ) -> None:
        super().__init__(path)
        if not hz > 0:
            raise SupportNodeError(f"{self.path}: folder rate must be > 0 Hz, got {hz}")
        self.topic, self.hz, self.frame_id = topic, hz, frame_id
        folder = Path(self.path)
        sim = sorted(folder.glob("frame_*.npz"), key=_natural_key)
        self.simulator = bool(sim)
        self.files = sim or sorted(
            (p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in CLOUD_EXTENSIONS),
            key=_natural_key,
        )
        if not self.files:
            raise SupportNodeError(
                f"{self.path}: no cloud files ({' '.join(CLOUD_EXTENSIONS)}) or frame_*.npz"
            )
        self._times: list[float] | None = None

    def times(self) -> list[float]:
        """Each file's time: simulator stamps, else index / hz."""
        if self._times is None:
            if self.simulator:
                self._times = []
                for i, p in enumerate(self.files):
                    try:
                        with np.load(p) as z:
                            self._times.append(
                                float(z["stamp"]) if "stamp" in z.files else i / self.hz
                            )
                    except Exception:
                        self._times.append(i / self.hz)  # reported when the frame is read
            else:
                self._times = [i / self.hz for i in range(len(self.files))]
        return self._times

    def topics(self) -> dict[str, str]:
        return {self.topic: "PointCloud"}

    def start_time(self) -> float | None:
        return self.times()[0]

    def duration(self) -> float | None:
        return self.times()[-1] - self.times()[0]

    def count(self, topic: str) -> int | None:
        return len(self.files) if topic == self.topic else 0

    def messages(
        self,
        topics: Collection[str] | None = None,
        start: float = 0.0,
        duration: float | None = None,
    ) -> Iterator[SourceMessage]:
        if topics is not None and self.topic not in topics:
            return
        begin, end = self._window(start, duration)
        for seq, (p, t) in enumerate(zip(self.files, self.times(), strict=True)):
            if (begin is not None and t < begin - 1e-9) or (end is not None and t >= end - 1e-9):
                continue
            try:
                cloud = (
                    self._sim_frame(p, t, seq) if self.simulator else self._cloud_file(p, t, seq)
                )
                frames = list(cloud.encode(self.topic))
            except (SupportNodeError, OSError, ValueError, KeyError) as err:
                self.warnings.append(f"{p}: skipped ({str(err).removeprefix(str(p) + ': ')})")
                continue
            yield SourceMessage(t, cloud.stamp, self.topic, "PointCloud", frames)

    def _cloud_file(self, p: Path, t: float, seq: int) -> PointCloud:
        from supportnode.io.clouds import read_cloud

        c = read_cloud(p)
        fields = {}
        for name, values in c.fields.items():
            a = np.asarray(values)
            if (
                re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,63}", name)
                and a.dtype.kind in "iuf"
                and a.dtype.itemsize <= 8
            ):
                fields[name] = a if a.dtype != np.float16 else a.astype(np.float32)
            else:
                self.warn_once(f"field:{name}", f"{self.path}: field '{name}' ({a.dtype}) left out")
        return PointCloud.from_xyz(
            c.points, stamp=t, frame_id=self.frame_id, seq=seq, fields=fields
        )

    def _sim_frame(self, p: Path, t: float, seq: int) -> PointCloud:
        try:
            with np.load(p) as z:
                points = np.asarray(z["points"], dtype=np.float64)
                pose = np.asarray(z["sensor_pose"], dtype=np.float64)
                frame = str(z["frame"]) if "frame" in z.files else "world"
                tilt = np.asarray(z["tilt_rotation"]) if "tilt_rotation" in z.files else np.eye(3)
        except (KeyError, ValueError, OSError) as err:
            raise CloudFormatError(f"{p}: not a simulator frame ({err})") from err
        if points.ndim != 2 or points.shape[1] != 3:
            raise CloudFormatError(f"{p}: points must be (N, 3), got {points.shape}")
        if frame == "world":  # into the sensor frame, as a driver sends it: p_s = R^T (p_w - t)
            points = (points - pose[:3, 3]) @ pose[:3, :3]
        # A tilted sensor frame (simulated IMU-less mount) is not the pose's frame: no pose then.
        posed = frame == "world" or np.allclose(tilt, np.eye(3))
        return PointCloud.from_xyz(
            points.astype(np.float32),
            stamp=t,
            frame_id="lidar",
            seq=seq,
            pose=Pose.from_matrix(pose) if posed else None,
        )
