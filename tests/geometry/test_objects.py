"""Object segmentation on hand-built clouds with known answers."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from supportnode.errors import InputError
from supportnode.geometry.objects import describe_objects, detect_objects, segment_objects
from supportnode.geometry.surfaces import Surface, SurfaceResult, detect_surfaces
from supportnode.params import ObjectParams

CELL = 0.1  # coarse surface footprint grid, as the surface detector uses


def make_surface(sid: int, height: float, x0: float, x1: float, y0: float, y1: float) -> Surface:
    """A rectangular horizontal surface with footprint cells consistent with its extent."""
    ii, jj = np.meshgrid(
        np.arange(int(np.floor(x0 / CELL + 1e-9)), int(np.ceil(x1 / CELL - 1e-9))),
        np.arange(int(np.floor(y0 / CELL + 1e-9)), int(np.ceil(y1 / CELL - 1e-9))),
        indexing="ij",
    )
    cells = np.stack([ii.ravel(), jj.ravel()], axis=1).astype(np.int64)
    area = (x1 - x0) * (y1 - y0)
    return Surface(
        id=sid,
        height=height,
        area=area,
        centroid=np.array([(x0 + x1) / 2, (y0 + y1) / 2, height]),
        normal=np.array([0.0, 0.0, 1.0]),
        flatness=0.0,
        bbox_min=np.array([x0, y0, height]),
        bbox_max=np.array([x1, y1, height]),
        outline=[np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])],
        point_count=0,
        voxel_count=len(cells),
        cells=cells,
        cell_size=(CELL, CELL),
    )


def plane(x0: float, x1: float, y0: float, y1: float, z: float, step: float = 0.02) -> np.ndarray:
    """Grid points of a horizontal rectangle, (P, 3)."""
    xs = np.arange(x0 + step / 2, x1, step)
    ys = np.arange(y0 + step / 2, y1, step)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    return np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)], axis=1)


def box(lo, hi, step: float = 0.01) -> np.ndarray:
    """Points on the five visible faces of an axis-aligned box (no bottom), (P, 3)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    faces = []
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        u = np.arange(lo[others[0]], hi[others[0]] + 1e-9, step)
        v = np.arange(lo[others[1]], hi[others[1]] + 1e-9, step)
        gu, gv = np.meshgrid(u, v, indexing="ij")
        ends = (lo[axis], hi[axis]) if axis < 2 else (hi[axis],)
        for w in ends:
            f = np.empty((gu.size, 3))
            f[:, others[0]], f[:, others[1]], f[:, axis] = gu.ravel(), gv.ravel(), w
            faces.append(f)
    return np.unique(np.round(np.concatenate(faces), 9), axis=0)


def cylinder(cx: float, cy: float, r: float, z0: float, z1: float, step: float = 0.01):
    """Side and top of a vertical cylinder, (P, 3)."""
    n_a = int(np.ceil(2 * np.pi * r / step))
    a = np.linspace(0, 2 * np.pi, n_a, endpoint=False)
    zs = np.arange(z0, z1 + 1e-9, step)
    ga, gz = np.meshgrid(a, zs, indexing="ij")
    side = np.stack([cx + r * np.cos(ga.ravel()), cy + r * np.sin(ga.ravel()), gz.ravel()], 1)
    top = plane(cx - r, cx + r, cy - r, cy + r, z1, step)
    top = top[(top[:, 0] - cx) ** 2 + (top[:, 1] - cy) ** 2 <= r * r]
    return np.concatenate([side, top])


