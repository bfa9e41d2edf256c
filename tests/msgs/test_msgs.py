"""The wire protocol: round trips, zero-copy, every rejection a one-line ProtocolError, fuzzing."""

from __future__ import annotations

import math
import statistics
import time
import tracemalloc

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from supportnode.detection.messages import obstacles_message, surfaces_message
from supportnode.errors import ProtocolError
from supportnode.geometry.freespace import FreeSpace
from supportnode.geometry.objects import Cluster
from supportnode.geometry.surfaces import Surface
from supportnode.msgs import (
    MESSAGE_TYPES,
    SCHEMA_VERSION,
    Diagnostics,
    LatencyStats,
    Limits,
    ObstacleCluster,
    ObstacleClusters,
    PointCloud,
    Pose,
    SupportSurface,
    SupportSurfaces,
    decode_any,
    peek_header,
)

TOPIC = "scan"


# ---------------------------------------------------------------- helpers


def wire(frames):
    """Frames as a receiver sees them: independent bytes objects."""
    return [bytes(f) for f in frames]


def header_of(frames) -> dict:
    return msgpack.unpackb(bytes(frames[1]), raw=False)


def reheader(frames, change):
    """Frames with the header map changed in place by ``change(header)``."""
    h = header_of(frames)
    change(h)
    return [bytes(frames[0]), msgpack.packb(h, use_bin_type=True), *wire(frames[2:])]


def rejects(frames, *needles, limits=None, topic=TOPIC, **kw):
    """The ProtocolError that decoding ``frames`` raises: one line, naming the topic."""
    with pytest.raises(ProtocolError) as info:
        decode_any(frames, limits, **kw)
    text = str(info.value)
    assert "\n" not in text
    assert text.startswith(f"topic {topic!r}: "), text
    for needle in needles:
        assert needle in text, text
    return text


def small_cloud(n=5, dtype=np.float32, **kw) -> PointCloud:
    rng = np.random.default_rng(7)
    return PointCloud.from_xyz(rng.normal(size=(n, 3)).astype(dtype), 12.5, "lidar", seq=9, **kw)


def make_surface(sid=0, z=0.7, holes=1) -> Surface:
    outer = np.array([[0, 0], [2, 0], [2, 1], [0, 1]], dtype=np.float64) + sid
    rings = [outer] + [np.array([[0.5, 0.2], [0.6, 0.2], [0.6, 0.3]]) + sid] * holes
    return Surface(
        id=sid,
        height=z,
        area=2.0,
        centroid=np.array([1.0, 0.5, z]),
        normal=np.array([0.0, 0.6, 0.8]),
        flatness=0.004,
        bbox_min=np.array([0, 0, z]),
        bbox_max=np.array([2, 1, z]),
        outline=rings,
        point_count=1234 + sid,
        voxel_count=99,
        cells=np.zeros((0, 2), dtype=np.int64),
        cell_size=(0.05, 0.05),
    )


def make_free(sid, radius=0.3) -> FreeSpace:
    centre = np.array([1.0, 0.5]) if radius > 0 else np.full(2, np.nan)
    return FreeSpace(sid, 1.5, 0.5, centre, radius, np.zeros(2), 0.01, np.zeros((2, 2), bool))


def make_cluster(cid=0, surface_id=0) -> Cluster:
    return Cluster(
        id=cid,
        surface_id=surface_id,
        point_count=300 + cid,
        centroid=np.array([0.1, 0.2, 0.8]),
        bbox_min=np.array([0.0, 0.1, 0.73]),
        bbox_max=np.array([0.2, 0.3, 0.93]),
        obb_center=np.array([0.1, 0.2, 0.83]),
        obb_size=np.array([0.25, 0.2, 0.2]),
        obb_yaw=0.3,
        height=0.2,
        footprint=np.zeros((0, 2)),
        volume=0.008,
    )


def all_examples() -> dict[str, list]:
    """One valid encoded message of every type (frames as received)."""
    surfaces = surfaces_message(
        [make_surface(0), make_surface(1, 0.0)], [make_free(0)], 3.0, "map", 4
    )
    rng = np.random.default_rng(3)
    clusters = obstacles_message(
        [make_cluster(0), make_cluster(1, None)], 3.0, "map", 4, points=[rng.random((5, 3))] * 2
    )
    diag = Diagnostics(
        3.0,
        "supportnode",
        "warn",
        "slow",
        {"scans": 10},
        {"detect": LatencyStats(0.01, 0.05)},
        {"map_voxels": 1e5},
    )
    cloud = small_cloud(fields={"intensity": np.arange(5, dtype=np.float32)}, gravity=[0, 0, -1])
    return {
        "PointCloud": wire(cloud.encode(TOPIC)),
        "SupportSurfaces": wire(surfaces.encode(TOPIC)),
        "ObstacleClusters": wire(clusters.encode(TOPIC)),
        "Diagnostics": wire(diag.encode(TOPIC)),
    }


EXAMPLES = all_examples()


