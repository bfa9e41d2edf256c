"""Shape of one cluster's points: convex-hull volume and the yaw-only minimum-area box of its
footprint (the footprints themselves: `supportnode.kernels.hull`).

Points p (P, 3) float64 metres, z up; footprints (K, 2) float64; volumes m^3; yaw radians in
(-pi/2, pi/2], the direction of the box's length axis.
"""

from __future__ import annotations

import numpy as np

from supportnode.kernels.hull import footprint_hulls
from supportnode.kernels.lines import column_ends
from supportnode.kernels.rects import min_area_boxes

# Clusters of more points than this take their 3-D hull from the ends of their vertical lines
# (see _column_ends) and, if still more, from an even sample of those (see _hull_candidates).
# Qhull takes fewer whole: a depth camera's points make no vertical lines (the mOSD scans'
# clusters: nothing dropped), and Qhull on 3000 of them costs ~0.4 ms.
_HULL_MAX_POINTS = 3000


def footprint_ring(xy: np.ndarray) -> np.ndarray | None:
    """The convex hull of xy (K, 2 or more) float64 m in x, y: its vertices (V, 2),
    counter-clockwise, no collinear ones; None when it has no area (fewer than three points
    off one line), where Qhull would raise."""
    pts = np.ascontiguousarray(xy, dtype=np.float64)
    rows, _ = footprint_hulls(pts, np.zeros(1, np.int64), np.full(1, len(pts), np.int64))
    return pts[rows, :2] if len(rows) >= 3 else None


def footprint_equations(ring: np.ndarray) -> np.ndarray:
    """(V, 3) float64: each edge of a counter-clockwise ``ring`` (V, 2) as Qhull gives a
    facet: unit outward normal (nx, ny) and offset d, nx x + ny y + d <= 0 inside."""
    a, b = ring, np.roll(ring, -1, axis=0)
    n = np.column_stack([b[:, 1] - a[:, 1], a[:, 0] - b[:, 0]])
    n /= np.sqrt(n[:, 0] * n[:, 0] + n[:, 1] * n[:, 1])[:, None]
    return np.column_stack([n, -(n[:, 0] * a[:, 0] + n[:, 1] * a[:, 1])])


def footprint_area(ring: np.ndarray) -> float:
    """Area (m^2) of the polygon ``ring`` (V, 2), counter-clockwise (the shoelace)."""
    x, y = ring[:, 0] - ring[0, 0], ring[:, 1] - ring[0, 1]  # small numbers: exact enough
    return float(0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)))


