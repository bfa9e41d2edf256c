"""The noise of a structured-light depth camera (Kinect v1) on an organised simulated scan.

Axial and lateral noise follow Nguyen, Izadi and Lovell, "Modeling Kinect Sensor Noise for
Improved 3D Reconstruction and Tracking", 3DIMPVT 2012 (z the optical depth in metres, theta the
angle between the ray and the surface normal):

    sigma_z = 1.2 mm + 1.9 mm/m^2 (z - 0.4 m)^2 + 0.1 mm m^0.5 / sqrt(z) * theta^2 / (pi/2 - theta)^2
    sigma_L = 0.8 px + 0.035 px * theta / (pi/2 - theta)        (pixels; sigma_L z / f metres)

Depth is quantised as the sensor measures it, in disparity steps of 1/8 pixel: d = f b / z
rounded to 1/8 px (Khoshelham and Elberink, "Accuracy and Resolution of Kinect Depth Data for
Indoor Mapping Applications", Sensors 12, 2012: with f = 525 px and b = 7.5 cm a step of 3.2 mm
at 1 m and 7.1 mm at 1.5 m, growing with z^2). Holes (NaN) open where the sensor loses the
pattern: at grazing angles, on depth edges, and on scattered dark pixels. Lateral noise moves a pixel's measurement to a
neighbouring pixel's surface point (its depth and its ground truth) near depth edges, which is
how edges fray.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.ndimage import binary_dilation

from supportnode.sim.cloud import SimCloud, rotate
from supportnode.sim.scene_model import Scene
from supportnode.sim.sensors import DepthCamera, surface_normals

GRAZING_DEG = (70.0, 85.0)  # returns thin out linearly between these incidence angles, then none
EDGE_JUMP = 0.03  # a neighbour this much deeper or shallower (relative to depth) marks an edge
EDGE_LOSS = 0.5  # share of edge pixels that return nothing
DARK_LOSS = 0.002  # share of other pixels that return nothing (dark or specular spots)
DISPARITY_STEP = 1.0 / 8.0  # pixels
KINECT_BASELINE = 0.075  # metres, projector to camera (when the camera gives none)


def kinect_noise(
    cloud: SimCloud,
    scene: Scene,
    camera: DepthCamera,
    rng: np.random.Generator,
    scale: float = 1.0,
) -> SimCloud:
    """The organised world-frame scan `cloud` of `scene` by `camera` (`camera.scan(...,
    organized=True)`) as a Kinect would measure it: the same image, labels following the
    measured point, NaN holes with role ROLE_NONE. scale multiplies the noise sigmas (not the
    holes); the disparity steps use the camera's baseline (7.5 cm when it has none)."""
    if cloud.image_shape != (camera.height, camera.width) or cloud.frame != "world":
        raise ValueError("kinect_noise expects an organised world-frame scan of this camera")
    if not scale >= 0:
        raise ValueError(f"the noise scale must be >= 0, got {scale}")
    rows, cols = cloud.image_shape
    focal_px = camera.focal_px
    normals = surface_normals(scene, cloud.primitive, cloud.points)
    origin = cloud.sensor_pose[:3, 3]
    axis = cloud.sensor_pose[:3, 0]  # the optical axis: the body's x
    ray = cloud.points.astype(np.float64) - origin
    dist = np.sqrt(np.einsum("ij,ij->i", ray, ray))
    unit_ray = ray / dist[:, None]
    with np.errstate(invalid="ignore"):
        depth = ray @ axis
        cos_inc = np.abs(np.einsum("ij,ij->i", normals, unit_ray))
    # Capped at 89 degrees: the model's terms diverge at 90 (such pixels are lost anyway).
    theta = np.arccos(np.clip(np.nan_to_num(cos_inc, nan=1.0), np.cos(np.radians(89.0)), 1.0))
    edge = _edges(depth, rows, cols)
    src = _lateral_source(theta, _near(edge, rows, cols), rows, cols, rng, scale)
    depth, theta = depth[src], theta[src]
    out = replace(cloud.select(src), image_shape=cloud.image_shape)  # labels of the source
    sigma = 0.0012 + 0.0019 * (depth - 0.4) ** 2
    sigma = sigma + 0.0001 / np.sqrt(np.maximum(depth, 1e-3)) * (theta / (np.pi / 2 - theta)) ** 2
    noisy = depth + scale * sigma * rng.standard_normal(depth.size)
    fb = focal_px * (camera.baseline or KINECT_BASELINE)
    with np.errstate(invalid="ignore", divide="ignore"):
        disparity = np.round(fb / noisy / DISPARITY_STEP) * DISPARITY_STEP
        measured = fb / disparity
    hole = _holes(depth, np.degrees(theta), _edges(depth, rows, cols), rng) | ~(measured > 0)
    # The measurement lies on this pixel's ray, at the measured optical depth.
    pixel_ray = rotate(camera.directions(), cloud.sensor_pose[:3, :3])
    points = origin + pixel_ray * (measured / (pixel_ray @ axis))[:, None]
    return replace(out, points=points.astype(np.float32)).without_returns(hole)


