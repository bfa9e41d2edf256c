"""Smooth faces of the points on no surface: fine cells, their normals, faces grown across
cells whose normals agree.

A cell's normal comes from the moments of the cells within a window around it (a few
centimetres: a depth camera's noise and its depth steps make a centimetre patch's normal
scatter by tens of degrees). Cells whose window is not flat (a box's edge, where two faces
meet) start no face and join the face nearest to their points afterwards. Once the faces
are known, each cell's normal is taken again from the cells of its own face only: on both
sides of a crease the normals are then those of the faces, not their blend.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from supportnode.geometry.linalg import sym3_eigen_entries
from supportnode.kernels.components import label_edges

if TYPE_CHECKING:  # the kernels are imported by make_cells, on the clouds that need faces
    from supportnode.kernels.cellgraph import CellGrid

# Moment columns' (a, b) pairs in the order of linalg's entries (xx, yy, zz, xy, xz, yz).
_OUTER = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
# Rounds of attaching the unassigned cells to the face beside them (a crease band is a few
# cells wide).
_ATTACH_ROUNDS = 8


@dataclass
class Cells:
    """Fine cells of M points: ``of_point`` (M,) cell of each point; ``grid`` the occupied
    cells; ``moments`` (F, 10) count, sums and products of the points' coordinates relative
    to ``base`` (3,), metres; ``centroid`` (F, 3) in the points' frame; ``size`` the edge."""

    of_point: np.ndarray
    grid: CellGrid
    moments: np.ndarray
    centroid: np.ndarray
    base: np.ndarray
    size: float


def make_cells(pts: np.ndarray, size: float, pad: int) -> Cells:
    """The occupied ``size`` cells of (M, 3) points, metres, padded by ``pad`` cells."""
    # Imported here, not with the module: only dense clouds (a depth camera's) grow faces, and
    # `runtime.warm` loads the kernels of every imported kernel module (~4 ms each, 5 here).
    from supportnode.kernels.cellgraph import bin_points

    grid, of_point, mom, base = bin_points(pts, size, pad)
    centroid = mom[:, 1:4] / mom[:, :1] + base
    return Cells(of_point, grid, mom, centroid, base, float(size))


def window_normals(
    cells: Cells, w: int, label: np.ndarray | None = None, at: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (F, 3) (sign arbitrary) and surface variation (F,) (least eigenvalue over
    their sum: 0 on a plane, ~1/3 for isotropic scatter) of the points within ``w`` cells of
    each cell, only those of cells with the same ``label`` when given; of the cells ``at``
    only (K,) when given."""
    s = cells.grid.window_sums(cells.moments, w, label, at)
    count = np.maximum(s[:, 0], 1.0)
    mean = [s[:, 1 + a] / count for a in range(3)]
    entries = [s[:, 4 + q] / count - mean[a] * mean[b] for q, (a, b) in enumerate(_OUTER)]
    evals, normal = sym3_eigen_entries(*entries)
    evals = np.maximum(evals, 0.0)
    total = evals.sum(axis=1)
    variation = np.where(total > 0, evals[:, 0] / np.where(total > 0, total, 1.0), 1.0)
    norm = np.linalg.norm(normal, axis=1, keepdims=True)
    return normal / np.where(norm > 0, norm, 1.0), variation


def orient(
    normal: np.ndarray,
    centroid: np.ndarray,
    origin: np.ndarray | None,
    inside: np.ndarray | None = None,
) -> np.ndarray:
    """Normals (F, 3) turned toward the sensor at ``origin`` (3,); without one, away from
    ``inside`` (F, 3), a point inside each cell's object (its group's centroid), or from
    the centroid of all cells when None."""
    if origin is not None:
        view = np.asarray(origin, np.float64) - centroid
        flip = np.einsum("ij,ij->i", normal, view) < 0
    else:
        mid = centroid.mean(axis=0) if inside is None else inside
        flip = np.einsum("ij,ij->i", normal, centroid - mid) < 0
    return np.where(flip[:, None], -normal, normal)


def group_centroids(centroid: np.ndarray, group: np.ndarray) -> np.ndarray:
    """(F, 3) the centroid of each cell's ``group`` (F,) of cells."""
    n = np.maximum(np.bincount(group), 1).astype(np.float64)
    mid = np.stack([np.bincount(group, centroid[:, a]) / n for a in range(3)], axis=1)
    return mid[group]


def grow_faces(
    cells: Cells,
    normal: np.ndarray,
    variation: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    max_variation: float,
    max_angle_deg: float,
    max_offset: float,
    min_points: int,
) -> np.ndarray:
    """(F,) face of each cell, -1 for none: adjacent flat cells (variation at most
    ``max_variation``) whose normals differ by at most ``max_angle_deg`` and whose centroids
    lie within ``max_offset`` of each other's plane join; faces of fewer than
    ``min_points`` points, and the cells that are not flat, then join the face whose plane
    passes nearest to them (see :func:`attach`)."""
    c = cells.centroid
    flat = variation <= max_variation
    # Rows gathered once each with np.take (4x faster than fancy indexing of (F, 3) rows).
    n_src, n_dst = np.take(normal, src, axis=0), np.take(normal, dst, axis=0)
    d = np.take(c, dst, axis=0) - np.take(c, src, axis=0)
    ok = flat[src] & flat[dst]
    ok &= np.einsum("ij,ij->i", n_src, n_dst) >= np.cos(np.radians(max_angle_deg))
    ok &= np.abs(np.einsum("ij,ij->i", n_src, d)) <= max_offset
    ok &= np.abs(np.einsum("ij,ij->i", n_dst, d)) <= max_offset
    face = label_edges(len(c), src[ok], dst[ok])
    points = np.bincount(face, weights=cells.moments[:, 0])
    face = np.where(points[face] >= min_points, face, -1)
    face = attach(face, cells.centroid, normal, src, dst)
    _, face[face >= 0] = np.unique(face[face >= 0], return_inverse=True)
    return face


def attach(
    face: np.ndarray, centroid: np.ndarray, normal: np.ndarray, src: np.ndarray, dst: np.ndarray
) -> np.ndarray:
    """Cells without a face (-1) take, round by round, the face of the adjacent cell whose
    plane passes nearest to their centroid; cells that meet no face keep -1."""
    face = face.copy()
    a = np.concatenate([src, dst])
    b = np.concatenate([dst, src])
    for _ in range(_ATTACH_ROUNDS):
        # Only the links from cells still without a face (a cell once given one keeps it):
        # the list shrinks round by round, in its order, so ties fall as before.
        still = face[a] < 0
        a, b = a[still], b[still]
        pick = face[b] >= 0
        if not pick.any():
            break
        u, v = a[pick], b[pick]
        off = np.take(centroid, u, axis=0) - np.take(centroid, v, axis=0)
        dist = np.abs(np.einsum("ij,ij->i", np.take(normal, v, axis=0), off))
        order = np.lexsort((dist, u))
        first = order[np.r_[True, u[order][1:] != u[order][:-1]]]
        face[u[first]] = face[v[first]]
    return face