def _volume(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Convex-hull volume (m^3) of p (P, 3) with bounding box lo, hi (3,); 0 when flat."""
    # A set flat along an axis has no volume; Qhull would raise (slowly) on it.
    if len(p) < 4 or not (hi > lo).all():
        return 0.0
    return _hull_3d(_hull_candidates(p))


def _hull_candidates(p: np.ndarray) -> np.ndarray:
    """The points of p (P, 3) the hull is taken of: the ends of vertical lines (see
    _column_ends), and of a dense cluster an even sample and the extremes along the axes."""
    if len(p) <= _HULL_MAX_POINTS:
        return p
    q = np.compress(_column_ends(p), p, axis=0)
    if len(q) > _HULL_MAX_POINTS:
        # A depth camera's object is a dense surface: an even sample and the points extreme
        # along the axes give its hull within a point spacing, in a fraction of Qhull's time
        # on all of them.
        ext = np.r_[q.argmin(axis=0), q.argmax(axis=0)]
        q = np.concatenate([q[:: -(-len(q) // _HULL_MAX_POINTS)], q[ext]])
    return q


def _hull_3d(q: np.ndarray) -> float:
    """Volume (m^3) of the convex hull of q (Q, 3); 0 when it is flat."""
    # Imported here: a node publishes no volumes, and its warm-up compiles every kernel
    # module imported (this one costs a fresh install ~4 s).
    from supportnode.kernels.hull3d import FAILED, hull_volume

    volume = hull_volume(np.ascontiguousarray(q, dtype=np.float64))
    if volume != FAILED:
        return float(volume)
    from scipy.spatial import ConvexHull, QhullError  # rare: not on every detection's path

    try:  # round-off broke the compiled hull's faces (near-coplanar slivers): Qhull merges
        return float(ConvexHull(q).volume)
    except (QhullError, ValueError):
        return 0.0


def _oriented_rect(xy: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """Yaw-only box around xy (K, 2): (centre (2,), length, width, yaw of the length axis).

    For a hull polygon, the minimum-area rectangle (one side is flush with a hull edge, so only
    the K edge directions are tried); PCA of the spread would be arbitrary for a square footprint
    and too wide for a cylinder next to a box. Degenerate sets use the principal axis.
    """
    if len(xy) >= 3:
        edges = np.concatenate([xy[1:], xy[:1]]) - xy  # np.roll(xy, -1, axis=0) - xy
        angles = np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2)
    else:
        d = xy - xy.mean(axis=0)
        _, vec = np.linalg.eigh(d.T @ d)
        angles = np.array([np.mod(np.arctan2(vec[1, 1], vec[0, 1]), np.pi / 2)])
    cos, sin = np.cos(angles), np.sin(angles)
    u = xy[:, 0, None] * cos + xy[:, 1, None] * sin  # (K, A): coordinate along each direction
    v = -xy[:, 0, None] * sin + xy[:, 1, None] * cos
    ext_u = u.max(axis=0) - u.min(axis=0)
    ext_v = v.max(axis=0) - v.min(axis=0)
    best = int(np.argmin(ext_u * ext_v + 1e-12 * angles))  # ties: the smallest angle
    a, c, s = angles[best], cos[best], sin[best]
    mu = (u[:, best].max() + u[:, best].min()) / 2
    mv = (v[:, best].max() + v[:, best].min()) / 2
    centre = np.array([mu * c - mv * s, mu * s + mv * c])
    length, width = float(ext_u[best]), float(ext_v[best])
    if width > length:
        length, width, a = width, length, a + np.pi / 2
    if a > np.pi / 2:
        a -= np.pi  # yaw in (-pi/2, pi/2]
    return centre, length, width, float(a)


def _oriented_rects(polys: list[np.ndarray]) -> list[tuple[np.ndarray, float, float, float]]:
    """:func:`_oriented_rect` of each polygon of polys (K_i, 2), the same values.

    Polygons of 3 vertices or more go to one compiled pass (`kernels.rects`: the same
    element-wise operations as one at a time, with the edges' angles, cosines and sines
    still numpy's), without some 20 numpy calls per cluster; degenerate ones one by one.
    """
    out: list = [None] * len(polys)
    k = np.array([len(xy) for xy in polys], dtype=np.int64)
    batch = np.flatnonzero(k >= 3)
    for i in np.flatnonzero(k < 3):
        out[i] = _oriented_rect(polys[i])
    if len(batch) == 0:
        return out
    kb = k[batch]
    starts = np.cumsum(kb) - kb
    xy = np.concatenate([polys[i] for i in batch])  # (N, 2)
    nxt = np.arange(len(xy)) + 1
    nxt[starts + kb - 1] = starts  # each polygon's last vertex closes onto its first
    edges = np.take(xy, nxt, axis=0) - xy  # (N, 2), as np.roll(xy, -1, axis=0) - xy
    angles = np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2)
    cos, sin = np.cos(angles), np.sin(angles)
    best, ext = min_area_boxes(xy[:, 0], xy[:, 1], np.r_[starts, len(xy)], angles, cos, sin)
    a, c, s = angles[best], cos[best], sin[best]
    mu = (ext[:, 0] + ext[:, 1]) / 2
    mv = (ext[:, 2] + ext[:, 3]) / 2
    centre = np.stack([mu * c - mv * s, mu * s + mv * c], axis=1)
    length, width = ext[:, 0] - ext[:, 1], ext[:, 2] - ext[:, 3]
    swap = width > length
    length, width = np.where(swap, width, length), np.where(swap, length, width)
    a = np.where(swap, a + np.pi / 2, a)
    a = np.where(a > np.pi / 2, a - np.pi, a)  # yaw in (-pi/2, pi/2]
    for j, i in enumerate(batch.tolist()):
        out[i] = (centre[j], float(length[j]), float(width[j]), float(a[j]))
    return out


def _column_ends(p: np.ndarray) -> np.ndarray:
    """(P,) bool: the points of p (P, 3) that may be hull vertices, as far as columns tell.

    A point strictly between two points of exactly the same x, y lies on the vertical segment
    joining them and is never a vertex of the convex hull, so dropping it changes neither the
    hull nor its volume (up to round-off in the facet sums). Scanners put many points on one
    vertical line (the beams of one azimuth on a wall: 80k points on 2.7k lines in the
    simulator's kitchen); for others nothing is dropped. Compiled (`kernels.lines`): the
    points grouped by a 32-bit hash of their x, y bits (a hash collision only splits a line's
    points into runs and keeps more)."""
    return column_ends(p)