def scene(parts: list[tuple[np.ndarray, int]]) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate (points, label) parts; label >= 0 is a surface id, -1 an object part."""
    pts = np.concatenate([p for p, _ in parts])
    lab = np.concatenate([np.full(len(p), s, dtype=np.int32) for p, s in parts])
    return pts, lab


TABLE_Z = 0.75
BOXES = [
    ((0.2, 0.2, TABLE_Z), (0.5, 0.4, TABLE_Z + 0.3)),  # largest
    ((0.9, 0.3, TABLE_Z), (1.1, 0.5, TABLE_Z + 0.15)),
    ((1.5, 0.5, TABLE_Z), (1.6, 0.6, TABLE_Z + 0.1)),  # smallest
]


@pytest.fixture
def table_scene():
    table = make_surface(0, TABLE_Z, 0.0, 2.0, 0.0, 1.0)
    boxes = [box(lo, hi) for lo, hi in BOXES]
    pts, lab = scene([(plane(0, 2, 0, 1, TABLE_Z), 0)] + [(b, -1) for b in boxes])
    return pts, SurfaceResult(surfaces=[table], labels=lab), boxes


def test_three_boxes(table_scene):
    pts, surf, boxes = table_scene
    res = detect_objects(pts, surf)
    assert len(res.clusters) == 3
    assert res.labels.dtype == np.int32 and res.labels.shape == (len(pts),)
    assert (res.labels[surf.labels >= 0] == -1).all()
    for c, b, (lo, hi) in zip(res.clusters, boxes, BOXES, strict=True):
        assert c.point_count == len(b) == (res.labels == c.id).sum()
        assert c.surface_id == 0
        np.testing.assert_allclose(c.bbox_min, lo, atol=1e-9)
        np.testing.assert_allclose(c.bbox_max, hi, atol=1e-9)
        assert c.height == pytest.approx(hi[2] - TABLE_Z)
        size = np.array(hi) - np.array(lo)
        np.testing.assert_allclose(c.obb_size, [max(size[:2]), min(size[:2]), size[2]], atol=1e-6)
        np.testing.assert_allclose(c.obb_center, (np.array(lo) + hi) / 2, atol=1e-6)
        assert c.volume == pytest.approx(np.prod(size), rel=1e-6)
        # Footprint: the box's rectangle, counter-clockwise (positive signed area).
        fp = c.footprint
        signed = 0.5 * np.sum(fp[:, 0] * np.roll(fp[:, 1], -1) - np.roll(fp[:, 0], -1) * fp[:, 1])
        assert signed == pytest.approx(size[0] * size[1], rel=1e-6)
    json.dumps([c.to_dict() for c in res.clusters])


def test_yaw_of_long_box():
    table = make_surface(0, 0.0, -1, 1, -1, 1)
    b = box((-0.3, -0.05, 0.0), (0.3, 0.05, 0.1))
    ang = np.deg2rad(30)
    rot = np.array([[np.cos(ang), -np.sin(ang), 0], [np.sin(ang), np.cos(ang), 0], [0, 0, 1]])
    pts = b @ rot.T + [0.2, 0.1, 0.0]
    res = detect_objects(pts, SurfaceResult([table], np.full(len(pts), -1, np.int32)))
    (c,) = res.clusters
    assert c.obb_yaw == pytest.approx(ang, abs=1e-3)
    np.testing.assert_allclose(c.obb_size, [0.6, 0.1, 0.1], atol=2e-3)
    np.testing.assert_allclose(c.obb_center, [0.2, 0.1, 0.05], atol=2e-3)


@pytest.mark.parametrize("method", ["voxel", "knn"])
def test_point_order_and_translation_invariance(table_scene, method):
    pts, surf, _ = table_scene
    params = ObjectParams(method=method, sample_fraction=1.0)
    ref = detect_objects(pts, surf, params)
    perm = np.random.default_rng(3).permutation(len(pts))
    res = detect_objects(pts[perm], SurfaceResult(surf.surfaces, surf.labels[perm]), params)
    np.testing.assert_array_equal(res.labels, ref.labels[perm])
    shifted_surf = [make_surface(0, TABLE_Z, 3.0, 5.0, -2.0, -1.0)]
    moved = pts + [3.0, -2.0, 0.0]
    res = detect_objects(moved, SurfaceResult(shifted_surf, surf.labels), params)
    np.testing.assert_array_equal(res.labels, ref.labels)
    assert [c.surface_id for c in res.clusters] == [0, 0, 0]
    for a, b in zip(res.clusters, ref.clusters, strict=True):
        np.testing.assert_allclose(a.centroid, b.centroid + [3.0, -2.0, 0.0], atol=1e-9)


def test_knn_full_sample_matches_voxel(table_scene):
    pts, surf, _ = table_scene
    vox = detect_objects(pts, surf, ObjectParams(method="voxel"))
    knn = detect_objects(pts, surf, ObjectParams(method="knn", sample_fraction=1.0, k=10))
    np.testing.assert_array_equal(knn.labels, vox.labels)
    assert knn.stats["sampled"] == knn.stats["candidates"]


def test_knn_sampled_is_seeded_and_labels_everything_nearby(table_scene):
    pts, surf, boxes = table_scene
    params = ObjectParams(method="knn", sample_fraction=0.3, k=20, seed=7)
    a = detect_objects(pts, surf, params)
    b = detect_objects(pts, surf, params)
    np.testing.assert_array_equal(a.labels, b.labels)
    assert a.stats["sampled"] == round(0.3 * sum(len(x) for x in boxes))
    assert [c.point_count for c in a.clusters] == [len(x) for x in boxes]


def test_room_wide_structure_is_not_split_but_a_row_of_barrels_is(rng):
    """Two pillars joined by a thin wall, 2 m apart, are room structure: one cluster, whatever
    necks its footprint has. The same shapes 0.8 m apart are two objects and a wall: split."""
    floor = make_surface(0, 0.0, -2, 4, -1, 1)
    for span, parts in ((2.0, 1), (0.8, 2)):
        pillars = [cylinder(x, 0.0, 0.15, 0.0, 0.6) for x in (0.0, span)]
        n = int(span * 20_000)
        wall = np.c_[rng.uniform(0, span, n), rng.uniform(-0.01, 0.01, n), rng.uniform(0, 0.6, n)]
        pts = np.vstack([*pillars, wall])
        res = detect_objects(pts, SurfaceResult([floor], np.full(len(pts), -1, np.int32)))
        assert len(res.clusters) == parts
        assert res.stats["merged_splits"] == parts - 1


def two_cylinders(gap: float, r: float = 0.15):
    floor = make_surface(0, 0.0, -1, 1, -1, 1)
    c1 = cylinder(-r - gap / 2, 0.0, r, 0.0, 0.3)
    c2 = cylinder(r + gap / 2, 0.0, r, 0.0, 0.25)
    pts, lab = scene([(plane(-1, 1, -1, 1, 0.0, 0.04), 0), (c1, -1), (c2, -1)])
    return pts, SurfaceResult([floor], lab), len(c1), len(c2)


def test_touching_cylinders_split():
    pts, surf, n1, n2 = two_cylinders(gap=0.0)
    merged = detect_objects(pts, surf, ObjectParams(split_touching=False))
    assert len(merged.clusters) == 1
    split = detect_objects(pts, surf, ObjectParams(split_touching=True))
    assert len(split.clusters) == 2
    assert split.stats["merged_splits"] == 1
    # Each part is one cylinder: left cylinder (x < 0) is the taller and larger one.
    left, right = sorted(split.clusters, key=lambda c: c.centroid[0])
    assert left.centroid[0] < 0 < right.centroid[0]
    # Ground truth: the first n1 object points are the left cylinder. The cut may miss the
    # contact by about a raster cell (1 cm), where wall points crowd: a few percent.
    obj = split.labels[surf.labels == -1]
    assert (obj[:n1] == left.id).mean() > 0.95 and (obj[n1:] == right.id).mean() > 0.95
    assert left.height == pytest.approx(0.3)
    assert right.obb_size[2] < 0.3 + 1e-9  # a few top points of the taller one at most
    assert left.bbox_max[0] == pytest.approx(0.0, abs=0.015)
    assert (merged.labels >= 0).sum() == (split.labels >= 0).sum() == n1 + n2


def test_row_of_three_touching_barrels_split_into_three():
    floor = make_surface(0, 0.0, -1, 1, -1, 1)
    r = 0.15
    row = np.concatenate([cylinder(x, 0.0, r, 0.0, 0.4, 0.015) for x in (-2 * r, 0.0, 2 * r)])
    res = detect_objects(row, SurfaceResult([floor], np.full(len(row), -1, np.int32)))
    assert len(res.clusters) == 3
    xs = sorted(c.centroid[0] for c in res.clusters)
    # The cut lies within about a raster cell (1 cm) of each contact, but wall points crowd at
    # a contact, so a few mm of cut moves hundreds of points and a centroid by up to ~2.5 cm.
    np.testing.assert_allclose(xs, [-2 * r, 0.0, 2 * r], atol=0.03)
    n = len(row) / 3
    assert all(abs(c.point_count - n) < 0.1 * n for c in res.clusters)


def test_single_objects_not_split(table_scene):
    pts, surf, _ = table_scene
    res = detect_objects(pts, surf, ObjectParams(split_touching=True))
    assert res.stats["merged_splits"] == 0
    # A lone cylinder and an L-shaped box pair (a wide junction, not a neck) stay whole.
    floor = make_surface(0, 0.0, -1, 1, -1, 1)
    for obj in (cylinder(0, 0, 0.1, 0, 0.3), ell_box()):
        r = detect_objects(obj, SurfaceResult([floor], np.full(len(obj), -1, np.int32)))
        assert len(r.clusters) == 1 and r.stats["merged_splits"] == 0


def ell_box(size=(0.4, 0.15, 0.2), step: float = 0.01) -> np.ndarray:
    """(P, 3) the visible faces of an L-shaped box: two boxes of size (long, short, height) m
    along x and along y from the origin, without the faces each hides inside the other (no
    sensor sees them; they would meet the outer walls in concave creases)."""
    long, short, height = size
    parts = [((0.0, 0.0, 0.0), (long, short, height)), ((0.0, 0.0, 0.0), (short, long, height))]
    pts = np.concatenate([box(lo, hi, step) for lo, hi in parts])
    hidden = np.zeros(len(pts), dtype=bool)
    for lo, hi in parts:  # strictly inside (by a millimetre) either box
        hidden |= ((pts > np.add(lo, 1e-3)) & (pts < np.subtract(hi, 1e-3))).all(axis=1)
    return pts[~hidden]


def test_stack_of_boxes_is_one_object():
    floor = make_surface(0, 0.0, -1, 1, -1, 1)
    stack = np.concatenate(
        [box((0, 0, 0), (0.4, 0.4, 0.2)), box((0.1, 0.1, 0.2), (0.3, 0.3, 0.35))]
    )
    r = detect_objects(stack, SurfaceResult([floor], np.full(len(stack), -1, np.int32)))
    assert len(r.clusters) == 1 and r.clusters[0].height == pytest.approx(0.35)


def chair_leg_scene(with_floor: bool):
    """A table (z 0.75) and, 5 cm beside its edge, a chair leg column from the floor to 0.9 m."""
    table = make_surface(1 if with_floor else 0, TABLE_Z, 0.0, 1.0, 0.0, 1.0)
    floor = make_surface(0, 0.0, -1.0, 2.0, -1.0, 2.0)
    leg = box((1.05, 0.5, 0.02), (1.08, 0.53, 0.9))  # floor points within 2 cm removed
    on_table = box((0.85, 0.45, TABLE_Z), (0.95, 0.55, TABLE_Z + 0.1))
    parts = [(plane(0, 1, 0, 1, TABLE_Z), table.id), (leg, -1), (on_table, -1)]
    surfaces = [table]
    if with_floor:
        fl = plane(-1, 2, -1, 2, 0.0, 0.05)
        fl = fl[~((fl[:, 0] > 0) & (fl[:, 0] < 1) & (fl[:, 1] > 0) & (fl[:, 1] < 1))]
        parts.insert(0, (fl, 0))
        surfaces = [floor, table]
    pts, lab = scene(parts)
    return pts, SurfaceResult(surfaces, lab), len(leg)


@pytest.mark.parametrize("with_floor", [True, False])
def test_chair_leg_stands_on_floor_not_table(with_floor):
    pts, surf, n_leg = chair_leg_scene(with_floor)
    res = detect_objects(pts, surf)
    assert len(res.clusters) == 2
    leg = next(c for c in res.clusters if c.point_count == n_leg)
    cup = next(c for c in res.clusters if c.point_count != n_leg)
    assert leg.surface_id == (0 if with_floor else None)
    table_id = 1 if with_floor else 0
    assert cup.surface_id == table_id
    assert cup.height == pytest.approx(0.1)
    if with_floor:
        assert leg.height == pytest.approx(0.9)
    else:
        assert leg.height == pytest.approx(0.88)  # above its own bottom


def test_object_over_a_notch_at_the_edge_stands_on_the_table_whole():
    """A sparse lidar view leaves a notch in the table's footprint (the box's own shadow, the
    gaps between rings) that reaches the table's edge; the box's front lies over it. The box
    stands on the table as one object, not cut where the footprint ends."""
    table = make_surface(0, TABLE_Z, 0.0, 1.0, 0.0, 1.0)
    notch = (table.cells[:, 0] >= 8) & (table.cells[:, 1] >= 4) & (table.cells[:, 1] < 6)
    table.cells = table.cells[~notch]  # x 0.8-1.0, y 0.4-0.6: open to the edge x = 1
    floor = make_surface(1, 0.0, -1.0, 2.0, -1.0, 2.0)  # under the table too
    b = box((0.72, 0.42, TABLE_Z), (0.86, 0.58, TABLE_Z + 0.12))
    res = detect_objects(b, SurfaceResult([table, floor], np.full(len(b), -1, np.int32)))
    assert [c.point_count for c in res.clusters] == [len(b)]
    assert res.clusters[0].surface_id == 0


def test_objects_along_an_edge_do_not_join_through_the_table_rim():
    """The table's side face, just below its top and beyond its footprint, touches both boxes
    standing at the edge; it stands on nothing, so it links neither to the other."""
    table = make_surface(0, TABLE_Z, 0.0, 1.0, 0.0, 1.0)
    a = box((0.86, 0.2, TABLE_Z), (0.995, 0.3, TABLE_Z + 0.1))
    b = box((0.86, 0.6, TABLE_Z), (0.995, 0.7, TABLE_Z + 0.1))
    gy, gz = np.meshgrid(np.arange(0.0, 1.0, 0.01), np.arange(TABLE_Z - 0.04, TABLE_Z - 1e-3, 0.01))
    rim = np.c_[np.full(gy.size, 1.002), gy.ravel(), gz.ravel()]
    pts = np.concatenate([a, b, rim])
    res = detect_objects(pts, SurfaceResult([table], np.full(len(pts), -1, np.int32)))
    of_a, of_b = res.labels[: len(a)], res.labels[len(a) : len(a) + len(b)]
    assert len(set(of_a)) == len(set(of_b)) == 1 and of_a[0] != of_b[0]
    assert of_a[0] >= 0 and of_b[0] >= 0
    assert [res.clusters[k].surface_id for k in (of_a[0], of_b[0])] == [0, 0]


def test_object_in_footprint_hole_stands_on_table():
    """Cells under an object hold no table points; the table is still what it stands on."""
    table = make_surface(0, 0.5, 0, 1, 0, 1)
    hole = (table.cells[:, 0] >= 4) & (table.cells[:, 0] < 6) & (table.cells[:, 1] >= 4)
    hole &= table.cells[:, 1] < 6
    table.cells = table.cells[~hole]
    b = box((0.42, 0.42, 0.52), (0.58, 0.58, 0.7))
    r = detect_objects(b, SurfaceResult([table], np.full(len(b), -1, np.int32)))
    assert r.clusters[0].surface_id == 0


def test_floating_object_has_no_surface():
    table = make_surface(0, 0.5, 0, 1, 0, 1)
    b = box((0.4, 0.4, 0.8), (0.6, 0.6, 0.9))  # 30 cm above the table: a lamp shade, a shelf
    r = detect_objects(b, SurfaceResult([table], np.full(len(b), -1, np.int32)))
    assert r.clusters[0].surface_id is None
    assert r.clusters[0].height == pytest.approx(0.1)


@pytest.mark.parametrize("method", ["voxel", "knn"])
def test_noise_specks_dropped(table_scene, method):
    # knn with k >= a speck's size links the speck to its nearest object (Algorithm 2 has no
    # distance limit), so the report's method drops specks only when k is below their size.
    pts, surf, boxes = table_scene
    rng = np.random.default_rng(1)
    specks = np.concatenate(
        [c + rng.normal(0, 0.005, (5, 3)) for c in [[1.8, 0.9, 1.2], [0.1, 0.9, 1.0]]]
    )
    allp = np.concatenate([pts, specks])
    lab = np.concatenate([surf.labels, np.full(len(specks), -1, np.int32)])
    res = detect_objects(
        allp,
        SurfaceResult(surf.surfaces, lab),
        ObjectParams(method=method, sample_fraction=1.0, k=3),
    )
    assert len(res.clusters) == 3
    assert (res.labels[-len(specks) :] == -1).all()
    assert res.stats["candidates"] == sum(len(b) for b in boxes) + len(specks)


def test_empty_and_degenerate_inputs():
    table = make_surface(0, 0.0, 0, 1, 0, 1)
    pts = plane(0, 1, 0, 1, 0.0)
    for method in ("voxel", "knn"):
        res = detect_objects(
            pts, SurfaceResult([table], np.zeros(len(pts), np.int32)), ObjectParams(method=method)
        )
        assert res.clusters == [] and (res.labels == -1).all()
        empty = detect_objects(
            np.zeros((0, 3)), SurfaceResult([], np.zeros(0, np.int32)), ObjectParams(method=method)
        )
        assert empty.clusters == [] and empty.labels.shape == (0,)
    # A flat patch of object points (a sheet of paper): volume 0, no exception from qhull.
    paper = plane(0.2, 0.5, 0.2, 0.4, 0.03, 0.01)
    r = detect_objects(paper, SurfaceResult([table], np.full(len(paper), -1, np.int32)))
    assert r.clusters[0].volume == 0.0 and r.clusters[0].surface_id == 0
    # A vertical line of points: collinear footprint.
    line = np.stack([np.full(40, 0.5), np.full(40, 0.5), np.linspace(0, 0.4, 40)], 1)
    r = detect_objects(line, SurfaceResult([table], np.full(40, -1, np.int32)))
    assert r.clusters[0].volume == 0.0 and len(r.clusters[0].footprint) == 1


def test_bad_input_raises():
    with pytest.raises(InputError):
        detect_objects(np.zeros((4, 2)), SurfaceResult([], np.full(4, -1, np.int32)))
    with pytest.raises(InputError):
        detect_objects(np.zeros((4, 3)), SurfaceResult([], np.full(3, -1, np.int32)))
    bad = np.zeros((4, 3))
    bad[0, 0] = np.nan
    with pytest.raises(InputError):
        detect_objects(bad, SurfaceResult([], np.full(4, -1, np.int32)))


def test_object_touching_frame_beside_its_board_is_separate():
    """A box on a shelf board, 2 cm from the shelf's side panel (which stands on the floor):
    voxels over different surfaces are not linked, so the box is not swallowed by the frame."""
    floor = make_surface(0, 0.0, -1.0, 2.0, -1.0, 2.0)
    board = make_surface(1, 0.4, 0.0, 1.0, 0.0, 0.4)
    b = box((0.78, 0.1, 0.42), (0.98, 0.3, 0.6))
    panel = box((1.0 + 1e-6, 0.0, 0.02), (1.02, 0.4, 1.0))
    pts = np.concatenate([b, panel])
    res = detect_objects(pts, SurfaceResult([floor, board], np.full(len(pts), -1, np.int32)))
    assert len(res.clusters) == 2 and res.stats["support_cuts"] > 0
    on_board = next(c for c in res.clusters if c.surface_id == 1)
    assert on_board.point_count == len(b)
    assert on_board.height == pytest.approx(0.2)


def test_flat_wall_cluster_has_a_line_footprint_and_a_thin_box():
    """A noise-free wall has a collinear footprint (no 2-D hull): its box must come from the
    line's two ends, not from a quadratic search over its 40k points."""
    rng = np.random.default_rng(3)
    n = 40_000
    wall = np.c_[rng.uniform(0, 4, n), np.full(n, 2.0), rng.uniform(0.0, 2.0, n)]
    floor = np.c_[rng.uniform(-1, 5, 30000), rng.uniform(-1, 1.9, 30000), np.zeros(30000)]
    pts = np.vstack([floor, wall])
    res = detect_objects(pts, detect_surfaces(pts), ObjectParams())
    big = res.clusters[0]
    assert big.point_count > 0.9 * n
    assert big.obb_size[0] == pytest.approx(4.0, abs=0.05) and big.obb_size[1] < 0.01
    assert len(big.footprint) == 2


