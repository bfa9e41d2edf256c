"""Tabletop test cases with ground truth, seen by a Kinect-like depth camera: what object
segmentation must get right (touching and stacked boxes, gaps of a few mm, a can against a box,
a mug with its handle, a bowl, a flat book, near and far objects, NaN holes).

    from supportnode.sim.tabletop import CASES, case
    c = case("box_on_box", seed=0, frame="optical")   # a Kinect-like organised cloud
    c.cloud.points.reshape(480, 640, 3)                # NaN where no return
    c.cloud.object, c.cloud.supported_by               # ground truth per point
    c.scene.object_names                               # names of the object ids

Every case is a table (top at TABLE_TOP, z up) on a floor with a few objects near the table's
centre, scanned once by `DepthCamera.preset("kinect")` with the `kinect` noise from 1 m at 50
degrees below the horizon (the mOSD view), from the side that shows what the case is about.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from supportnode.sim.cloud import SimCloud
from supportnode.sim.depth_noise import kinect_noise
from supportnode.sim.scene import parse_scene
from supportnode.sim.scene_model import Scene
from supportnode.sim.sensors import DepthCamera
from supportnode.sim.trajectory import look_at

TABLE_TOP = 0.75  # metres
_TABLE = f"""
primitives:
  - {{kind: box, name: floor, size: [4, 4, 0.02], xyz: [0, 0, -0.01], role: surface, surface: floor}}
  - {{kind: box, name: table, size: [1.2, 0.8, 0.04], xyz: [0, 0, {TABLE_TOP - 0.02}],
     role: surface, surface: table}}
  - {{kind: box, name: leg, size: [0.05, 0.05, {TABLE_TOP - 0.04}], xyz: [0.5, 0.3, {(TABLE_TOP - 0.04) / 2}],
     role: structure}}
"""


def _on_table(*items: str) -> Scene:
    """A scene of the table and `items` (YAML flow mappings, z relative to the table top)."""
    lines = [_TABLE.rstrip()] + [f"  - {item}" for item in items]
    return parse_scene("\n".join(lines) + "\n", source="tabletop")


def _box(
    name: str,
    size: tuple[float, float, float],
    x: float,
    y: float,
    z0: float = 0.0,
    yaw: float = 0.0,
) -> str:
    """A box standing with its bottom z0 above the table top."""
    z = TABLE_TOP + z0 + size[2] / 2.0
    return (
        f"{{kind: box, name: {name}, size: {list(size)}, xyz: [{x}, {y}, {z}], "
        f"rpy: [0, 0, {yaw}], role: object, object: {name}}}"
    )


def _can(name: str, x: float, y: float, radius: float = 0.033, height: float = 0.12) -> str:
    z = TABLE_TOP + height / 2.0
    return (
        f"{{kind: cylinder, name: {name}, radius: {radius}, height: {height}, "
        f"xyz: [{x}, {y}, {z}], role: object, object: {name}}}"
    )


def touching_boxes(gap: float = 0.0) -> Scene:
    """Two boxes of different heights face to face, `gap` metres apart (0: contact), their
    fronts flush; seen from the side of the lower one, the taller one's face shows above it."""
    return _on_table(
        _box("box_a", (0.16, 0.12, 0.14), 0.0, -0.06),
        _box("box_b", (0.16, 0.1, 0.1), 0.0, 0.05 + gap),
    )


def box_on_box() -> Scene:
    """A smaller box standing on a larger one, turned 15 degrees."""
    return _on_table(
        _box("lower", (0.2, 0.16, 0.1), 0.0, 0.0),
        _box("upper", (0.12, 0.1, 0.08), 0.01, 0.0, z0=0.1, yaw=15.0),
    )


def offset_boxes() -> Scene:
    """Two boxes of one height side by side, touching, one 4 cm further back: their tops are
    one level face whose outline steps at the contact."""
    return _on_table(
        _box("box_a", (0.12, 0.1, 0.1), 0.0, -0.05), _box("box_b", (0.12, 0.1, 0.1), 0.04, 0.05)
    )


def can_against_box() -> Scene:
    """A can touching the side of a box."""
    return _on_table(_box("box", (0.14, 0.2, 0.16), 0.0, 0.0), _can("can", -0.103, 0.02))


def two_cans(gap: float = 0.01) -> Scene:
    """Two cans side by side, `gap` metres apart."""
    return _on_table(_can("can_a", 0.0, -0.033 - gap / 2), _can("can_b", 0.0, 0.033 + gap / 2))


def three_cans() -> Scene:
    """Three cans of one height in a row, touching: their lids make one level face."""
    return _on_table(_can("can_a", 0.0, -0.066), _can("can_b", 0.0, 0.0), _can("can_c", 0.0, 0.066))


def bottle_before_book(gap: float = 0.02, height: float = 0.25) -> Scene:
    """A bottle `height` metres tall standing `gap` metres in front (-x) of a flat book: from
    the front its shadow crosses the book's top."""
    return _on_table(
        _box("book", (0.24, 0.17, 0.035), 0.0, 0.0),
        _can("bottle", -0.155 - gap, 0.0, radius=0.035, height=height),
    )


def box_on_book() -> Scene:
    """A box 12 cm deep standing on a book's edge: the book's visible top is notched."""
    return _on_table(
        _box("book", (0.24, 0.17, 0.035), 0.0, 0.0),
        _box("box", (0.08, 0.12, 0.05), 0.0, 0.025, z0=0.035),
    )


