"""Object tops among the surfaces: which faces are tried as an object's top (filters)."""

from __future__ import annotations

import numpy as np

from supportnode.params import SurfaceParams


def _footprint_surface(sid: int, height: float, cells: np.ndarray):
    """A level surface whose footprint is ``cells`` (C, 2) of 10 cm."""
    from supportnode.geometry.surfaces import Surface

    lo, hi = cells.min(axis=0) * 0.1, (cells.max(axis=0) + 1) * 0.1
    return Surface(
        id=sid,
        height=height,
        area=len(cells) * 0.01,
        centroid=np.array([*(lo + hi) / 2, height]),
        normal=np.array([0.0, 0.0, 1.0]),
        flatness=0.0,
        bbox_min=np.array([*lo, height]),
        bbox_max=np.array([*hi, height]),
        outline=[],
        point_count=0,
        voxel_count=len(cells),
        cells=cells.astype(np.int64),
        cell_size=(0.1, 0.1),
    )


def test_a_face_with_the_table_in_half_its_inner_cells_may_still_be_an_objects_top():
    """A 40 x 30 cm face has two inner cells; the table's footprint reaching into one of them
    (filled under the face at a coarse camera's resolution) is not the table plainly seen
    under it, which takes most of them: the face stays a candidate object top."""
    from supportnode.geometry.surfaces.filters import _candidates_below

    ii, jj = np.meshgrid(np.arange(12), np.arange(12), indexing="ij")
    grid = np.stack([ii.ravel(), jj.ravel()], axis=1)
    face = (grid[:, 0] >= 4) & (grid[:, 0] < 8) & (grid[:, 1] >= 4) & (grid[:, 1] < 7)
    inner = (grid[:, 0] == 5) & (grid[:, 1] == 5)  # of the two inner cells, (5, 5) and (6, 5)
    table = _footprint_surface(0, 0.0, grid[~face | inner])
    top = _footprint_surface(1, 0.07, grid[face])
    _, _, below = _candidates_below([table, top], [1], SurfaceParams())
    assert below == {1: [0]}
    both = (grid[:, 0] >= 5) & (grid[:, 0] < 7) & (grid[:, 1] == 5)
    seen = _footprint_surface(0, 0.0, grid[~face | both])  # under both: plainly seen
    _, _, below = _candidates_below([seen, top], [1], SurfaceParams())
    assert below == {}