def test_boxes_of_different_heights_face_to_face_split():
    """One rectangular footprint, no neck: only the top height steps (the simulator's
    box_1 + box_2). A box on a box (a toy car's cabin on its body) stays one object."""
    floor = make_surface(0, 0.0, -1, 1, -1, 1)
    tall = box((0.0, 0.0, 0.0), (0.3, 0.2, 0.15))
    low = box((0.3, 0.0, 0.0), (0.5, 0.2, 0.1))
    low = low[low[:, 0] > 0.3 + 1e-9]  # the shared face belongs to the tall box
    pts = np.concatenate([tall, low])
    res = detect_objects(pts, SurfaceResult([floor], np.full(len(pts), -1, np.int32)))
    assert len(res.clusters) == 2 and res.stats["step_splits"] == 1
    a, b = sorted(res.clusters, key=lambda c: c.centroid[0])
    assert a.height == pytest.approx(0.15) and b.height == pytest.approx(0.1)
    assert (res.labels[: len(tall)] == a.id).mean() > 0.95
    assert (res.labels[len(tall) :] == b.id).mean() > 0.95
    body = box((0.0, 0.0, 0.0), (0.4, 0.2, 0.1))
    cabin = box((0.1, 0.0, 0.1), (0.3, 0.2, 0.18))
    car = np.concatenate([body, cabin])
    res = detect_objects(car, SurfaceResult([floor], np.full(len(car), -1, np.int32)))
    assert len(res.clusters) == 1


