"""Objects standing on objects: a segment cut at the top face of what holds the rest.

Local convexity parts a box standing on a box where the upper box's faces meet the lower
one's top in a concave crease, but a face flush on both (their sides in one plane, as in a
neat stack) joins them again. Gravity settles it: where a segment holds an upward face well
above its surface (the top of a box, a book), what rises from that face's height and stands
within the footprint of what is below is another object, standing on it. A bowl's or a pot's
inner bottom lies too low to hold anything (``_MIN_TOP``), a box's own top has nothing above
it, and a taller box beside a lower one has faces going on down beside the lower one's top.
"""

from __future__ import annotations

import numpy as np

from supportnode.kernels.components import label_edges
from supportnode.kernels.groups import label_boxes

# An upward face (normal within _UP_DEG of +z, at least _TOP_POINTS points) at least
# _MIN_TOP above its surface can hold another object.
_UP_DEG = 15.0
_TOP_POINTS = 30
_MIN_TOP = 0.02
# What stands on it: at least _MIN_SHARE of the segment's points, its lowest cells within
# two clearances of the face's height, and _INSIDE of them over the face's footprint (its
# x, y box, grown by _MARGIN metres).
_MIN_SHARE = 0.1
_INSIDE = 0.8
_MARGIN = 0.01
# ... and under _MAX_BESIDE of those lowest cells lie on faces that go on down beside the
# face's footprint (a taller object beside the face's holder does).
_MAX_BESIDE = 0.3


def cut_stacks(
    centroid: np.ndarray,
    count: np.ndarray,
    above: np.ndarray,
    face: np.ndarray,
    face_up: np.ndarray,
    seg: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    clearance: float,
    min_points: int,
) -> np.ndarray:
    """(F,) segment of each cell with stacked objects cut apart (new segments numbered after
    the others); cells of no segment stay -1.

    centroid: (F, 3) cells' centroids, metres, z up; count: (F,) their points; above: (F,)
    their height above the surface under them (inf over none); face: (F,) face of each cell
    (-1: none); face_up: (n_faces,) each face's normal's z component; seg: (F,) segment of
    each cell; src, dst: (E,) adjacent cells; clearance: how far above a face's height a
    cell must lie to stand on it (a cell and the noise), metres."""
    seg = seg.copy()
    n_face = len(face_up)
    if n_face == 0 or not (seg >= 0).any():
        return seg
    on = face >= 0
    pts = np.bincount(face[on], weights=count[on], minlength=n_face)
    low = label_boxes(above[:, None], face, n_face)[0][:, 0]  # np.minimum.at's values
    tops = np.flatnonzero(
        (face_up >= np.cos(np.radians(_UP_DEG))) & (pts >= _TOP_POINTS) & (low >= _MIN_TOP)
    )
    # Higher tops first: a stack of three parts its top box before its middle one.
    # bincount adds in input order, as np.add.at does (the same sums), at a tenth of its cost.
    weighted = np.bincount(face[on], weights=centroid[on, 2] * count[on], minlength=n_face)
    height = weighted / np.maximum(pts, 1)
    for t in tops[np.argsort(-height[tops])]:
        _cut_at(t, height[t], centroid, count, face, seg, src, dst, clearance, min_points)
    return seg


def _cut_at(
    top: int,
    z_top: float,
    centroid: np.ndarray,
    count: np.ndarray,
    face: np.ndarray,
    seg: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    clearance: float,
    min_points: int,
) -> None:
    """Cut, in place, from the segment holding face ``top`` (at height ``z_top``) the parts
    standing on it (see the module)."""
    held = seg[face == top]
    if len(held) == 0 or held[0] < 0:
        return
    s = held[0]
    mine = seg == s
    upper = mine & (centroid[:, 2] > z_top + clearance) & (face != top)
    lower = mine & ~upper
    if count[upper].sum() < max(min_points, _MIN_SHARE * count[mine].sum()):
        return
    # The parts above, joined among themselves only.
    keep = upper[src] & upper[dst]
    part = label_edges(len(seg), src[keep], dst[keep])
    lo = centroid[lower, :2].min(axis=0) - _MARGIN
    hi = centroid[lower, :2].max(axis=0) + _MARGIN
    total = count[mine].sum()
    for p in np.unique(part[upper]):
        cells = upper & (part == p)
        if count[cells].sum() < max(min_points, _MIN_SHARE * total):
            continue
        z = centroid[cells, 2]
        bottom = cells.copy()
        bottom[cells] = z <= z.min() + clearance
        if z.min() > z_top + 2 * clearance:
            continue  # it does not come down to the face
        xy = centroid[bottom, :2]
        inside = np.all((xy >= lo) & (xy <= hi), axis=1).mean()
        if (
            inside >= _INSIDE
            and _beside(bottom, top, z_top, centroid, face, mine, clearance) < _MAX_BESIDE
        ):
            seg[cells] = seg.max() + 1


def _beside(
    bottom: np.ndarray,
    top: int,
    z_top: float,
    centroid: np.ndarray,
    face: np.ndarray,
    mine: np.ndarray,
    clearance: float,
) -> float:
    """The share of the ``bottom`` cells (F,) bool whose face goes on down, below the top
    face's height and beside its footprint (not under it): a taller object touching the
    top's holder from beside, its front flush with the holder's. A face flush with the
    holder's side goes on down too, but along the top's edge."""
    at = face == top
    lo = centroid[at, :2].min(axis=0) - clearance
    hi = centroid[at, :2].max(axis=0) + clearance
    col = 2.0 * clearance
    below = mine & (centroid[:, 2] < z_top - clearance) & (face >= 0)
    below &= ~np.all((centroid[:, :2] >= lo) & (centroid[:, :2] <= hi), axis=1)
    if not below.any() or not bottom.any():
        return 0.0

    def key(cells: np.ndarray) -> np.ndarray:
        ij = np.floor(centroid[cells, :2] / col).astype(np.int64)
        return (face[cells] * 2**21 + ij[:, 0]) * 2**21 + ij[:, 1]

    return float(np.isin(key(bottom), key(below)).mean())