# ---------------------------------------------------------------- PointCloud round trips


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_pointcloud_round_trip_all_fields(dtype):
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(100, 3)).astype(dtype)
    extra = {
        "intensity": rng.random(100).astype(np.float32),
        "ring": rng.integers(0, 128, 100).astype(np.uint16),
        "time": rng.random(100),
        "rgb": rng.integers(0, 255, (100, 3)).astype(np.uint8),
        "label": rng.integers(-5, 5, 100).astype(np.int8),
    }
    q = np.array([0.0, 0.0, math.sin(0.2), math.cos(0.2)])
    msg = PointCloud.from_xyz(
        pts, 17.25, "os_sensor", 42, extra, pose=([1, 2, 3], q), gravity=[0.1, 0, -9.8]
    )
    msg.imu_orientation = q
    out = decode_any(wire(msg.encode(TOPIC)))
    assert isinstance(out, PointCloud)
    assert (out.stamp, out.frame_id, out.seq, out.count, out.dropped_nonfinite) == (
        17.25,
        "os_sensor",
        42,
        100,
        0,
    )
    assert list(out.fields) == ["x", "y", "z", *extra]
    for name, a in {"x": pts[:, 0], "y": pts[:, 1], "z": pts[:, 2], **extra}.items():
        assert out.fields[name].dtype == a.dtype
        assert out.fields[name].shape == a.shape
        np.testing.assert_array_equal(out.fields[name], a)
    assert out.points.dtype == np.float64 and out.points.shape == (100, 3)
    np.testing.assert_array_equal(out.points, pts.astype(np.float64))
    np.testing.assert_array_equal(out.pose.translation, [1, 2, 3])
    np.testing.assert_array_equal(out.pose.rotation, q)
    np.testing.assert_array_equal(out.gravity, [0.1, 0, -9.8])
    np.testing.assert_array_equal(out.imu_orientation, q)


def test_pointcloud_optional_parts_absent_and_empty_cloud():
    msg = PointCloud.from_xyz(np.zeros((0, 3), np.float32), 0.0, "")
    frames = msg.encode(TOPIC)
    h = header_of(frames)
    assert "pose" not in h and "gravity" not in h and "imu_orientation" not in h
    out = PointCloud.decode(wire(frames))
    assert out.count == 0 and out.pose is None and out.gravity is None
    assert out.imu_orientation is None and out.points.shape == (0, 3)
    # nil means absent, as a C++ sender may write it.
    out = decode_any(reheader(frames, lambda h: h.update(pose=None, gravity=None)))
    assert out.pose is None and out.gravity is None


def test_header_layout_is_as_documented():
    frames = small_cloud(3).encode("scan")
    h = header_of(frames)
    assert list(h)[:6] == ["type", "version", "stamp", "frame_id", "seq", "buffers"]
    assert h["type"] == "PointCloud" and h["version"] == SCHEMA_VERSION == 1
    assert h["buffers"] == [{"name": k, "dtype": "<f4", "shape": [3]} for k in "xyz"]
    assert frames[0] == b"scan" and len(frames) == 5


def test_encode_is_zero_copy_for_contiguous_little_endian():
    x = np.arange(1000, dtype="<f4")
    msg = PointCloud(1.0, "f", {"x": x, "y": x.copy(), "z": x.copy()})
    frames = msg.encode(TOPIC)
    assert isinstance(frames[2], memoryview) and frames[2].obj is x
    assert np.shares_memory(np.frombuffer(frames[2], dtype="<f4"), x)
    # And the decoder views the received frame instead of copying it.
    received = wire(frames)
    out = PointCloud.decode(received)
    assert np.shares_memory(out.fields["x"], np.frombuffer(received[2], dtype=np.uint8))


def test_big_endian_arrays_are_sent_little_endian():
    x = np.linspace(0, 1, 10).astype(">f8")
    ring = np.arange(10).astype(">u2")
    msg = PointCloud(1.0, "f", {"x": x, "y": x, "z": x, "ring": ring})
    frames = msg.encode(TOPIC)
    specs = {b["name"]: b["dtype"] for b in header_of(frames)["buffers"]}
    assert specs == {"x": "<f8", "y": "<f8", "z": "<f8", "ring": "<u2"}
    assert bytes(frames[2]) == x.astype("<f8").tobytes()
    out = PointCloud.decode(wire(frames))
    np.testing.assert_array_equal(out.fields["x"], x)
    np.testing.assert_array_equal(out.fields["ring"], ring)


def test_nonfinite_points_dropped_and_counted():
    pts = np.random.default_rng(1).random((10, 3))
    pts[[2, 5], 0] = np.nan
    pts[5, 1] = np.inf
    pts[7, 2] = -np.inf
    msg = PointCloud.from_xyz(pts, 1.0, "f", fields={"i": np.arange(10, dtype=np.int32)})
    out = PointCloud.decode(wire(msg.encode(TOPIC)))
    assert out.dropped_nonfinite == 3 and out.count == 7
    np.testing.assert_array_equal(out.fields["i"], [0, 1, 3, 4, 6, 8, 9])
    assert np.isfinite(out.points).all()
    rejects(wire(msg.encode(TOPIC)), "4 NaN/Inf values in x,y,z", drop_nonfinite=False)


def test_nan_in_other_fields_is_kept():
    msg = small_cloud(fields={"time": np.full(5, np.nan)})
    out = PointCloud.decode(wire(msg.encode(TOPIC)), drop_nonfinite=False)
    assert out.count == 5 and np.isnan(out.fields["time"]).all()


# ---------------------------------------------------------------- results round trips


def test_support_surfaces_round_trip_from_geometry():
    surfaces = [make_surface(0, holes=2), make_surface(1, 0.0, holes=0), make_surface(2, 1.1)]
    free = [make_free(0), make_free(2, radius=0.0)]  # surface 1 has no free space computed
    msg = surfaces_message(
        surfaces, free, 5.5, "map", 8, ids=[10, 11, 12], safe=[True, False, True]
    )
    frames = msg.encode("surfaces")
    assert all(b["name"] != "outline" or b["dtype"] == "<f8" for b in header_of(frames)["buffers"])
    out = decode_any(wire(frames))
    assert isinstance(out, SupportSurfaces)
    assert (out.stamp, out.frame_id, out.seq) == (5.5, "map", 8)
    assert [s.id for s in out.surfaces] == [10, 11, 12]
    assert [s.safe for s in out.surfaces] == [True, False, True]
    for got, s in zip(out.surfaces, surfaces, strict=True):
        assert got.height == s.height and got.area == s.area and got.flatness == s.flatness
        assert got.point_count == s.point_count
        np.testing.assert_array_equal(got.normal, s.normal)
        assert len(got.outline) == len(s.outline)
        for a, b in zip(got.outline, s.outline, strict=True):
            assert a.shape == b.shape and a.dtype == np.float64
            np.testing.assert_array_equal(a, b)
    a, b, c = out.surfaces
    assert a.free_area == 1.5 and a.disc_radius == 0.3
    np.testing.assert_array_equal(a.disc_center, [1.0, 0.5])
    assert math.isnan(b.free_area) and math.isnan(b.disc_radius) and np.isnan(b.disc_center).all()
    assert c.disc_radius == 0.0 and np.isnan(c.disc_center).all()


