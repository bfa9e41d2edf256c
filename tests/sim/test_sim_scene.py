"""Scene files: parsing, labels across composites, errors naming file, line and key, and the
bundled scenes."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

from supportnode.errors import SceneError
from supportnode.sim.primitives import Box, Cylinder
from supportnode.sim.scene import bundled_scenes, load_scene, parse_scene


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text).lstrip("\n"))
    return path


def test_unknown_kind_names_file_line_and_kind(tmp_path):
    path = write(
        tmp_path,
        "shelf.yaml",
        """
        primitives:
          - {kind: box, size: [1, 1, 1], role: structure}
          - kind: box
            size: [1, 1, 1]
            role: structure
          - name: lamp_stem
            kind: cilinder
            role: object
        """,
    )
    with pytest.raises(SceneError) as err:
        load_scene(path)
    msg = str(err.value)
    assert msg.startswith("shelf.yaml:7: primitive 'lamp_stem': unknown kind 'cilinder'")
    assert "expected box, cylinder, sphere, cone" in msg and "\n" not in msg


def test_unknown_kind_unnamed_primitive_uses_index(tmp_path):
    path = write(tmp_path, "s.yaml", "primitives:\n  - {kind: cube, size: [1, 1, 1]}\n")
    with pytest.raises(SceneError, match=r"^s\.yaml:2: primitive 0: unknown kind 'cube'"):
        load_scene(path)


def test_missing_size_names_key_and_line(tmp_path):
    path = write(
        tmp_path,
        "table.yaml",
        """
        # comment
        primitives:
          - {kind: box, size: [1, 1, 1], role: structure}
          - kind: box
            name: top
            role: surface
            surface: t
        """,
    )
    with pytest.raises(SceneError, match=r"^table\.yaml:4: primitive 'top': missing key 'size'$"):
        load_scene(path)


@pytest.mark.parametrize(
    ("body", "pattern"),
    [
        (
            "  - {kind: cylinder, height: 1, role: structure}",
            r":2: primitive 0: missing key 'radius'",
        ),
        (
            "  - {kind: box, size: [1, 1], role: structure}",
            r":2: .*'size' must be 3 positive numbers",
        ),
        ("  - {kind: box, size: [1, 1, -1], role: structure}", r"'size' must be 3 positive"),
        ("  - {kind: box, size: [1, 1, 1], role: floor}", r":2: .*unknown role 'floor'"),
        ("  - {kind: box, size: [1, 1, 1], role: surface}", r":2: .*missing key 'surface'"),
        ("  - {kind: box, size: [1, 1, 1], role: object}", r":2: .*missing key 'object'"),
        ("  - {kind: box, size: [1, 1, 1]}", r":2: .*missing key 'role'"),
        ("  - {kind: sphere, radius: 1, role: surface, surface: s}", r"needs a box or a cylinder"),
        ("  - {kind: box, size: [1, 1, 1], role: structure, colour: red}", r"unknown key 'colour'"),
        ("  - {use: chair}", r":2: .*unknown define 'chair'"),
        ("  - {kind: box, size: [1, 1, 1], xyz: [0, 0], role: structure}", r"'xyz' must be 3"),
        ("  - {kind: box, kind: box}", r":2: duplicate key 'kind'"),
        ("  - {kind: box, size: [1, 1, 1], role: structure\n", r":\d+: YAML syntax error"),
    ],
)
def test_errors_are_one_line_with_file_and_line(tmp_path, body, pattern):
    path = write(tmp_path, "bad.yaml", "primitives:\n" + body + "\n")
    with pytest.raises(SceneError, match=pattern) as err:
        load_scene(path)
    assert str(err.value).startswith("bad.yaml:") and "\n" not in str(err.value)


def test_unknown_top_level_key_and_missing_primitives(tmp_path):
    with pytest.raises(SceneError, match=r"^a\.yaml:1: unknown key 'primitive'"):
        load_scene(write(tmp_path, "a.yaml", "primitive: []\n"))
    with pytest.raises(SceneError, match=r"missing key 'primitives'"):
        load_scene(write(tmp_path, "b.yaml", "name: x\n"))


def test_unknown_scene_name():
    with pytest.raises(SceneError, match=r"unknown scene 'nope' \(bundled: .*shelf"):
        load_scene("nope")


DEFINE = """
define:
  chair:
    - {kind: box, name: seat, size: [0.4, 0.4, 0.04], xyz: [0, 0, 0.43], role: surface, surface: seat}
    - {kind: cylinder, radius: 0.02, height: 0.41, xyz: [0.18, 0.18, 0.205], role: structure}
  barrel:
    - {kind: cylinder, radius: 0.1, height: 0.3, xyz: [0, 0, 0.15], role: object, object: barrel}
