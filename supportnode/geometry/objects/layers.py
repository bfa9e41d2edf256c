"""Objects standing on objects in clusters too sparse for convexity (a lidar's returns, a
thinly sampled map): a cluster cut at the height of a top face that what stands on it leaves
in view around it.

The convex segmentation parts a dense stack at its concave creases (:mod:`stacks`); a sparse
cluster has no creases to find, only heights. A horizontal face puts many points at one
height: a *level*. What rises from a level, within the face's outline, stands on it when
- the face shows beyond it (a box's own scan line at that height lies under the rest of the
  box: nothing of it shows beyond; the top of a box under a smaller box does, turned or not:
  see `rising`),
- its lowest points reach down to the level and spread at least a third as wide as it does
  (a lamp's shade on its thin stem is one object with its base; a box on a box, a bowl on a
  board, fruit in a bowl are two),
- and the face lies at least ``_MIN_TOP`` above the cluster's bottom (a bowl's inner bottom
  holds nothing).

Points p (P, 3) float64 metres, z up; labels (M,) int64, -1 none.
"""

from __future__ import annotations

import numpy as np

from supportnode.geometry.nearest import count_within, within
from supportnode.geometry.objects.clusters import _cluster_voxel
from supportnode.geometry.objects.convexity import _MAX_EXTENT
from supportnode.geometry.objects.hull import footprint_area, footprint_equations, footprint_ring
from supportnode.geometry.objects.rising import Footprint, footprint
from supportnode.geometry.objects.stacks import _INSIDE, _MAX_BESIDE, _MIN_SHARE, _MIN_TOP
from supportnode.kernels.groups import group_rows
from supportnode.kernels.layers import may_hold, screen_levels
from supportnode.kernels.turned import outside_turned
from supportnode.params import ObjectParams

# `kernels.groups.group_rows`' answer: start, rows, points, lo, hi.
Groups = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]

# A bin of the height histogram is _SLAB wide; a level's points lie in its bin or the two beside.
_SLAB = 0.005
# What stands on a level starts at least a clearance above it: half a clustering cell.
_CLEAR_CELLS = 0.5
# The face shows beyond what stands on it: at least this share of its points lie outside
# the outline of the part above.
_BEYOND = 0.15
# The part above rests on a base at least this share of its own width.
_BASE_WIDTH = 1.0 / 3.0
# ... seen at least this many times, ...
_BASE_POINTS = 5
# ... and its upper half at least this share as wide as its base.
_TAPER = 0.8
# A face's point is flat when, of the points within _FLAT_RADIUS (metres) of it, this share
# lie at its level, and at least _FLAT_MIN of them (itself included: a patch, not a speck).
_FLAT = 0.5
_FLAT_RADIUS = 0.02
_FLAT_MIN = 3
# A point has something under it when a point lower down lies within this in x, y (metres).
_COLUMN = 0.01
# The face shows beyond the part above when _BEYOND of its points lie this far outside it.
_BEYOND_BY = 0.01


def cut_layers(
    cp: np.ndarray,
    lab: np.ndarray,
    sparse: np.ndarray,
    supports: np.ndarray,
    params: ObjectParams,
    stats: dict,
    groups: Groups | None = None,
) -> tuple[np.ndarray, Groups | None]:
    """(M,) labels of the candidates cp (M, 3) with the sparse clusters' stacks cut apart
    (new parts take ids after the others), and, when nothing was cut, the labels' rows
    (`kernels.groups.group_rows`: the footprint splits need them too). sparse: (M,) bool, the points of the clusters the
    convex segmentation left whole; a cluster is tried when most of its points are and it
    stands on a surface (supports: (C,) the surface under each label, -1 none: a wall, the
    frame of a shelf, a chair's back hold nothing that stands). groups: ``group_rows(cp,
    lab, n)`` when the caller has it (`clusters._order` made it)."""
    n = int(lab.max()) + 1 if len(lab) else 0
    out = lab.copy()
    if n == 0:
        return out, None
    clear = _CLEAR_CELLS * params.cluster_cell
    groups = group_rows(cp, lab, n) if groups is None else groups
    start, order, _, lo, hi = groups
    size = np.diff(start)
    tall = hi[:, 2] - lo[:, 2] >= _MIN_TOP + 2 * clear
    small = (hi - lo)[:, :2].max(axis=1) <= _MAX_EXTENT  # room structure is not parted
    standing = np.zeros(n, bool)
    standing[: len(supports)] = supports[:n] >= 0
    tried = np.flatnonzero(tall & small & standing & (size >= 2 * params.min_points))
    next_id = n
    for c in tried.tolist():
        idx = order[start[c] : start[c + 1]]
        if 2 * np.count_nonzero(sparse[idx]) <= len(idx):
            continue  # segmented by convexity (its stacks by `stacks`)
        parts = _cut(np.take(cp, idx, axis=0), clear, params.min_points)
        if parts is None:
            continue
        stats["layer_splits"] = stats.get("layer_splits", 0) + 1
        rest = parts > 0
        out[idx[rest]] = next_id + parts[rest] - 1
        next_id += int(parts.max())
    return out, groups if next_id == n else None


