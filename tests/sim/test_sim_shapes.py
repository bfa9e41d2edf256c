"""Every primitive, old and new (cup, bowl, torus arc): exact first hits, normals, sampling on
the surface, and what a sensor sees of the open vessels."""

from __future__ import annotations

import numpy as np
import pytest

from supportnode.errors import SceneError
from supportnode.sim.primitives import Bowl, Box, Cone, Cup, Cylinder, Sphere, Torus
from supportnode.sim.scene import parse_scene
from supportnode.sim.sensors import raycast, sample_scene

SHAPES = {
    "box": Box((0.3, 0.2, 0.1)),
    "cylinder": Cylinder(0.05, 0.12),
    "sphere": Sphere(0.08),
    "cone": Cone(0.1, 0.12),
    "cup": Cup(0.04, 0.1, 0.004),
    "bowl": Bowl(0.08, 0.06, 0.004, 0.035),
    "pot": Bowl(0.06, 0.1, 0.005, 0.05),  # bulges: the sphere's equator is inside the zone
    "torus": Torus(0.05, 0.01),
    "handle": Torus(0.03, 0.006, arc_deg=180.0),
}


def random_rays(shape, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Rays from a sphere around the shape towards random points of its box."""
    rng = np.random.default_rng(seed)
    v = rng.standard_normal((n, 3))
    o = 3.0 * shape.bounding_radius * v / np.linalg.norm(v, axis=1, keepdims=True)
    target = (rng.random((n, 3)) * 2.0 - 1.0) * 1.3 * shape.half_extent
    d = target - o
    return o, d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_first_hit_is_the_first_material_along_the_ray(name):
    shape = SHAPES[name]
    o, d = random_rays(shape, 3000, seed=1)
    t, _ = shape.intersect(o, d)
    hit = np.isfinite(t)
    assert 0.1 < hit.mean() < 0.95  # both hits and misses are tested
    p = o[hit] + t[hit, None] * d[hit]
    assert shape.contains(p, 1e-6).all()
    assert not shape.contains(o[hit] + (t[hit, None] - 1e-5) * d[hit], 0.0).any()
    # The hit faces the ray, and the normal points out of the material.
    n = shape.normals(p)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    assert (np.einsum("ij,ij->i", n, d[hit]) < 1e-9).mean() > 0.995
    # Marching each ray in 0.2 mm steps finds no material before the hit (nor on a miss).
    span = 6.0 * shape.bounding_radius
    steps = np.arange(0.0, span, 2e-4)
    for i in np.flatnonzero(hit)[:150].tolist() + np.flatnonzero(~hit)[:150].tolist():
        s = steps[steps < t[i] - 1e-5] if np.isfinite(t[i]) else steps
        assert not shape.contains(o[i] + s[:, None] * d[i], 0.0).any(), (name, i)


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_sampled_points_lie_on_the_surface_with_outward_normals(name):
    shape = SHAPES[name]
    rng = np.random.default_rng(2)
    for face in shape.faces():
        p = face.sample(rng, 2000)
        assert p.shape == (2000, 3)
        assert shape.contains(p, 1e-7).all()
        n = shape.normals(p)
        outside = ~shape.contains(p + 1e-5 * n, 0.0)
        inside = shape.contains(p - 1e-5 * n, 0.0)
        assert outside.mean() > 0.995 and inside.mean() > 0.995, name
    assert sum(f.area for f in shape.faces()) > 0


def test_areas_of_the_vessels_and_the_torus():
    cup = SHAPES["cup"]
    r, ri, h, t = 0.04, 0.036, 0.1, 0.004
    expected = 2 * np.pi * r * h + 2 * np.pi * ri * (h - t) + np.pi * (r * r - ri * ri)
    expected += np.pi * r * r + np.pi * ri * ri
    assert sum(f.area for f in cup.faces()) == pytest.approx(expected)
    handle = SHAPES["handle"]
    tube = handle.faces()[0]
    assert tube.area == pytest.approx(np.pi * 0.006 * 2 * np.pi * 0.03)
    assert len(handle.faces()) == 3  # tube and two flat ends
    # Uniform by area: the outer half of the tube (cos v > 0) holds (pi R + 2 r) / (2 pi R).
    p = tube.sample(np.random.default_rng(3), 200_000)
    outer = np.hypot(p[:, 0], p[:, 1]) > 0.03
    assert outer.mean() == pytest.approx((np.pi * 0.03 + 2 * 0.006) / (2 * np.pi * 0.03), abs=0.005)
    assert (np.abs(np.degrees(np.arctan2(p[:, 1], p[:, 0]))) <= 90.0 + 1e-9).all()


def test_looking_into_a_cup_and_a_bowl():
    down = np.tile([0.0, 0.0, -1.0], (5, 1))
    rho = np.array([0.0, 0.01, 0.02, 0.03, 0.035])
    o = np.column_stack([rho, np.zeros(5), np.full(5, 1.0)])
    cup = SHAPES["cup"]
    t, _ = cup.intersect(o, down)
    assert np.allclose(1.0 - t, cup.floor)  # the inside bottom, not the outside one
    bowl = SHAPES["bowl"]
    t, _ = bowl.intersect(o, down)
    r_in = bowl.sphere_radius - bowl.thickness
    inner = bowl.zc - np.sqrt(r_in**2 - rho**2)
    assert np.allclose(1.0 - t, np.maximum(inner, bowl.floor))
    # From the side, below the rim, the outside of the wall.
    t, _ = bowl.intersect(np.array([[1.0, 0.0, 0.0]]), np.array([[-1.0, 0.0, 0.0]]))
    assert 1.0 - t[0] == pytest.approx(np.sqrt(bowl.sphere_radius**2 - bowl.zc**2))
    # Onto the rim from above: the rim's annulus at the top.
    t, _ = bowl.intersect(np.array([[0.078, 0.0, 1.0]]), down[:1])
    assert 1.0 - t[0] == pytest.approx(0.03)


def test_handle_arc_hits_only_its_half():
    handle = SHAPES["handle"]
    o = np.array([[0.03, -1.0, 0.0], [-0.03, -1.0, 0.0], [1.0, 0.0, 0.0]])
    d = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    t, _ = handle.intersect(o, d)
    # Along y at x = R the ray enters where the tube's outside (rho = R + r) crosses it.
    assert t[0] == pytest.approx(1.0 - np.sqrt(0.036**2 - 0.03**2))
    assert np.isinf(t[1])  # where a whole torus would be
    assert t[2] == pytest.approx(1.0 - 0.036)  # the outside of the tube
    t, _ = SHAPES["torus"].intersect(o[1:2] * [5 / 3, 1, 1], d[1:2])
    assert t[0] == pytest.approx(1.0 - np.sqrt(0.06**2 - 0.05**2))


MUG = """
primitives:
  - {kind: box, size: [0.3, 0.3, 0.02], xyz: [0, 0, -0.01], role: surface, surface: table}
  - kind: group
    role: object
    object: mug
    xyz: [0, 0, 0.05]
    children:
      - {kind: cup, name: body, radius: 0.04, height: 0.1, thickness: 0.004}
      - {kind: torus, name: handle, major_radius: 0.03, minor_radius: 0.006, arc_deg: 180,
         xyz: [0.038, 0, 0], rpy: [90, 0, 0]}
"""


def test_mug_scene_parses_and_samples_outside_the_wall():
    scene = parse_scene(MUG)
    assert [p.kind for p in scene.primitives] == ["box", "cup", "torus"]
    assert scene.object_names == ("mug",)
    cloud = sample_scene(scene, 40_000, seed=0)
    handle = cloud.points[cloud.primitive == 2].astype(np.float64)
    assert len(handle) > 500
    # The handle's ends are buried in the wall: no handle point inside the cup or its wall.
    assert (np.hypot(handle[:, 0], handle[:, 1]) >= 0.04 - 1e-3).all()
    # The inside of the cup is sampled: the inside bottom and the inner wall.
    body = cloud.points[cloud.primitive == 1].astype(np.float64)
    rho = np.hypot(body[:, 0], body[:, 1])
    assert ((rho < 0.036 + 1e-6) & (np.abs(body[:, 2] - 0.004) < 1e-6)).sum() > 50
    # A camera above sees into the mug; the handle blocks the wall behind it from the side.
    t, prim, _ = raycast(scene, np.array([0.0, 0.0, 1.0]), np.array([[0.0, 0.0, -1.0]]))
    assert prim[0] == 1 and 1.0 - t[0] == pytest.approx(0.004)
    t, prim, _ = raycast(scene, np.array([1.0, 0.0, 0.05]), np.array([[-1.0, 0.0, 0.0]]))
    assert prim[0] == 2 and 1.0 - t[0] == pytest.approx(0.038 + 0.036)


@pytest.mark.parametrize(
    "item, message",
    [
        ("{kind: cup, radius: 0.04, height: 0.1, thickness: 0.05, role: structure}", "thickness"),
        (
            "{kind: bowl, radius: 0.05, height: 0.05, thickness: 0.004, role: structure}",
            "base_radius",
        ),
        (
            "{kind: bowl, radius: 0.05, height: 0.05, thickness: 0.004, base_radius: 0.06, "
            "role: structure}",
            "base_radius must be",
        ),
        ("{kind: torus, major_radius: 0.01, minor_radius: 0.02, role: structure}", "minor_radius"),
        (
            "{kind: torus, major_radius: 0.03, minor_radius: 0.01, arc_deg: 0, role: structure}",
            "arc_deg",
        ),
        (
            "{kind: cup, radius: 0.04, height: 0.1, thickness: 0.004, role: surface, surface: s}",
            "surface",
        ),
    ],
)
def test_bad_vessel_sizes_name_the_line(item, message):
    with pytest.raises(SceneError, match=message) as err:
        parse_scene("primitives:\n  - {kind: box, size: [1, 1, 1], role: structure}\n  - " + item)
    assert str(err.value).startswith("<string>:3:")