def test_three_boxes_in_a_row_step_twice_down_to_two_centimetres():
    """Three boxes of three heights face to face (the cluttered scene's box_a, box_b, box_c):
    the first cut leaves two boxes on one side, cut again; the last step is 2 cm."""
    floor = make_surface(0, 0.0, -1, 1, -1, 1)
    heights = (0.14, 0.10, 0.08)
    edges = (0.0, 0.16, 0.36, 0.48)  # x, metres: the middle box the widest
    parts = []
    for k, h in enumerate(heights):
        b = box((edges[k], 0.0, 0.0), (edges[k + 1], 0.12, h))
        parts.append(b if k == 0 else b[b[:, 0] > edges[k] + 1e-9])  # shared face: the left box
    pts = np.concatenate(parts)
    res = detect_objects(pts, SurfaceResult([floor], np.full(len(pts), -1, np.int32)))
    assert len(res.clusters) == 3
    ordered = sorted(res.clusters, key=lambda c: c.centroid[0])
    assert [c.height for c in ordered] == pytest.approx(heights)
    start = 0
    for part, c in zip(parts, ordered, strict=True):
        assert (res.labels[start : start + len(part)] == c.id).mean() > 0.9
        start += len(part)


def test_fast_paths_match_reference_implementations(monkeypatch: pytest.MonkeyPatch):
    """The speed-ups of the voxel method give the same answer as the straightforward code."""
    import scipy.ndimage as ndi

    from supportnode.geometry.objects import clusters, hull, support_lookup
    from supportnode.kernels.footprint import fill_holes

    rng = np.random.default_rng(7)
    for _ in range(20):  # hole filling by one labelling == binary_fill_holes
        mask = rng.random((rng.integers(3, 40), rng.integers(3, 40))) < rng.uniform(0.3, 0.8)
        np.testing.assert_array_equal(fill_holes(mask), ndi.binary_fill_holes(mask))

    # Points on vertical lines: dropping the inner ones keeps the hull's volume.
    xy = rng.uniform(0, 1, (300, 2))
    p = np.c_[np.repeat(xy, 10, axis=0), rng.uniform(0, 1, 3000)]
    keep = hull._column_ends(p)
    assert keep.sum() <= 600
    lo, hi = p.min(axis=0), p.max(axis=0)
    monkeypatch.setattr(hull, "_HULL_MAX_POINTS", 10**9)  # every point to Qhull
    ref_vol = hull._volume(p, lo, hi)
    monkeypatch.setattr(hull, "_HULL_MAX_POINTS", 1000)  # the lines' ends (600), no sample
    assert len(hull._hull_candidates(p)) == keep.sum()
    assert hull._volume(p, lo, hi) == pytest.approx(ref_vol, rel=1e-12)
    assert ref_vol == pytest.approx(ConvexHull(p).volume, rel=1e-12)

    # Support look-up in one pass == surface by surface; dense voxel ids == sorted keys.
    surfaces = [
        make_surface(0, 0.0, -1, 1, -1, 1),
        make_surface(1, 0.4, -0.5, 0.3, -0.2, 0.6),
        make_surface(2, 0.8, 0.0, 0.6, 0.1, 0.5),
    ]
    cp = np.c_[rng.uniform(-1.2, 1.2, (20000, 2)), rng.uniform(-0.1, 1.5, 20000)]
    fast = support_lookup._support_below(cp, surfaces, 0.05)
    with monkeypatch.context() as m:
        m.setattr(support_lookup._SupportTable, "build", classmethod(lambda cls, *args: None))
        np.testing.assert_array_equal(fast, support_lookup._support_below(cp, surfaces, 0.05))
        # No floor, nothing below 0.35 but one point far off (so surface 1 is no ground):
        # surface 1's ring (nothing there comes up from below its height - tol) holds
        # points, surface 2's does not.
        high = np.r_[cp[cp[:, 2] >= 0.35], [[-1.15, -1.15, 0.0]]]
        slow = support_lookup._support_below(high, surfaces[1:], 0.05)
    one = support_lookup._support_below(high, surfaces[1:], 0.05)
    np.testing.assert_array_equal(one, slow)
    x, y, z = high.T
    ring1 = (x >= 0.3) & (x < 0.4) & (y >= -0.1) & (y < 0.1)  # on no other footprint
    assert (one[ring1 & (z >= 0.4)] == 1).all() and (one[ring1 & (z < 0.4)] == -1).all()
    ring2 = (x >= 0.6) & (x < 0.7) & (y >= 0.1) & (y < 0.5)
    assert (one[ring2] == -1).all()
    dense = clusters._cluster_voxel(cp * 0.3, 0.03, {}, fast)
    monkeypatch.setattr(clusters, "_DENSE_MIN_CELLS", 0)
    monkeypatch.setattr(clusters, "_DENSE_CELLS_PER_POINT", 0)
    np.testing.assert_array_equal(dense, clusters._cluster_voxel(cp * 0.3, 0.03, {}, fast))