def test_support_surfaces_empty_and_float32_outline():
    out = decode_any(wire(SupportSurfaces(1.0, "map").encode("s")))
    assert out.surfaces == [] and out.frame_id == "map"
    ring = np.array([[0, 0], [1, 0], [1, 1]], np.float32)
    s = SupportSurface(3, 0.5, np.array([0, 0, 1.0]), 0.5, [ring], safe=True)
    out = decode_any(wire(SupportSurfaces(1.0, "map", 0, [s]).encode("s")))
    assert out.surfaces[0].outline[0].dtype == np.float32
    np.testing.assert_array_equal(out.surfaces[0].outline[0], ring)


def test_obstacle_clusters_round_trip_from_geometry():
    rng = np.random.default_rng(5)
    pts = [rng.random((50, 3)), rng.random((3, 3))]
    clusters = [make_cluster(0, 0), make_cluster(1, None)]
    msg = obstacles_message(
        clusters,
        2.0,
        "map",
        1,
        ids=[7, 8],
        surface_ids={0: 20},
        points=pts,
        max_points_per_cluster=10,
    )
    frames = msg.encode("obstacles")
    h = header_of(frames)
    assert {b["name"]: b["shape"] for b in h["buffers"]}["points"] == [13, 3]
    assert bytes(frames[2 + [b["name"] for b in h["buffers"]].index("surface_id")]) == (
        np.array([20, -1], "<i8").tobytes()
    )
    out = decode_any(wire(frames))
    assert [c.id for c in out.clusters] == [7, 8]
    assert [c.surface_id for c in out.clusters] == [20, None]
    for got, c in zip(out.clusters, clusters, strict=True):
        for name in ("centroid", "bbox_min", "bbox_max", "obb_center", "obb_size"):
            np.testing.assert_array_equal(getattr(got, name), getattr(c, name))
        assert (got.obb_yaw, got.height, got.point_count) == (c.obb_yaw, c.height, c.point_count)
    assert out.clusters[0].points.shape == (10, 3) and out.clusters[0].points.dtype == np.float32
    np.testing.assert_array_equal(out.clusters[0].points[[0, -1]], pts[0][[0, -1]].astype("f4"))
    np.testing.assert_array_equal(out.clusters[1].points, pts[1].astype(np.float32))


def test_old_from_detection_names_give_the_same_frames():
    # The node's call sites (SupportSurfaces/ObstacleClusters.from_detection) keep working.
    s, free = [make_surface(0), make_surface(1)], [make_free(1)]
    new = surfaces_message(s, free, 1.0, "map", 2, ids=[9, 8], safe=[True, False])
    old = SupportSurfaces.from_detection(s, free, 1.0, "map", 2, ids=[9, 8], safe=[True, False])
    assert [bytes(f) for f in new.encode("s")] == [bytes(f) for f in old.encode("s")]
    c = [make_cluster(0, 1), make_cluster(1, None)]
    new = obstacles_message(c, 1.0, "map", surface_ids={1: 8})
    old = ObstacleClusters.from_detection(c, 1.0, "map", surface_ids={1: 8})
    assert [bytes(f) for f in new.encode("o")] == [bytes(f) for f in old.encode("o")]


def test_obstacle_clusters_without_points_and_empty():
    frames = obstacles_message([make_cluster()], 1.0, "map").encode("o")
    names = [b["name"] for b in header_of(frames)["buffers"]]
    assert "points" not in names and "point_offsets" not in names
    out = decode_any(wire(frames))
    assert out.clusters[0].points is None and out.clusters[0].surface_id == 0
    assert decode_any(wire(ObstacleClusters(1.0, "map").encode("o"))).clusters == []


def test_diagnostics_round_trip():
    msg = Diagnostics(
        9.0,
        "node-a",
        "error",
        "scan topic silent",
        counters={"scans": 12, "rejected": 0},
        latencies={"decode": LatencyStats(0.001, 0.004), "detect": LatencyStats(0.05, 0.2)},
        gauges={"map_voxels": 1234.0, "rate_hz": 9.5},
        seq=3,
    )
    frames = msg.encode("diagnostics")
    assert len(frames) == 2 and header_of(frames)["buffers"] == []
    out = decode_any(wire(frames))
    assert isinstance(out, Diagnostics)
    for name in ("stamp", "node", "level", "message", "counters", "latencies", "gauges", "seq"):
        assert getattr(out, name) == getattr(msg, name)
    empty = decode_any(wire(Diagnostics(1.0, "n").encode("d")))
    assert (empty.counters, empty.latencies, empty.gauges, empty.level) == ({}, {}, {}, "ok")


def test_peek_header_and_dispatch():
    for type_name, frames in EXAMPLES.items():
        h = peek_header(frames)
        assert (h.topic, h.type, h.version, h.stamp) == (TOPIC, type_name, 1, h.stamp)
        assert len(h.buffers) == len(frames) - 2
        assert type(decode_any(frames)) is MESSAGE_TYPES[type_name]
    with pytest.raises(ProtocolError, match="expected a SupportSurfaces message, got PointCloud"):
        SupportSurfaces.decode(EXAMPLES["PointCloud"])