primitives:
  - {kind: box, name: floor, size: [4, 4, 0.02], xyz: [0, 0, -0.01], role: surface, surface: floor}
  - {use: chair, name: a, xyz: [1, 0, 0], rpy: [0, 0, 90]}
  - {use: chair, name: b, xyz: [-1, 0, 0]}
  - {use: barrel, xyz: [0, 1, 0]}
  - {use: barrel, xyz: [0.2, 1, 0]}
  - kind: group
    name: lamp
    xyz: [0, -1, 0]
    role: object
    object: lamp
    children:
      - {kind: cylinder, radius: 0.01, height: 0.3, xyz: [0, 0, 0.15]}
      - {kind: cone, radius: 0.1, height: 0.1, xyz: [0, 0, 0.35]}
"""


def test_define_use_group_labels_and_poses():
    s = parse_scene(DEFINE)
    assert s.surface_names == ("floor", "a/seat", "b/seat")
    assert s.object_names == ("barrel_0/barrel", "barrel_1/barrel", "lamp")
    by_name = {p.name: p for p in s.primitives}
    assert [p.surface_id for p in s.primitives if p.name == "seat"] == [1, 2]
    lamp = [p for p in s.primitives if p.object_id == 2]
    assert len(lamp) == 2 and {p.role for p in lamp} == {"object"}
    # Poses compose: chair a's leg at (0.18, 0.18) in the chair rotated 90 deg about z at x=1.
    leg = next(p for p in s.primitives if p.kind == "cylinder" and p.role == "structure")
    assert np.allclose(leg.pose[:3, 3], [1 - 0.18, 0.18, 0.205])
    assert isinstance(by_name["floor"].shape, Box) and isinstance(leg.shape, Cylinder)
    assert s.primitives[0].line == 9


def test_define_that_uses_itself(tmp_path):
    text = "define:\n  a:\n    - {use: a}\nprimitives:\n  - {use: a}\n"
    with pytest.raises(SceneError, match=r"define 'a' uses itself"):
        load_scene(write(tmp_path, "loop.yaml", text))


def test_label_table_top_faces_only():
    s = parse_scene(DEFINE)
    table = s.label_table()
    floor = 0
    assert table["role_top"][floor] == 0 and table["role_other"][floor] == 1
    assert table["surface_top"][floor] == 0


@pytest.mark.parametrize(
    "name", ["shelf", "table_chairs", "u_table", "kitchen", "sloped", "cluttered_table"]
)
def test_bundled_scene_contents(name):
    assert name in bundled_scenes()
    s = load_scene(name)
    expected = {  # (surfaces, objects)
        "shelf": (5, 14),  # the toy car and its cabin (a box on its body) are two objects
        "table_chairs": (4, 1),
        "u_table": (2, 7),
        "kitchen": (4, 15),
        "sloped": (3, 2),
        "cluttered_table": (2, 18),
    }[name]
    assert (len(s.surface_names), len(s.object_names)) == expected
    assert s.surface_names[0] == "floor"


def _top_z(p, x, y):
    """World z of the +z face of primitive p above (x, y), or None if (x, y) is outside it."""
    inv = np.linalg.inv(p.pose)
    local = inv[:3, :3] @ np.array([x, y, 0.0]) + inv[:3, 3]
    s = p.shape
    if isinstance(s, Box):
        h = s.half
        if abs(local[0]) > h[0] + 1e-9 or abs(local[1]) > h[1] + 1e-9:
            return None
        top = np.array([local[0], local[1], h[2]])
    elif isinstance(s, Cylinder):
        if np.hypot(local[0], local[1]) > s.radius + 1e-9:
            return None
        top = np.array([local[0], local[1], s.height / 2])
    else:
        return None
    # Follow the face along world z: (x, y) fixed, so solve on the face plane.
    n = p.pose[:3, :3] @ np.array([0, 0, 1.0])
    point = p.pose[:3, :3] @ top + p.pose[:3, 3]
    return point[2] - (n[0] * (x - point[0]) + n[1] * (y - point[1])) / n[2]


@pytest.mark.parametrize("name", ["shelf", "table_chairs", "u_table", "kitchen", "sloped"])
def test_objects_stand_on_something(name):
    """Each object's lowest sampled points lie on a surface top or on another object's top."""
    from supportnode.sim.sensors import sample_scene

    s = load_scene(name)
    cloud = sample_scene(s, 200_000, seed=0)
    for oid, oname in enumerate(s.object_names):
        pts = cloud.points[cloud.object == oid].astype(float)
        # The lowest few points (the bottom rim; sampling leaves out points within 1 mm of a
        # support, and a rotated box may overhang the one below at a corner).
        low = pts[np.argsort(pts[:, 2])[:8]]
        supports = [
            p
            for p in s.primitives
            if p.object_id != oid and (p.role == "surface" or p.object_id >= 0)
        ]
        gaps = [
            abs(h - z) for x, y, z in low for p in supports if (h := _top_z(p, x, y)) is not None
        ]
        assert gaps, f"{name}: nothing under object {oname}"
        gap = min(gaps)
        # Spheres and tilted bottoms touch at a point or an edge: the lowest samples are a few
        # mm above it at 200k points.
        assert gap < 0.006, f"{name}: object {oname} floats {gap:.4f} m above its support"
