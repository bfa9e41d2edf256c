"""`supportnode view`: our messages in Foxglove's schemas, field by field (decoded from the
protobuf bytes the SDK encodes, with the schema the SDK ships), deletions of vanished ids, the
recording conversion read back with the mcap library, the live WebSocket server end to end
(headless: a minimal WebSocket client speaks the Foxglove protocol to it), and the one-line
error without foxglove-sdk."""

from __future__ import annotations

import base64
import json
import math
import os
import socket
import struct
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("foxglove")  # the `view` extra (also in `test`)

from supportnode.cli import main
from supportnode.client import Publisher
from supportnode.io.recording import RecordingWriter
from supportnode.msgs import (
    Diagnostics,
    LatencyStats,
    ObstacleCluster,
    ObstacleClusters,
    PointCloud,
    SupportSurface,
    SupportSurfaces,
)
from supportnode.view.foxglove_bridge import (
    Bridge,
    quaternion_from_yaw,
    scan_pointcloud,
    scan_transform,
    timestamp,
)
from supportnode.view.style import OBSTACLE_COLOR, SAFE_COLOR, UNSAFE_COLOR

# ------------------------------------------------------------ protobuf, decoded by its schema


def _varint(buf: memoryview, pos: int) -> tuple[int, int]:
    out = shift = 0
    while True:
        b = buf[pos]
        pos += 1
        out |= (b & 0x7F) << shift
        shift += 7
        if b < 0x80:
            return out, pos


def _fields(buf: Any):
    """(field number, wire type, value) of a protobuf message."""
    buf, pos = memoryview(bytes(buf)), 0
    while pos < len(buf):
        key, pos = _varint(buf, pos)
        num, wt = key >> 3, key & 7
        if wt == 0:
            v, pos = _varint(buf, pos)
        elif wt == 1:
            v, pos = buf[pos : pos + 8], pos + 8
        elif wt == 2:
            n, pos = _varint(buf, pos)
            v, pos = buf[pos : pos + n], pos + n
        elif wt == 5:
            v, pos = buf[pos : pos + 4], pos + 4
        else:
            raise ValueError(f"wire type {wt}")
        yield num, wt, v


def _descriptors(fds: bytes) -> dict[str, dict[int, dict]]:
    """Message full name -> field number -> {name, type, label, type_name}, from a
    FileDescriptorSet (itself protobuf: file=1 {package=2, message_type=4 {name=1, field=2
    {name=1, number=3, label=4, type=5, type_name=6}, nested_type=3}})."""
    out: dict[str, dict[int, dict]] = {}

    def message(prefix: str, data: Any) -> None:
        name, fields, nested = "", {}, []
        for n, _, v in _fields(data):
            if n == 1:
                name = bytes(v).decode()
            elif n == 2:
                f = {}
                for m, _, w in _fields(v):
                    key = {1: "name", 3: "number", 4: "label", 5: "type", 6: "type_name"}.get(m)
                    if key:
                        f[key] = bytes(w).decode() if key in ("name", "type_name") else w
                fields[f["number"]] = f
            elif n == 3:
                nested.append(v)
        out[f"{prefix}.{name}"] = fields
        for v in nested:
            message(f"{prefix}.{name}", v)

    for n, _, fd in _fields(fds):
        if n == 1:
            parts = list(_fields(fd))
            pkg = next((bytes(v).decode() for m, _, v in parts if m == 2), "")
            for m, _, v in parts:
                if m == 4:
                    message("." + pkg if pkg else "", v)
    return out


_FIXED = {1: "<d", 2: "<f", 6: "<Q", 7: "<I", 15: "<i", 16: "<q"}


def _decode(data: Any, type_name: str, descs: dict) -> dict[str, Any]:
    """A protobuf message as a dict (absent fields absent: proto3 omits zeros)."""
    out: dict[str, Any] = {}
    for num, wt, v in _fields(data):
        f = descs[type_name].get(num)
        if f is None:
            continue
        t = f["type"]
        if t == 11:
            vals = [_decode(v, f["type_name"], descs)]
        elif t == 9:
            vals = [bytes(v).decode()]
        elif t == 12:
            vals = [bytes(v)]
        elif t in _FIXED:
            vals = [x[0] for x in struct.iter_unpack(_FIXED[t], bytes(v))]
        elif wt == 2:  # packed varints
            vals, p = [], 0
            while p < len(v):
                x, p = _varint(v, p)
                vals.append(x)
        else:
            vals = [v]
        if f.get("label") == 3:
            out.setdefault(f["name"], []).extend(vals)
        else:
            out[f["name"]] = vals[-1]
    return out