def test_unknown_keys_and_buffers_are_ignored():
    frames = EXAMPLES["SupportSurfaces"]
    h = header_of(frames)
    h["future_key"] = {"anything": [1, 2]}
    h["buffers"].append({"name": "future", "dtype": "<f4", "shape": [2]})
    out = decode_any([frames[0], msgpack.packb(h), *frames[2:], bytes(8)])
    assert len(out.surfaces) == 2


# ---------------------------------------------------------------- rejections


def pc_frames(**kw):
    return EXAMPLES["PointCloud"] if not kw else wire(small_cloud(**kw).encode(TOPIC))


def set_buffer(i, **spec):
    return lambda h: h["buffers"][i].update(spec)


FRAMING_CASES = {
    "buffer too short": (
        lambda f: [*f[:2], f[2][:-4], *f[3:]],
        "buffer 'x' has 16 bytes, header says (5,) '<f4' = 20",
    ),
    "buffer too long": (
        lambda f: [*f[:2], f[2] + b"\0" * 4, *f[3:]],
        "buffer 'x' has 24 bytes, header says (5,) '<f4' = 20",
    ),
    "one frame": (lambda f: f[:1], "message has 1 frame(s)"),
    "missing buffer frame": (lambda f: f[:-1], "header lists 4 buffers, message has 3"),
    "extra buffer frame": (lambda f: [*f, b""], "header lists 4 buffers, message has 5"),
    "header not a map": (lambda f: [f[0], msgpack.packb([1, 2]), *f[2:]], "must be a msgpack map"),
    "header garbage": (lambda f: [f[0], b"\xc1\xff\x00", *f[2:]], "header is not valid msgpack"),
    "header empty": (lambda f: [f[0], b"", *f[2:]], "header is not valid msgpack"),
    "header trailing bytes": (lambda f: [f[0], f[1] + b"\x01", *f[2:]], "not valid msgpack"),
    "header int keys": (lambda f: [f[0], msgpack.packb({1: 2}), *f[2:]], "not valid msgpack"),
    "header ext type": (
        lambda f: [f[0], msgpack.packb({"type": msgpack.ExtType(5, b"abc")}), *f[2:]],
        "not valid msgpack",
    ),
    "header bytes key": (
        lambda f: [f[0], msgpack.packb({b"type": 1}, use_bin_type=True), *f[2:]],
        "non-string key",
    ),
}


@pytest.mark.parametrize("case", FRAMING_CASES)
def test_framing_rejections(case):
    change, needle = FRAMING_CASES[case]
    rejects(change(pc_frames()), needle)


MISSING = ["type", "version", "stamp", "frame_id", "seq", "buffers"]


@pytest.mark.parametrize("key", MISSING)
def test_missing_common_key(key):
    rejects(reheader(pc_frames(), lambda h: h.pop(key)), f"header has no key '{key}'")


WRONG_TYPES = [
    ("type", 1, "'type' must be a string"),
    ("type", "Foo", "unknown message type 'Foo'"),
    ("version", "1", "'version' must be an integer"),
    ("version", True, "'version' must be an integer"),
    ("version", 7, "unsupported schema version 7 (this node speaks 1)"),
    ("version", 0, "unsupported schema version 0"),
    ("stamp", "now", "'stamp' must be a number"),
    ("stamp", None, "'stamp' must be a number, got nil"),
    ("stamp", math.nan, "'stamp' is nan"),
    ("stamp", math.inf, "'stamp' is inf"),
    ("frame_id", 3, "'frame_id' must be a string"),
    ("frame_id", b"map", "'frame_id' must be a string, got bytes"),
    ("seq", -1, "'seq' = -1 is out of range"),
    ("seq", 1.0, "'seq' must be an integer"),
    ("seq", False, "'seq' must be an integer"),
    ("buffers", {}, "'buffers' must be a list"),
    ("buffers", None, "'buffers' must be a list"),
]


@pytest.mark.parametrize(("key", "value", "needle"), WRONG_TYPES)
def test_wrong_type_for_common_key(key, value, needle):
    rejects(reheader(pc_frames(), lambda h: h.update({key: value})), needle)


def test_integer_stamp_and_huge_seq_are_accepted():
    frames = reheader(pc_frames(), lambda h: h.update(stamp=5, seq=2**64 - 1))
    out = decode_any(frames)
    assert out.stamp == 5.0 and out.seq == 2**64 - 1


BUFFER_CASES = [
    (lambda h: h["buffers"].__setitem__(0, [1]), "buffers[0] must be a map"),
    (lambda h: h["buffers"][0].pop("dtype"), "buffers[0] has no key 'dtype'"),
    (lambda h: h["buffers"][0].pop("name"), "buffers[0] has no key 'name'"),
    (lambda h: h["buffers"][0].pop("shape"), "buffers[0] has no key 'shape'"),
    (set_buffer(0, name=5), "buffers[0].name must be a string"),
    (set_buffer(0, name="x y"), "is not an identifier"),
    (set_buffer(0, name=""), "is not an identifier"),
    (set_buffer(1, name="x"), "buffer 'x' appears twice"),
    (set_buffer(0, dtype=4), "buffer 'x' dtype must be a string"),
    (set_buffer(0, dtype="float32"), "unsupported dtype 'float32'"),
    (set_buffer(0, dtype=">f4"), "unsupported dtype '>f4'"),
    (set_buffer(0, dtype="<f16"), "unsupported dtype '<f16'"),
    (set_buffer(0, dtype="|O"), "unsupported dtype '|O'"),
    (set_buffer(0, dtype="|O8"), "unsupported dtype '|O8'"),
    (set_buffer(0, dtype="|b1"), "unsupported dtype '|b1'"),
    (set_buffer(0, dtype="[('a', '<f4')]"), "unsupported dtype"),
    (set_buffer(0, dtype="|V4"), "unsupported dtype '|V4'"),
    (set_buffer(0, dtype=[["a", "<f4"]]), "dtype must be a string"),
    (set_buffer(0, shape=5), "shape must be a list of 1 to 4 integers"),
    (set_buffer(0, shape=[]), "shape must be a list of 1 to 4 integers"),
    (set_buffer(0, shape=[1, 1, 1, 1, 5]), "shape must be a list of 1 to 4 integers"),
    (set_buffer(0, shape=[-5]), "shape[0] = -5 is out of range"),
    (set_buffer(0, shape=["5"]), "shape[0] must be an integer"),
    (set_buffer(0, shape=[2**63 - 1]), "header says (9223372036854775807,) '<f4' = "),
    (set_buffer(0, shape=[2**62, 2**62]), "buffer 'x' has 20 bytes"),
    (set_buffer(0, shape=[2**64 - 1]), "is out of range"),
    (set_buffer(0, dtype="<f8", shape=[5]), "buffer 'x' has 20 bytes, header says (5,) '<f8' = 40"),
]


