"""Gravity alignment without an IMU: find the up axis from the scene's planes.

Steps (all vectorised; loops run over a handful of plane families or planes, never points):
1. Voxel-downsample (``GravityParams.voxel_size``) so every voxel stands for about the same area
   whatever the sensor density; counts of downsampled normals are then areas.
2. k-NN normals of the downsampled points; keep the planar ones (low surface variation).
3. Plane families: directions on the sphere, n and -n being one axis, where many normals agree
   (ball counts in a k-d tree of the normals and their negatives), densest first.
4. Pick the up family and its sign from four cues: area, several parallel planes at different
   heights (floor, table, shelf boards share the up axis), things resting *on* the planes (the
   floor has everything on its up side), and a sensor looking down on the planes (the floor and
   table tops are below a camera; planes are seen obliquely rather than face-on like a wall
   ahead). ``GravityParams.up_hint``, when set, is a soft prior: families within 75 deg of it
   compete (closer ones preferred) and it fixes the sign. For organised camera-frame clouds
   pass (0, -1, 0): a side wall or cabinet fronts can outscore a small strip of floor.
5. Refine the axis: principal direction of the inlier normals' outer-product sum, inliers
   re-selected within ``inlier_angle_deg``, a few iterations.
6. The minimal rotation taking up to +z (Rodrigues), so yaw stays as it was.

With no plane family of enough support (a sphere, noise, a single bare plane) the estimate
raises :class:`~supportnode.errors.AlignmentError` instead of returning a wrong rotation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from supportnode.errors import AlignmentError, InputError
from supportnode.geometry.normals import normals_at
from supportnode.params import GravityParams

__all__ = ["GravityEstimate", "apply_rotation", "estimate_gravity", "rotation_to_z"]

_K = 20  # neighbours for normals of the downsampled cloud: ~2.5 voxels radius on a plane
_MAX_CURVATURE = 0.08  # above: edge or clutter. Not lower: a 3 cm slab (a table top with
# its underside, as mesh sampling gives) measures 0.06 at this scale
_MIN_FAMILY_FRACTION = 0.05  # a family needs this share of all downsampled normals
_MAX_FAMILIES = 4
_MAX_CANDIDATES = 3000  # directions tried as family centres (a random subset of the normals)
_REFINE_ITERATIONS = 5
_MIN_PLANE_FRACTION = 0.01  # a plane of a family needs this share of all downsampled normals
_MIN_PLANE_POINTS = 8
_STAND_HEIGHT = 0.5  # m: points this far on either side of a plane count as resting on/under it
_SEED = 0
_HINT_CONE_DEG = 75.0  # families farther than this from up_hint cannot be up


@dataclass(frozen=True)
class GravityEstimate:
    """Result of :func:`estimate_gravity`.

    rotation: (3, 3) float64, R such that ``R @ p`` brings the cloud's up to +z (yaw unchanged).
    up: (3,) float64 unit, the up direction in the input frame.
    tilt_deg: angle between ``up`` and the input +z, degrees.
    inliers: number of downsampled normals (about voxel_size^2 m^2 each) that refined ``up``.
    residual_deg: rms angle of those inlier normals to ``up`` after refinement, degrees.
    """

    rotation: np.ndarray
    up: np.ndarray
    tilt_deg: float
    inliers: int
    residual_deg: float


@dataclass
class _Family:
    axis: np.ndarray  # (3,) unit, sign arbitrary
    members: np.ndarray  # indices into the downsampled points
    residual_deg: float


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


def _voxel_centroids(points: np.ndarray, size: float) -> np.ndarray:
    """Centroid of the points in each occupied cube of edge ``size`` m; (V, 3) float64."""
    origin = points.min(axis=0)
    ijk = np.floor((points - origin) / size).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    sums = np.stack([np.bincount(inverse, weights=points[:, i]) for i in range(3)], axis=1)
    return sums / counts[:, None]


def _refine_axis(
    normals: np.ndarray, axis: np.ndarray, cos_in: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """Axis maximising the sum of (n . a)^2 over inliers |n . a| >= cos_in, inliers re-selected.

    Returns (axis (3,), inlier mask (M,), rms inlier angle in degrees)."""
    a = axis
    inl = np.abs(normals @ a) >= cos_in
    for _ in range(_REFINE_ITERATIONS):
        if inl.sum() < 3:
            break
        sel = normals[inl]
        _, v = np.linalg.eigh(sel.T @ sel)  # one 3x3: eigh is fine here
        a = v[:, 2] * (1.0 if v[:, 2] @ a >= 0 else -1.0)
        new = np.abs(normals @ a) >= cos_in
        if np.array_equal(new, inl):
            break
        inl = new
    ang = np.arccos(np.clip(np.abs(normals[inl] @ a), 0.0, 1.0))
    rms = float(np.degrees(np.sqrt(np.mean(ang**2)))) if ang.size else 0.0
    return a, inl, rms


def _families(
    normals: np.ndarray, planar_idx: np.ndarray, angle_deg: float, min_support: int
) -> tuple[list[_Family], int]:
    """Dense axis families among the planar normals, densest first.

    Returns the families with at least ``min_support`` members and the largest count seen."""
    cos_in = float(np.cos(np.radians(angle_deg)))
    chord = 2.0 * np.sin(np.radians(angle_deg) / 2.0)
    rng = np.random.default_rng(_SEED)
    remaining = np.ones(planar_idx.size, dtype=bool)
    axes = normals[planar_idx]
    out: list[_Family] = []
    best_count = 0
    for _ in range(_MAX_FAMILIES):
        rem = np.flatnonzero(remaining)
        if rem.size < max(min_support, 3):
            break
        pool = axes[rem]
        # n and -n are the same axis: count both, so a family straddling any hemisphere
        # boundary is not split in two.
        tree = cKDTree(np.concatenate([pool, -pool]))
        cand = pool[rng.choice(rem.size, size=min(rem.size, _MAX_CANDIDATES), replace=False)]
        counts = tree.query_ball_point(cand, chord, return_length=True)
        top = int(np.argmax(counts))
        axis, inl, rms = _refine_axis(pool, cand[top], cos_in)
        count = int(inl.sum())
        best_count = max(best_count, count)
        if count < min_support:
            break
        out.append(_Family(axis=axis, members=planar_idx[rem[inl]], residual_deg=rms))
        # Drop a wider cone than the inliers so the skirt of this family (edges, slightly
        # bent boards) does not come back as a separate family next to it.
        remaining[rem[np.abs(pool @ axis) >= np.cos(np.radians(2.0 * angle_deg))]] = False
    return out, best_count


def _planes(t: np.ndarray, bin_size: float, min_count: int) -> list[tuple[float, np.ndarray]]:
    """Parallel planes of one family from the members' offsets ``t`` (M,) along its axis.

    Runs of occupied histogram bins (bin ``bin_size`` m) with at least ``min_count`` members.
    Returns [(offset m, member mask (M,)), ...]."""
    lo = t.min()
    b = np.floor((t - lo) / bin_size).astype(np.int64)
    hist = np.bincount(b)
    # A few stray members (edges, sloped parts) must not bridge two planes into one run.
    occupied = hist >= max(2, int(0.002 * t.size))
    # Label runs of consecutive occupied bins (one plane each, however thick the noise).
    starts = occupied & ~np.concatenate([[False], occupied[:-1]])
    run = np.cumsum(starts) - 1
    run_of_member = np.where(occupied[b], run[b], -1)
    sizes = np.bincount(run_of_member[run_of_member >= 0], minlength=1)
    out = []
    for r in np.flatnonzero(sizes >= min_count):
        m = run_of_member == r
        out.append((float(np.median(t[m])), m))
    return out


def _cues(
    fam: _Family,
    ds: np.ndarray,
    sensor: np.ndarray,
    voxel: float,
    n_total: int,
    normals: np.ndarray,
) -> dict:
    """Evidence for ``fam`` being the up axis, with the sign it implies (see module doc)."""
    a = fam.axis
    pts = ds[fam.members]
    t = (pts - sensor) @ a
    planes = _planes(t, voxel, max(_MIN_PLANE_POINTS, int(_MIN_PLANE_FRACTION * n_total)))
    margin = 2.0 * voxel

    # Sensor cue, for +a as up: member area below the sensor minus area above it.
    below = int((t < -margin).sum())
    above = int((t > margin).sum())
    sensor_vote = (below - above) / max(below + above, 1)
    if planes:
        largest = max(planes, key=lambda pm: int(pm[1].sum()))[0]
        if abs(largest) < margin:
            # No sensor stands inside its largest plane: the origin is not a sensor here (a
            # world-frame cloud with the origin on the floor, a mesh sampling). No vote.
            sensor_vote = 0.0

    # Resting cue, for +a as up: points just on the +a side of a plane and over its footprint
    # minus points just on the -a side. Footprints are cells of a 2-D grid in the plane.
    e1 = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    cell = 2.0 * voxel
    uv_all = np.floor(np.stack([ds @ e1, ds @ e2], axis=1) / cell).astype(np.int64)
    key_all = uv_all[:, 0] * 1_000_003 + uv_all[:, 1]
    t_all = (ds - sensor) @ a
    on, under = 0, 0
    for offset, m in planes:  # a handful of planes
        foot = np.unique(key_all[fam.members[m]])
        over = np.isin(key_all, foot)
        dt = t_all[over] - offset
        # Clear of the plane's own noise, but low enough that a mug on a table counts.
        gap = max(voxel, 2.0 * float(np.std(t[m])))
        on += int(((dt > gap) & (dt < _STAND_HEIGHT)).sum())
        under += int(((dt < -gap) & (dt > -_STAND_HEIGHT)).sum())
    # A handful of points either side is noise, not evidence: scale by the amount.
    rest_vote = (on - under) / max(on + under, 1) * min(1.0, (on + under) / (0.2 * t.size))

    # Obliquity: planes seen from the sensor at a slant (floor, table) rather than face-on (a
    # wall ahead). sin of the angle between each viewing ray and the axis, averaged.
    rays = pts - sensor
    rn = np.linalg.norm(rays, axis=1)
    ok = rn > 1e-9
    sin_view = np.linalg.norm(np.cross(rays[ok], a), axis=1) / rn[ok]
    oblique = float(sin_view.mean()) if sin_view.size else 0.5

    # Vertical structure: normals perpendicular to this axis (walls, box and bottle sides).
    perp = float((np.abs(normals @ a) < np.sin(np.radians(10.0))).mean())
    return {
        "planes": planes,
        "n_planes": len(planes),
        "sensor_vote": sensor_vote,
        "rest_vote": rest_vote,
        "resting": on + under,
        "oblique": oblique,
        "perp": perp,
    }


def estimate_gravity(
    points: np.ndarray,
    params: GravityParams = GravityParams(),  # noqa: B008 (frozen dataclass: safe default)
    sensor_origin: np.ndarray | None = None,
) -> GravityEstimate:
    """Up direction and the rotation to gravity of a cloud, from its planes (no IMU).

    points: (N, 3) float64 metres, any frame; rows with NaN/inf are ignored (organised camera
    clouds mark missing pixels so). params: voxel_size, inlier_angle_deg and up_hint are used
    (``enabled`` is the pipeline's switch, not read here). sensor_origin: (3,) metres, where the
    sensor was in this frame; default the origin (true for clouds in a camera or lidar frame).
    Raises AlignmentError when no plane family has enough support or the choice is ambiguous.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {pts.shape}")
    pts = pts[np.isfinite(pts).all(axis=1)]
    sensor = (
        np.zeros(3)
        if sensor_origin is None
        else np.asarray(sensor_origin, dtype=np.float64).reshape(3)
    )
    voxel = float(params.voxel_size)
    if pts.shape[0] < _K:
        raise AlignmentError(f"no horizontal surface in view: only {pts.shape[0]} finite points")
    ds = _voxel_centroids(pts, voxel)
    n_total = ds.shape[0]
    if n_total < _K:
        raise AlignmentError(
            f"no horizontal surface in view: {pts.shape[0]} points fill only {n_total} voxels "
            f"of {voxel} m"
        )
    tree = cKDTree(ds)
    normals, curvature = normals_at(tree, ds, ds, _K)
    planar = np.flatnonzero(curvature < _MAX_CURVATURE)
    min_support = max(_MIN_PLANE_POINTS, int(np.ceil(_MIN_FAMILY_FRACTION * n_total)))
    fams, best = _families(normals, planar, params.inlier_angle_deg, min_support)
    if not fams:
        raise AlignmentError(
            f"no horizontal surface in view: largest planar family has {best} of {n_total} "
            f"normals (need {_MIN_FAMILY_FRACTION:.0%})"
        )

    hint = np.asarray(params.up_hint, dtype=np.float64).reshape(3)
    hint_norm = float(np.linalg.norm(hint))
    up, _ = _choose(
        fams, ds, sensor, voxel, n_total, normals, hint / hint_norm if hint_norm else None
    )

    # Final refinement over every downsampled normal (not only the planar ones): the family
    # axis is known now, so inliers within the cone are safe to use and add support.
    cos_in = float(np.cos(np.radians(params.inlier_angle_deg)))
    up, inl, rms = _refine_axis(normals[planar], up, cos_in)
    up = up / np.linalg.norm(up)
    tilt = float(np.degrees(np.arccos(np.clip(up[2], -1.0, 1.0))))
    return GravityEstimate(
        rotation=rotation_to_z(up),
        up=up,
        tilt_deg=tilt,
        inliers=int(inl.sum()),
        residual_deg=rms,
    )


def _choose(
    fams: list[_Family],
    ds: np.ndarray,
    sensor: np.ndarray,
    voxel: float,
    n_total: int,
    normals: np.ndarray,
    hint: np.ndarray | None,
) -> tuple[np.ndarray, _Family]:
    """The up axis (signed) among the families, from area and the cues of :func:`_cues`.

    hint: unit (3,) approximate up or None. A hint is soft: families more than
    ``_HINT_CONE_DEG`` from it are out, the rest are scored as usual with a preference for
    the closer ones, and the sign follows the hint. A camera's image axis (-y) is such a hint:
    the true up can be 45 deg or more from it when the camera looks down."""
    if hint is not None:
        cos_h = np.array([abs(float(f.axis @ hint)) for f in fams])
        keep = cos_h >= np.cos(np.radians(_HINT_CONE_DEG))
        if not keep.any():
            raise AlignmentError(
                f"no horizontal surface in view: no plane family within {_HINT_CONE_DEG:.0f} "
                f"deg of up_hint {np.round(hint, 3).tolist()} (closest "
                f"{np.degrees(np.arccos(cos_h.max())):.0f} deg)"
            )
        fams = [f for f, k in zip(fams, keep, strict=True) if k]
    scored = []
    for fam in fams:
        c = _cues(fam, ds, sensor, voxel, n_total, normals)
        # Sign: things rest on the up side of support planes; the sensor looks down on them.
        # The resting cue holds for any cloud; the sensor cue only where a sensor is at
        # `sensor`, so it counts half.
        # When the cues disagree (a wall ahead: seen from its front, things "resting" behind
        # it) the vote is weak and so is the family's claim to be horizontal.
        vote = c["rest_vote"] + 0.5 * c["sensor_vote"]
        sign = 1.0 if vote >= 0 else -1.0
        prior = 1.0
        if hint is not None:
            sign = 1.0 if fam.axis @ hint >= 0 else -1.0
            vote = abs(vote)  # the hint settles the sign; the cues still rate the family
            prior = 0.5 + 0.5 * abs(float(fam.axis @ hint))
        score = (
            fam.members.size
            * (1.0 + 0.5 * min(c["n_planes"] - 1, 4))
            * (0.5 + c["oblique"])
            * (0.2 + c["perp"])
            * (0.25 + 0.75 * min(abs(vote), 1.0))
            * prior
        )
        scored.append((score, sign, fam, c))
    scored.sort(key=lambda s: -s[0])
    score, sign, fam, c = scored[0]
    # A single bare plane (one offset, nothing on either side, nothing perpendicular) is a
    # wall as much as a floor: refuse rather than guess.
    if c["n_planes"] <= 1 and c["perp"] < 0.02 and c["resting"] < 0.01 * n_total:
        raise AlignmentError(
            "no horizontal surface in view: only one bare plane "
            f"({fam.members.size} of {n_total} normals), nothing rests on it or stands "
            "across it, so floor and wall cannot be told apart; set gravity.up_hint"
        )
    return sign * fam.axis, fam