def decoded(msg: Any) -> dict[str, Any]:
    """A foxglove message object decoded from its own encoding and schema."""
    schema = type(msg).get_schema()
    assert schema.encoding == "protobuf"
    return decode_bytes(msg.encode(), schema.name, bytes(schema.data))


def decode_bytes(data: bytes, schema_name: str, schema_data: bytes) -> dict[str, Any]:
    return _decode(data, "." + schema_name, _descriptors(schema_data))


def vec(d: dict | None, keys: str = "xyz") -> tuple[float, ...]:
    d = d or {}
    return tuple(float(d.get(k, 0.0)) for k in keys)


def rgba(d: dict) -> tuple[float, ...]:
    return vec(d, "rgba")


# ----------------------------------------------------------------------------- messages


def surfaces_msg(ids=(1, 2), stamp: float = 1000.25) -> SupportSurfaces:
    """Surface 1: safe, square 1 x 1 m at 0.7 m with a hole and a free disc; surface 2: not safe,
    triangle at 0 m, free space not computed."""
    out = []
    for i in ids:
        if i == 1:
            out.append(
                SupportSurface(
                    id=1,
                    height=0.7,
                    normal=np.array([0.0, 0.0, 1.0]),
                    area=0.96,
                    outline=[
                        np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float),
                        np.array([[0.4, 0.4], [0.4, 0.6], [0.6, 0.6], [0.6, 0.4]], float),
                    ],
                    free_area=0.8,
                    disc_center=np.array([0.25, 0.3]),
                    disc_radius=0.2,
                    safe=True,
                    point_count=500,
                )
            )
        else:
            out.append(
                SupportSurface(
                    id=i,
                    height=0.0,
                    normal=np.array([0.0, 0.0, 1.0]),
                    area=2.0,
                    outline=[np.array([[-1, -1], [1, -1], [0, 1]], float)],
                    safe=False,
                )
            )
    return SupportSurfaces(stamp=stamp, frame_id="map", seq=3, surfaces=out)


def cluster(i: int, surface_id: int | None = 1, yaw: float = 0.5, points: bool = True):
    return ObstacleCluster(
        id=i,
        surface_id=surface_id,
        centroid=np.array([0.5, 0.5, 0.8]),
        bbox_min=np.array([0.4, 0.4, 0.7]),
        bbox_max=np.array([0.6, 0.6, 0.9]),
        obb_center=np.array([0.5 + i, 0.5, 0.8]),
        obb_size=np.array([0.3, 0.2, 0.2]),
        obb_yaw=yaw,
        height=0.2,
        point_count=40,
        points=np.arange(3 * i * 3, dtype=np.float32).reshape(-1, 3) if points else None,
    )


def clusters_msg(ids=(1, 2), stamp: float = 1000.25) -> ObstacleClusters:
    cs = [cluster(i, surface_id=1 if i % 2 else None) for i in ids]
    return ObstacleClusters(stamp=stamp, frame_id="map", seq=3, clusters=cs)


def scan_msg(n: int = 200, stamp: float = 1000.25, pose: bool = True) -> PointCloud:
    rng = np.random.default_rng(n)
    return PointCloud.from_xyz(
        rng.normal(size=(n, 3)),  # float64: converted to float32 for Foxglove
        stamp=stamp,
        frame_id="lidar",
        seq=1,
        fields={
            "intensity": rng.integers(0, 255, n).astype(np.uint8),
            "rgb": rng.integers(0, 255, (n, 3)).astype(np.uint8),  # (N, 3): left out
        },
        pose=(np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.0, math.sin(0.2), math.cos(0.2)]))
        if pose
        else None,
    )


