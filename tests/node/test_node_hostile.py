"""A hostile or broken driver against a node on real 127.0.0.1 sockets: nothing it sends ends
the node, poisons later scans, or costs a good scan its result (issue 21's six faults).

Written against the node's behaviour over sockets (scans in, results and diagnostics out),
not its internals, so that it holds through a rewrite of `supportnode.node`."""

from __future__ import annotations

import contextlib
import threading
import time

import numpy as np
import pytest
from conftest import box_points, plane_points, spinning_node

from supportnode.bus import Publisher
from supportnode.client import Diagnostics, PointCloud, Subscriber, SupportSurfaces
from supportnode.node.node import Node

SENSOR = np.array([0.0, 0.0, 1.5])
POSE = (SENSOR, np.array([0.0, 0.0, 0.0, 1.0]))
INT64_MAX = (1 << 63) - 1


def scene(n_floor: int = 8000, seed: int = 0) -> np.ndarray:
    """A 4 x 4 m floor, a table top at 0.73 m with a box on it, in the sensor frame."""
    rng = np.random.default_rng(seed)
    world = np.vstack(
        [
            plane_points(rng, -2, 2, -2, 2, 0.0, n_floor),
            plane_points(rng, -0.5, 0.5, -0.35, 0.35, 0.73, max(2500, n_floor // 3)),
            box_points(rng, (0.1, 0.0, 0.83), (0.2, 0.2, 0.2), 800),
        ]
    )
    return world - SENSOR


def frames(points, stamp, seq=0, **kw):
    """The wire frames of a scan (posed at SENSOR unless ``pose`` is given)."""
    kw.setdefault("pose", POSE)
    return PointCloud.from_xyz(points, stamp, "lidar", seq, **kw).encode("scan")


class Driver:
    """The scan publisher (binds, as a driver does) and a subscriber of the node's results."""

    def __init__(self, node: Node, pub: Publisher, sub: Subscriber, thread: threading.Thread):
        self.node, self.pub, self.sub, self.thread = node, pub, sub, thread
        self.surfaces: dict[float, SupportSurfaces] = {}
        self.diagnostics: list[Diagnostics] = []
        self.points = scene()

    def send(self, f) -> None:
        self.pub.send(f)

    def good(self, stamp: float, seq: int = 0, **kw) -> None:
        self.send(frames(self.points, stamp, seq, **kw))

    def _take(self, timeout: float) -> None:
        msg = self.sub.recv(timeout)
        if isinstance(msg, SupportSurfaces):
            self.surfaces[msg.stamp] = msg
        elif isinstance(msg, Diagnostics):
            self.diagnostics.append(msg)

    def result(self, stamp: float, timeout: float = 15.0) -> SupportSurfaces | None:
        """The surfaces published for the scan stamped ``stamp``, or None after ``timeout``."""
        deadline = time.monotonic() + timeout
        while stamp not in self.surfaces and time.monotonic() < deadline:
            self._take(0.05)
        return self.surfaces.get(stamp)

    def good_result(self, stamp: float, seq: int = 0, **kw) -> SupportSurfaces | None:
        self.good(stamp, seq, **kw)
        return self.result(stamp)

    def fresh_diagnostics(self, timeout: float = 5.0) -> Diagnostics | None:
        """The first Diagnostics published from now on."""
        seen = len(self.diagnostics)
        deadline = time.monotonic() + timeout
        while len(self.diagnostics) == seen and time.monotonic() < deadline:
            self._take(0.05)
        return self.diagnostics[-1] if len(self.diagnostics) > seen else None


@contextlib.contextmanager
def hostile(**node_keys):
    """A node spinning in a thread on 127.0.0.1 (``node.*`` keys overridden) and its Driver."""
    with Publisher("tcp://127.0.0.1:*", hwm=1000) as pub:
        keys = {"scan_endpoint": pub.endpoint, "pub_endpoint": "tcp://127.0.0.1:*", **node_keys}
        with spinning_node(**keys) as (node, th):
            with Subscriber(["surfaces", "diagnostics"], node.pub_endpoint, keep_newest=100) as sub:
                d = Driver(node, pub, sub, th)
                assert d.fresh_diagnostics(10) is not None  # subscribed: no slow joiner
                yield d


def heights(msg: SupportSurfaces) -> list[float]:
    return sorted(round(s.height, 1) for s in msg.surfaces)


def test_any_uint64_seq_never_ends_the_node():
    """seq = 2^64 - 1 made the seq_gaps counter overflow int64, and the next diagnostics
    ended spin. Gaps are bounded now: a jump over 10^6 is a restart or wrap."""
    with hostile() as d:
        for stamp, seq in ((1.0, 1), (1.1, 2**64 - 1), (1.2, 3), (1.3, 2**63), (1.4, 2**63 + 5)):
            assert d.good_result(stamp, seq) is not None, f"seq {seq}"
        diag = d.fresh_diagnostics()
        assert diag is not None and d.thread.is_alive()
        assert diag.counters["seq_gaps"] == 4  # 2^63 + 1 .. 2^63 + 4
        assert diag.counters["seq_restarts"] == 3  # up to 2^64 - 1, back to 3, up to 2^63
        assert all(abs(v) <= INT64_MAX for v in diag.counters.values())


def test_extreme_gravity_is_rejected_and_poisons_nothing():
    """[1e308, 1e308, -1e308] and [0, 0, -1e-320] normalise to NaN: they were kept as the
    node's up and every later scan failed. Now each is a bad_gravity reject."""
    with hostile() as d:
        assert heights(d.good_result(1.0)) == [0.0, 0.7]
        d.good(1.1, gravity=[1e308, 1e308, -1e308])
        d.good(1.2, gravity=[0.0, 0.0, -1e-320])
        for stamp in (1.3, 1.4):
            got = d.good_result(stamp)
            assert got is not None and heights(got) == [0.0, 0.7]
        diag = d.fresh_diagnostics()
        assert diag.counters["rejected_bad_gravity"] == 2
        assert 1.1 not in d.surfaces and 1.2 not in d.surfaces
        assert diag.gauges["gravity_tilt_deg"] == 0.0


def test_one_sideways_gravity_is_an_outlier_not_the_map_up():
    """One scan saying gravity pulls along +x made every later scan come out with 0
    surfaces. A scan's gravity is an observation of the map's one up: a lone one that
    disagrees is counted, not adopted; an up that agreeing scans set is not moved by it."""
    with hostile() as d:
        assert heights(d.good_result(1.0)) == [0.0, 0.7]
        # processed (awaited: a scan sent right behind it could take its place in the queue)
        assert heights(d.good_result(1.1, gravity=[9.8, 0.0, 0.0])) == [0.0, 0.7]
        assert heights(d.good_result(1.2)) == [0.0, 0.7]
        diag = d.fresh_diagnostics()
        assert diag.counters["gravity_outliers"] == 1
        assert diag.gauges["gravity_source"] == 0.0  # none: still the assumed +z
        # three scans that agree set the up; a sideways one then is rejected
        level = [0.0, 0.05, -9.8]  # 0.3 deg off +z
        for i in range(3):
            d.good_result(2.0 + 0.1 * i, gravity=level)
        assert d.good_result(2.5, gravity=[0.0, -9.8, 0.0]) is not None
        got = d.good_result(2.6, gravity=level)
        assert got is not None and heights(got) == [0.0, 0.7]
        diag = d.fresh_diagnostics()
        assert diag.gauges["gravity_source"] == 1.0  # given
        assert diag.gauges["gravity_tilt_deg"] == pytest.approx(0.29, abs=0.05)
        assert diag.counters["gravity_outliers"] == 2


BAD_MESSAGES = {
    "malformed": lambda p: [b"scan", b"\xc1 not msgpack"],
    "all_nonfinite": lambda p: frames(np.full((500, 3), np.nan), 9.0),
    "empty": lambda p: frames(np.zeros((0, 3)), 9.0),
    "bad_gravity": lambda p: frames(p, 9.0, gravity=[1e308, 1e308, -1e308]),
    "stamp_jump": lambda p: frames(p, 1e9),
    "out_of_range": lambda p: frames(p, 9.0, pose=([1e300, 0, 0], [0, 0, 0, 1])),
}


@pytest.mark.parametrize("reason", list(BAD_MESSAGES))
def test_a_bad_message_never_pushes_a_good_scan_out_of_the_queue(reason):
    """A good scan G waits in the newest-scans queue while the node merges a big scan; a bad
    message B arrives right after G. Every reject is decided before the queue, so G keeps its
    place and gets its result (an all-NaN or 0-point B used to take it, being rejected only
    after the queue)."""
    big = scene(600_000, seed=1)
    with hostile() as d:
        assert d.good_result(1.0) is not None
        for k in range(3):
            stamp = 2.0 + k
            d.send(frames(big, stamp - 0.5))  # keeps the receiving thread busy
            d.good(stamp)
            d.send(BAD_MESSAGES[reason](d.points))
            assert d.result(stamp) is not None, f"round {k}: the good scan lost its place"
        assert d.good_result(9.5) is not None  # after the last bad message: it was counted
        diag = d.fresh_diagnostics()
        assert diag.counters[f"rejected_{reason}"] == 3
        assert diag.counters["time_jumps"] == 0


def test_stamp_jumps_are_rejected_unless_the_source_really_restarted():
    """A far-future stamp made the next good scan reset the map, alternating stamps reset it
    on every scan. Now a jump beyond node.max_stamp_jump is a stamp_jump reject, and only a
    new timeline that a second scan continues (a restarted driver) resets the map."""
    with hostile() as d:
        first = d.good_result(10.0)
        assert first is not None and heights(first) == [0.0, 0.7]
        d.good(1e9)  # one far-future stamp
        for i in range(4):  # then alternating: two clocks on one topic
            assert d.good_result(10.1 + 0.1 * i) is not None
            d.good(1e9 + 0.1 * (i + 1) + 100.0 * i)
        assert d.good_result(10.45) is not None  # after the last far one: it was counted
        diag = d.fresh_diagnostics()
        assert diag.counters["time_jumps"] == 0  # no reset
        assert diag.counters["rejected_stamp_jump"] == 5
        # a burst of far-future stamps among the real scans: still no new timeline
        for i in range(3):
            d.good(2e9 + 0.1 * i)
        assert d.good_result(10.5) is not None
        # the driver restarts (quiet for a second): stamps start over; the second scan on the
        # new timeline confirms it
        time.sleep(1.1)
        d.good(0.5)
        assert d.good_result(0.6) is not None
        diag = d.fresh_diagnostics()
        assert diag.counters["time_jumps"] == 1 and diag.counters["rejected_stamp_jump"] == 9
        assert diag.counters["stamp_restarts"] == 1


def test_translation_beyond_the_map_range_is_rejected():
    """A 1e300 translation (finite) would overflow the map's voxel keys."""
    with hostile() as d:
        assert d.good_result(1.0) is not None
        d.good(1.1, pose=([1e300, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]))
        d.good(1.2, pose=([0.0, 2e5, 1.5], [0.0, 0.0, 0.0, 1.0]))  # beyond +-105 km
        assert heights(d.good_result(1.3)) == [0.0, 0.7]
        diag = d.fresh_diagnostics()
        assert diag.counters["rejected_out_of_range"] == 2


def test_no_error_while_publishing_diagnostics_ends_spin(monkeypatch):
    """Whatever goes wrong while encoding or sending diagnostics is counted and logged; the
    node goes on with scans and the next diagnostics."""
    calls = {"n": 0}
    encode = Diagnostics.encode

    def flaky(self, topic):
        calls["n"] += 1
        if calls["n"] in (3, 4):
            raise RuntimeError("diagnostics bug")
        return encode(self, topic)

    monkeypatch.setattr(Diagnostics, "encode", flaky)
    with hostile() as d:
        deadline = time.monotonic() + 10
        while calls["n"] < 5 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert d.good_result(1.0) is not None and d.thread.is_alive()
        diag = d.fresh_diagnostics()
        assert diag is not None and diag.counters["diagnostics_failures"] == 2


def test_internal_errors_are_logged_rate_limited(monkeypatch, caplog):
    """A bug hit by every scan logs one line (with its traceback) per reject_log_period,
    not one per scan; each is still counted."""
    from supportnode.map import store as node_map

    def broken(self, *a, **kw):
        raise RuntimeError("map bug")

    monkeypatch.setattr(node_map.VoxelMap, "merge", broken)
    with caplog.at_level("WARNING", logger="supportnode.node"), hostile() as d:
        for i in range(20):
            d.good(1.0 + 0.1 * i)
            time.sleep(0.05)
        deadline = time.monotonic() + 10
        c = d.fresh_diagnostics().counters
        while c["scans_received"] < 20 and time.monotonic() < deadline:
            c = d.fresh_diagnostics().counters
    lines = [r for r in caplog.records if "internal error" in r.getMessage()]
    # each scan counted once: a failed merge, or dropped for a newer one while one failed
    assert c["scans_received"] == 20
    assert c["rejected_internal_error"] + c["scans_dropped"] == 20
    assert c["rejected_internal_error"] >= 10
    assert len(lines) == 1 and lines[0].exc_info is not None