@pytest.mark.parametrize(("change", "needle"), BUFFER_CASES)
def test_bad_buffer_specs(change, needle):
    rejects(reheader(pc_frames(), change), needle)


def test_wrong_dtype_for_xyz_and_mismatched_lengths():
    f = pc_frames()
    x = np.frombuffer(f[2], "<f4").astype("<i4").tobytes()
    as_int = reheader([*f[:2], x, *f[3:]], set_buffer(0, dtype="<i4"))
    rejects(as_int, "buffer 'x' has dtype '<i4', expected '<f4' or '<f8'")
    # intensity with 4 rows for 5 points
    f2 = reheader(f, set_buffer(3, shape=[4]))
    rejects([*f2[:5], f2[5][:16]], "buffer 'intensity' has 4 rows, expected 5")
    f3 = reheader(f, set_buffer(2, shape=[4]))
    rejects([*f3[:4], f3[4][:16], *f3[5:]], "buffer 'z' has 4 rows, expected 5")
    rejects(reheader(f, lambda h: h["buffers"][0].update(name="xx")), "missing buffer 'x'")


def test_limits():
    f = pc_frames()
    rejects(f, "5 points exceeds max_points 4", limits=Limits(max_points=4))
    rejects(f, "exceeds max_message_bytes 100", limits=Limits(max_message_bytes=100))
    rejects(f, "exceeds max_header_bytes 50", limits=Limits(max_header_bytes=50))
    rejects(f, "4 buffer frames exceed max_buffers 3", limits=Limits(max_buffers=3))
    many = reheader(
        f,
        lambda h: h["buffers"].extend(
            {"name": f"f{i}", "dtype": "|u1", "shape": [5]} for i in range(61)
        ),
    )
    rejects([*many, *[bytes(5)] * 61], "65 buffer frames exceed max_buffers 64")
    s = EXAMPLES["SupportSurfaces"]
    rejects(s, "2 surfaces exceeds max_surfaces 1", limits=Limits(max_surfaces=1))
    rejects(
        s, "outline vertices exceed max_polygon_vertices 10", limits=Limits(max_polygon_vertices=10)
    )
    c = EXAMPLES["ObstacleClusters"]
    rejects(c, "2 clusters exceeds max_clusters 1", limits=Limits(max_clusters=1))
    rejects(c, "10 cluster points exceeds max_points 9", limits=Limits(max_points=9))
    with pytest.raises(Exception, match="max_points must be a positive integer"):
        Limits(max_points=0)


def test_huge_point_count_fails_fast_without_allocating():
    """A 3,000,000-point header with tiny frames, and a real one over the limit."""
    f = pc_frames()
    lie = reheader(f, lambda h: [b.update(shape=[3_000_000]) for b in h["buffers"]])
    tracemalloc.start()
    t0 = time.perf_counter()
    rejects(lie, "buffer 'x' has 20 bytes, header says (3000000,) '<f4' = 12000000")
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 1_000_000 and time.perf_counter() - t0 < 0.5
    big = PointCloud(0.0, "f", {k: np.zeros(3_000_000, np.float32) for k in "xyz"})
    rejects(
        wire(big.encode(TOPIC)),
        "3000000 points exceeds max_points 2000000",
        limits=Limits(max_points=2_000_000),
    )


POSE_CASES = [
    (
        {"pose": {"translation": [0, math.nan, 0], "rotation": [0, 0, 0, 1]}},
        "pose.translation[1] is nan",
    ),
    (
        {"pose": {"translation": [0, 0, 0], "rotation": [0, 0, math.inf, 1]}},
        "pose.rotation[2] is inf",
    ),
    ({"pose": {"translation": [0, 0, 0], "rotation": [0, 0, 0, 2]}}, "pose.rotation has norm 2"),
    (
        {"pose": {"translation": [0, 0], "rotation": [0, 0, 0, 1]}},
        "must be a list of 3 numbers, got 2",
    ),
    ({"pose": {"rotation": [0, 0, 0, 1]}}, "pose has no key 'translation'"),
    ({"pose": [1, 2, 3]}, "header key 'pose' must be a map"),
    ({"gravity": [0, 0, 0]}, "has magnitude 0, not in [0.001, 1000]"),
    ({"gravity": [1e308, 1e308, -1e308]}, "has magnitude 1.73205e+308, not in [0.001, 1000]"),
    ({"gravity": [0, 0, -1e-320]}, "has magnitude 9.99989e-321, not in [0.001, 1000]"),
    ({"gravity": [0, 0, -2e3]}, "has magnitude 2000, not in [0.001, 1000]"),
    ({"gravity": [0, 0, math.nan]}, "gravity[2] is nan"),
    ({"gravity": "down"}, "gravity must be a list of 3 numbers, got str"),
    ({"imu_orientation": [0, 0, 0, 0.5]}, "imu_orientation has norm 0.5"),
    ({"imu_orientation": [0, 0, "a", 1]}, "imu_orientation[2] must be a number"),
]