def diagnostics_msg(level: str = "warn", stamp: float = 1001.0) -> Diagnostics:
    return Diagnostics(
        stamp=stamp,
        node="supportnode",
        level=level,
        message="no scans processed yet on topic scan",
        counters={"scans_received": 7, "scans_dropped": 1},
        latencies={"total": LatencyStats(0.012, 0.031)},
        gauges={"map_voxels": 1234.0},
    )


# --------------------------------------------------------------------------- small pieces


def test_timestamp_and_quaternion_from_yaw() -> None:
    t = timestamp(1000.25)
    assert (t.sec, t.nsec) == (1000, 250_000_000)
    assert (timestamp(-3.0).sec, timestamp(-3.0).nsec) == (0, 0)  # Foxglove time is unsigned
    for yaw in (0.0, 0.5, math.pi / 2, -2.0, math.pi):
        x, y, z, w = quaternion_from_yaw(yaw)
        assert (x, y) == (0.0, 0.0)
        assert math.isclose(z * z + w * w, 1.0)
        # Rotating the x axis by the quaternion gives (cos yaw, sin yaw, 0).
        rx = (1 - 2 * z * z, 2 * z * w)
        assert rx == pytest.approx((math.cos(yaw), math.sin(yaw)), abs=1e-12)


def test_scan_becomes_a_packed_float32_point_cloud() -> None:
    cloud = scan_msg()
    d = decoded(scan_pointcloud(cloud))
    assert d["frame_id"] == "lidar"
    assert (d["timestamp"]["seconds"], d["timestamp"]["nanos"]) == (1000, 250_000_000)
    fields = {f["name"]: (f.get("offset", 0), f.get("type", 0)) for f in d["fields"]}
    # x, y, z float32 (type 7) at 0, 4, 8; intensity uint8 (type 1); the (N, 3) rgb left out.
    assert fields == {"x": (0, 7), "y": (4, 7), "z": (8, 7), "intensity": (12, 1)}
    assert d["point_stride"] == 13
    rows = np.frombuffer(
        d["data"], dtype=np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("i", "u1")])
    )
    assert len(rows) == cloud.count
    np.testing.assert_array_equal(
        np.c_[rows["x"], rows["y"], rows["z"]], cloud.points.astype(np.float32)
    )
    np.testing.assert_array_equal(rows["i"], cloud.fields["intensity"])


def test_scan_pose_becomes_a_frame_transform_from_the_map() -> None:
    d = decoded(scan_transform(scan_msg(), "map"))
    assert (d["parent_frame_id"], d["child_frame_id"]) == ("map", "lidar")
    assert vec(d["translation"]) == (1.0, 2.0, 3.0)
    assert vec(d["rotation"], "xyzw") == pytest.approx((0, 0, math.sin(0.2), math.cos(0.2)))
    assert scan_transform(scan_msg(pose=False), "map") is None


def test_surfaces_become_outlines_discs_and_labels() -> None:
    (item,) = Bridge().convert(surfaces_msg(), "surfaces")
    assert item.topic == "surfaces"
    d = decoded(item.message)
    assert "deletions" not in d
    ents = {e["id"]: e for e in d["entities"]}
    assert set(ents) == {"surface/1", "surface/2"}
    safe, unsafe = ents["surface/1"], ents["surface/2"]
    assert safe["frame_id"] == "map"
    assert (safe["timestamp"]["seconds"], safe["timestamp"]["nanos"]) == (1000, 250_000_000)
    # Both rings as closed lines (LINE_LOOP = 1) at the surface height, in the safe colour.
    assert len(safe["lines"]) == 2
    for line, ring in zip(safe["lines"], surfaces_msg().surfaces[0].outline, strict=True):
        assert line["type"] == 1
        pts = np.array([vec(p) for p in line["points"]])
        np.testing.assert_allclose(pts[:, :2], ring)
        np.testing.assert_allclose(pts[:, 2], 0.7)
        assert rgba(line["color"]) == pytest.approx(SAFE_COLOR)
    assert rgba(unsafe["lines"][0]["color"]) == pytest.approx(UNSAFE_COLOR)
    np.testing.assert_allclose([vec(p)[2] for p in unsafe["lines"][0]["points"]], 0.0)
    # The free disc: a thin cylinder centred on the disc, diameter 2r, just above the surface.
    (disc,) = safe["cylinders"]
    x, y, z = vec(disc["pose"]["position"])
    assert (x, y) == pytest.approx((0.25, 0.3)) and 0.7 < z < 0.72
    sx, sy, sz = vec(disc["size"])
    assert (sx, sy) == pytest.approx((0.4, 0.4)) and 0 < sz <= 0.02
    assert "cylinders" not in unsafe  # free space not computed: no disc
    assert safe["texts"][0]["text"] == "1  0.70 m  0.96 m²"
    assert unsafe["texts"][0]["text"] == "2  0.00 m  2.00 m²"
    meta = {kv["key"]: kv["value"] for kv in safe["metadata"]}
    assert meta["safe"] == "yes"