def _lateral_source(
    theta: np.ndarray,
    near_edge: np.ndarray,
    rows: int,
    cols: int,
    rng: np.random.Generator,
    scale: float,
) -> np.ndarray:
    """(N,) index of the pixel whose surface point each pixel measures: near a depth edge,
    itself shifted by round(N(0, sigma_L)) pixels in each image direction (clipped to the
    image); elsewhere itself. Nguyen et al. measured sigma_L at edges; on a smooth surface the
    sensor's correlation window does not jitter (mOSD's tables: 1.1-1.3 mm off a local plane
    at 0.8-0.95 m, as the axial sigma and the disparity steps alone give)."""
    sigma_px = scale * (0.8 + 0.035 * theta / (np.pi / 2 - theta))
    n = rows * cols
    du = np.rint(sigma_px * rng.standard_normal(n)).astype(np.int64)
    dv = np.rint(sigma_px * rng.standard_normal(n)).astype(np.int64)
    du[~near_edge] = 0
    dv[~near_edge] = 0
    r, c = np.divmod(np.arange(n), cols)
    return np.clip(r + dv, 0, rows - 1) * cols + np.clip(c + du, 0, cols - 1)


def _edges(depth: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """(N,) bool: pixels whose depth differs from a 4-neighbour's by more than EDGE_JUMP
    (relative), or whose neighbour returned nothing."""
    img = depth.reshape(rows, cols)
    jump = np.zeros((rows, cols))
    with np.errstate(invalid="ignore"):
        for axis in (0, 1):
            step = np.abs(np.diff(img, axis=axis)) / np.fmin(
                np.delete(img, -1, axis=axis), np.delete(img, 0, axis=axis)
            )
            step = np.nan_to_num(step, nan=np.inf)
            pad_lo = [(1, 0) if a == axis else (0, 0) for a in (0, 1)]
            pad_hi = [(0, 1) if a == axis else (0, 0) for a in (0, 1)]
            jump = np.maximum(jump, np.pad(step, pad_lo))
            jump = np.maximum(jump, np.pad(step, pad_hi))
    return jump.reshape(-1) > EDGE_JUMP


def _near(mask: np.ndarray, rows: int, cols: int, radius: int = 2) -> np.ndarray:
    """(N,) bool: pixels within `radius` pixels (a square) of a pixel in `mask`."""
    grown = binary_dilation(mask.reshape(rows, cols), np.ones((2 * radius + 1,) * 2, bool))
    return grown.reshape(-1)


def _holes(
    depth: np.ndarray, theta_deg: np.ndarray, edge: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """(N,) bool: pixels that return nothing (grazing, edge and dark pixels; already NaN)."""
    lo, hi = GRAZING_DEG
    p_lost = np.clip((theta_deg - lo) / (hi - lo), 0.0, 1.0)
    p_lost = np.maximum(p_lost, np.where(edge, EDGE_LOSS, DARK_LOSS))
    return (rng.random(depth.size) < p_lost) | ~np.isfinite(depth)
