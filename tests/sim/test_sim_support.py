"""Ground truth of support: which object each object stands on and the surface under its stack,
derived from geometry, carried per point by sampled and scanned clouds and their files."""

from __future__ import annotations

import numpy as np
import pytest

from supportnode.io.clouds import read_cloud
from supportnode.sim import bundled_scenes, load_scene, look_at, parse_scene, sample_scene
from supportnode.sim.files import read_sim_npz, write_sim_cloud
from supportnode.sim.sensors import DepthCamera

STACKS = """
primitives:
  - {kind: box, name: table, size: [1.2, 0.8, 0.04], xyz: [0, 0, 0.73], role: surface, surface: table}
  - {kind: box, name: shelf, size: [0.3, 0.3, 0.02], xyz: [0.45, 0.25, 1.0], role: structure}
  - {kind: box, size: [0.2, 0.2, 0.1], xyz: [0, 0, 0.8], role: object, object: low}
  - {kind: box, size: [0.1, 0.1, 0.06], xyz: [0, 0, 0.883], role: object, object: mid}
  - {kind: box, size: [0.05, 0.05, 0.05], xyz: [0, 0, 0.9385], role: object, object: top}
  - {kind: box, size: [0.1, 0.1, 0.1], xyz: [0.3, 0, 0.8], role: object, object: beside}
  - {kind: box, size: [0.1, 0.1, 0.05], xyz: [0.3, 0, 0.885], rpy: [0, 0, 20], role: object, object: floating}
  - {kind: cylinder, radius: 0.03, height: 0.2, xyz: [-0.3, 0.1, 0.78], rpy: [90, 0, 0], role: object, object: lying_can}
  - {kind: sphere, radius: 0.04, xyz: [-0.3, -0.2, 0.79], role: object, object: ball}
  - {kind: box, size: [0.08, 0.08, 0.08], xyz: [0.45, 0.25, 1.05], role: object, object: on_structure}
"""


@pytest.fixture(scope="module")
def stacks():
    return parse_scene(STACKS)


def names(scene, ids):
    return [scene.object_names[i] if i >= 0 else "-" for i in ids]


def test_stacks_resolve_down_to_the_surface(stacks):
    sup = stacks.support
    assert names(stacks, sup.supported_by) == [
        "-",  # low: on the table
        "low",  # mid: 3 mm above low's top (within the 5 mm of contact)
        "mid",  # top: 3 mm above mid
        "-",
        "-",  # floating: 1 cm above `beside`, nothing within 5 mm
        "-",
        "-",
        "-",  # on the shelf board (structure)
    ]
    table = stacks.surface_names.index("table")
    assert sup.surface.tolist() == [table, table, table, table, -1, table, table, -1]


def test_bundled_scenes_support():
    shelf = load_scene("shelf")
    sup, obj = shelf.support, shelf.object_names.index
    assert sup.supported_by[obj("toy_car_cabin")] == obj("toy_car")
    assert sup.supported_by[obj("stack_a_3")] == obj("stack_a_2")
    assert sup.supported_by[obj("stack_a_2")] == obj("stack_a_1")
    assert sup.supported_by[obj("stack_b_2")] == obj("stack_b_1")
    assert sup.surface[obj("stack_a_3")] == shelf.surface_names.index("board_2")
    assert sup.supported_by[obj("mini_shelf")] == -1
    kitchen = load_scene("kitchen")
    k = kitchen.object_names.index
    assert [kitchen.support.supported_by[k(f"orange_{i}")] for i in (1, 2, 3)] == [
        k("fruit_bowl")
    ] * 3
    assert kitchen.support.supported_by[k("bowl")] == k("cutting_board")
    clutter = load_scene("cluttered_table")
    c = clutter.object_names.index
    stacked = {clutter.object_names[o] for o in np.flatnonzero(clutter.support.supported_by >= 0)}
    assert stacked == {"stack_top", "small_box"}
    assert clutter.support.supported_by[c("small_box")] == c("book")
    # Every object of every bundled scene stands on something that leads to a surface.
    for name in bundled_scenes():
        assert (load_scene(name).support.surface >= 0).all(), name


def test_points_carry_their_objects_support(stacks, tmp_path):
    cloud = sample_scene(stacks, 30_000, seed=0)
    sup = stacks.support
    on = cloud.object >= 0
    assert np.array_equal(cloud.supported_by[on], sup.supported_by[cloud.object[on]])
    assert np.array_equal(cloud.support_surface[on], sup.surface[cloud.object[on]])
    assert (cloud.supported_by[~on] == -1).all() and (cloud.support_surface[~on] == -1).all()
    pose = look_at([-0.8, 0.0, 1.5], [0.0, 0.0, 0.75])
    scan = DepthCamera(120, 90, 60.0).scan(stacks, pose, organized=True)
    seen = scan.object >= 0
    assert seen.sum() > 100
    assert np.array_equal(scan.supported_by[seen], sup.supported_by[scan.object[seen]])
    assert (scan.supported_by[~seen] == -1).all()
    # Both file formats keep them.
    ply = read_cloud(write_sim_cloud(tmp_path / "c.ply", cloud))
    assert np.array_equal(ply.fields["supported_by"], cloud.supported_by)
    assert np.array_equal(ply.fields["support_surface"], cloud.support_surface)
    npz = read_sim_npz(write_sim_cloud(tmp_path / "c.npz", scan))
    assert np.array_equal(npz.supported_by, scan.supported_by)


def test_files_without_support_read_as_unknown(tmp_path):
    old = tmp_path / "old.npz"
    np.savez(
        old,
        points=np.zeros((3, 3), np.float32),
        role=np.zeros(3, np.int8),
        primitive=np.zeros(3, np.int32),
        object=np.array([0, 1, -1], np.int32),
        surface=np.full(3, -1, np.int32),
        sensor_pose=np.eye(4),
        stamp=np.float64(0),
    )
    cloud = read_sim_npz(old)
    assert (cloud.supported_by == -1).all() and (cloud.support_surface == -1).all()