def test_footprints_without_volumes_are_the_same_polygons():
    """The node's describe (no 3-D hulls) gives the offline footprints and boxes, vertex for
    vertex: the exact hull of all of each cluster's points, from its lowest x, y."""
    rng = np.random.default_rng(3)
    lines = rng.uniform(0, 1, (200, 2))
    clouds = [
        rng.normal(0, 0.1, (5000, 3)),  # dense: its 3-D hull from a sample, not its footprint
        np.c_[np.repeat(lines, 20, axis=0), rng.uniform(0, 1, 4000)] + [3, 0, 0],  # columns
        box((0.0, 0.0, 0.0), (0.3, 0.2, 0.1)) + [0, 3, 0],
    ]
    pts = np.concatenate(clouds)
    floor = make_surface(0, -0.5, -2, 5, -2, 5)
    seg = segment_objects(pts, SurfaceResult([floor], np.full(len(pts), -1, np.int32)))
    offline = describe_objects(seg)
    node = describe_objects(seg, volumes=False)
    assert len(offline.clusters) >= 3 and offline.clusters[0].point_count > 4000
    for a, b in zip(offline.clusters, node.clusters, strict=True):
        np.testing.assert_array_equal(a.footprint, b.footprint)
        assert a.obb_yaw == b.obb_yaw and np.isnan(b.volume) and a.volume >= 0
        mine = pts[offline.labels == a.id]
        if len(a.footprint) < 3:
            continue  # a line: Qhull refuses it
        ref = ConvexHull(mine[:, :2])
        assert sorted(map(tuple, a.footprint)) == sorted(map(tuple, mine[ref.vertices, :2]))
        lowest = a.footprint[a.footprint[:, 0] == a.footprint[:, 0].min()]
        assert (a.footprint[0] == lowest.min(axis=0)).all()


