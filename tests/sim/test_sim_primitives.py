"""Ray casting against hand-computed hits, occlusion, and face sampling of each primitive."""

from __future__ import annotations

import numpy as np
import pytest

from supportnode.sim.primitives import Box, Cone, Cylinder, Sphere
from supportnode.sim.scene import parse_scene
from supportnode.sim.sensors import raycast


def ray(origin, direction):
    d = np.asarray(direction, float)
    return np.asarray(origin, float)[None], (d / np.linalg.norm(d))[None]


def scene(*lines: str):
    return parse_scene("primitives:\n" + "\n".join(f"  - {s}" for s in lines))


def test_unit_box_head_on_from_minus_x():
    s = scene("{kind: box, size: [1, 1, 1], role: structure}")
    t, prim, top = raycast(s, np.array([-5.0, 0, 0]), np.array([[1.0, 0, 0]]))
    assert t[0] == pytest.approx(4.5) and prim[0] == 0 and not top[0]
    hit = np.array([-5.0, 0, 0]) + t[0] * np.array([1.0, 0, 0])
    assert hit[0] == pytest.approx(-0.5)


def test_box_top_face_flag_and_rotated_box():
    s = scene("{kind: box, size: [2, 1, 0.5], xyz: [1, 2, 3], rpy: [0, 0, 90], role: structure}")
    # Straight down onto the top (z = 3.25) hits the +z face.
    t, _, top = raycast(s, np.array([1.0, 2.0, 10.0]), np.array([[0, 0, -1.0]]))
    assert t[0] == pytest.approx(6.75) and top[0]
    # Rotated 90 deg about z, the 2 m side now runs along y: from y = -5 the face is at y = 1.
    t, _, top = raycast(s, np.array([1.0, -5.0, 3.0]), np.array([[0, 1.0, 0]]))
    assert t[0] == pytest.approx(6.0) and not top[0]
    # From below the bottom face is not the top.
    t, _, top = raycast(s, np.array([1.0, 2.0, 0.0]), np.array([[0, 0, 1.0]]))
    assert t[0] == pytest.approx(2.75) and not top[0]


def test_sphere_hits_and_misses():
    o, d = ray([0, 0, 0], [1, 0, 0])
    t, top = Sphere(1.0).intersect(o - [4.0, 0, 0], d)
    assert t[0] == pytest.approx(3.0) and not top[0]
    # Offset ray: x^2 + 0.6^2 = 1 -> first hit 0.8 before the centre.
    t, _ = Sphere(1.0).intersect(np.array([[-4.0, 0.6, 0]]), d)
    assert t[0] == pytest.approx(4.0 - 0.8)
    t, _ = Sphere(1.0).intersect(np.array([[-4.0, 1.01, 0]]), d)
    assert np.isinf(t[0])
    # From inside, the exit point.
    t, _ = Sphere(1.0).intersect(np.zeros((1, 3)), d)
    assert t[0] == pytest.approx(1.0)


def test_cylinder_side_and_caps():
    cyl = Cylinder(radius=0.5, height=2.0)
    t, top = cyl.intersect(np.array([[-3.0, 0, 0.7]]), np.array([[1.0, 0, 0]]))
    assert t[0] == pytest.approx(2.5) and not top[0]  # side
    t, top = cyl.intersect(np.array([[0.2, 0.1, 5.0]]), np.array([[0, 0, -1.0]]))
    assert t[0] == pytest.approx(4.0) and top[0]  # top cap at z = +1
    t, top = cyl.intersect(np.array([[0.2, 0.1, -5.0]]), np.array([[0, 0, 1.0]]))
    assert t[0] == pytest.approx(4.0) and not top[0]  # bottom cap
    t, _ = cyl.intersect(np.array([[-3.0, 0, 1.2]]), np.array([[1.0, 0, 0]]))
    assert np.isinf(t[0])  # passes above
    # Oblique ray entering through the side below the rim: 45 deg down from (-2, 0, 2).
    d = np.array([[1.0, 0, -1.0]]) / np.sqrt(2)
    t, top = cyl.intersect(np.array([[-2.0, 0, 2.0]]), d)
    assert t[0] == pytest.approx(1.5 * np.sqrt(2)) and not top[0]  # x = -0.5, z = 0.5