@pytest.mark.parametrize(("keys", "needle"), POSE_CASES)
def test_bad_pose_gravity_imu(keys, needle):
    rejects(reheader(pc_frames(), lambda h: h.update(keys)), needle)


def test_reject_reasons_are_structured():
    """Every ProtocolError carries the reason a receiver counts it under."""
    cases = {
        "bad_gravity": reheader(pc_frames(), lambda h: h.update(gravity=[1e308, 1e308, -1e308])),
        "nonfinite": reheader(pc_frames(), lambda h: h.update(stamp=math.inf)),
        "version": reheader(pc_frames(), lambda h: h.update(version=7)),
        "malformed": [b"scan", b"\xc1"],
    }
    for reason, frames in cases.items():
        with pytest.raises(ProtocolError) as info:
            decode_any(frames)
        assert info.value.reason == reason, str(info.value)
    big = wire(PointCloud(0.0, "f", {k: np.zeros(30, np.float32) for k in "xyz"}).encode(TOPIC))
    with pytest.raises(ProtocolError) as info:
        decode_any(big, Limits(max_points=10))
    assert info.value.reason == "too_many_points"
    # good gravities of any unit pass: m/s^2, g, a unit vector
    for g in ([0, 0, -9.81], [0, 0, -1.0], [0.001, 0, 0]):
        out = decode_any(reheader(pc_frames(), lambda h, g=g: h.update(gravity=g)))
        np.testing.assert_array_equal(out.gravity, g)


def test_bad_topic_and_frames():
    f = pc_frames()
    with pytest.raises(ProtocolError, match="topic is not UTF-8"):
        decode_any([b"\xffscan", *f[1:]])
    with pytest.raises(ProtocolError, match="must be a list of frames"):
        decode_any(b"scan")
    with pytest.raises(ProtocolError, match="frame 2 is a int, not bytes"):
        decode_any([*f[:2], 5])
    with pytest.raises(ProtocolError, match="topic has 300 bytes"):
        decode_any([b"t" * 300, *f[1:]])
    with pytest.raises(ProtocolError, match="message has 0 frame"):
        decode_any([])


def buffer_index(frames, name):
    return 2 + [b["name"] for b in header_of(frames)["buffers"]].index(name)


def replace_buffer(frames, name, array):
    """Frames with buffer ``name`` replaced by ``array`` (header updated to match)."""
    a = np.ascontiguousarray(array)
    i = buffer_index(frames, name)
    out = reheader(frames, set_buffer(i - 2, dtype=a.dtype.str, shape=list(a.shape)))
    out[i] = a.tobytes()
    return out


SURFACE_CASES = [
    ("id", np.array([1, 1], "<i8"), "duplicate ids"),
    ("id", np.array([1, 2], "<i4"), "buffer 'id' has dtype '<i4', expected '<i8'"),
    ("height", np.array([0.0, np.nan]), "1 NaN/Inf values in height"),
    ("height", np.array([0.0]), "buffer 'height' has 1 rows, expected 2"),
    ("normal", np.array([[0, 0, 1], [0, 0, 2.0]]), "not unit length"),
    ("normal", np.array([0, 0, 1.0, 0, 0, 1]), "buffer 'normal' has shape (6,), expected (n, 3)"),
    ("area", np.array([1.0, -1.0]), "buffer 'area' has negative values"),
    ("free_area", np.array([np.inf, 0.0]), "buffer 'free_area' has infinite values"),
    ("disc_radius", np.array([0.3, 0.3]), "disc_center is NaN where disc_radius"),
    ("safe", np.array([0, 2], "|u1"), "values other than 0 and 1"),
    ("point_count", np.array([1, -3], "<i8"), "buffer 'point_count' has negative values"),
    ("surface_rings", np.array([0, 1, 9], "<i8"), "'surface_rings' must run from 0 to 4"),
    ("surface_rings", np.array([0, 2**62, 4], "<i8"), "'surface_rings' must run from 0 to 4"),
    ("surface_rings", np.array([0, 4], "<i8"), "'surface_rings' has 2 rows, expected 3"),
    ("surface_rings", np.array([0, 4, 4], "<i8"), None),
    ("ring_offsets", np.array([0, 4, 3, 11, 14], "<i8"), "'ring_offsets' must be non-decreasing"),
    ("ring_offsets", np.array([0, 4, 7, 11, 99], "<i8"), "'ring_offsets' must run from 0 to 14"),
    ("ring_offsets", np.zeros(0, "<i8"), "'ring_offsets' is empty"),
    ("outline", np.full((14, 2), np.nan), "28 NaN/Inf values in outline"),
    ("outline", np.zeros((14, 2), "<i4"), "expected '<f4' or '<f8'"),
]


@pytest.mark.parametrize(("name", "array", "needle"), SURFACE_CASES)
def test_bad_support_surfaces(name, array, needle):
    frames = replace_buffer(EXAMPLES["SupportSurfaces"], name, array)
    if needle is None:  # a valid variant: all rings on the first surface
        assert [len(s.outline) for s in decode_any(frames).surfaces] == [4, 0]
    else:
        rejects(frames, needle)


def test_missing_surface_buffer():
    frames = EXAMPLES["SupportSurfaces"]
    i = buffer_index(frames, "flatness")
    cut = reheader(frames, lambda h: h["buffers"].pop(i - 2))
    rejects([*cut[:i], *cut[i + 1 :]], "missing buffer 'flatness'")