def barrel_triangle(r: float = 0.06, step: float = 0.005) -> np.ndarray:
    """Three touching vertical cylinders with centres on a triangle of side 2r, (P, 3)."""
    centres = [(-r, 0.0), (r, 0.0), (0.0, r * np.sqrt(3.0))]
    return np.concatenate([cylinder(x, y, r, 0.0, 0.18, step) for x, y in centres])


def test_barrels_touching_in_a_triangle_split_at_concave_creases():
    floor = make_surface(0, 0.0, -1, 1, -1, 1)
    # The small gap in the middle fills on the footprint raster: no neck to cut. By default
    # the walls part them (their tops join: see split_concave._split_walls); split_concave
    # cuts the creases first, which needs denser sampling (8 mm; at 1 cm it finds no parts).
    for step, params, key in (
        (0.01, ObjectParams(), "wall_splits"),
        (0.008, ObjectParams(split_concave=True), "concave_splits"),
    ):
        pts = barrel_triangle(step=step)
        surf = SurfaceResult([floor], np.full(len(pts), -1, np.int32))
        res = detect_objects(pts, surf, params)
        assert res.stats[key] == 1 and len(res.clusters) == 3
        n = len(pts) // 3
        truth = np.repeat(np.arange(3), n)
        for k in range(3):  # each barrel is (mostly) one cluster of its own
            assert np.bincount(res.labels[truth == k]).max() > 0.85 * n
        assert len({int(np.bincount(res.labels[truth == k]).argmax()) for k in range(3)}) == 3


