"""Per-scan results of a sequence into one output: an MCAP of our result messages (topics
``surfaces`` and ``obstacles``, readable by `play`, `info`, `view`) and a JSON line per scan."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import IO, Any

from supportnode._closing import Closing
from supportnode.io.recording import RecordingWriter
from supportnode.msgs import ObstacleClusters, PointCloud, SupportSurfaces

__all__ = ["SequenceResults", "result_line"]


def _num(v: float, digits: int = 4) -> float | None:
    return round(float(v), digits) if math.isfinite(v) else None


def result_line(
    scan: PointCloud,
    surfaces: SupportSurfaces | None,
    obstacles: ObstacleClusters | None,
    timings: dict[str, float],
) -> dict[str, Any]:
    """The JSON-ready summary of one scan's results (lengths m, areas m^2, times s)."""
    line: dict[str, Any] = {
        "seq": scan.seq,
        "stamp": scan.stamp,
        "frame_id": None if surfaces is None else surfaces.frame_id,
        "points": scan.count,
        "detected": surfaces is not None,
        "timings": {k: round(v, 6) for k, v in timings.items()},
    }
    if surfaces is not None:
        line["surfaces"] = [
            {
                "id": s.id,
                "height": _num(s.height),
                "area": _num(s.area),
                "flatness": _num(s.flatness, 5),
                "free_area": _num(s.free_area),
                "disc_radius": _num(s.disc_radius),
                "safe": s.safe,
            }
            for s in surfaces.surfaces
        ]
    if obstacles is not None:
        line["obstacles"] = [
            {
                "id": c.id,
                "surface_id": c.surface_id,
                "centroid": [_num(v) for v in c.centroid],
                "height": _num(c.height),
                "points": c.point_count,
            }
            for c in obstacles.clusters
        ]
    return line


class SequenceResults(Closing):
    """Writes ``mcap_path`` and ``jsonl_path`` scan after scan; ``scans``: lines written.
    Both files stay valid when the writing stops early (the MCAP is finished on close)."""

    def __init__(
        self,
        mcap_path: str | os.PathLike[str],
        jsonl_path: str | os.PathLike[str],
        metadata: dict[str, str] | None = None,
    ) -> None:
        self.mcap_path, self.jsonl_path = Path(mcap_path), Path(jsonl_path)
        for p in (self.mcap_path, self.jsonl_path):
            p.parent.mkdir(parents=True, exist_ok=True)
        self._mcap = RecordingWriter(self.mcap_path, metadata=metadata)
        self._jsonl: IO[str] | None = self.jsonl_path.open("w")
        self.scans = 0

    def write(
        self,
        scan: PointCloud,
        surfaces: SupportSurfaces | None,
        obstacles: ObstacleClusters | None,
        timings: dict[str, float],
    ) -> None:
        """One scan's results; the MCAP's log time is the scan's stamp (replay keeps its pace)."""
        for topic, msg in (("surfaces", surfaces), ("obstacles", obstacles)):
            if msg is not None:
                self._mcap.write(msg.encode(topic), receive_time=scan.stamp)
        assert self._jsonl is not None
        line = result_line(scan, surfaces, obstacles, timings)
        self._jsonl.write(json.dumps(line, separators=(",", ":"), allow_nan=False) + "\n")
        self.scans += 1

    def close(self) -> None:
        self._mcap.close()
        if self._jsonl is not None:
            self._jsonl.close()
            self._jsonl = None