def _low_percentile(z: np.ndarray, q: float) -> float:
    """numpy's linear percentile q (%) of z (P,) ascending, without a partition."""
    v = (len(z) - 1) * (q / 100)
    i = int(v)
    lo, hi = float(z[i]), float(z[min(i + 1, len(z) - 1)])
    t, d = v - i, hi - lo
    return hi - d * (1 - t) if t >= 0.5 else lo + d * t  # numpy's _lerp


def _cut(p: np.ndarray, clear: float, min_points: int) -> np.ndarray | None:
    """(P,) part of each point of the cluster p (P, 3), 0 for the one on the surface, or None
    when nothing in it stands on anything else. Higher levels first: a stack of three parts
    its top box, then the middle one."""
    min_face = _face_points(min_points)
    min_up = max(min_points, _MIN_SHARE * len(p))
    if not may_hold(p, _SLAB, clear, min_up, _BEYOND * min_face):
        return None  # most clusters: no level could show a face beyond what rises from it
    order = np.argsort(p[:, 2], kind="stable")
    q = p[order]  # by height: a level's slab and what rises above it are runs of rows
    z, xy = q[:, 2], q[:, :2]
    bottom = _low_percentile(z, 1.0) if len(z) >= 100 else float(z[0])
    # The levels (horizontal faces' heights: peaks of the height histogram, at least
    # _face_points within 1.5 _SLAB) from _MIN_TOP above the bottom up to a
    # clearance below the top, highest first; each one's slab [a, b) of rows and first row
    # u above its clearance; and whether, with nothing cut yet, it is worth trying: enough
    # rises above it, and enough of it lies outside the box of what rises to show beyond it
    # (a lidar's line across one box does not); and the x, y box of the rows from each row
    # up. Compiled: a lidar's cluster has a level at every line.
    levels, a, b, u, whole, *above = screen_levels(
        z,
        xy,
        bottom + _MIN_TOP,
        float(z[-1]) - clear,
        clear,
        _SLAB,
        min_face,
        min_up,
        _BEYOND * min_face,
    )
    whole = _turned(xy, a, b, u, whole, min_up, _BEYOND * min_face)
    if not whole.any():
        return None  # no level of the uncut cluster: nothing is ever cut
    part = np.zeros(len(q), np.int64)
    n_parts = 1
    everything = np.ones(len(q), bool)
    for i, level in enumerate(levels.tolist()):
        if n_parts == 1 and not whole[i]:
            continue
        rising = _rising(xy, part, n_parts, (a[i], b[i], u[i]), min_points, above)
        if rising is None:
            continue
        mine = everything if n_parts == 1 else part == rising[1]
        at = a[i] + np.flatnonzero(mine[a[i] : b[i]])
        cut = _cut_at(q, mine, at, u[i], level, clear, min_points, rising[0])
        for rows in cut:
            part[rows] = n_parts
            n_parts += 1
    if n_parts == 1:
        return None
    out = np.empty_like(part)
    out[order] = part
    return out


