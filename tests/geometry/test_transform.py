"""Pose and quaternion maths (`supportnode.geometry.transform`) against first principles."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.errors import InputError
from supportnode.geometry.transform import (
    is_rotation,
    pose_matrix,
    quaternion_from_matrix,
    quaternion_from_yaw,
    quaternion_matrix,
)
from supportnode.msgs import Pose

_unit = st.floats(-1.0, 1.0, allow_nan=False)
quaternions = st.tuples(_unit, _unit, _unit, _unit).filter(lambda q: np.linalg.norm(q) > 1e-3)


@settings(max_examples=300, deadline=None)
@given(quaternions)
def test_matrix_and_back_is_the_same_rotation(q):
    q = np.asarray(q) / np.linalg.norm(q)
    r = quaternion_matrix(q)
    assert is_rotation(r, atol=1e-9)
    back = quaternion_from_matrix(r)
    assert abs(np.linalg.norm(back) - 1.0) < 1e-12
    # q and -q are one rotation
    assert min(np.abs(back - q).max(), np.abs(back + q).max()) < 1e-9
    np.testing.assert_allclose(quaternion_matrix(back), r, atol=1e-12)


@pytest.mark.parametrize("axis", range(3))
def test_half_turns_are_exact(axis):
    # 180 degrees: the trace-only formula divides by ~0 here; Shepperd's does not.
    r = -np.eye(3)
    r[axis, axis] = 1.0
    q = quaternion_from_matrix(r)
    want = np.zeros(4)
    want[axis] = 1.0
    assert min(np.abs(q - want).max(), np.abs(q + want).max()) < 1e-12


@given(st.floats(-10.0, 10.0, allow_nan=False))
def test_yaw_turns_x_towards_y(yaw):
    x_axis = quaternion_matrix(np.array(quaternion_from_yaw(yaw))) @ [1.0, 0.0, 0.0]
    np.testing.assert_allclose(x_axis, [math.cos(yaw), math.sin(yaw), 0.0], atol=1e-12)


def test_is_rotation_rejects_what_is_not_one():
    assert is_rotation(np.eye(3))
    assert not is_rotation(np.diag([1.0, 1.0, -1.0]))  # a reflection
    assert not is_rotation(2 * np.eye(3))  # a scale
    assert not is_rotation(np.full((3, 3), np.nan))
    assert not is_rotation(np.eye(4))


def test_pose_from_matrix_round_trip_and_bad_input():
    m = pose_matrix(np.array([1.0, -2.0, 0.5]), np.array([0.1, 0.2, 0.3, 0.9]))
    pose = Pose.from_matrix(m)
    np.testing.assert_allclose(pose.matrix(), m, atol=1e-12)
    np.testing.assert_array_equal(pose.translation, [1.0, -2.0, 0.5])
    with pytest.raises(InputError, match="not a rotation"):
        Pose.from_matrix(np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(InputError, match="4x4"):
        Pose.from_matrix(np.eye(3))
    bad = m.copy()
    bad[0, 3] = np.inf
    with pytest.raises(InputError, match="finite"):
        Pose.from_matrix(bad)
