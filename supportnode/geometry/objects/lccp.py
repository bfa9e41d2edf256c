"""Objects as faces joined across convex boundaries (local convexity, after LCCP).

Faces (:mod:`faces`) meet along boundaries of adjacent cells. Each boundary link votes with
the two faces' own normals on its sides: convex where the normals diverge along the vector
between the cells, concave where they converge by more than the smoothness angle (a bowl's
inside curves gently and stays whole). Faces join across a boundary whose links are mostly
not concave; the segments are the groups so joined.
"""

from __future__ import annotations

import numpy as np

from supportnode.geometry.objects.faces import Cells, orient, window_normals
from supportnode.kernels.components import label_edges


def face_normals(
    cells: Cells, face: np.ndarray, w: int, origin: np.ndarray | None
) -> np.ndarray:
    """(F, 3) each cell's normal from the cells of its own face within ``w`` cells, turned
    toward the sensor (cells of no face: from all cells around)."""
    label = np.where(face >= 0, face, -2 - np.arange(len(face)))
    normal, _ = window_normals(cells, w, label)
    return orient(normal, cells.centroid, origin)


def boundary_votes(
    cells: Cells,
    normal: np.ndarray,
    face: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    smooth_deg: float,
    convex_tol: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The boundaries between faces: pairs (fa, fb) (B,) with fa < fb, their links (B,) and
    how many of those are concave (B,)."""
    fa, fb = face[src], face[dst]
    on = (fa >= 0) & (fb >= 0) & (fa != fb)
    s, t = src[on], dst[on]
    d = cells.centroid[s] - cells.centroid[t]
    dist = np.linalg.norm(d, axis=1)
    d /= np.where(dist > 0, dist, 1.0)[:, None]
    conv = np.einsum("ij,ij->i", normal[s] - normal[t], d)
    smooth = np.einsum("ij,ij->i", normal[s], normal[t]) >= np.cos(np.radians(smooth_deg))
    concave = (conv < -convex_tol) & ~smooth
    lo, hi = np.minimum(fa[on], fb[on]), np.maximum(fa[on], fb[on])
    n_face = int(face.max()) + 1
    pair, inv = np.unique(lo * n_face + hi, return_inverse=True)
    links = np.bincount(inv.reshape(-1))
    conc = np.bincount(inv.reshape(-1), weights=concave.astype(np.float64))
    return np.stack([pair // n_face, pair % n_face], axis=1), links, conc


def join_faces(
    n_face: int, pairs: np.ndarray, links: np.ndarray, concave: np.ndarray, share: float
) -> np.ndarray:
    """(n_face,) segment of each face: faces joined across boundaries whose concave links
    are fewer than ``share`` of their links."""
    keep = concave < share * links
    return label_edges(n_face, pairs[keep, 0], pairs[keep, 1])
