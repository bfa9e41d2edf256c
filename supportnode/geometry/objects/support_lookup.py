"""Which surface lies under a point or a cluster: footprint rasters of the support surfaces
(_SupportLookup), all of them on one raster for a one-pass look-up (_SupportTable), the
support under each candidate point (_support_below) and under each cluster's lowest points
(_supports).

Points are (M, 3) float64 metres, z up; surface ids as in ``SurfaceResult``, -1 for none. A
point is over a surface when its x, y falls on the surface's (hole-filled, optionally dilated)
footprint cells and it is at most ``tol`` below the surface's height.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from supportnode.geometry.surfaces import Surface
from supportnode.kernels.footprint import fill_holes
from supportnode.kernels.lookup import cluster_bottoms, lowest_per_cell, table_lookup
from supportnode.kernels.morphology import binary_closing, binary_dilation

# Points within this of a cluster's (robust) bottom are its "lowest points" for the support lookup.
_BOTTOM_BAND = 0.02
# A cluster stands on a surface when at least this fraction of its lowest points are over it.
_SUPPORT_MIN_FRACTION = 0.5
# Largest raster (surfaces + 1) x H x W of the one-pass support look-up (32 MB of int32).
_TABLE_MAX_CELLS = 8_000_000
# A depth camera's surface (one its noise band labelled) has its footprint's notches up to
# twice this wide (metres) closed: an object near a table's edge hides the table behind it
# from the camera, and that shadow, reaching the edge, is a notch, not a hole; the object's
# far part stands on the table all the same. Footprint rasters above _NOTCH_MAX_CELLS cells
# are not closed.
_NOTCH = 0.15
_NOTCH_MAX_CELLS = 250_000


def _support_below(
    cp: np.ndarray,
    surfaces: list[Surface],
    tol: float,
    lookups: tuple[list[_SupportLookup], list[_SupportLookup]] | None = None,
) -> np.ndarray:
    """(M,) int64: the highest surface under each point of cp (M, 3), -1 when none.

    A point is over a surface when its x, y falls on the surface's (filled) footprint and it is
    no more than ``tol`` below the surface's height; or when it falls on the one-cell ring
    around that footprint, off the footprints of the surfaces as high or higher, at or above
    the height, in a cell whose points all lie above ``height - tol``. lookups: the
    surfaces' lookups undilated and dilated (see _lookups), built here when None.
    """
    plain, dilated = lookups if lookups is not None else _lookups(surfaces)
    by_id = {s.id: k for k, s in enumerate(surfaces)}
    ordered = sorted(surfaces, key=lambda s: s.height)
    # The ground (lowest surface with nothing below it) is dilated: a wall standing on its
    # ragged edge would otherwise alternate between "over the floor" and "over nothing" and
    # fall into strips.
    ground = (
        ordered[0] if ordered and len(cp) and cp[:, 2].min() >= ordered[0].height - tol else None
    )
    # Undilated: a chair back rising just beside a table must not be cut at table height.
    lks = [(dilated if s is ground else plain)[by_id[s.id]] for s in ordered]
    # The ring one cell around a footprint holds what rises from the surface's height: an
    # object at a sparse scan's ragged table edge, its front over a notch its own shadow or
    # the gap between two rings left, or a microwave at the back of a counter, the counter
    # under it hidden by its front, stands on the surface as a whole (cut where the
    # footprint ends, it fell in two). Not the surface's own rim (its side face, below its
    # top: that would link the objects along the edge), nor a chair's leg beside a table,
    # which comes up from below in its cell. A depth camera's surface has its notches closed
    # already (see _SupportLookup), and its band claims the foot of what the ring would add.
    rings = [
        (k, dilated[by_id[s.id]])
        for k, s in enumerate(ordered)
        if s is not ground and s.band[0] <= 0
    ]
    table = _SupportTable.build(lks, tol, rings, cp)
    if table is not None:
        return table.lookup(cp)
    return _support_by_layers(cp, lks, tol, rings)


def _support_by_layers(
    cp: np.ndarray,
    lks: list[_SupportLookup],
    tol: float,
    rings: Sequence[tuple[int, _SupportLookup]],
) -> np.ndarray:
    """:func:`_support_below` layer by layer (the footprints' grids differ, or the one raster
    would be too large): the same layers, in the same order, as :class:`_SupportTable`."""
    sup = np.full(len(cp), -1, dtype=np.int64)
    cells = _CellIndex(cp[:, :2])  # floor(xy / cell) once per cell size, not once per surface
    z = cp[:, 2]
    over = [lk.over_cells(cells.of(lk.cell)) for lk in lks]
    writes = [(lk.height - tol, lk.id, over[k]) for k, lk in enumerate(lks)]
    for k, ring in rings:
        ij = cells.of(ring.cell)
        on = ring.over_cells(ij) & ~_shadowing(over, lks, k)
        rows = np.flatnonzero(on)
        low = lowest_per_cell(np.take(cp, rows, axis=0), ring.cell, ring.origin, ring.mask.shape)
        i, j = ij[rows, 0] - ring.origin[0], ij[rows, 1] - ring.origin[1]
        on[rows] = low[i, j] >= ring.height - tol
        writes.append((ring.height, ring.id, on))
    # Stable: footprints before rings on ties, lower surfaces first.
    for w in np.argsort([t for t, _, _ in writes], kind="stable").tolist():
        threshold, sid, hit = writes[w]
        sup[hit & (z >= threshold)] = sid
    return sup


def _shadowing(masks: list[np.ndarray], lks: list[_SupportLookup], k: int) -> np.ndarray:
    """Where surface k's ring gives way: the union of masks (of points or of cells) of its
    own footprint and of every other surface as high as it or higher (lks sorted by
    height)."""
    out = masks[k].copy()
    for k2, lk in enumerate(lks):
        if k2 != k and lk.height >= lks[k].height:
            out |= masks[k2]
    return out


@dataclass
class _SupportTable:
    """All surfaces' footprints on one raster, for :func:`_support_below` in one pass.

    ``best[k, i, j]``: id of the surface of the last of the first k layers (by threshold)
    that covers cell (i, j), -1 for none; a layer is a surface's footprint from ``height -
    tol`` up, or its ring (see :func:`_support_below`) from ``height`` up. A point at height
    z is over exactly the layers whose threshold is at most z, a prefix of k of them, so its
    support is one look-up; the same answer as overwriting the support layer by layer.
    """

    cell: np.ndarray  # (2,) m, shared by all surfaces
    origin: np.ndarray  # (2,) int64 cell index of best[:, 0, 0]
    best: np.ndarray  # (L + 1, H, W) int32
    threshold: np.ndarray  # (L,) ascending, m

    @classmethod
    def build(
        cls,
        lookups: list[_SupportLookup],
        tol: float,
        rings: Sequence[tuple[int, _SupportLookup]],
        cp: np.ndarray,
    ) -> _SupportTable | None:
        """From lookups sorted by height (each over its footprint from ``height - tol`` up)
        and ``rings`` (k, the dilated lookup of lookups[k]), each over its cells off
        :func:`_shadowing`'s where no point of cp (M, 3) lies below ``height - tol``, from
        ``height`` up; None when their grids differ or the raster would exceed
        _TABLE_MAX_CELLS (then :func:`_support_by_layers`)."""
        every = [*lookups, *(ring for _, ring in rings)]
        if not lookups or len({(float(lk.cell[0]), float(lk.cell[1])) for lk in every}) != 1:
            return None
        used = [lk for lk in every if lk.mask.any()]  # an empty footprint covers no cell
        if not used:
            return None
        lo = np.min([lk.origin for lk in used], axis=0)
        hi = np.max([lk.origin + lk.mask.shape for lk in used], axis=0)
        h, w = (int(v) for v in hi - lo)
        layers = len(lookups) + len(rings)
        if (layers + 1) * h * w > _TABLE_MAX_CELLS:
            return None

        def placed(lk: _SupportLookup) -> np.ndarray:
            out = np.zeros((h, w), dtype=bool)
            i0, j0 = (int(v) for v in lk.origin - lo)
            out[i0 : i0 + lk.mask.shape[0], j0 : j0 + lk.mask.shape[1]] = lk.mask
            return out

        masks = [placed(lk) for lk in lookups]
        if rings:
            low = lowest_per_cell(cp, lookups[0].cell, lo, (h, w))
            plain = list(masks)
            for k, ring in rings:
                masks.append(placed(ring) & ~_shadowing(plain, lookups, k))
                masks[-1] &= low >= ring.height - tol
        # Stable: footprints before rings on ties, lower surfaces first.
        threshold = np.array(
            [lk.height - tol for lk in lookups] + [ring.height for _, ring in rings]
        )
        order = np.argsort(threshold, kind="stable")
        ids = [lk.id for lk in every]
        best = np.full((layers + 1, h, w), -1, dtype=np.int32)
        for k, q in enumerate(order.tolist()):  # one raster per layer
            best[k + 1] = best[k]
            best[k + 1][masks[q]] = ids[q]
        return cls(lookups[0].cell, lo, best, threshold[order])

    def lookup(self, cp: np.ndarray) -> np.ndarray:
        """(M,) int64 support surface id of each point of cp (M, 3), -1 for none (compiled:
        `kernels.lookup`)."""
        return table_lookup(cp, self.threshold, self.cell, self.origin, self.best)


def _lookups(surfaces: list[Surface]) -> tuple[list[_SupportLookup], list[_SupportLookup]]:
    """Lookups of the surfaces, undilated and dilated by one cell (filled once for both)."""
    plain = [_SupportLookup(s, dilate=False) for s in surfaces]
    return plain, [lk.dilated() for lk in plain]


class _CellIndex:
    """``floor(xy / cell)`` of fixed points (P, 2) m, computed once per cell size (C, 2) m."""

    def __init__(self, xy: np.ndarray) -> None:
        self.xy = xy
        self._cache: dict[tuple[float, float], np.ndarray] = {}

    def of(self, cell: np.ndarray) -> np.ndarray:
        """(P, 2) int64 cell indices of the points on the grid of size cell (2,) m."""
        key = (float(cell[0]), float(cell[1]))
        if key not in self._cache:
            # Column by column: numpy runs its inner loop over 2 elements on (P, 2) arrays.
            ij = np.empty((len(self.xy), 2), np.int64)
            for a in range(2):
                ij[:, a] = np.floor(self.xy[:, a] / cell[a])
            self._cache[key] = ij
        return self._cache[key]


class _SupportLookup:
    """Dense footprint raster of one surface for point-over-surface queries."""

    def __init__(self, surface: Surface, dilate: bool = True) -> None:
        self.id = surface.id
        self.height = float(surface.height)
        self.cell = np.asarray(surface.cell_size, dtype=np.float64)
        cells = np.asarray(surface.cells, dtype=np.int64).reshape(-1, 2)
        if len(cells) == 0:
            self.mask = np.zeros((1, 1), dtype=bool)
            self.origin = np.zeros(2, dtype=np.int64)
            return
        # One cell of border, then: holes filled (the cells under an object on a table hold no
        # table points, yet the table is under it) and one cell of dilation (an object at the edge
        # of a table sits in a notch of the footprint).
        self.origin = cells.min(axis=0) - 1
        rel = cells - self.origin
        mask = np.zeros(tuple(rel.max(axis=0) + 2), dtype=bool)
        mask[rel[:, 0], rel[:, 1]] = True
        if surface.band[0] > 0:  # one depth camera's view: the shadows are its
            mask = _close_notches(mask, self.cell)
        mask = fill_holes(mask)
        if dilate:
            mask = binary_dilation(mask, np.ones((3, 3), dtype=bool))
        self.mask = mask

    def dilated(self) -> _SupportLookup:
        """This lookup with its footprint dilated by one cell, as ``dilate=True`` builds it."""
        out = copy.copy(self)
        out.mask = binary_dilation(self.mask, np.ones((3, 3), dtype=bool))
        return out

    def over_cells(self, ij: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """(P,) bool: which points lie over this surface's (filled) footprint, from their
        cells ij (P, 2) int64 = floor(xy / self.cell); or (Q,) for the rows ``rows`` of ij."""
        i = ij[:, 0] if rows is None else ij[rows, 0]
        j = ij[:, 1] if rows is None else ij[rows, 1]
        i = i - self.origin[0]
        j = j - self.origin[1]
        h, w = self.mask.shape
        # One unsigned comparison per axis tests 0 <= i < h (negatives wrap to huge values).
        inside = (i.astype(np.uint64) < h) & (j.astype(np.uint64) < w)
        res = np.zeros(len(i), dtype=bool)
        res[inside] = self.mask[i[inside], j[inside]]
        return res


def _close_notches(mask: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """The footprint raster ``mask`` (cells ``cell`` (2,) m) closed by a disc of radius
    _NOTCH (the raster grows by that much each side, then shrinks back: nothing beyond the
    footprint's outline is added, only notches narrower than twice the radius are filled)."""
    r = np.ceil(_NOTCH / cell).astype(np.int64)
    if mask.size > _NOTCH_MAX_CELLS or (r <= 0).any():
        return mask
    ii, jj = np.mgrid[-r[0] : r[0] + 1, -r[1] : r[1] + 1]
    disc = (ii / r[0]) ** 2 + (jj / r[1]) ** 2 <= 1.0
    pad = np.zeros((mask.shape[0] + 2 * r[0], mask.shape[1] + 2 * r[1]), dtype=bool)
    pad[r[0] : -r[0], r[1] : -r[1]] = mask
    closed = binary_closing(pad, disc)
    return mask | closed[r[0] : -r[0], r[1] : -r[1]]


def _supports(
    pts: np.ndarray, runs: np.ndarray, lookups: list[_SupportLookup], tol: float
) -> np.ndarray:
    """(C,) int64: the surface id under the lowest points of each cluster, -1 for none; the
    clusters are the row ranges ``runs`` (C, 2) [a, b) of pts (P, 3).

    The lowest points of every cluster are tested against each surface once (a loop over
    surfaces, not over cluster-surface pairs). A cluster stands on the surface over which the
    largest fraction of its lowest points lie (at least _SUPPORT_MIN_FRACTION), ties to the
    surface closest in height, then to the lowest id.
    """
    n = len(runs)
    best = np.full(n, -1, dtype=np.int64)
    if n == 0 or not lookups:
        return best
    # A robust bottom (the 1st percentile of a cluster of 100 points or more): one stray low
    # point must not decide what the cluster stands on. Compiled: kernels.lookup.
    bottom, n_low, rows_low = cluster_bottoms(pts[:, 2], runs, _BOTTOM_BAND, 100, 1.0)
    owner = np.repeat(np.arange(n), n_low)
    low_xy = np.take(pts, rows_low, axis=0)[:, :2]
    starts = np.cumsum(n_low) - n_low
    cells = _CellIndex(low_xy)
    best_frac = np.full(n, -np.inf)
    best_gap = np.full(n, -np.inf)
    for lk in lookups:  # one iteration per surface
        gap = bottom - lk.height
        # Surface points within point_tolerance were removed, so object bottoms start a little
        # above the surface; noise may put them a little below.
        near = np.flatnonzero((-tol <= gap) & (gap <= tol))
        if len(near) == 0:
            continue
        # The low rows of the near clusters, cluster by cluster: their ranges concatenated.
        take_n = n_low[near]
        rows = np.arange(int(take_n.sum())) + np.repeat(
            starts[near] - (np.cumsum(take_n) - take_n), take_n
        )
        hits = lk.over_cells(cells.of(lk.cell), rows)
        count = np.bincount(owner[rows], weights=hits, minlength=n)[near]
        frac = count / n_low[near]  # the mean of the booleans, exactly
        key_gap = -np.abs(gap[near])
        # Lexicographic (frac, -|gap|, -id) as before, compared with the best so far.
        better = (frac > best_frac[near]) | (
            (frac == best_frac[near])
            & (
                (key_gap > best_gap[near])
                | ((key_gap == best_gap[near]) & ((best[near] < 0) | (lk.id < best[near])))
            )
        )
        take = near[better & (frac >= _SUPPORT_MIN_FRACTION)]
        sel = better & (frac >= _SUPPORT_MIN_FRACTION)
        best[take] = lk.id
        best_frac[take] = frac[sel]
        best_gap[take] = key_gap[sel]
    return best