def test_single_concave_objects_not_split_at_creases():
    floor = make_surface(0, 0.0, -1, 1, -1, 1)
    ell = ell_box((0.3, 0.1, 0.15), 0.005)
    # A bowl: a hemispherical shell (inside and outside) with its rim up.
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 120), np.linspace(0.05, np.pi / 2, 40))
    shell = [
        np.stack([r * np.cos(u) * np.sin(v), r * np.sin(u) * np.sin(v), 0.1 - r * np.cos(v)], -1)
        for r in (0.1, 0.095)
    ]
    bowl = np.concatenate([s.reshape(-1, 3) for s in shell])
    on = ObjectParams(split_concave=True)
    for obj, params in ((ell, ObjectParams()), (bowl, ObjectParams()), (bowl, on)):
        r = detect_objects(obj, SurfaceResult([floor], np.full(len(obj), -1, np.int32)), params)
        assert len(r.clusters) == 1 and r.stats["concave_splits"] == 0
        assert r.stats["wall_splits"] == 0


def test_walls_around_two_rooms_are_not_cut_at_the_doorway(rng):
    """The walls of two 2 x 2 m rooms joined by a 0.8 m passage: one cluster. The rooms they
    enclose are no hole in an object's footprint; filled, they would make a dumbbell that the
    neck split cuts at the passage."""
    floor = np.c_[
        rng.uniform(-0.5, 5.5, 120_000), rng.uniform(-0.5, 2.5, 120_000), np.zeros(120_000)
    ]
    # outline of the dumbbell: room A [0,2]x[0,2], passage [2,3]x[0.6,1.4], room B [3,5]x[0,2]
    corners = np.array(
        [[0, 0], [2, 0], [2, 0.6], [3, 0.6], [3, 0], [5, 0], [5, 2], [3, 2], [3, 1.4],
         [2, 1.4], [2, 2], [0, 2], [0, 0]], dtype=float
    )  # fmt: skip
    walls = []
    for a, b in itertools.pairwise(corners):
        n = int(np.hypot(*(b - a)) * 3000)
        t = rng.uniform(0, 1, n)
        walls.append(np.c_[a + t[:, None] * (b - a), rng.uniform(0.02, 0.5, n)])
    pts = np.vstack([floor, *walls])
    res = detect_objects(pts, detect_surfaces(pts), ObjectParams(min_points=30))
    wall_labels = res.labels[len(floor) :]
    big = np.bincount(wall_labels[wall_labels >= 0]).argmax()
    assert (wall_labels == big).mean() > 0.98


