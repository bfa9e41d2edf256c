"""Stacks in clusters too sparse for convexity (layers.py): a box on a box, a sphere in a
bowl are two objects; one box, a laptop, a cone, a lamp, two boxes side by side are not cut."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sparse_scenes import box_faces, detect_parts, table_surface, whole

from supportnode.geometry.surfaces import Surface
from supportnode.kernels.layers import screen_levels

TABLE = 0.75
SPACING = 0.02  # a sparsely sampled scene: a few points per 3 cm voxel


def _table() -> Surface:
    return table_surface(TABLE)


def _box(lo, hi, rng) -> np.ndarray:
    return box_faces(lo, hi, rng, SPACING)


def _sphere(centre, r, rng) -> np.ndarray:
    n = rng.poisson(4 * np.pi * r**2 / SPACING**2)
    d = rng.normal(size=(n, 3))
    return np.asarray(centre) + r * d / np.linalg.norm(d, axis=1, keepdims=True)


def _cone(centre, r, h, rng) -> np.ndarray:
    """The side of an upright cone, its base on the table at centre (x, y)."""
    n = rng.poisson(np.pi * r * np.hypot(r, h) / SPACING**2)
    t = np.sqrt(rng.uniform(0, 1, n))  # area grows with the distance from the tip
    a = rng.uniform(0, 2 * np.pi, n)
    return np.c_[centre[0] + r * t * np.cos(a), centre[1] + r * t * np.sin(a), TABLE + h * (1 - t)]


def _without(p: np.ndarray, lo, hi) -> np.ndarray:
    """p less the points inside (or on) the box [lo, hi]: what another object covers."""
    inside = np.all((p >= np.asarray(lo) - 1e-3) & (p <= np.asarray(hi) + 1e-3), axis=1)
    return p[~inside]


def _detect(parts: list[np.ndarray]):
    return detect_parts(parts, _table())


def test_a_box_on_a_box_is_two_objects_the_upper_on_the_lower():
    rng = np.random.default_rng(0)
    lower_hi = (0.1, 0.075, TABLE + 0.08)
    lower = _without(_box((-0.1, -0.075, TABLE), lower_hi, rng), (-0.06, -0.05, 0), (0.06, 0.05, 1))
    upper = _box((-0.06, -0.05, TABLE + 0.08), (0.06, 0.05, TABLE + 0.14), rng)
    res, (a, b) = _detect([lower, upper])
    ia, ib = whole(a), whole(b)
    assert ia != ib
    assert res.clusters[ib].supported_by == ia
    assert res.clusters[ia].surface_id == 0 and res.clusters[ib].surface_id == 0


def _turned(p: np.ndarray, deg: float, centre=(0.0, 0.0)) -> np.ndarray:
    """p turned by deg about the vertical through centre (x, y)."""
    t = np.radians(deg)
    c = np.asarray(centre, float)
    rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    return np.c_[(p[:, :2] - c) @ rot.T + c, p[:, 2]]


@pytest.mark.parametrize(("deg", "seed"), [(45.0, 0), (40.0, 1), (-30.0, 2)])
def test_a_box_turned_on_a_box_is_its_own_object(deg, seed):
    """The upper box turned: the lower box's top shows at its corners, outside the upper's
    turned box but inside its axis-aligned one (the sampled shelf's stacks)."""
    rng = np.random.default_rng(seed)
    top = TABLE + 0.08
    lower = _box((-0.1, -0.1, TABLE), (0.1, 0.1, top), rng)
    under = _turned(lower, -deg)  # the lower box's points in the upper box's frame
    covered = np.all(np.abs(under[:, :2]) <= 0.07, axis=1) & (lower[:, 2] >= top - 1e-3)
    upper = _turned(_box((-0.07, -0.07, top), (0.07, 0.07, top + 0.07), rng), deg)
    res, (a, b) = _detect([lower[~covered], upper])
    ia, ib = whole(a), whole(b)
    assert ia != ib
    assert res.clusters[ib].supported_by == ia


def test_the_footprint_of_what_rises_is_inside_both_of_its_boxes():
    from supportnode.geometry.objects.rising import footprint

    rng = np.random.default_rng(5)
    flat = np.c_[rng.uniform(-0.08, 0.08, 400), rng.uniform(-0.06, 0.06, 400), np.zeros(400)]
    box = _turned(flat, 10)[:, :2]
    fp = footprint(box, 0.005)
    assert fp.inside(box).all()
    # The corners of its axis-aligned box are outside the turned box; beyond both, outside.
    corners = np.array([[fp.lo[0], fp.lo[1]], [fp.hi[0], fp.hi[1]], [0.3, 0.0]])
    assert not fp.inside(corners).any()
    # An axis-aligned set: its turned box is its axis-aligned box.
    square = np.c_[rng.uniform(0, 0.1, 200), rng.uniform(0, 0.05, 200)]
    grid = np.stack(np.meshgrid(np.linspace(-0.01, 0.11, 25), np.linspace(-0.01, 0.06, 15)), -1)
    grid = grid.reshape(-1, 2)
    fp = footprint(square, 0.002)
    in_box = np.all((grid >= fp.lo) & (grid <= fp.hi), axis=1)
    np.testing.assert_array_equal(fp.inside(grid), in_box)


def test_a_sphere_in_a_low_bowl_is_its_own_object():
    rng = np.random.default_rng(1)
    base = _without(
        _box((-0.12, -0.12, TABLE), (0.12, 0.12, TABLE + 0.05), rng),
        (-0.03, -0.03, 0),
        (0.03, 0.03, 1),
    )
    ball = _sphere((0.0, 0.0, TABLE + 0.05 + 0.045), 0.045, rng)
    ball = ball[ball[:, 2] > TABLE + 0.052]  # the cap inside the box's top is hidden
    _, (a, b) = _detect([base, ball])
    assert whole(a) != whole(b)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_one_box_one_cone_one_sphere_are_not_cut(seed):
    rng = np.random.default_rng(seed)
    box = _box((-0.6, -0.1, TABLE), (-0.4, 0.1, TABLE + 0.25), rng)
    cone = _cone((0.0, 0.0), 0.08, 0.2, rng)
    ball = _sphere((0.5, 0.0, TABLE + 0.1), 0.1, rng)
    res, labs = _detect([box, cone, ball])
    ids = [whole(lab) for lab in labs]
    assert len(set(ids)) == 3
    assert res.stats["layer_splits"] == 0


def test_a_laptop_and_a_lamp_stay_whole():
    rng = np.random.default_rng(3)
    # An open laptop: a 2 cm base, its screen rising flush with the base's back edge.
    base = _box((-0.6, -0.16, TABLE), (-0.37, 0.16, TABLE + 0.02), rng)
    screen = _box((-0.38, -0.16, TABLE + 0.02), (-0.37, 0.16, TABLE + 0.24), rng)
    base = _without(base, (-0.38, -0.16, TABLE + 0.015), (-0.37, 0.16, 1.0))
    # A lamp: a 2 cm base, a thin stem, a wide shade (its sides) around the stem's top.
    foot = _box((0.3, -0.07, TABLE), (0.44, 0.07, TABLE + 0.02), rng)
    h = np.arange(TABLE + 0.02, TABLE + 0.34, 0.01)  # a thin stem up into the shade
    stem = np.c_[np.full(len(h), 0.37), np.zeros(len(h)), h]
    shade = _box((0.26, -0.11, TABLE + 0.22), (0.48, 0.11, TABLE + 0.34), rng)
    res, labs = _detect([np.r_[base, screen], np.r_[foot, stem, shade]])
    assert whole(labs[0]) != whole(labs[1])
    assert res.stats["layer_splits"] == 0


def test_a_tall_box_beside_a_low_one_is_not_cut_at_the_low_top():
    rng = np.random.default_rng(4)
    low = _without(
        _box((-0.1, -0.1, TABLE), (0.1, 0.1, TABLE + 0.08), rng), (0.1, -1, 0), (1, 1, 1)
    )
    tall = _box((0.1, -0.08, TABLE), (0.25, 0.08, TABLE + 0.3), rng)
    res, _ = _detect([low, tall])
    assert res.stats["layer_splits"] == 0


def _numpy_screen(z, xy, bottom, top, clear, slab, min_window, min_up, min_out):
    """The numpy version screen_levels replaced (histogram, windows, suffix boxes)."""
    empty, box = np.zeros(0, np.int64), np.zeros((0, 2))
    edges = np.arange(bottom - slab, top + slab, slab)
    if top <= bottom or len(edges) < 4 or len(z) == 0:
        return np.zeros(0), empty, empty, empty, np.zeros(0, bool), box, box
    count = np.histogram(z, edges)[0]
    window = count[:-2] + count[1:-1] + count[2:]
    padded = np.r_[-1, window, -1]
    peak = (window >= padded[:-2]) & (window > padded[2:]) & (window >= min_window)
    levels = ((edges[1:-2] + edges[2:-1]) / 2.0)[peak][::-1]
    if len(levels) == 0:
        return levels, empty, empty, empty, np.zeros(0, bool), box, box
    a = np.searchsorted(z, levels - 1.5 * slab, "right")
    b = np.searchsorted(z, levels + 1.5 * slab, "right")
    u = np.searchsorted(z, levels + clear, "right")
    n = len(z)
    whole = np.zeros(len(levels), bool)
    for i in range(len(levels)):
        if a[i] >= b[i] or u[i] >= n or n - u[i] < min_up:
            continue
        lo, hi = xy[u[i] :].min(axis=0) - slab, xy[u[i] :].max(axis=0) + slab
        out = ~np.all((xy[a[i] : b[i]] >= lo) & (xy[a[i] : b[i]] <= hi), axis=1)
        whole[i] = out.sum() >= min_out
    lo = np.minimum.accumulate(xy[::-1], axis=0)[::-1]  # the box of the rows from each up
    hi = np.maximum.accumulate(xy[::-1], axis=0)[::-1]
    return levels, a, b, u, whole, lo, hi


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(0, 300),
    seed=st.integers(0, 10_000),
    clear=st.sampled_from([0.004, 0.015, 0.03]),
    min_window=st.integers(1, 12),
)
def test_screen_levels_matches_numpy(n, seed, clear, min_window):
    rng = np.random.default_rng(seed)
    # Heights on a few shelves (ties, peaks) and spread between; x, y in a few boxes.
    z = np.sort(np.r_[rng.choice([0.1, 0.13, 0.2], n // 2), rng.uniform(0.0, 0.3, n - n // 2)])
    xy = rng.uniform(-0.1, 0.1, (n, 2)) * rng.choice([0.3, 1.0], (n, 1))
    args = (0.02, 0.28, clear, 0.005, min_window, 5.0, 1.0)
    got = screen_levels(z, xy, *args)
    want = _numpy_screen(z, xy, *args)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)


def test_screen_levels_bad_input():
    with pytest.raises(ValueError, match="ascend"):
        screen_levels(np.array([0.2, 0.1]), np.zeros((2, 2)), 0.0, 0.3, 0.01, 0.005, 1, 1, 1)
    with pytest.raises(ValueError, match="one row per height"):
        screen_levels(np.array([0.1, 0.2]), np.zeros((3, 2)), 0.0, 0.3, 0.01, 0.005, 1, 1, 1)
    with pytest.raises(ValueError, match="positive"):
        screen_levels(np.array([0.1]), np.zeros((1, 2)), 0.0, 0.3, 0.01, 0.0, 1, 1, 1)


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(1, 300),
    seed=st.integers(0, 10_000),
    clear=st.sampled_from([0.0075, 0.015, 0.03]),
    min_up=st.sampled_from([1.0, 5.0, 30.0]),
)
def test_may_hold_never_rejects_a_cluster_worth_trying(n, seed, clear, min_up):
    from supportnode.kernels.layers import may_hold

    rng = np.random.default_rng(seed)
    z = np.r_[rng.choice([0.1, 0.13, 0.2], n // 2), rng.uniform(0.0, 0.3, n - n // 2)]
    xy = rng.uniform(-0.1, 0.1, (n, 2)) * np.where(z > 0.15, 0.3, 1.0)[:, None]
    p = np.c_[xy, z][rng.permutation(n)]
    order = np.argsort(p[:, 2], kind="stable")
    zs, xys = p[order, 2], p[order, :2]
    whole = screen_levels(zs, xys, zs[0] + 0.02, zs[-1] - clear, clear, 0.005, 1, min_up, 1.0)[4]
    if whole.any():
        assert may_hold(p, 0.005, clear, min_up, 1.0)


def test_may_hold_passes_over_a_single_box_but_not_a_stack():
    from supportnode.kernels.layers import may_hold

    rng = np.random.default_rng(5)
    # A lidar's lines across one box's front (the highest 4 cm below its edge) and its top:
    # each inside the box of what is above it. (A line within the 3.5 cm the screen looks
    # up may pass it: then the exact screen decides.)
    h = np.arange(TABLE, TABLE + 0.16, 0.012)
    front = np.c_[rng.uniform(-0.1, 0.1, (len(h), 40)).ravel(), np.full(len(h) * 40, -0.05)]
    front = np.c_[front, np.repeat(h, 40)]
    top = np.c_[rng.uniform(-0.1, 0.1, (200, 2)) * [1, 0.5], np.full(200, TABLE + 0.2)]
    assert not may_hold(np.r_[front, top], 0.005, 0.015, 30.0, 2.25)
    lower = _without(
        _box((-0.1, -0.075, TABLE), (0.1, 0.075, TABLE + 0.08), rng),
        (-0.06, -0.05, 0),
        (0.06, 0.05, 1),
    )
    upper = _box((-0.06, -0.05, TABLE + 0.08), (0.06, 0.05, TABLE + 0.14), rng)
    assert may_hold(np.r_[lower, upper], 0.005, 0.015, 30.0, 2.25)


def test_the_sampled_shelfs_stacked_boxes_are_objects_each_on_the_one_below():
    # The shelf's boxes sampled sparsely (150k points for the whole room): the top box's
    # face under it shows a rim of 10-14 flat points, which must be enough; the middle box
    # is turned 10 degrees on the bottom one.
    from supportnode.config import load_config
    from supportnode.pipeline import detect
    from supportnode.sim import load_scene
    from supportnode.sim.simulate import sampled

    scene = load_scene("shelf")
    cloud = sampled(scene, 150_000, seed=0)
    det = detect(cloud.points.astype(np.float64), load_config(None, []))
    names = list(scene.object_names)
    for upper, lower in [("stack_a_3", "stack_a_2"), ("stack_a_2", "stack_a_1")]:
        top = whole(det.objects.labels[cloud.object == names.index(upper)])
        under = whole(det.objects.labels[cloud.object == names.index(lower)])
        assert top != under
        assert det.objects.clusters[top].supported_by == under
    # The other stack (its upper box turned 8 degrees) by the shelf's side panel, and the
    # lamp, whose stem meets its shade where nothing is seen, held up by it: one object.
    top = whole(det.objects.labels[cloud.object == names.index("stack_b_2")])
    under = whole(det.objects.labels[cloud.object == names.index("stack_b_1")])
    assert det.objects.clusters[top].supported_by == under != top
    assert det.objects.clusters[under].surface_id == det.objects.clusters[top].surface_id
    whole(det.objects.labels[cloud.object == names.index("lamp")])