def test_cone_side_and_base():
    cone = Cone(radius=1.0, height=2.0)  # base at z = -1, apex at z = +1
    # At z = 0 the radius is 0.5.
    t, _ = cone.intersect(np.array([[-3.0, 0, 0]]), np.array([[1.0, 0, 0]]))
    assert t[0] == pytest.approx(2.5)
    t, _ = cone.intersect(np.array([[0.0, 0, 5.0]]), np.array([[0, 0, -1.0]]))
    assert t[0] == pytest.approx(4.0)  # apex
    t, _ = cone.intersect(np.array([[0.3, 0, -5.0]]), np.array([[0, 0, 1.0]]))
    assert t[0] == pytest.approx(4.0)  # base disc
    # The upper nappe of the double cone is not part of the shape.
    t, _ = cone.intersect(np.array([[-3.0, 0, 2.0]]), np.array([[1.0, 0, 0]]))
    assert np.isinf(t[0])


def test_occlusion_box_behind_box():
    s = scene(
        "{kind: box, name: front, size: [1, 1, 1], role: structure}",
        "{kind: box, name: back, size: [0.8, 0.8, 0.8], xyz: [3, 0, 0], role: object, object: b}",
    )
    rng = np.random.default_rng(0)
    # Rays from x = -5 aimed at random points of the hidden box's front face.
    targets = np.c_[np.full(500, 2.6), rng.uniform(-0.4, 0.4, (500, 2))]
    origin = np.array([-5.0, 0, 0])
    d = targets - origin
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    _, prim, _ = raycast(s, origin, d)
    assert (prim == 0).all()
    # Without the front box, the same rays reach the back one.
    s2 = scene("{kind: box, size: [0.8, 0.8, 0.8], xyz: [3, 0, 0], role: structure}")
    t, prim, _ = raycast(s2, origin, d)
    assert (prim == 0).all() and np.allclose((origin + d * t[:, None])[:, 0], 2.6)


def test_max_range_and_misses():
    s = scene("{kind: sphere, radius: 1, xyz: [10, 0, 0], role: structure}")
    d = np.array([[1.0, 0, 0], [-1.0, 0, 0]])
    t, prim, _ = raycast(s, np.zeros(3), d, max_range=5.0)
    assert (prim == -1).all() and np.isinf(t).all()
    t, prim, _ = raycast(s, np.zeros(3), d)
    assert prim.tolist() == [0, -1] and t[0] == pytest.approx(9.0)


@pytest.mark.parametrize(
    "shape",
    [Box((1.0, 2.0, 0.5)), Cylinder(0.3, 1.2), Sphere(0.7), Cone(0.5, 1.5)],
    ids=lambda s: s.kind,
)
def test_face_samples_lie_on_the_surface(shape):
    rng = np.random.default_rng(3)
    for face in shape.faces():
        p = face.sample(rng, 2000)
        assert p.shape == (2000, 3)
        if isinstance(shape, Box):
            on = np.isclose(np.abs(p), shape.half).any(axis=1)
            assert on.all() and (np.abs(p) <= shape.half + 1e-12).all()
        elif isinstance(shape, Sphere):
            assert np.allclose(np.linalg.norm(p, axis=1), shape.radius)
        elif isinstance(shape, Cylinder):
            r = np.hypot(p[:, 0], p[:, 1])
            cap = np.isclose(np.abs(p[:, 2]), shape.height / 2)
            assert (cap | np.isclose(r, shape.radius)).all() and (r <= shape.radius + 1e-9).all()
        else:
            r = np.hypot(p[:, 0], p[:, 1])
            expected = shape.radius * (shape.height / 2 - p[:, 2]) / shape.height
            base = np.isclose(p[:, 2], -shape.height / 2)
            assert (base | np.isclose(r, expected)).all()
    tops = [f for f in shape.faces() if f.top]
    assert len(tops) == (1 if isinstance(shape, (Box, Cylinder)) else 0)


def test_face_areas():
    assert sum(f.area for f in Box((1.0, 2.0, 3.0)).faces()) == pytest.approx(22.0)
    assert sum(f.area for f in Cylinder(1.0, 2.0).faces()) == pytest.approx(6 * np.pi)
    assert sum(f.area for f in Cone(3.0, 4.0).faces()) == pytest.approx(np.pi * 3 * 5 + 9 * np.pi)