CLUSTER_CASES = [
    ("surface_id", np.array([0, -2], "<i8"), "values below -1"),
    ("bbox_max", np.zeros((2, 3)), "bbox_min exceeds bbox_max"),
    ("obb_size", np.array([[1, 1, -1.0], [1, 1, 1]]), "buffer 'obb_size' has negative values"),
    ("centroid", np.full((2, 3), np.inf), "6 NaN/Inf values in centroid"),
    ("obb_yaw", np.array([0.0, np.nan]), "1 NaN/Inf values in obb_yaw"),
    ("points", np.full((10, 3), np.nan, "<f4"), "30 NaN/Inf values in points"),
    ("points", np.zeros((10, 2), "<f4"), "buffer 'points' has shape (10, 2), expected (n, 3)"),
    ("point_offsets", np.array([0, 5, 11], "<i8"), "'point_offsets' must run from 0 to 10"),
    ("point_offsets", np.array([0, 5], "<i8"), "'point_offsets' has 2 rows, expected 3"),
]


@pytest.mark.parametrize(("name", "array", "needle"), CLUSTER_CASES)
def test_bad_obstacle_clusters(name, array, needle):
    rejects(replace_buffer(EXAMPLES["ObstacleClusters"], name, array), needle)


def test_cluster_points_need_offsets():
    frames = EXAMPLES["ObstacleClusters"]
    i = buffer_index(frames, "point_offsets")
    cut = reheader(frames, lambda h: h["buffers"].pop(i - 2))
    rejects([*cut[:i], *cut[i + 1 :]], "'points' and 'point_offsets' must come together")


DIAG_CASES = [
    ({"level": "fatal"}, "level 'fatal' is not one of ok, warn, error"),
    ({"node": None}, "header key 'node' must be a string, got nil"),
    ({"message": 3}, "header key 'message' must be a string"),
    ({"counters": {"a": 1.5}}, "counters['a'] must be an integer"),
    ({"counters": {"a": 2**64 - 1}}, "counters['a'] = 18446744073709551615 is out of range"),
    ({"counters": [1]}, "header key 'counters' must be a map"),
    ({"gauges": {"g": math.nan}}, "gauges['g'] is nan"),
    ({"gauges": {"g": "x"}}, "gauges['g'] must be a number"),
    ({"latencies": {"s": {"p50": 0.1}}}, "latencies['s'] has no key 'p99'"),
    ({"latencies": {"s": {"p50": -0.1, "p99": 1}}}, "latencies['s'].p50 = -0.1 must be >= 0"),
    ({"latencies": {"s": 0.1}}, "latencies['s'] must be a map"),
]


@pytest.mark.parametrize(("keys", "needle"), DIAG_CASES)
def test_bad_diagnostics(keys, needle):
    rejects(reheader(EXAMPLES["Diagnostics"], lambda h: h.update(keys)), needle)


@pytest.mark.parametrize("key", ["node", "level", "message", "counters", "latencies", "gauges"])
def test_diagnostics_missing_key(key):
    rejects(reheader(EXAMPLES["Diagnostics"], lambda h: h.pop(key)), f"has no key '{key}'")


def test_diagnostics_with_buffers_rejected():
    f = reheader(
        EXAMPLES["Diagnostics"],
        lambda h: h.update(buffers=[{"name": "a", "dtype": "|u1", "shape": [1]}]),
    )
    rejects([*f, b"\0"], "Diagnostics carries no buffers")


# ---------------------------------------------------------------- encode-side checks


def test_encode_rejects_what_receivers_would_reject():
    x = np.zeros(3, np.float32)
    cases = [
        (PointCloud(math.nan, "f", {"x": x, "y": x, "z": x}), "stamp is nan"),
        (PointCloud(0.0, "f", {"x": x, "y": x}), "without field(s) z"),
        (PointCloud(0.0, "f", {"x": x, "y": x, "z": x[:2]}), "field 'z' has shape (2,)"),
        (PointCloud(0.0, "f", {"x": x, "y": x, "z": x.astype(int)}), "must be float32 or float64"),
        (PointCloud(0.0, "f", {"x": x, "y": x, "z": x, "o": np.array([None] * 3)}), "dtype '|O'"),
        (PointCloud(0.0, "f", {"x": x, "y": x, "z": x, "b": np.ones(3, bool)}), "dtype '|b1'"),
        (
            PointCloud(0.0, "f", {"x": x, "y": x, "z": x}, pose=Pose([0, 0, 0], [0, 0, 0, 3])),
            "unit quaternion",
        ),
        (
            PointCloud(0.0, "f", {"x": x, "y": x, "z": x}, gravity=np.array([0, np.nan, 1])),
            "gravity must be 3 finite",
        ),
        (
            SupportSurfaces(
                0.0, "m", 0, [SupportSurface(1, math.nan, np.array([0, 0, 1.0]), 1.0, [])]
            ),
            "NaN/Inf values in height",
        ),
        (
            ObstacleClusters(
                0.0, "m", 0, [ObstacleCluster(1, None, *[np.zeros(2)] * 5, 0.0, 0.0, 1)]
            ),
            "'centroid' values do not form",
        ),
        (
            PointCloud(0.0, "f", {"x": x, "y": x, "z": x, "a b": x}),
            "buffer 'a b': not an identifier",
        ),
        (Diagnostics(0.0, "n", level="bad"), "level 'bad'"),
        (Diagnostics(0.0, "n", counters={"a": "many"}), "not numbers"),
    ]
    for msg, needle in cases:
        with pytest.raises(ProtocolError, match=r"^topic 'scan': cannot encode") as info:
            msg.encode(TOPIC)
        assert needle in str(info.value), str(info.value)


# ---------------------------------------------------------------- fuzzing


def only_protocol_errors(frames, limits=None):
    try:
        decode_any(frames, limits)
    except ProtocolError as err:
        assert "\n" not in str(err)


SMALL = Limits(max_points=10_000, max_message_bytes=1 << 20, max_header_bytes=1 << 16)


@settings(max_examples=300, deadline=1000, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.binary(max_size=64), min_size=0, max_size=6))
def test_fuzz_random_frames(frames):
    only_protocol_errors(frames, SMALL)


