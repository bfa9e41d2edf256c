"""Gravity alignment without an IMU: find the up axis from the scene's planes.

Steps (vectorised or compiled; Python loops run over a handful of families or planes):
1. Voxel-downsample (``GravityParams.downsample_voxel``) so every voxel stands for about the same
   area whatever the sensor density; counts of downsampled normals are then areas.
2. k-NN normals of the downsampled points; keep the planar ones (low surface variation).
3. Plane families: directions on the sphere, n and -n being one axis, where many normals agree.
4. The up family and its sign (:mod:`.choice`), or with ``up_hint`` the family nearest the
   hint (never a refusal, see :func:`estimate_gravity`).
5. Refine the axis on the inlier normals (principal direction of their outer products).
6. The minimal rotation taking up to +z (Rodrigues), so yaw stays as it was.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from supportnode.errors import AlignmentError, InputError
from supportnode.geometry.gravity.choice import choose_up, fmt_vector
from supportnode.geometry.gravity.families import (
    Family,
    find_families,
    parallel_planes,
    plane_normal,
    refine_axis,
)
from supportnode.geometry.normals import normals_among
from supportnode.kernels.downsample import voxel_moments
from supportnode.params import GravityParams

_K = 20  # neighbours for normals of the downsampled cloud: ~2.5 voxels radius on a plane
_MAX_CURVATURE = 0.08  # above: edge or clutter. Not lower: a 3 cm slab (a table top with
# its underside, as mesh sampling gives) measures 0.06 at this scale
_MIN_FAMILY_FRACTION = 0.05  # a family needs this share of all downsampled normals
_MIN_FAMILY_POINTS = 8
_LEVEL_DEG = 2.0  # a plane this far from the family's mean normal is not level (the same
# tolerance as "level" in the real-scan checks)


@dataclass(frozen=True)
class GravityEstimate:
    """Result of :func:`estimate_gravity`.

    rotation: (3, 3) float64, R such that ``R @ p`` brings the cloud's up to +z (yaw unchanged).
    up: (3,) float64 unit, the up direction in the input frame.
    tilt_deg: angle between ``up`` and the input +z, degrees.
    inliers: number of downsampled normals (about downsample_voxel^2 m^2 each) that refined ``up``.
    residual_deg: rms angle of those inlier normals to ``up`` after refinement, degrees.
    reason: one line, why this axis and this sign were chosen.
    warning: one line when the result rests on the hint alone (else None).
    sensor_height: height of ``sensor_origin`` above the largest plane of the up axis, m
    (about 0: the origin is on that plane, so no sensor was there); NaN when no plane.
    """

    rotation: np.ndarray
    up: np.ndarray
    tilt_deg: float
    inliers: int
    residual_deg: float
    reason: str = ""
    warning: str | None = None
    sensor_height: float = float("nan")


def rotation_to_z(up: np.ndarray) -> np.ndarray:
    """Minimal rotation (Rodrigues) taking the unit vector ``up`` (3,) to +z; (3, 3) float64.

    For ``up`` = -z, any half turn about a horizontal axis is minimal; the x axis is used.
    """
    u = np.asarray(up, dtype=np.float64).reshape(3)
    u = u / np.linalg.norm(u)
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(u, z)
    s = float(np.linalg.norm(v))
    c = float(u @ z)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + vx + vx @ vx * ((1.0 - c) / (s * s))


def apply_rotation(points: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """``R @ p`` for every row p of ``points`` (N, 3); returns (N, 3) float64 (metres kept)."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {pts.shape}")
    return pts @ np.asarray(rotation, dtype=np.float64).T


