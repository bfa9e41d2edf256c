"""Free space and the largest free disc on hand-built surfaces."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from conftest import REPO
from test_objects import box, make_surface, plane

from supportnode.errors import InputError
from supportnode.geometry.freespace import free_space, free_space_all
from supportnode.geometry.objects import detect_objects
from supportnode.geometry.surfaces import SurfaceResult
from supportnode.params import FreeSpaceParams

C = 0.02  # fine grid


def test_empty_square():
    sq = make_surface(0, 0.7, 0.0, 1.0, 0.0, 1.0)
    fs = free_space(sq, [], None, FreeSpaceParams(cell_size=C, margin=0.05))
    assert fs.free_area == pytest.approx(1.0, abs=1e-9)
    assert fs.occupied_area == 0.0
    assert fs.disc_radius == pytest.approx(0.5, abs=C)
    np.testing.assert_allclose(fs.disc_center, [0.5, 0.5], atol=C)
    assert fs.free_mask.dtype == bool and fs.free_mask.sum() == 2500
    # Row = y, column = x: the mask's free cells map back to the square.
    rows, cols = np.nonzero(fs.free_mask)
    x = fs.grid_origin[0] + (cols + 0.5) * C
    y = fs.grid_origin[1] + (rows + 0.5) * C
    assert x.min() > 0 and x.max() < 1 and y.min() > 0 and y.max() < 1
    d = fs.to_dict()
    json.dumps(d)
    assert "free_mask" not in d and d["grid_shape"] == list(fs.free_mask.shape)


def table_with_box(lo_xy, hi_xy, surface=None):
    """A 1 x 1 m table at z=0.7 with one box on it, run through detect_objects."""
    surface = surface or make_surface(0, 0.7, 0.0, 1.0, 0.0, 1.0)
    b = box((*lo_xy, 0.7), (*hi_xy, 0.9))
    pts = np.concatenate([plane(0, 1, 0, 1, 0.7), b])
    lab = np.concatenate([np.zeros(len(pts) - len(b), np.int32), np.full(len(b), -1, np.int32)])
    surfs = SurfaceResult([surface], lab)
    objs = detect_objects(pts, surfs)
    assert len(objs.clusters) == 1 and objs.clusters[0].surface_id == 0
    return pts, surfs, objs


def test_object_in_the_middle():
    pts, surfs, objs = table_with_box((0.4, 0.4), (0.6, 0.6))
    margin = 0.05
    (fs,) = free_space_all(surfs, objs, pts, FreeSpaceParams(cell_size=C, margin=margin))
    # Occupied: the 0.2 m box footprint grown by the margin (rounded corners), within a cell.
    side = 0.2 + C  # the box's points reach into the cells on its far edges
    expected_occ = side**2 + 4 * side * margin + np.pi * margin**2
    assert fs.occupied_area == pytest.approx(expected_occ, abs=4 * side * C)
    assert fs.free_area + fs.occupied_area == pytest.approx(1.0, abs=1e-9)
    # Largest free disc: in a corner region, touching two table edges and the occupied zone.
    # Centre (r, r) from the corner at (0, 0), clear of the box corner (0.4, 0.4) by the margin:
    # sqrt(2) (0.4 - r) = r + margin  ->  r = (0.4 sqrt(2) - margin) / (1 + sqrt(2)).
    r = (0.4 * np.sqrt(2) - margin) / (1 + np.sqrt(2))
    assert fs.disc_radius == pytest.approx(r, abs=C)
    cx, cy = fs.disc_center
    corner = np.array([0.0 if cx < 0.5 else 1.0, 0.0 if cy < 0.5 else 1.0])
    np.testing.assert_allclose(np.abs(fs.disc_center - corner), [r, r], atol=1.5 * C)
    # The disc is free: no free-mask hole inside it.
    rows, cols = np.nonzero(~fs.free_mask)
    blocked = fs.grid_origin + (np.stack([cols, rows], 1) + 0.5) * C
    assert np.hypot(*(blocked - fs.disc_center).T).min() >= fs.disc_radius


def test_margin_grows_occupied_area():
    pts, surfs, objs = table_with_box((0.3, 0.3), (0.5, 0.5))
    areas = [
        free_space_all(surfs, objs, pts, FreeSpaceParams(cell_size=C, margin=m))[0].occupied_area
        for m in (0.0, 0.05, 0.1)
    ]
    side = 0.2 + C
    for a, m in zip(areas, (0.0, 0.05, 0.1), strict=True):
        assert a == pytest.approx(side**2 + 4 * side * m + np.pi * m**2, abs=4 * (side + m) * C)
    assert areas[0] < areas[1] < areas[2]


def test_footprint_polygons_when_no_points():
    pts, surfs, objs = table_with_box((0.4, 0.4), (0.6, 0.6))
    params = FreeSpaceParams(cell_size=C, margin=0.05)
    with_pts = free_space_all(surfs, objs, pts, params)[0]
    hull = free_space(surfs.surfaces[0], objs.clusters, None, params)
    assert hull.occupied_area == pytest.approx(with_pts.occupied_area, rel=0.1)
    assert hull.disc_radius == pytest.approx(with_pts.disc_radius, abs=C)


def test_l_shaped_surface():
    # An L: the square [0, 1]^2 without its top-right quarter [0.5, 1]^2.
    surf = make_surface(0, 0.7, 0.0, 1.0, 0.0, 1.0)
    keep = ~((surf.cells[:, 0] >= 5) & (surf.cells[:, 1] >= 5))
    surf.cells = surf.cells[keep]
    surf.area = 0.75
    fs = free_space(surf, [], None, FreeSpaceParams(cell_size=C, margin=0.05))
    assert fs.free_area == pytest.approx(0.75, abs=1e-9)
    # The largest disc of an L of arm width 0.5 has radius 0.25 * ... at the inner corner
    # region: centre on the diagonal, touching both outer edges and the re-entrant corner
    # (0.5, 0.5): r = sqrt(2) (0.5 - r) -> r = 0.5 sqrt(2) / (1 + sqrt(2)) ~ 0.293 m.
    r = 0.5 * np.sqrt(2) / (1 + np.sqrt(2))
    assert fs.disc_radius == pytest.approx(r, abs=C)
    np.testing.assert_allclose(fs.disc_center, [r, r], atol=1.5 * C)


def test_objects_elsewhere_are_ignored_and_empty_surface():
    _, _, objs = table_with_box((0.4, 0.4), (0.6, 0.6))
    other = make_surface(1, 0.0, 2.0, 3.0, 0.0, 1.0)
    fs = free_space(other, objs.clusters, None, FreeSpaceParams(cell_size=C))
    assert fs.occupied_area == 0.0 and fs.free_area == pytest.approx(1.0)
    empty = make_surface(2, 0.0, 0.0, 0.0, 0.0, 0.0)
    fe = free_space(empty, [], None, FreeSpaceParams(cell_size=C))
    assert fe.free_area == 0.0 and fe.disc_radius == 0.0 and np.isnan(fe.disc_center).all()
    json.dumps(fe.to_dict())


def test_fully_covered_surface_has_no_disc():
    small = make_surface(0, 0.7, 0.4, 0.6, 0.4, 0.6)
    _, _, objs = table_with_box((0.4, 0.4), (0.6, 0.6))
    fs = free_space(small, objs.clusters, None, FreeSpaceParams(cell_size=C, margin=0.05))
    assert fs.free_area == 0.0 and fs.disc_radius == 0.0 and np.isnan(fs.disc_center).all()


def test_free_space_from_the_segmentation_equals_that_from_the_described_objects():
    """Free space needs only which points form which object and what it stands on: computed
    before the objects are described (hulls, boxes), it is the same, mask and all."""
    from supportnode.geometry.objects import describe_objects, segment_objects

    sq = make_surface(0, 0.7, 0.0, 1.0, 0.0, 1.0)
    boxes = [box((0.1, 0.1, 0.7), (0.3, 0.25, 0.85)), box((0.55, 0.5, 0.7), (0.8, 0.9, 1.0))]
    pts = np.concatenate([plane(0, 1, 0, 1, 0.7), *boxes])
    n_obj = sum(len(b) for b in boxes)
    lab = np.concatenate([np.zeros(len(pts) - n_obj, np.int32), np.full(n_obj, -1, np.int32)])
    surfs = SurfaceResult([sq], lab)
    seg = segment_objects(pts, surfs)
    objs = describe_objects(seg)
    assert len(objs.clusters) == 2
    np.testing.assert_array_equal(seg.labels, objs.labels)
    assert seg.surface_ids.tolist() == [c.surface_id for c in objs.clusters] == [0, 0]
    np.testing.assert_array_equal(seg.bbox_min, [c.bbox_min for c in objs.clusters])
    ref = detect_objects(pts, surfs)
    assert [c.to_dict() for c in objs.clusters] == [c.to_dict() for c in ref.clusters]
    params = FreeSpaceParams(cell_size=C, margin=0.05)
    (a,), (b,) = free_space_all(surfs, seg, pts, params), free_space_all(surfs, objs, pts, params)
    assert a.to_dict() == b.to_dict() and 0 < a.free_area < 1.0
    np.testing.assert_array_equal(a.free_mask, b.free_mask)


def test_detect_reports_surfaces_before_describing_objects(rng):
    """pipeline.detect(on_surfaces=...) hands over the surfaces and free space, the same as in
    its result, while the objects are not yet described."""
    from supportnode.pipeline import detect

    floor = plane(-1, 1, -1, 1, 0.0, step=0.02)
    b = box((0.0, 0.0, 0.0), (0.3, 0.3, 0.4))
    pts = np.concatenate([floor, b])
    seen = []
    d = detect(pts, on_surfaces=lambda s, f, seg: seen.append((s, f, seg)))
    assert len(seen) == 1
    s, f, seg = seen[0]
    assert s is d.surfaces and [x.to_dict() for x in f] == [x.to_dict() for x in d.free_space]
    assert len(seg.surface_ids) == len(d.objects.clusters) >= 1
    assert f[0].occupied_area > 0.09  # the box's footprint, before any hull was computed


def test_detect_free_below_leaves_out_only_the_higher_surfaces():
    """pipeline.detect(free_below=h): free space of the surfaces lower than h, exactly as a
    detection of all gives it, and none for the others (a node's ceiling)."""
    from supportnode.pipeline import detect

    floor = plane(-1, 1, -1, 1, 0.0, step=0.02)
    table = plane(1.5, 2.5, -0.5, 0.5, 0.8, step=0.02)
    ceiling = plane(-1, 1, -1, 1, 2.4, step=0.02)
    b = box((0.0, 0.0, 0.0), (0.3, 0.3, 0.4))
    pts = np.concatenate([floor, table, ceiling, b])
    every = detect(pts)
    heights = sorted(round(s.height, 2) for s in every.surfaces.surfaces)
    assert heights == [0.0, 0.4, 0.8, 2.4]  # 0.4: the box top
    cut = detect(pts, free_below=1.0)
    low = {s.id for s in every.surfaces.surfaces if s.height < 1.0}
    assert {f.surface_id for f in cut.free_space} == low
    want = [f.to_dict() for f in every.free_space if f.surface_id in low]
    assert [f.to_dict() for f in cut.free_space] == want
    assert [s.to_dict() for s in cut.surfaces.surfaces] == [
        s.to_dict() for s in every.surfaces.surfaces
    ]
    with pytest.raises(InputError, match="free_below must be a height in metres or None, got nan"):
        detect(pts, free_below=float("nan"))


def test_free_space_does_not_depend_on_how_touching_objects_are_split():
    """A pile occupies its surface however it is split into objects: free space comes from the
    connected components standing on each surface (the kitchen has a cluster cut in two). The
    sloped scene's ramp (on the floor, rising to 0.5 m; its high end stands on no surface) is
    room structure, one cluster: the floor under it is not free."""
    from supportnode.io.clouds import read_cloud
    from supportnode.params import DetectParams
    from supportnode.pipeline import detect

    def both(name: str) -> tuple:
        pts = np.asarray(read_cloud(REPO / "sim_scans" / f"{name}.ply").points, float)
        results = {}
        for split in (True, False):
            params = DetectParams()
            params = dataclasses.replace(
                params, objects=dataclasses.replace(params.objects, split_touching=split)
            )
            results[split] = detect(pts, params)
        return results[True], results[False]

    split, whole = both("kitchen_sampled")
    stats = split.objects.stats
    assert stats["merged_splits"] + stats["layer_splits"] >= 1  # a cluster is cut into parts
    assert len(split.objects.clusters) > len(whole.objects.clusters)
    for a, b in zip(split.free_space, whole.free_space, strict=True):
        assert a.to_dict() == b.to_dict()
        np.testing.assert_array_equal(a.free_mask, b.free_mask)
    split, _ = both("sloped_sampled")
    (floor,) = [
        f for f, s in zip(split.free_space, split.surfaces.surfaces, strict=True) if s.height < 0.01
    ]
    rows, cols = np.nonzero(floor.free_mask)
    x = floor.grid_origin[0] + (cols + 0.5) * floor.cell_size
    y = floor.grid_origin[1] + (rows + 0.5) * floor.cell_size
    under_ramp = (
        (x > 0.6) & (x < 2.4) & (np.abs(y) < 0.45)
    )  # its footprint: x 0.53..2.45, |y| < 0.5
    assert not under_ramp.any(), f"{under_ramp.sum()} free cells under the ramp"