def _turned(
    xy: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    u: np.ndarray,
    whole: np.ndarray,
    min_up: float,
    min_out: float,
) -> np.ndarray:
    """``whole`` (L,) from `kernels.layers.screen_levels`, with the levels that show beyond
    what rises from them only past its turned box (see `rising`) added: xy (P, 2) by height;
    a, b, u (L,): each level's slab and first row above its clearance (`kernels.turned`)."""
    out = whole.copy()
    n = len(xy)
    todo = np.flatnonzero(~whole & (a < b) & (n - u >= min_up) & (u < n))
    out[todo] = outside_turned(xy, a[todo], b[todo], u[todo], _SLAB) >= min_out
    return out


def _rising(
    xy: np.ndarray,
    part: np.ndarray,
    n_parts: int,
    rows: tuple[int, int, int],
    min_points: int,
    above: list[np.ndarray],
) -> tuple[Footprint, int] | None:
    """The footprint (grown by _SLAB, see `rising`) of what rises from a level and the part
    holding the level, or None when too little rises or too little of the level lies outside
    that footprint to show beyond it. xy: (P, 2) the cluster's points by height; part: (P,)
    their parts so far (n_parts of them); rows: the level's slab [a, b) and first row above
    its clearance u; above: the suffix boxes (with nothing cut yet, the level was screened:
    see `kernels.layers.screen_levels`, `_turned`)."""
    a, b, u = rows
    if n_parts == 1:
        return footprint(xy[u:], _SLAB, (above[0][u], above[1][u])), 0
    if a == b:
        return None
    holder = int(np.bincount(part[a:b]).argmax())
    mine = part == holder
    if mine[u:].sum() < max(min_points, _MIN_SHARE * mine.sum()):
        return None
    fp = footprint(xy[u + np.flatnonzero(mine[u:])], _SLAB)
    outside = ~fp.inside(xy[a + np.flatnonzero(mine[a:b])])
    if outside.sum() < _BEYOND * _face_points(min_points):
        return None
    return fp, holder


def _cut_at(
    q: np.ndarray,
    mine: np.ndarray,
    at: np.ndarray,
    u: int,
    level: float,
    clear: float,
    min_points: int,
    rising: Footprint,
) -> list[np.ndarray]:
    """The parts standing on the face at ``level`` of the holder ``mine`` (P,) bool of the
    cluster q (P, 3) sorted by height: the rows of each (its side just above the face
    included). at: the holder's rows at the level; u: the first row above its clearance;
    rising: the footprint of what of the holder rises from it."""
    z, xy = q[:, 2], q[:, :2]
    # What lies under the level's slab (a 2 cm board's sides are all below its top).
    under = int(np.searchsorted(z, level - 1.5 * _SLAB))
    below = _Below(xy[:under][mine[:under]])
    # A face: points at the level with nothing of the holder under them (a lidar's line
    # across a wall has the next line under it), flat around them (a sparse wall's, a
    # sphere's or a cone's points at that height have neighbours above and below).
    min_face = _face_points(min_points)
    face = at[~below.under(xy[at])]
    if len(face) < min_face:
        return []
    # Only the rows within _FLAT_RADIUS of the level in height can lie that near a face.
    near = np.arange(*np.searchsorted(z, [level - 2 * _FLAT_RADIUS, level + 2 * _FLAT_RADIUS]))
    face = face[_flat(q, near[mine[near]], at, face)]
    if len(face) < min_face:
        return []
    fxy = xy[face]
    # A face wholly under what rises from it. (Its boxes, not its hull: tested against the
    # hull, on the TUM desk a keyboard-high face cut off all that stands behind it, and the
    # monitors, thin strips once apart from it, no longer split from each other.)
    if rising.inside(fxy).mean() > 1.0 - _BEYOND:
        return []
    rows = u + np.flatnonzero(mine[u:])
    comp = _cluster_voxel(q[rows], 2.0 * clear, {})
    band_rows = np.flatnonzero(mine & (z > level + 1.5 * _SLAB) & (z <= level + clear))
    out = []
    for k in range(int(comp.max()) + 1 if len(comp) else 0):
        mine_k = rows[comp == k]
        enough = len(mine_k) >= max(min_points, _MIN_SHARE * mine.sum())
        if enough and _stands(q, mine_k, fxy, level, clear, below):
            # Its side just above the face (between the face and the clearance) too.
            inside = _inside(xy[mine_k], xy[band_rows], 0.0)
            out.append(np.r_[mine_k, band_rows[inside]])
    return out


