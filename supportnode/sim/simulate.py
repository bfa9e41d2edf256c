"""From a scene to finished clouds: sensor, then noise, then output frame, then tilt.

Each cloud draws its noise from its own seeded generator (`seed` for a sampled cloud,
`(seed, frame index)` for scans), so a frame does not change when more frames are requested.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from supportnode.errors import ConfigError
from supportnode.sim.cloud import SimCloud
from supportnode.sim.depth_noise import kinect_noise
from supportnode.sim.noise import NoiseSpec, apply_noise, apply_tilt
from supportnode.sim.scene import Scene
from supportnode.sim.sensors import DepthCamera, Lidar, sample_scene

# Outliers fill the scene's box grown by this much (metres) so a few float above and around it.
_OUTLIER_MARGIN = 0.1


def finish(
    cloud: SimCloud, scene: Scene, noise: NoiseSpec, rng: np.random.Generator, frame: str
) -> SimCloud:
    """Apply `noise` to a world-frame `cloud`, express it in `frame`, then tilt it."""
    bounds = scene.bounds() + np.array([[-1.0], [1.0]]) * _OUTLIER_MARGIN
    out = apply_noise(cloud, noise, bounds, rng).to_frame(frame)
    if noise.tilt != (0.0, 0.0):
        out = apply_tilt(out, *noise.tilt)
    return out


def sampled(scene: Scene, n_points: int, seed: int = 0, noise: NoiseSpec | None = None) -> SimCloud:
    """A mesh-sampled world-frame cloud of `n_points` (plus outliers if requested)."""
    noise = noise or NoiseSpec()
    if noise.kinect > 0:
        raise ConfigError("kinect noise follows a depth camera's pixels: scan with DepthCamera")
    cloud = sample_scene(scene, n_points, seed)
    # A separate stream for noise keeps the noise-free points identical across noise settings.
    return finish(cloud, scene, noise, np.random.default_rng([seed, 1]), "world")


def scans(
    scene: Scene,
    sensor: Lidar | DepthCamera,
    poses: np.ndarray,
    seed: int = 0,
    noise: NoiseSpec | None = None,
    frame: str = "world",
    organized: bool = False,
    on_scan: Callable[[int], None] | None = None,
) -> list[SimCloud]:
    """One scan per pose ((F, 4, 4) sensor-to-world), stamps i / sensor.rate seconds.

    organized: a depth camera's scans keep a row per pixel (NaN where nothing returns). The
    depth-camera noise (`kinect`) draws from its own stream, `(seed, frame index, 2)`.
    on_scan: called with each scan's index once it is done (progress)."""
    noise = noise or NoiseSpec()
    if (noise.kinect > 0 or organized) and not isinstance(sensor, DepthCamera):
        raise ConfigError("kinect noise and organised clouds need the depth camera")
    out = []
    for i, pose in enumerate(poses):
        stamp = i / sensor.rate
        if isinstance(sensor, Lidar):
            cloud = sensor.scan(scene, pose, stamp=stamp)
        else:
            cloud = sensor.scan(scene, pose, stamp, organized or noise.kinect > 0)
            if noise.kinect > 0:
                rng = np.random.default_rng([seed, i, 2])
                cloud = kinect_noise(cloud, scene, sensor, rng, noise.kinect)
                if not organized:
                    cloud = cloud.select(np.isfinite(cloud.points[:, 0]))
        out.append(finish(cloud, scene, noise, np.random.default_rng([seed, i]), frame))
        if on_scan is not None:
            on_scan(i)
    return out
