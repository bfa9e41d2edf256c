"""ROS bags with their poses: /tf and /tf_static give each scan its pose in the fixed frame
(interpolated; late or missing transforms skip the scan, counted), sensor_msgs/Imu its gravity
near rest. Bags written here with rosbags' writers: a sensor driving past a table."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

rosbags = pytest.importorskip("rosbags")

from rosbags.typesys import Stores, get_typestore  # noqa: E402

from supportnode.geometry.transform import pose_matrix, quaternion_matrix  # noqa: E402
from supportnode.io.sources import open_source  # noqa: E402
from supportnode.io.tf import TfBuffer, TfError  # noqa: E402
from supportnode.node.node import Node  # noqa: E402

T0 = 100.0
SPEED = 1.0  # m/s along x
YAW_RATE = 0.3  # rad/s
LIDAR_ON_BASE = (0.2, 0.0, 1.0)
# the IMU is mounted on its side: rotated +90 deg about x from base_link
IMU_Q = (math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4))
TABLE = (3.0, 4.0, -0.5, 0.5, 0.75)  # x0, x1, y0, y1, z in odom


def _yaw_q(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


def base_pose(t: float) -> np.ndarray:
    """odom <- base_link at time t: the true (continuous) motion."""
    dt = t - T0
    return pose_matrix((SPEED * dt, 0.0, 0.0), _yaw_q(YAW_RATE * dt))


def _world_points(rng) -> np.ndarray:
    x0, x1, y0, y1, z = TABLE
    floor = np.c_[rng.uniform(-1, 6, 12000), rng.uniform(-2.5, 2.5, 12000), np.zeros(12000)]
    top = np.c_[rng.uniform(x0, x1, 5000), rng.uniform(y0, y1, 5000), np.full(5000, z)]
    return np.vstack([floor, top])


def _stamp(store, t: float):
    Time = store.types["builtin_interfaces/msg/Time"]
    sec = math.floor(t)
    return Time(sec=sec, nanosec=round((t - sec) * 1e9))


def _header(store, t: float, frame: str):
    Header = store.types["std_msgs/msg/Header"]
    kw = {"stamp": _stamp(store, t), "frame_id": frame}
    if "seq" in Header.__dataclass_fields__:
        kw["seq"] = 0
    return Header(**kw)


def _tf_message(store, t: float, parent: str, child: str, trans, quat):
    types = store.types
    return types["tf2_msgs/msg/TFMessage"](
        transforms=[
            types["geometry_msgs/msg/TransformStamped"](
                header=_header(store, t, parent),
                child_frame_id=child,
                transform=types["geometry_msgs/msg/Transform"](
                    translation=types["geometry_msgs/msg/Vector3"](*map(float, trans)),
                    rotation=types["geometry_msgs/msg/Quaternion"](*map(float, quat)),
                ),
            )
        ]
    )


def _cloud_message(store, t: float, frame: str, points: np.ndarray):
    types = store.types
    pf = types["sensor_msgs/msg/PointField"]
    data = np.ascontiguousarray(points, dtype="<f4")
    return types["sensor_msgs/msg/PointCloud2"](
        header=_header(store, t, frame),
        height=1,
        width=len(data),
        fields=[pf(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")],
        is_bigendian=False,
        point_step=12,
        row_step=12 * len(data),
        data=data.view(np.uint8).ravel(),
        is_dense=True,
    )


def _imu_message(store, t: float, accel):
    types = store.types
    v3, q = types["geometry_msgs/msg/Vector3"], types["geometry_msgs/msg/Quaternion"]
    return types["sensor_msgs/msg/Imu"](
        header=_header(store, t, "imu"),
        orientation=q(0.0, 0.0, 0.0, 1.0),
        orientation_covariance=np.zeros(9),
        angular_velocity=v3(0.0, 0.0, YAW_RATE),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=v3(*map(float, accel)),
        linear_acceleration_covariance=np.zeros(9),
    )


SCAN_TIMES = [T0 + 0.05 + 0.25 * i for i in range(6)]  # between the 10 Hz tf samples
LATE_SCAN = T0 + 2.5  # tf ends at T0 + 2.0
LOST_SCAN = T0 + 0.6  # in a frame tf does not know


def write_bag(path: Path, ros1: bool, rng) -> None:
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if ros1:  # Noetic's store lacks tf2_msgs; the bag carries the definition it is written with
        from rosbags.typesys import get_types_from_msg

        text = "geometry_msgs/TransformStamped[] transforms"
        store.register(get_types_from_msg(text, "tf2_msgs/msg/TFMessage"))
    ser = store.serialize_ros1 if ros1 else store.serialize_cdr
    writer = Writer1(path) if ros1 else Writer2(path, version=9)
    world = _world_points(rng)
    up_in_imu = quaternion_matrix(IMU_Q).T @ np.array([0.0, 0.0, 9.80665])
    with writer as w:
        kw = {"typestore": store}
        c_tf = w.add_connection("/tf", "tf2_msgs/msg/TFMessage", **kw)
        c_static = w.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", **kw)
        c_pc = w.add_connection("/points", "sensor_msgs/msg/PointCloud2", **kw)
        c_imu = w.add_connection("/imu", "sensor_msgs/msg/Imu", **kw)
        msgs: list[tuple[float, object, object, str]] = []
        static = [
            ("base_link", "lidar", LIDAR_ON_BASE, (0, 0, 0, 1)),
            ("base_link", "imu", (0, 0, 0.3), IMU_Q),
        ]
        for parent, child, tr, q in static:
            msgs.append((T0, c_static, _tf_message(store, T0, parent, child, tr, q), "tf"))
        for k in range(21):
            t = T0 + 0.1 * k
            m = base_pose(t)
            msgs.append(
                (
                    t,
                    c_tf,
                    _tf_message(
                        store, t, "odom", "base_link", m[:3, 3], _yaw_q(YAW_RATE * (t - T0))
                    ),
                    "tf",
                )
            )
        for i, t in enumerate([*SCAN_TIMES, LATE_SCAN, LOST_SCAN]):
            lidar = base_pose(t) @ pose_matrix(LIDAR_ON_BASE, (0, 0, 0, 1))
            local = (world - lidar[:3, 3]) @ lidar[:3, :3]  # odom -> lidar frame
            frame = "camera" if t == LOST_SCAN else "lidar"
            msgs.append((t, c_pc, _cloud_message(store, t, frame, local), "PointCloud2"))
            # at constant velocity the accelerometer reads g up, except once mid-run
            accel = up_in_imu * (1.3 if i == 3 else 1.0)
            msgs.append((t + 0.01, c_imu, _imu_message(store, t + 0.01, accel), "Imu"))
        for t, conn, msg, _ in sorted(msgs, key=lambda x: x[0]):
            w.write(conn, round(t * 1e9), ser(msg, conn.msgtype))


@pytest.fixture(params=["ros2", "ros1"])
def bag(request, tmp_path, rng) -> Path:
    path = tmp_path / ("run.bag" if request.param == "ros1" else "run2")
    write_bag(path, request.param == "ros1", rng)
    return path


def test_scans_get_interpolated_poses_and_imu_gravity(bag: Path) -> None:
    with open_source(bag) as src:
        assert src.topics() == {"/points": "PointCloud"}
        clouds = [m.decode() for m in src.messages()]
        skipped = dict(src.skipped)
        warnings = list(src.warnings)
    assert skipped == {"tf late": 1, "tf missing": 1}
    assert any("tf late" in w and "no transform within 0.1 s" in w for w in warnings)
    assert any("tf missing" in w and "'camera'" in w for w in warnings)
    assert [round(c.stamp, 3) for c in clouds] == [round(t, 3) for t in SCAN_TIMES]
    for i, c in enumerate(clouds):
        want = base_pose(c.stamp) @ pose_matrix(LIDAR_ON_BASE, (0, 0, 0, 1))
        got = pose_matrix(c.pose.translation, c.pose.rotation)
        # linear interpolation between 10 Hz samples of a 0.3 rad/s turn: sub-millimetre
        np.testing.assert_allclose(got, want, atol=2e-3)
        if i == 3:
            assert c.gravity is None  # |a| = 1.3 g: accelerating, no gravity reading
        else:
            np.testing.assert_allclose(c.gravity, [0, 0, -1], atol=1e-6)


def test_fixed_frame_and_tolerance_options(bag: Path) -> None:
    with open_source(bag, fixed_frame="base_link", tf_tolerance=1.0) as src:
        clouds = [m.decode() for m in src.messages()]
        assert src.skipped == {"tf missing": 1}  # the late one is within 1 s now
    np.testing.assert_allclose(clouds[0].pose.translation, LIDAR_ON_BASE, atol=1e-9)
    with open_source(bag, fixed_frame="map") as src:
        assert list(src.messages()) == []
        assert src.skipped == {"tf missing": 8}


def test_scans_land_in_the_map_where_they_belong(bag: Path) -> None:
    x0, x1, y0, y1, z = TABLE
    with open_source(bag) as src, Node() as node:
        for m in src.messages():
            out = node.process(m.decode())
        points = node.map_cloud().points
    top = points[np.abs(points[:, 2] - z) < 0.05]
    # the table stays where it is while the sensor drives 1.25 m and turns 20 degrees past it
    assert len(top) > 100
    assert top[:, 0].min() > x0 - 0.1 and top[:, 0].max() < x1 + 0.1
    assert top[:, 1].min() > y0 - 0.1 and top[:, 1].max() < y1 + 0.1
    heights = sorted(round(s.height, 2) for s in out.surfaces.surfaces)
    assert heights[-1] == pytest.approx(z, abs=0.02) and heights[0] == pytest.approx(0, abs=0.02)


def test_tf_buffer_chain_inverse_and_errors() -> None:
    tf = TfBuffer()
    tf.add("map", "odom", 0.0, (1.0, 0, 0), (0, 0, 0, 1), static=True)
    tf.add("odom", "base", 0.0, (0.0, 0, 0), _yaw_q(0.0))
    tf.add("odom", "base", 1.0, (2.0, 0, 0), _yaw_q(math.pi / 2))
    m = tf.lookup("map", "/base", 0.5, 0.1)  # ROS 1's leading slash is the same frame
    np.testing.assert_allclose(m[:3, 3], [2.0, 0, 0])
    np.testing.assert_allclose(m[:3, :3], quaternion_matrix(_yaw_q(math.pi / 4)), atol=1e-12)
    np.testing.assert_allclose(tf.lookup("base", "map", 0.5, 0.1), np.linalg.inv(m), atol=1e-12)
    np.testing.assert_allclose(tf.lookup("map", "base", 1.05, 0.1)[:3, 3], [3.1, 0, 0], atol=1e-9)
    assert tf.root("base") == "map"
    with pytest.raises(TfError) as late:
        tf.lookup("map", "base", 1.2, 0.1)
    assert late.value.reason == "tf late"
    with pytest.raises(TfError) as missing:
        tf.lookup("map", "camera", 0.5, 0.1)
    assert missing.value.reason == "tf missing"


def test_detect_on_a_bag_counts_the_skipped_scans(bag: Path, tmp_path: Path, capsys) -> None:
    import json

    from supportnode.cli import main

    out = tmp_path / "o"
    assert main(["detect", str(bag), "--out", str(out), "--no-objects"]) == 0
    printed = capsys.readouterr()
    assert "6 scans on topic '/points' (1 tf missing, 1 tf late skipped)" in printed.out
    lines = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
    assert all(x["frame_id"] == "map" for x in lines)
    for x in lines:  # in the fixed frame: the table at its height in every scan
        assert any(abs(s["height"] - TABLE[4]) < 0.02 for s in x["surfaces"])