@settings(max_examples=300, deadline=1000)
@given(
    st.sampled_from(sorted(EXAMPLES)),
    st.data(),
)
def test_fuzz_byte_mutations(type_name, data):
    frames = list(EXAMPLES[type_name])
    i = data.draw(st.integers(1, len(frames) - 1))
    b = bytearray(frames[i])
    for _ in range(data.draw(st.integers(1, 4))):
        op = data.draw(st.sampled_from(["flip", "cut", "grow"]))
        if op == "flip" and b:
            k = data.draw(st.integers(0, len(b) - 1))
            b[k] = data.draw(st.integers(0, 255))
        elif op == "cut" and b:
            del b[data.draw(st.integers(0, len(b) - 1)) :]
        else:
            b += data.draw(st.binary(max_size=16))
    frames[i] = bytes(b)
    only_protocol_errors(frames, SMALL)


msgpack_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.floats()
    | st.text(max_size=8)
    | st.binary(max_size=8)
    | st.sampled_from(["<f4", "<f8", "|u1", "|O", "PointCloud", "x", "id", "ok"]),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4)
    ),
    max_leaves=12,
)


def _paths(obj, prefix=()):
    """Every (path) into nested dicts/lists of a header."""
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _paths(v, (*prefix, i))


@settings(max_examples=300, deadline=1000)
@given(st.sampled_from(sorted(EXAMPLES)), st.data())
def test_fuzz_header_value_mutations(type_name, data):
    frames = EXAMPLES[type_name]
    h = header_of(frames)
    paths = [p for p in _paths(h) if p]
    path = data.draw(st.sampled_from(paths))
    parent = h
    for k in path[:-1]:
        parent = parent[k]
    action = data.draw(st.sampled_from(["set", "delete", "shape"]))
    if action == "delete":
        del parent[path[-1]]
    elif action == "shape":
        parent[path[-1]] = data.draw(st.lists(st.integers(-(2**63), 2**64 - 1), max_size=5))
    else:
        parent[path[-1]] = data.draw(msgpack_values)
    only_protocol_errors([frames[0], msgpack.packb(h, use_bin_type=True), *frames[2:]], SMALL)


# ---------------------------------------------------------------- timing


def test_timing_131072_point_cloud():
    """Encode/decode of a 131,072-point x, y, z, intensity float32 scan: median of 20."""
    rng = np.random.default_rng(0)
    n = 131_072
    msg = PointCloud.from_xyz(
        rng.normal(size=(n, 3)).astype(np.float32),
        1.0,
        "lidar",
        fields={"intensity": rng.random(n, dtype=np.float32)},
        pose=([0, 0, 1], [0, 0, 0, 1]),
    )
    enc, dec = [], []
    for _ in range(20):
        t0 = time.perf_counter()
        frames = msg.encode(TOPIC)
        t1 = time.perf_counter()
        received = wire(frames)  # what a socket hands over: not part of either timing
        t2 = time.perf_counter()
        out = PointCloud.decode(received)
        t3 = time.perf_counter()
        enc.append(t1 - t0)
        dec.append(t3 - t2)
    assert out.count == n
    e, d = statistics.median(enc), statistics.median(dec)
    print(f"\n131072-point xyz+intensity float32: encode {e * 1e3:.3f} ms, decode {d * 1e3:.3f} ms")
    assert e < 0.05 and d < 0.05


def test_frames_survive_a_real_zmq_socket_pair():
    """encode() output goes to send_multipart(copy=False) as is; received zmq.Frames decode."""
    import zmq

    ctx = zmq.Context()
    try:
        a, b = ctx.socket(zmq.PAIR), ctx.socket(zmq.PAIR)
        a.bind("inproc://msgs-test")
        b.connect("inproc://msgs-test")
        msg = small_cloud(1000, np.float64, fields={"ring": np.zeros(1000, np.uint16)})
        a.send_multipart(msg.encode(TOPIC), copy=False)
        out = decode_any(b.recv_multipart(copy=False))
        np.testing.assert_array_equal(out.points, msg.points)
        a.close(linger=0)
        b.close(linger=0)
    finally:
        ctx.term()


def test_worked_example_in_docs_matches_the_encoder():
    """docs/protocol.md's hex dump is what the encoder writes, byte for byte."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "protocol.md").read_text()
    dump = text.split("## 10.")[1].split("```")[1]
    frames, current = [], None
    for line in dump.splitlines():
        if line.startswith("frame "):
            current = bytearray()
            frames.append(current)
        elif m := re.match(r"\s+[0-9a-f]{4}  ((?:[0-9a-f]{2} ?)+)", line):
            current += bytes.fromhex(m.group(1))
    msg = PointCloud.from_xyz(
        np.array([[1, 2, 3], [0.5, -1, 0.25], [0, 0, -2]], np.float32),
        1700000000.5,
        "lidar",
        seq=7,
        fields={"intensity": np.array([10, 200, 255], np.uint8)},
    )
    assert [bytes(f) for f in frames] == wire(msg.encode("scan"))


def test_hostile_catalogue_is_rejected_under_its_reasons():
    """`supportnode.msgs.hostile`: every message of a wire-level reason is rejected under it
    (the node-level ones decode: the node's intake rejects them, see test_node_hostile)."""
    from supportnode.msgs.hostile import rejects

    limits = Limits(max_points=1000, max_message_bytes=100_000)
    pts = np.random.default_rng(0).uniform(-1, 1, (500, 3))
    node_level = {"wrong_type", "empty", "all_nonfinite", "out_of_range", "stamp_jump"}
    for reason, messages in rejects(pts, 10.0, limits).items():
        for frames in messages:
            if reason in node_level:
                decode_any(frames, limits)
                continue
            with pytest.raises(ProtocolError) as info:
                decode_any(frames, limits)
            assert info.value.reason == reason, str(info.value)
