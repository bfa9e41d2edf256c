"""Node keys that no other test sets: the topic names and the gravity fusion's angle and vote.
(tests/config/test_config_keys.py lists, for every key of config/default.yaml, what shows it matters.)"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest
from conftest import plane_points, spinning_node

from supportnode.client import Publisher, Subscriber, pose_from_matrix
from supportnode.msgs import PointCloud
from supportnode.node.gravity import Gravity, Verdict
from supportnode.node.node import Node
from supportnode.params import DetectParams


def _params(**node_keys) -> DetectParams:
    p = DetectParams()
    return dataclasses.replace(p, node=dataclasses.replace(p.node, **node_keys))


def _tilted(deg: float, seq: int) -> PointCloud:
    """A scan whose gravity is tilted ``deg`` from -z about x."""
    a = math.radians(deg)
    return PointCloud.from_xyz(
        np.zeros((1, 3)),
        float(seq),
        "lidar",
        seq=seq,
        gravity=(0.0, 9.8 * math.sin(a), -9.8 * math.cos(a)),
    )


def _verdicts(gravity: Gravity, deg: float, n: int) -> list[Verdict]:
    return [gravity.update(_tilted(deg, i + 1), np.eye(3), np.zeros((0, 3))) for i in range(n)]


def test_gravity_max_angle_decides_what_is_an_outlier() -> None:
    # 20 deg from the assumed +z: beyond 15 deg an outlier (still voting), within 30 pending
    assert _verdicts(Gravity(_params(gravity_max_angle_deg=15.0)), 20.0, 1) == [Verdict.OUTLIER]
    assert _verdicts(Gravity(_params(gravity_max_angle_deg=30.0)), 20.0, 1) == [Verdict.PENDING]


def test_gravity_min_agreeing_is_the_vote_before_adopting() -> None:
    for votes in (2, 4):
        g = Gravity(_params(gravity_min_agreeing=votes))
        verdicts = _verdicts(g, 10.0, votes)
        assert verdicts[-1] is Verdict.ADOPTED and Verdict.ADOPTED not in verdicts[:-1]
        assert g.source == "given" and g.tilt_deg == pytest.approx(10.0, abs=1e-6)


def test_topic_names_are_the_configured_ones(rng) -> None:
    names = {
        "scan_topic": "lidar/points",
        "surfaces_topic": "support/surfaces",
        "obstacles_topic": "support/obstacles",
        "diagnostics_topic": "support/diagnostics",
        "map_topic": "support/map",
    }
    floor = plane_points(rng, -2, 2, -2, 2, 0.0, 4000) + (0.0, 0.0, -1.5)
    with Publisher("tcp://127.0.0.1:*", names["scan_topic"], hwm=100) as pub:
        with spinning_node(
            scan_endpoint=pub.endpoint, pub_endpoint="tcp://127.0.0.1:*", map_period=0.2, **names
        ) as (node, _):
            topics = [v for k, v in names.items() if k != "scan_topic"] + ["surfaces", "obstacles"]
            subs = {t: Subscriber(t, node.pub_endpoint, keep_newest=10) for t in topics}
            time.sleep(0.5)  # slow joiner
            heard: set[str] = set()
            try:
                deadline = time.monotonic() + 20
                seq = 0
                while len(heard) < 4 and time.monotonic() < deadline:
                    seq += 1
                    pub.publish(PointCloud.from_xyz(floor, float(seq), "lidar", seq=seq))
                    time.sleep(0.3)
                    heard |= {t for t, sub in subs.items() if sub.recv(0.0) is not None}
            finally:
                for sub in subs.values():
                    sub.close()
    assert heard == set(topics[:4]), f"heard {sorted(heard)}"


def _posed_scan(rng, seq: int = 1) -> PointCloud:
    """A floor 1.5 m below a posed sensor (identity rotation, at z = 1.5)."""
    pose = np.eye(4)
    pose[2, 3] = 1.5
    floor = plane_points(rng, -3, 3, -3, 3, 0.0, 6000) - pose[:3, 3]
    return PointCloud.from_xyz(floor, float(seq), "lidar", seq=seq, pose=pose_from_matrix(pose))


def test_name_and_frame_id_are_what_results_and_diagnostics_say(rng) -> None:
    with Node(_params(name="left_arm_node", frame_id="odom")) as node:
        out = node.process(_posed_scan(rng))
        assert out.surfaces.frame_id == "odom" and out.obstacles.frame_id == "odom"
        assert node.diagnostics().node == "left_arm_node"


def test_map_voxel_size_and_radius_shape_the_map(rng) -> None:
    def voxels(**map_keys) -> int:
        p = DetectParams()
        node_p = dataclasses.replace(p.node, map=dataclasses.replace(p.node.map, **map_keys))
        with Node(dataclasses.replace(p, node=node_p)) as node:
            node.process(_posed_scan(rng))
            return node.map.stats()["voxels"]

    default = voxels()
    assert voxels(voxel_size=0.2) < default / 2  # coarser voxels: fewer of them
    assert voxels(radius=1.0) < default / 4  # a floor 6 m wide cropped to a 1 m radius


def test_reject_log_period_rate_limits_the_reject_lines(caplog) -> None:
    def lines(period: float) -> int:
        caplog.clear()
        with Node(_params(reject_log_period=period)) as node:
            for _ in range(5):
                node.handle([b"scan", b"not a message"])
        return sum(
            "not a message" in r.getMessage() or "reject" in r.getMessage().lower()
            for r in caplog.records
        )

    with caplog.at_level("WARNING"):
        assert lines(1000.0) == 1
        assert lines(0.0) == 5


def test_pub_bind_false_connects_to_a_forwarder_and_diagnostics_period_paces_it() -> None:
    """With ``pub_bind: false`` the node connects its results to a bound subscriber (a
    forwarder's), which hears diagnostics at ``diagnostics_period``."""
    heard = {}
    for period in (0.1, 0.5):
        with Subscriber("diagnostics", "tcp://127.0.0.1:*", bind=True, keep_newest=100) as sub:
            with spinning_node(
                pub_endpoint=sub.endpoint, pub_bind=False, diagnostics_period=period
            ):
                time.sleep(0.5)  # slow joiner
                n, end = 0, time.monotonic() + 2.0
                while time.monotonic() < end:
                    n += sub.recv(0.05) is not None
        heard[period] = n
    assert heard[0.1] >= 10 and heard[0.5] <= 6 and heard[0.1] > 2 * heard[0.5], heard
