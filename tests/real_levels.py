"""The floors and tables of the real scans in ../shared/real_scans: ground truth for checking
that ``detect --align`` brings them out level (the optional real-data test and
``bench/real_gravity.py``). Nothing here runs without the scans."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from supportnode.io.clouds import Cloud, read_cloud
from supportnode.io.units import UNITS, guess_units

# Distance from the camera down to each support plane, m: RANSAC planes (1.5 cm) refined by
# PCA, picked out by eye on the colour images. office1: its floor; the TUM desk: floor, desk.
SUPPORT_DISTANCE = {
    "grabber_frame_20121214T142255.814212.pcd": (("table", 0.715),),
    "grabber_frame_20121214T142256.068683.pcd": (("table", 0.712),),
    "grabber_frame_20121214T142256.332395.pcd": (("table", 0.712),),
    "milk_cartoon_all_small_clorox.pcd": (("floor", 0.464),),
    "office1.pcd": (("floor", 1.344),),
    "region_growing_rgb_tutorial.pcd": (("floor", 0.798),),
    "sick_static_scene.pcd": (("table", 0.952),),
    "table_scene_mug_stereo_textured.pcd": (("table", 0.529),),
    "tum_fr3_desk.pcd": (("floor", 1.685), ("desk", 1.077)),
}
_HEIGHT_TOLERANCE = 0.1  # m: depth distortion moves a far floor by a few cm


@dataclass
class Support:
    """One floor or table of a scan as detected: its surface id (-1: not found), height below
    the camera (m, negative) and the tilt of its normal from +z (deg)."""

    name: str
    surface: int
    height: float
    tilt_deg: float


def scan_paths(root: Path) -> list[Path]:
    """Every real scan: the PCDs beside the README, then mosd_learn in numeric order."""
    learn = sorted((root / "mosd_learn").glob("learn*.pcd"), key=lambda p: int(p.stem[5:]))
    return sorted(root.glob("*.pcd")) + learn


def read_metres(path: Path) -> Cloud:
    """The cloud in metres (the SICK scan is in millimetres: its unit is guessed, as the
    command line says to pass --units)."""
    cloud = read_cloud(path)
    cloud.points = cloud.points * UNITS[guess_units(cloud.points).unit]
    return cloud


def supports(path: Path, cloud: Cloud, detection) -> list[Support]:
    """The detected surfaces that are the scan's floor or table (see SUPPORT_DISTANCE; for
    mOSD scans the surface holding most points labelled table, 1-9)."""
    surfaces = {s.id: s for s in detection.surfaces.surfaces}
    labels = detection.surfaces.labels
    if "label" in cloud.fields:
        label = cloud.fields["label"].reshape(-1)
        table = (label >= 1) & (label <= 9)
        ids = labels[table & (labels >= 0)]
        sid = int(np.bincount(ids).argmax()) if ids.size else -1
        return [_support("table", surfaces.get(sid))]
    out = []
    for name, distance in SUPPORT_DISTANCE[path.name]:
        near = [s for s in surfaces.values() if abs(s.height + distance) < _HEIGHT_TOLERANCE]
        out.append(_support(name, max(near, key=lambda s: s.point_count) if near else None))
    return out


def _support(name: str, surface) -> Support:
    if surface is None:
        return Support(name, -1, float("nan"), float("nan"))
    tilt = float(np.degrees(np.arccos(np.clip(abs(surface.normal[2]), 0.0, 1.0))))
    return Support(name, surface.id, float(surface.height), tilt)