def _flat(p: np.ndarray, mine: np.ndarray, slab: np.ndarray, face: np.ndarray) -> np.ndarray:
    """(F,) bool: which points p[face] are flat around them: of the points p[mine] within
    _FLAT_RADIUS of each, at least _FLAT, and _FLAT_MIN, lie in the level's slab (the rows
    p[slab])."""
    r = _FLAT_RADIUS
    near = count_within(p[mine], p[face], r)
    level = count_within(p[slab], p[face], r)
    return (level >= _FLAT * near) & (level >= _FLAT_MIN)


class _Below:
    """What of a holder lies below a level: its points' x, y (L, 2), metres."""

    def __init__(self, xy: np.ndarray) -> None:
        self.xy = xy

    def under(self, xy: np.ndarray) -> np.ndarray:
        """(Q,) bool: which of xy (Q, 2) have a point below within _COLUMN in x, y."""
        if len(self.xy) == 0 or len(xy) == 0:
            return np.zeros(len(xy), bool)
        return within(self.xy, xy, _COLUMN)


def _stands(
    p: np.ndarray, rows: np.ndarray, fxy: np.ndarray, level: float, clear: float, below: _Below
) -> bool:
    """Whether the points p[rows] stand on the face whose points (F, 2) lie at ``level``: they
    reach down to it, rest on a base a third as wide as they are that lies within the face's
    outline and does not go on down past it, and the face shows beyond them (see the
    module)."""
    q = p[rows]
    z = q[:, 2]
    if z.min() > level + 2 * clear:
        return False  # it does not come down to the face
    base = q[z <= z.min() + clear, :2]
    width = np.ptp(q[:, :2], axis=0).max()
    base_width = np.ptp(base, axis=0).max() if len(base) else 0.0
    if len(base) < _BASE_POINTS or base_width < _BASE_WIDTH * width:
        return False
    # Nor what tapers from its base up (a cone's tip above one of its rings, a lamp's shade):
    # a box is as wide at the top as at its base, a sphere or a bowl wider.
    top_half = q[z >= (z.min() + z.max()) / 2.0, :2]
    if np.ptp(top_half, axis=0).max() < _TAPER * base_width:
        return False
    if _inside(fxy, base, max(_SLAB, _spacing(fxy))).mean() < _INSIDE:
        return False
    # A laptop's screen rises flush with its base's back: its side goes on down.
    if below.under(base).mean() > _MAX_BESIDE:
        return False
    # The face shows beyond it by more than a slope would (a cone's ring, just outside the
    # cone above it, is no face).
    return 1.0 - _inside(q[:, :2], fxy, _BEYOND_BY).mean() >= _BEYOND


def _inside(outline_xy: np.ndarray, xy: np.ndarray, margin: float) -> np.ndarray:
    """(Q,) bool: which of xy (Q, 2) lie within ``margin`` metres of the convex hull of
    outline_xy (K, 2) (all of them when the hull is degenerate: a line holds no outline)."""
    if len(xy) == 0:
        return np.zeros(0, bool)
    ring = footprint_ring(outline_xy)
    if ring is None:
        return np.ones(len(xy), bool)
    eq = footprint_equations(ring)  # each edge: normal . x + offset <= 0 inside (unit normals)
    return np.all(xy @ eq[:, :2].T + eq[:, 2] <= margin, axis=1)


def _face_points(min_points: int) -> int:
    """The fewest points of a face: a third of an object's (a sampled map's box under a box
    shows a rim of 15-25), and 5."""
    return max(min_points // 3, 5)


def _spacing(xy: np.ndarray) -> float:
    """The typical distance (m) between neighbouring points of xy (K, 2) spread over their
    hull: a sparse face's hull falls short of its edge by about that much."""
    ring = footprint_ring(xy)
    if ring is None:
        return 0.0
    return float(np.sqrt(footprint_area(ring) / len(xy)))
