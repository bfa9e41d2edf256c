"""The unit of a cloud guessed from its size: metres never flagged, cm and mm recognised."""

import camera_views
import numpy as np
import pytest
from conftest import box_points, plane_points

from supportnode.io.units import guess_units


def _room(rng) -> np.ndarray:
    """A 4 x 4 m floor, a table and a box, points ~1.5 cm apart: metres."""
    return np.vstack(
        [
            plane_points(rng, -2, 2, -2, 2, 0.0, 60000),
            plane_points(rng, -0.6, 0.6, -0.4, 0.4, 0.75, 8000),
            box_points(rng, (0.0, 0.0, 0.85), (0.2, 0.2, 0.2), 2000),
        ]
    )


@pytest.mark.parametrize(("scale", "unit"), [(1.0, "m"), (100.0, "cm"), (1000.0, "mm")])
def test_room_in_metres_centimetres_millimetres(rng, scale, unit):
    guess = guess_units(_room(rng) * scale)
    assert guess.unit == unit
    assert guess.extent == pytest.approx(5.7 * scale, rel=0.05)
    assert guess.spacing == pytest.approx(0.01 * scale, rel=0.5)
    message = guess.message("room.ply")
    if unit == "m":
        assert message is None
    else:
        assert message.startswith(f"room.ply: looks like {unit}, not metres")
        assert f"pass --units {unit}" in message and len(message.splitlines()) == 1


def test_depth_camera_view_in_millimetres():
    cloud, _ = camera_views.tabletop(0, 45.0)
    cloud = cloud[np.isfinite(cloud).all(axis=1)]
    assert guess_units(cloud).unit == "m"  # 1.5 m across, points ~2 mm apart
    assert guess_units(cloud * 1000.0).unit == "mm"


def test_a_lidar_map_in_metres_is_not_flagged(rng):
    """400 m across, points 20 cm apart far out and denser near the sensor: metres."""
    far = np.c_[rng.uniform(-200, 200, (4000, 2)), np.zeros(4000)]
    near = np.c_[rng.uniform(-20, 20, (40000, 2)), np.zeros(40000)]
    assert guess_units(np.vstack([far, near])).unit == "m"


def test_no_plausible_unit_or_too_few_points_is_no_guess(rng):
    assert guess_units(_room(rng) * 1e-6).unit == "m"  # 6 um across: nothing fits
    assert guess_units(np.zeros((1, 3))).unit == "m"
    assert guess_units(np.zeros((500, 3))).unit == "m"  # all one point: no spacing
