"""Sparse synthetic tabletops for the objects tests: a table surface given directly (no
surface detection) and boxes sampled on their faces, a few points per 3 cm voxel."""

from __future__ import annotations

import itertools

import numpy as np

from supportnode.geometry.surfaces import Surface


def table_surface(
    height: float, normal=(0.0, 0.0, 1.0), band: tuple[float, float] = (0.0, 0.0)
) -> Surface:
    """Surface 0: a 2 x 2 m table at ``height`` m, its fitted plane's ``normal`` (turned
    unit), ``band`` its noise band (zeros: none measured, a lidar's or a sampled map's)."""
    ii, jj = np.meshgrid(np.arange(-10, 10), np.arange(-10, 10), indexing="ij")
    cells = np.stack([ii.ravel(), jj.ravel()], axis=1).astype(np.int64)
    n = np.asarray(normal, float)
    return Surface(
        id=0,
        height=height,
        area=4.0,
        centroid=np.array([0.0, 0.0, height]),
        normal=n / np.linalg.norm(n),
        flatness=0.0,
        bbox_min=np.array([-1.0, -1.0, height]),
        bbox_max=np.array([1.0, 1.0, height]),
        outline=[np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])],
        point_count=0,
        voxel_count=len(cells),
        cells=cells,
        cell_size=(0.1, 0.1),
        band=band,
    )


def box_faces(lo, hi, rng: np.random.Generator, spacing: float) -> np.ndarray:
    """(P, 3) points uniformly on the five faces of a box seen from above (no bottom),
    about one per spacing^2 (m)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    out = []
    for axis in range(3):
        other = [a for a in range(3) if a != axis]
        area = np.prod(hi[other] - lo[other])
        for end in (lo[axis], hi[axis]) if axis < 2 else (hi[axis],):
            n = rng.poisson(area / spacing**2)
            f = np.empty((n, 3))
            f[:, other] = rng.uniform(lo[other], hi[other], (n, 2))
            f[:, axis] = end
            out.append(f)
    return np.concatenate(out)


def detect_parts(parts: list[np.ndarray], table: Surface):
    """detect_objects on the parts' points over ``table`` (all of them candidates): the
    result and each part's labels."""
    from supportnode.geometry.objects import detect_objects
    from supportnode.geometry.surfaces import SurfaceResult

    pts = np.concatenate(parts)
    res = detect_objects(pts, SurfaceResult([table], np.full(len(pts), -1, np.int32)))
    bounds = np.cumsum([0] + [len(p) for p in parts])
    return res, [res.labels[a:b] for a, b in itertools.pairwise(bounds)]


def whole(lab: np.ndarray) -> int:
    """The one cluster holding (nearly, 90 %) all of a part's points."""
    ids, counts = np.unique(lab, return_counts=True)
    assert counts.max() >= 0.9 * len(lab), dict(zip(ids.tolist(), counts.tolist(), strict=True))
    return int(ids[counts.argmax()])