def test_memo_gives_the_same_clusters_and_reuses_the_unchanged_ones(table_scene):
    """The node's map changes in a few places per scan: with a memo, the clusters whose points
    did not change take their volumes and splits from the previous call, and every result is
    what a call without it gives."""
    from supportnode.geometry.memo import Memo

    pts, surf, _ = table_scene
    lifted = pts.copy()
    first_box = (surf.labels == -1) & (pts[:, 0] < pts[surf.labels == -1, 0].min() + 0.3)
    lifted[first_box, 2] += 0.01  # one box lifted by a centimetre, the others as they were
    barrels, bsurf, _, _ = two_cylinders(gap=0.0)  # touching: they are split
    memo = Memo()
    counts = []
    for p, s in ((pts, surf), (lifted, surf), (barrels, bsurf), (barrels, bsurf)):
        memo.next_round()
        before = (memo.hits, memo.misses)
        with_memo = detect_objects(p, s, ObjectParams(), memo)
        plain = detect_objects(p, s, ObjectParams())
        assert [c.to_dict() for c in with_memo.clusters] == [c.to_dict() for c in plain.clusters]
        np.testing.assert_array_equal(with_memo.labels, plain.labels)
        assert with_memo.stats["merged_splits"] == plain.stats["merged_splits"]
        counts.append((memo.hits - before[0], memo.misses - before[1]))
    (_, boxes), (kept, lifted_box), (_, both), (again, none) = counts
    assert kept >= 2 and 0 < lifted_box < boxes  # the lifted box (its volume, maybe its split)
    assert none == 0 and again == both >= 3  # the barrels' split and both volumes
    assert plain.stats["merged_splits"] == 1


def test_split_objects_finds_again_only_the_surfaces_of_split_clusters():
    """split_objects takes the surface of each cluster that was not split from its component
    (a function of the same points): the same surfaces as looking every cluster up anew."""
    from conftest import REPO

    from supportnode.geometry.objects import cluster_objects, split_objects
    from supportnode.geometry.objects.clusters import _order
    from supportnode.io.clouds import read_cloud
    from supportnode.params import DetectParams

    params = DetectParams()
    for name in ("sloped", "shelf", "table_chairs"):
        pts = np.asarray(read_cloud(REPO / "sim_scans" / f"{name}_sampled.ply").points, float)
        surf = detect_surfaces(pts, params.surfaces)
        comp = cluster_objects(pts, surf, params.objects)
        seg = split_objects(comp, params.objects)
        # Labels of the candidates, in the final numbering: _order again with no known surfaces.
        cand = comp._candidates
        fresh = _order(
            comp._points, seg.labels[cand].astype(np.int64), comp._lookups[1], params.objects
        )
        np.testing.assert_array_equal(seg.surface_ids, fresh.surface_ids)
        assert (seg.surface_ids >= 0).sum() >= 3


def test_hull_volume_is_convex_hulls():
    """The compiled hull's volume is Qhull's (ConvexHull) to round-off, far from the origin
    too; flat and too small sets are degenerate (0); where the compiled hull gives up,
    Qhull answers."""
    from supportnode.geometry.objects import hull

    rng = np.random.default_rng(11)
    for n in (4, 5, 40, 3006):
        for scale in (1e-3, 1.0, 50.0):
            q = rng.normal(0, scale, (n, 3)) + rng.normal(0, 100, 3)
            assert hull._hull_3d(q) == pytest.approx(ConvexHull(q).volume, rel=1e-9)
    flat = np.c_[rng.uniform(0, 1, (50, 2)), np.zeros(50)]
    assert hull._hull_3d(flat) == 0.0
    assert hull._hull_3d(flat[:3]) == 0.0


def test_hull_volume_falls_back_to_qhull(monkeypatch):
    from supportnode.geometry.objects import hull
    from supportnode.kernels.hull3d import FAILED

    q = np.random.default_rng(5).normal(size=(60, 3))
    monkeypatch.setattr("supportnode.kernels.hull3d.hull_volume", lambda p: FAILED)
    assert hull._hull_3d(q) == pytest.approx(ConvexHull(q).volume, rel=1e-12)