def test_clusters_become_oriented_boxes_with_ids() -> None:
    items = Bridge().convert(clusters_msg(), "obstacles")
    assert [i.topic for i in items] == ["obstacles", "obstacles/points"]
    ents = {e["id"]: e for e in decoded(items[0].message)["entities"]}
    assert set(ents) == {"obstacle/1", "obstacle/2"}
    (cube,) = ents["obstacle/1"]["cubes"]
    assert vec(cube["pose"]["position"]) == pytest.approx((1.5, 0.5, 0.8))
    assert vec(cube["pose"]["orientation"], "xyzw") == pytest.approx(quaternion_from_yaw(0.5))
    assert vec(cube["size"]) == pytest.approx((0.3, 0.2, 0.2))
    assert rgba(cube["color"]) == pytest.approx(OBSTACLE_COLOR)
    assert rgba(ents["obstacle/2"]["cubes"][0]["color"]) != pytest.approx(OBSTACLE_COLOR)
    assert ents["obstacle/1"]["texts"][0]["text"] == "1 on 1"
    assert ents["obstacle/2"]["texts"][0]["text"] == "2"
    label_z = vec(ents["obstacle/1"]["texts"][0]["pose"]["position"])[2]
    assert label_z > 0.9  # above the box top
    # The clusters' points with their cluster id per point.
    pc = decoded(items[1].message)
    rows = np.frombuffer(
        pc["data"], dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("cluster", "<i4")]
    )
    assert pc["point_stride"] == 16
    np.testing.assert_array_equal(rows["cluster"], [1] * 3 + [2] * 6)
    np.testing.assert_array_equal(rows["x"][3:], np.arange(18, dtype=np.float32)[::3])


def test_vanished_ids_are_deleted_per_topic() -> None:
    bridge = Bridge()

    def update(msg, topic):
        d = decoded(bridge.convert(msg, topic)[0].message)
        return (
            sorted(x["id"] for x in d.get("deletions", [])),
            sorted(e["id"] for e in d.get("entities", [])),
        )

    assert update(surfaces_msg((1, 2)), "surfaces") == ([], ["surface/1", "surface/2"])
    assert update(clusters_msg((5,)), "obstacles") == ([], ["obstacle/5"])
    assert update(surfaces_msg((2, 3)), "surfaces") == (["surface/1"], ["surface/2", "surface/3"])
    assert update(clusters_msg((6,)), "obstacles") == (["obstacle/5"], ["obstacle/6"])
    assert update(surfaces_msg(()), "surfaces") == (["surface/2", "surface/3"], [])
    assert update(surfaces_msg(()), "surfaces") == ([], [])
    # A deletion matches by id (type MATCHING_ID = 0, omitted on the wire as proto3's default).
    d = decoded(bridge.convert(surfaces_msg((7,)), "other")[0].message)
    assert "deletions" not in d
    d = decoded(bridge.convert(surfaces_msg(()), "other")[0].message)
    assert d["deletions"][0].get("type", 0) == 0 and d["deletions"][0]["id"] == "surface/7"


def test_diagnostics_become_log_and_json() -> None:
    items = Bridge().convert(diagnostics_msg("warn"), "diagnostics")
    assert [i.topic for i in items] == ["diagnostics", "diagnostics/log"]
    js = items[0].message
    assert js["counters"] == {"scans_received": 7, "scans_dropped": 1}
    assert js["latencies"]["total"] == {"p50": 0.012, "p99": 0.031}
    assert json.loads(json.dumps(js)) == js
    log = decoded(items[1].message)
    assert log["level"] == 3  # WARNING
    assert log["name"] == "supportnode"
    assert "no scans processed" in log["message"] and "scans_dropped=1" in log["message"]
    levels = [
        decoded(Bridge().convert(diagnostics_msg(lv))[1].message)["level"] for lv in ("ok", "error")
    ]
    assert levels == [2, 4]  # INFO, ERROR


