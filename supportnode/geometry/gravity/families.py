"""Plane families of a downsampled cloud: directions many planar normals share, and the
parallel planes of each family (offsets along its axis)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from supportnode.kernels.orientation import axis_support

_MAX_FAMILIES = 4
# Directions tried as family centres, and normals they are counted against: random subsets.
# The count only ranks the candidates; the axis is then refined on every normal of its cone.
_MAX_CANDIDATES = 512
_MAX_COUNTED = 4096
_REFINE_ITERATIONS = 5
_SEED = 0
_MIN_PLANE_FRACTION = 0.01  # a plane of a family needs this share of all downsampled points
_MIN_PLANE_POINTS = 8


@dataclass
class Family:
    """Planar normals sharing one axis. axis: (3,) unit, sign arbitrary; members: indices into
    the downsampled points; residual_deg: rms angle of the members' normals to the axis."""

    axis: np.ndarray
    members: np.ndarray
    residual_deg: float


def refine_axis(
    normals: np.ndarray, axis: np.ndarray, cos_in: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """Axis maximising the sum of (n . a)^2 over inliers |n . a| >= cos_in, inliers re-selected.

    normals: (M, 3) unit; axis: (3,) start. Returns (axis (3,) unit on the side of the start,
    inlier mask (M,), rms inlier angle in degrees)."""
    a = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
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


def find_families(
    normals: np.ndarray, planar: np.ndarray, angle_deg: float, min_support: int
) -> tuple[list[Family], int]:
    """Dense axis families among the planar normals, densest first.

    normals: (V, 3) unit; planar: indices of the planar ones. Returns the families with at
    least ``min_support`` members and the largest member count seen."""
    cos_in = float(np.cos(np.radians(angle_deg)))
    rng = np.random.default_rng(_SEED)
    remaining = np.ones(planar.size, dtype=bool)
    axes = normals[planar]
    out: list[Family] = []
    best_count = 0
    for _ in range(_MAX_FAMILIES):
        rem = np.flatnonzero(remaining)
        if rem.size < max(min_support, 3):
            break
        pool = axes[rem]
        cand = pool[rng.choice(rem.size, size=min(rem.size, _MAX_CANDIDATES), replace=False)]
        counted = pool[rng.choice(rem.size, size=min(rem.size, _MAX_COUNTED), replace=False)]
        top = int(np.argmax(axis_support(cand, counted, cos_in)))
        axis, inl, rms = refine_axis(pool, cand[top], cos_in)
        count = int(inl.sum())
        best_count = max(best_count, count)
        if count < min_support:
            break
        out.append(Family(axis=axis, members=planar[rem[inl]], residual_deg=rms))
        # Drop a wider cone than the inliers so the skirt of this family (edges, slightly
        # bent boards) does not come back as a separate family next to it.
        remaining[rem[np.abs(pool @ axis) >= np.cos(np.radians(2.0 * angle_deg))]] = False
    return out, best_count


def parallel_planes(t: np.ndarray, bin_size: float, n_total: int) -> list[tuple[float, np.ndarray]]:
    """Parallel planes of one family from its members' offsets ``t`` (M,) m along the axis.

    Runs of occupied histogram bins (bin ``bin_size`` m) holding at least 1 % of the
    ``n_total`` downsampled points (and 8). Returns [(median offset m, member mask (M,)),
    ...] in order of offset."""
    min_count = max(_MIN_PLANE_POINTS, int(_MIN_PLANE_FRACTION * n_total))
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


def inside_extent(plane_uv: np.ndarray, query_uv: np.ndarray, margin: float) -> np.ndarray:
    """Which query points project inside a plane's extent: its convex hull grown by ``margin``.

    plane_uv: (M, 2) in-plane coordinates of the plane's points, m; query_uv: (Q, 2) m. The
    hull, not the cells seen: an object standing on a table hides the table under and behind
    it, and at the near edge of a camera's view the table shows only beside and beyond it.
    Returns (Q,) bool."""
    # Joggled input: a plane seen as a thin strip (its points almost on a line) still has a
    # hull, and qhull does not fail on it.
    from scipy.spatial import ConvexHull  # here: ~0.18 s to import

    eq = ConvexHull(plane_uv, qhull_options="QJ").equations  # (K, 3): n . x + d <= 0 inside
    return ((query_uv @ eq[:, :2].T + eq[:, 2]) <= margin).all(axis=1)


def plane_normal(
    counts: np.ndarray, centroids: np.ndarray, covs: np.ndarray, up: np.ndarray
) -> np.ndarray | None:
    """Normal (3,) on the side of ``up`` of the plane through the points of some voxels.

    counts (M,), centroids (M, 3) m, covs (M, 6) m^2 (xx yy zz xy xz yz): the voxels' points,
    so the fit is the least-squares plane of the points themselves (each point weighs the
    same), without touching them. Voxels whose points lie beyond 3 robust sigmas of the plane
    (an object's foot, an edge) are dropped. None when the voxels do not span a plane."""
    w = counts.astype(np.float64)
    spread = np.zeros((len(w), 3, 3))
    for c, (a, b) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
        spread[:, a, b] = spread[:, b, a] = covs[:, c]
    keep = np.ones(len(w), dtype=bool)
    for _ in range(3):
        wk = w[keep]
        mean = wk @ centroids[keep] / wk.sum()
        d = centroids[keep] - mean
        scatter = np.einsum("v,vab->ab", wk, spread[keep]) + (d * wk[:, None]).T @ d
        evals, vecs = np.linalg.eigh(scatter)
        n = vecs[:, 0]
        # rms distance of each voxel's points to the plane: its centroid's offset and its own
        # spread along the normal
        along = np.maximum(np.einsum("a,vab,b->v", n, spread, n), 0.0)
        dist = np.sqrt(((centroids - mean) @ n) ** 2 + along)
        new = dist <= 3.0 * 1.4826 * np.median(dist[keep]) + 1e-9
        if new.sum() < 8 or np.array_equal(new, keep):
            break
        keep = new
    # A strip (points near a line) leaves the normal free to turn about it.
    if evals[1] < 16.0 * max(evals[0], 1e-30):
        return None
    return n if n @ up >= 0 else -n
