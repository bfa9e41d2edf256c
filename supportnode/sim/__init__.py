"""Scene simulator with per-point ground truth: scenes from YAML, mesh sampling, lidar and depth
camera ray casting, seeded noise, trajectories.

    from supportnode.sim import load_scene, sample_scene, Lidar
    scene = load_scene("shelf")
    cloud = sample_scene(scene, 200_000, seed=0)          # world frame, z up
    scan = Lidar.preset("os128").scan(scene, pose)        # pose: (4, 4) sensor-to-world
"""

from __future__ import annotations

from supportnode.sim.cloud import (
    ROLE_NAMES,
    ROLE_OBJECT,
    ROLE_OUTLIER,
    ROLE_STRUCTURE,
    ROLE_SURFACE,
    SimCloud,
)
from supportnode.sim.noise import NoiseSpec, parse_noise
from supportnode.sim.scene import Primitive, Scene, bundled_scenes, load_scene, parse_scene
from supportnode.sim.sensors import DepthCamera, Lidar, raycast, sample_scene
from supportnode.sim.trajectory import circle, line, look_at, poses_for

__all__ = [
    "ROLE_NAMES",
    "ROLE_OBJECT",
    "ROLE_OUTLIER",
    "ROLE_STRUCTURE",
    "ROLE_SURFACE",
    "DepthCamera",
    "Lidar",
    "NoiseSpec",
    "Primitive",
    "Scene",
    "SimCloud",
    "bundled_scenes",
    "circle",
    "line",
    "load_scene",
    "look_at",
    "parse_noise",
    "parse_scene",
    "poses_for",
    "raycast",
    "sample_scene",
]