# --------------------------------------------------------------------- recording -> MCAP


def write_recording(path: Path) -> dict[str, int]:
    """Scans, surfaces, obstacles and diagnostics as the node and recorder write them."""
    with RecordingWriter(path) as w:
        for i in range(4):
            t = 1000.0 + 0.1 * i
            w.write(scan_msg(stamp=t).encode("scan"), receive_time=t + 0.01)
            w.write(surfaces_msg((1, 2) if i < 2 else (2,), t).encode("surfaces"), t + 0.02)
            w.write(clusters_msg((1, 2), t).encode("obstacles"), receive_time=t + 0.03)
        w.write(diagnostics_msg(stamp=1000.5).encode("diagnostics"), receive_time=1000.5)
    return {"scan": 4, "surfaces": 4, "obstacles": 4, "diagnostics": 1}


def test_recording_converts_to_a_foxglove_mcap(tmp_path: Path, capsys) -> None:
    from mcap.reader import make_reader

    rec, out = tmp_path / "run.mcap", tmp_path / "fox.mcap"
    write_recording(rec)
    assert main(["view", str(rec), "--out", str(out)]) == 0
    assert "wrote 22 messages" in capsys.readouterr().out
    with open(out, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        channels = {c.topic: c for c in summary.channels.values()}
        schemas = {c.topic: summary.schemas[c.schema_id] for c in channels.values()}
        counts = {
            c.topic: summary.statistics.channel_message_counts[c.id] for c in channels.values()
        }
        expected = {
            "scan": ("foxglove.PointCloud", 4),
            "tf": ("foxglove.FrameTransform", 4),
            "surfaces": ("foxglove.SceneUpdate", 4),
            "obstacles": ("foxglove.SceneUpdate", 4),
            "obstacles/points": ("foxglove.PointCloud", 4),
            "diagnostics/log": ("foxglove.Log", 1),
        }
        for topic, (schema, n) in expected.items():
            assert (schemas[topic].name, schemas[topic].encoding) == (schema, "protobuf")
            assert channels[topic].message_encoding == "protobuf"
            assert counts[topic] == n
        assert channels["diagnostics"].message_encoding == "json"
        assert schemas["diagnostics"].encoding == "jsonschema"
        assert set(channels) == set(expected) | {"diagnostics"}
        # Recorded receive times are the log times; the third surfaces update deletes id 1.
        surfaces = [
            (m.log_time, m.data)
            for _, ch, m in reader.iter_messages(topics=["surfaces"])
            if ch.topic == "surfaces"
        ]
        assert [t for t, _ in surfaces] == [
            round((1000.0 + 0.1 * i + 0.02) * 1e9) for i in range(4)
        ]
        s = schemas["surfaces"]
        third = decode_bytes(surfaces[2][1], s.name, s.data)
        assert [x["id"] for x in third["deletions"]] == ["surface/1"]
        assert [e["id"] for e in third["entities"]] == ["surface/2"]
        diag = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=["diagnostics"])]
        assert diag[0]["counters"]["scans_received"] == 7


# ------------------------------------------------------------------------------ live