def estimate_gravity(
    points: np.ndarray,
    params: GravityParams = GravityParams(),  # noqa: B008 (frozen dataclass: safe default)
    sensor_origin: np.ndarray | None = None,
) -> GravityEstimate:
    """Up direction and the rotation to gravity of a cloud, from its planes (no IMU).

    points: (N, 3) float metres, any frame; rows with NaN/inf are ignored (organised camera
    clouds mark missing pixels so). params: downsample_voxel, inlier_angle_deg, up_hint and
    hint_cone_deg are used (``enabled`` is the pipeline's switch, not read here).
    sensor_origin: (3,) metres, where the sensor was in this frame; default the origin (true
    for clouds in a camera or lidar frame).

    With ``up_hint`` set this never refuses: the plane family nearest the hint within
    ``hint_cone_deg`` is up; with none there, up is refined on the planar normals within that
    cone of the hint, or is the hint itself, and ``warning`` says so. Without a hint it
    raises AlignmentError (one line, with advice that works) when no plane family has enough
    support, or the only one is a bare plane that could be a wall as well as a floor.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {pts.shape}")
    sensor = (
        np.zeros(3)
        if sensor_origin is None
        else np.asarray(sensor_origin, dtype=np.float64).reshape(3)
    )
    given = np.asarray(params.up_hint, dtype=np.float64).reshape(3)
    hint = given / np.linalg.norm(given) if np.linalg.norm(given) > 0 else None
    voxel = float(params.downsample_voxel)
    counts, ds, covs = voxel_moments(pts, voxel)
    if ds.shape[0] < _K:
        what = f"the finite points fill only {ds.shape[0]} voxels of {voxel} m"
        if hint is not None:
            return _from_hint(hint, None, params, what)
        raise AlignmentError(f"no horizontal surface in view: {what}; {_ADVICE}")
    # Voxel centroids on a plane lie a voxel apart: the k-th neighbour ~voxel * sqrt(k / pi)
    # away; cells of twice that are the exact grid search's quickest (no k-d tree to build).
    normals, curvature = normals_among(ds, ds, _K, 2.0 * voxel * np.sqrt(_K / np.pi), workers=-1)
    planar = np.flatnonzero(curvature < _MAX_CURVATURE)
    min_support = max(_MIN_FAMILY_POINTS, int(np.ceil(_MIN_FAMILY_FRACTION * ds.shape[0])))
    fams, best = find_families(normals, planar, params.inlier_angle_deg, min_support)
    if hint is not None:
        picked = _nearest(fams, hint, params.hint_cone_deg)
        if picked is None:
            what = (
                f"no plane family within {params.hint_cone_deg:g} deg of up_hint {fmt_vector(hint)}"
            )
            return _from_hint(hint, normals[planar], params, what)
        fam, up, reason = picked
    elif not fams:
        raise AlignmentError(
            f"no horizontal surface in view: the largest family of parallel planes has "
            f"{best} of {ds.shape[0]} normals (need {_MIN_FAMILY_FRACTION:.0%}); {_ADVICE}"
        )
    else:
        up, reason, fam = choose_up(fams, ds, normals, sensor, voxel)
    up, planes, height = _level(fam, up, counts, ds, covs, sensor, params)
    cos_in = float(np.cos(np.radians(params.inlier_angle_deg)))
    _, inl, rms = refine_axis(normals[planar], up, cos_in)
    est = _estimate(up, int(inl.sum()), rms, f"{reason}; levelled on {planes} plane(s)")
    return replace(est, sensor_height=height)


_ADVICE = (
    "if you know the up direction in the cloud's frame, pass it, e.g. "
    "--set gravity.up_hint=[0,-1,0] for a level camera's optical frame (y down)"
)


def _nearest(
    fams: list[Family], hint: np.ndarray, cone_deg: float
) -> tuple[Family, np.ndarray, str] | None:
    """The family nearest the unit ``hint`` within ``cone_deg``, its axis signed like the
    hint, and why; None when no family is that near."""
    near = [f for f in fams if abs(f.axis @ hint) >= np.cos(np.radians(cone_deg))]
    if not near:
        return None
    fam = max(near, key=lambda f: abs(f.axis @ hint))
    off = np.degrees(np.arccos(min(1.0, abs(float(fam.axis @ hint)))))
    return (
        fam,
        fam.axis * np.sign(fam.axis @ hint),
        f"up_hint: the plane family nearest it, {off:.0f} deg away",
    )


def _level(
    fam: Family,
    up: np.ndarray,
    counts: np.ndarray,
    ds: np.ndarray,
    covs: np.ndarray,
    sensor: np.ndarray,
    params: GravityParams,
) -> tuple[np.ndarray, int, float]:
    """Up as the mean normal of the family's planes, each fitted to its points and weighted
    by them: a floor and a desk of one scan that a depth camera's distortion tilts apart
    both come out level, and no 5 cm normal's noise is left. Returns (up (3,), planes used,
    the sensor's height above the largest plane m); the family's axis when no plane fits."""
    t = (ds[fam.members] - sensor) @ up
    cos_in = np.cos(np.radians(params.inlier_angle_deg))
    planes = parallel_planes(t, params.downsample_voxel, ds.shape[0])
    height = -max(planes, key=lambda p: int(p[1].sum()))[0] if planes else float("nan")
    fits = []
    for _, m in planes:
        idx = fam.members[m]
        n = plane_normal(counts[idx], ds[idx], covs[idx], up)
        if n is not None and n @ up >= cos_in:
            fits.append(counts[idx].sum() * n)
    if not fits:
        return up, 0, height
    weighted = np.array(fits)
    mean = weighted.sum(axis=0)
    # A plane more than _LEVEL_DEG off the others is sloped (a tilted table), not level.
    cos_level = np.cos(np.radians(_LEVEL_DEG))
    keep = weighted @ mean >= cos_level * np.linalg.norm(weighted, axis=1) * np.linalg.norm(mean)
    if keep.any():
        mean = weighted[keep].sum(axis=0)
    return mean / np.linalg.norm(mean), int(keep.sum()) if keep.any() else len(fits), height


def _estimate(
    up: np.ndarray, inliers: int, rms: float, reason: str, warning: str | None = None
) -> GravityEstimate:
    up = up / np.linalg.norm(up)
    tilt = float(np.degrees(np.arccos(np.clip(up[2], -1.0, 1.0))))
    return GravityEstimate(rotation_to_z(up), up, tilt, inliers, rms, reason, warning)


def _from_hint(
    hint: np.ndarray, planar: np.ndarray | None, params: GravityParams, what: str
) -> GravityEstimate:
    """Nothing to choose near the hint: refine it on the planar normals (M, 3) within its
    cone, or keep it as given; the warning says which, and why (``what``)."""
    cone = float(params.hint_cone_deg)
    if planar is not None:
        near = planar[np.abs(planar @ hint) >= np.cos(np.radians(cone))]
        cos_in = float(np.cos(np.radians(params.inlier_angle_deg)))
        # The normals near the hint may all be farther from it than the inlier angle: start
        # from their own principal direction.
        start = np.linalg.eigh(near.T @ near)[1][:, 2] if len(near) else hint
        up, inl, rms = refine_axis(near, start if start @ hint >= 0 else -start, cos_in)
        if inl.sum() >= _MIN_FAMILY_POINTS:
            off = np.degrees(np.arccos(np.clip(up @ hint, -1.0, 1.0)))
            return _estimate(
                up,
                int(inl.sum()),
                rms,
                f"up_hint refined on {int(inl.sum())} planar normals near it",
                f"gravity: {what}: up refined on the {int(inl.sum())} planar normals within "
                f"{cone:g} deg of it ({off:.1f} deg from the hint)",
            )
    return _estimate(hint, 0, 0.0, "up_hint as given", f"gravity: {what}: up_hint used as is")