def mug() -> Scene:
    """A mug (an open cup with a bottom) with its handle to the side: one object."""
    z = TABLE_TOP + 0.0475
    return _on_table(
        f"{{kind: group, name: mug, role: object, object: mug, xyz: [0, 0, {z}], children: ["
        "{kind: cup, name: body, radius: 0.04, height: 0.095, thickness: 0.004}, "
        "{kind: torus, name: handle, major_radius: 0.028, minor_radius: 0.006, arc_deg: 180, "
        "xyz: [0, 0.038, 0.005], rpy: [90, 0, 90]}]}"
    )


def bottle() -> Scene:
    """A bottle: body, sloped shoulder and a narrow neck meeting the shoulder in a concave
    crease (as a box meets the box it stands on); the neck rests on nothing level: one
    object."""
    z = TABLE_TOP
    return _on_table(
        f"{{kind: group, name: bottle, role: object, object: bottle, xyz: [0, 0, {z}], children: ["
        "{kind: cylinder, radius: 0.035, height: 0.17, xyz: [0, 0, 0.085]}, "
        "{kind: cone, radius: 0.035, height: 0.05, xyz: [0, 0, 0.195]}, "
        "{kind: cylinder, radius: 0.012, height: 0.04, xyz: [0, 0, 0.225]}]}"
    )


def bowl() -> Scene:
    """An open bowl on its flat base: one object."""
    z = TABLE_TOP + 0.03
    return _on_table(
        f"{{kind: bowl, name: bowl, radius: 0.08, height: 0.06, thickness: 0.004, "
        f"base_radius: 0.04, xyz: [0, 0, {z}], role: object, object: bowl}}"
    )


def flat_book() -> Scene:
    """A closed book lying flat: 3.5 cm tall, an object, not part of the table."""
    return _on_table(_box("book", (0.24, 0.17, 0.035), 0.0, 0.0, yaw=20.0))


def spread_boxes() -> Scene:
    """Three separate boxes, for the near and far views."""
    return _on_table(
        _box("box_a", (0.12, 0.1, 0.1), 0.0, -0.15),
        _box("box_b", (0.1, 0.1, 0.06), 0.0, 0.0),
        _box("box_c", (0.08, 0.14, 0.12), 0.05, 0.15, yaw=30.0),
    )


@dataclass(frozen=True)
class Case:
    """One test case: its scene (object names by id) and the scan with per-point truth."""

    name: str
    scene: Scene
    cloud: SimCloud


# name -> (scene builder, camera distance in metres, camera azimuth in degrees)
CASES: dict[str, tuple[Callable[[], Scene], float, float]] = {
    "touching_boxes": (touching_boxes, 1.0, -30.0),
    "boxes_1mm_apart": (lambda: touching_boxes(0.001), 1.0, -30.0),
    "boxes_1cm_apart": (lambda: touching_boxes(0.01), 1.0, -30.0),
    "boxes_3cm_apart": (lambda: touching_boxes(0.03), 1.0, -30.0),
    "box_on_box": (box_on_box, 1.0, 20.0),
    "offset_boxes": (offset_boxes, 1.0, 0.0),
    "can_against_box": (can_against_box, 1.0, 30.0),
    "mug": (mug, 1.0, -20.0),
    "bowl": (bowl, 1.0, 0.0),
    "bottle": (bottle, 1.0, 0.0),
    "two_cans_1cm_apart": (two_cans, 1.0, 0.0),
    "two_cans_touching": (lambda: two_cans(0.0), 1.0, 0.0),
    "two_cans_touching_oblique": (lambda: two_cans(0.0), 1.0, -45.0),
    "three_cans_in_a_row": (three_cans, 1.0, 0.0),
    "three_cans_oblique": (three_cans, 1.0, 30.0),
    "bottle_before_book": (bottle_before_book, 1.0, 0.0),
    "flat_book": (flat_book, 1.0, 0.0),
    "boxes_at_0.5m": (spread_boxes, 0.5, 0.0),
    "boxes_at_1.5m": (spread_boxes, 1.5, 0.0),
}


def view(
    scene: Scene,
    distance: float = 1.0,
    seed: int = 0,
    frame: str = "world",
    noise: float = 1.0,
    elevation_deg: float = 50.0,
    azimuth_deg: float = 0.0,
    camera: DepthCamera | None = None,
) -> SimCloud:
    """One organised scan of the table's centre from `distance` metres at `elevation_deg`
    below the horizon, from the azimuth (degrees about z, 0: from -x), with the kinect noise
    times `noise` (0: exact depths, the projector's shadow only). frame: "world" (z up),
    "sensor" or "optical" (the camera's, as a Kinect's PCD)."""
    camera = camera or DepthCamera.preset("kinect")
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    target = np.array([0.0, 0.0, TABLE_TOP + 0.05])
    eye = target + distance * np.array(
        [-np.cos(el) * np.cos(az), -np.cos(el) * np.sin(az), np.sin(el)]
    )
    cloud = camera.scan(scene, look_at(eye, target), organized=True)
    if noise > 0:
        cloud = kinect_noise(cloud, scene, camera, np.random.default_rng([seed, 2]), noise)
    return cloud.to_frame(frame)


def case(name: str, seed: int = 0, frame: str = "world", noise: float = 1.0) -> Case:
    """The test case `name` (one of CASES) scanned with `seed`, in `frame` (see `view`)."""
    if name not in CASES:
        raise ValueError(f"unknown tabletop case {name!r} (expected {', '.join(CASES)})")
    build, distance, azimuth = CASES[name]
    scene = build()
    return Case(name, scene, view(scene, distance, seed, frame, noise, azimuth_deg=azimuth))