class WsClient:
    """Just enough of a WebSocket client (RFC 6455) and of the Foxglove protocol
    (subprotocol foxglove.sdk.v1) to subscribe to a channel and read one message."""

    def __init__(self, port: int, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while True:
            try:
                self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n"
            ).encode()
        )
        head = b""
        while b"\r\n\r\n" not in head:
            head += self._exact(1)
        assert head.startswith(b"HTTP/1.1 101"), head

    def _exact(self, n: int) -> bytes:
        out = b""
        while len(out) < n:
            chunk = self.sock.recv(n - len(out))
            if not chunk:
                raise EOFError("server closed the connection")
            out += chunk
        return out

    def frame(self) -> tuple[int, bytes]:
        """(opcode, payload): 1 text, 2 binary."""
        b0, b1 = self._exact(2)
        n = b1 & 0x7F
        if n == 126:
            n = struct.unpack(">H", self._exact(2))[0]
        elif n == 127:
            n = struct.unpack(">Q", self._exact(8))[0]
        return b0 & 0x0F, self._exact(n)

    def send_json(self, obj: Any) -> None:
        data, mask = json.dumps(obj).encode(), os.urandom(4)
        assert len(data) < 126
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(data))
        self.sock.sendall(bytes([0x81, 0x80 | len(data)]) + mask + masked)

    def close(self) -> None:
        self.sock.close()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_live_view_forwards_the_node_topics_over_websocket(capsys) -> None:
    """`view` subscribes to a publisher standing in for the node; a WebSocket client sees the
    surfaces channel advertised with Foxglove's schema and receives a SceneUpdate."""
    port, endpoint = free_port(), f"tcp://127.0.0.1:{free_port()}"
    got: dict[str, Any] = {}

    def client() -> None:
        with Publisher(endpoint, "surfaces") as pub:
            ws = WsClient(port)
            try:
                ws.sock.settimeout(0.2)
                channel, deadline = None, time.monotonic() + 8
                while time.monotonic() < deadline and "update" not in got:
                    pub.publish(surfaces_msg())  # again and again: ZeroMQ's slow joiner
                    try:
                        op, payload = ws.frame()
                    except TimeoutError:
                        continue
                    if op == 1:
                        m = json.loads(payload)
                        got.setdefault("ops", []).append(m["op"])
                        for c in m.get("channels", []) if m["op"] == "advertise" else []:
                            if c["topic"] == "surfaces":
                                channel = c
                                ws.send_json(
                                    {
                                        "op": "subscribe",
                                        "subscriptions": [{"id": 9, "channelId": c["id"]}],
                                    }
                                )
                    elif op == 2 and payload[0] == 1 and channel is not None:
                        sub_id, _log_time = struct.unpack_from("<IQ", payload, 1)
                        schema = base64.b64decode(channel["schema"])
                        got["channel"] = channel
                        got["update"] = decode_bytes(payload[13:], channel["schemaName"], schema)
                        got["sub"] = sub_id
            finally:
                ws.close()

    t = threading.Thread(target=client, daemon=True)
    t.start()
    args = ["view", "--endpoint", endpoint, "--no-scan", "--port", str(port), "--duration", "3"]
    assert main(args) == 0
    t.join(5)
    out = capsys.readouterr().out
    assert f"ds.url=ws%3A%2F%2F127.0.0.1%3A{port}" in out and f"ws://127.0.0.1:{port}" in out
    assert got["ops"][0] == "serverInfo"
    assert got["channel"]["schemaName"] == "foxglove.SceneUpdate"
    assert got["channel"]["encoding"] == "protobuf"
    assert got["sub"] == 9
    assert sorted(e["id"] for e in got["update"]["entities"]) == ["surface/1", "surface/2"]


def test_replay_serves_a_recording_and_stops(tmp_path: Path, capsys) -> None:
    rec = tmp_path / "run.mcap"
    write_recording(rec)
    argv = ["view", str(rec), "--port", "0", "--rate", "50", "--duration", "0.8"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "forwarded 22 messages" in out


# ---------------------------------------------------------------------------- errors


def test_missing_sdk_is_one_line_with_the_install_command(monkeypatch, capsys) -> None:
    for name in ("foxglove", "foxglove.channels", "foxglove.messages"):
        monkeypatch.setitem(sys.modules, name, None)  # import raises ImportError
    assert main(["view", "--duration", "0.1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "install with pip install 'supportnode[view]'" in err


def test_bad_use_is_one_line(tmp_path: Path, capsys) -> None:
    rec = tmp_path / "run.mcap"
    write_recording(rec)
    assert main(["view", "--out", str(tmp_path / "x.mcap")]) == 2
    assert "give the recording" in capsys.readouterr().err
    assert main(["view", str(rec), "--out", str(rec)]) == 2
    assert "would overwrite" in capsys.readouterr().err
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        assert main(["view", str(rec), "--port", str(port), "--duration", "0.1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"cannot serve on 127.0.0.1:{port}" in err
