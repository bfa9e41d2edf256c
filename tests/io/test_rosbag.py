"""PointCloud2 -> PointCloud conversion against messages serialised by rosbags, and ROS bags,
ROS 2 MCAP files as sources (all made here with the library's own writers)."""

from __future__ import annotations

import numpy as np
import pytest

rosbags = pytest.importorskip("rosbags")

from rosbags.typesys import Stores, get_typestore  # noqa: E402

from supportnode.io.rosbag import (  # noqa: E402
    DATATYPES,
    PointCloud2Error,
    deserialize_pointcloud2,
    pointcloud2_to_cloud,
)
from supportnode.io.sources import open_source  # noqa: E402
from supportnode.msgs import PointCloud, decode_any  # noqa: E402

ROS2 = get_typestore(Stores.ROS2_HUMBLE)
ROS1 = get_typestore(Stores.ROS1_NOETIC)
PC2 = "sensor_msgs/msg/PointCloud2"


def make_pc2(
    store,
    columns: dict[str, np.ndarray],
    *,
    height: int,
    width: int,
    big_endian: bool = False,
    pad: int = 0,
    row_pad: int = 0,
    stamp: tuple[int, int] = (1700000000, 500_000_000),
    frame_id: str = "os_sensor",
):
    """A PointCloud2 of ``columns`` (name -> (N,) or (N, count) array of a ROS datatype), each
    field followed by ``pad`` bytes of padding, rows padded by ``row_pad`` bytes."""
    Pc2 = store.types[PC2]
    PointField = store.types["sensor_msgs/msg/PointField"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    code_of = {v[0]: k for k, v in DATATYPES.items()}
    order = ">" if big_endian else "<"
    names, formats, offsets, fields = [], [], [], []
    offset = 0
    for name, col in columns.items():
        count = 1 if col.ndim == 1 else col.shape[1]
        code = col.dtype.str[1:]
        fields.append(PointField(name=name, offset=offset, datatype=code_of[code], count=count))
        names.append(name)
        formats.append((order + code, (count,)) if count > 1 else order + code)
        offsets.append(offset)
        offset += col.dtype.itemsize * count + pad
    point_step = offset
    layout = np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step}
    )
    rows = np.zeros((height, width), dtype=layout)
    for name, col in columns.items():
        rows[name] = col.reshape((height, width, *col.shape[1:]))
    row_step = width * point_step + row_pad
    data = np.zeros(height * row_step, dtype=np.uint8)
    raw = rows.view(np.uint8).reshape(height, width * point_step)
    for r in range(height):
        data[r * row_step : r * row_step + width * point_step] = raw[r]
    # Padding bytes hold garbage in real clouds: never read them.
    if pad or row_pad:
        mask = np.ones(height * row_step, dtype=bool)
        for r in range(height):
            for c in range(width):
                base = r * row_step + c * point_step
                for name, off in zip(names, offsets, strict=True):
                    size = layout.fields[name][0].itemsize
                    mask[base + off : base + off + size] = False
        data[mask] = 0xAB
    header_kwargs = {"stamp": Time(sec=stamp[0], nanosec=stamp[1]), "frame_id": frame_id}
    if store is ROS1:
        header_kwargs["seq"] = 42
    return Pc2(
        header=Header(**header_kwargs),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=big_endian,
        point_step=point_step,
        row_step=row_step,
        data=data,
        is_dense=False,
    )


def all_datatype_columns(n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    return {
        "x": rng.normal(size=n).astype(np.float32),
        "y": rng.normal(size=n).astype(np.float64),
        "z": rng.normal(size=n).astype(np.float32),
        "i8": rng.integers(-128, 127, n).astype(np.int8),
        "u8": rng.integers(0, 255, n).astype(np.uint8),
        "i16": rng.integers(-30000, 30000, n).astype(np.int16),
        "u16": rng.integers(0, 65535, n).astype(np.uint16),
        "i32": rng.integers(-(2**31), 2**31 - 1, n).astype(np.int32),
        "ring": rng.integers(0, 2**32 - 1, n).astype(np.uint32),
        "t": rng.normal(size=n).astype(np.float64),
        "normal": rng.normal(size=(n, 3)).astype(np.float32),  # count 3
    }


@pytest.mark.parametrize("big_endian", [False, True])
@pytest.mark.parametrize("pad,row_pad", [(0, 0), (3, 0), (1, 17)])
def test_all_datatypes_endianness_padding_via_cdr(big_endian: bool, pad: int, row_pad: int) -> None:
    rng = np.random.default_rng(1)
    cols = all_datatype_columns(24, rng)
    msg = make_pc2(ROS2, cols, height=4, width=6, big_endian=big_endian, pad=pad, row_pad=row_pad)
    back = deserialize_pointcloud2(ROS2.serialize_cdr(msg, PC2), "cdr")
    cloud = pointcloud2_to_cloud(back)
    assert cloud.frame_id == "os_sensor"
    assert cloud.stamp == pytest.approx(1700000000.5)
    assert list(cloud.fields) == list(cols)
    for name, col in cols.items():
        got = cloud.fields[name]
        assert got.dtype.str in ("|i1", "|u1") or got.dtype.str.startswith("<")
        assert got.dtype.str[1:] == col.dtype.str[1:], name
        np.testing.assert_array_equal(got, col, err_msg=name)
    # ... and it travels: the converted cloud encodes and decodes unchanged.
    again = decode_any(cloud.encode("scan"))
    assert isinstance(again, PointCloud)
    np.testing.assert_array_equal(again.fields["normal"], cols["normal"])


def test_organised_cloud_with_nans_via_ros1() -> None:
    rng = np.random.default_rng(2)
    h, w = 8, 16
    x = rng.normal(size=h * w).astype(np.float32)
    x[::5] = np.nan  # missing returns
    cols = {
        "x": x,
        "y": rng.normal(size=h * w).astype(np.float32),
        "z": rng.normal(size=h * w).astype(np.float32),
        "intensity": rng.normal(size=h * w).astype(np.float32),
        "rgb": rng.integers(0, 2**24, h * w).astype(np.uint32).view(np.float32),  # PCL packing
    }
    msg = make_pc2(ROS1, cols, height=h, width=w, pad=4)
    back = deserialize_pointcloud2(ROS1.serialize_ros1(msg, PC2), "ros1")
    cloud = pointcloud2_to_cloud(back)
    assert cloud.count == h * w and cloud.seq == 42
    np.testing.assert_array_equal(cloud.fields["x"], x)  # NaNs kept (legal on the wire)
    assert cloud.fields["rgb"].dtype.str == "<u4"
    np.testing.assert_array_equal(cloud.fields["rgb"], cols["rgb"].view(np.uint32))
    decoded = decode_any(cloud.encode("scan"))
    assert decoded.dropped_nonfinite == int(np.isnan(x).sum())


def test_unsupported_layouts_name_the_field() -> None:
    rng = np.random.default_rng(3)
    n = 4
    base = {k: rng.normal(size=n).astype(np.float32) for k in "xyz"}
    no_z = make_pc2(ROS2, {"x": base["x"], "y": base["y"]}, height=1, width=n)
    with pytest.raises(PointCloud2Error, match="no field 'z'"):
        pointcloud2_to_cloud(no_z)
    int_x = make_pc2(ROS2, {**base, "x": np.arange(n, dtype=np.int16)}, height=1, width=n)
    with pytest.raises(PointCloud2Error, match="field 'x' has datatype INT16"):
        pointcloud2_to_cloud(int_x)
    past = make_pc2(ROS2, base, height=1, width=n)
    past.fields[2].offset = past.point_step - 2
    with pytest.raises(PointCloud2Error, match=r"field 'z' at offset 10 .* past point_step 12"):
        pointcloud2_to_cloud(past)
    short = make_pc2(ROS2, base, height=2, width=2)
    short.data = short.data[:-1]
    with pytest.raises(PointCloud2Error, match="data has 47 bytes"):
        pointcloud2_to_cloud(short)
    # A bad optional field is left out with a note, not fatal.
    odd = make_pc2(ROS2, {**base, "flags": np.arange(n, dtype=np.uint8)}, height=1, width=n)
    odd.fields[3].datatype = 9
    notes: list[str] = []
    cloud = pointcloud2_to_cloud(odd, warnings=notes)
    assert "flags" not in cloud.fields
    assert notes == [
        "PointCloud2 field 'flags' left out: it has unknown datatype 9 (known: 1 INT8 .. 8 FLOAT64)"
    ]


def _clouds(n_msgs: int, store) -> list:
    rng = np.random.default_rng(4)
    out = []
    for i in range(n_msgs):
        cols = {k: rng.normal(size=32).astype(np.float32) for k in ("x", "y", "z", "intensity")}
        out.append((cols, make_pc2(store, cols, height=2, width=16, stamp=(100 + i, 0))))
    return out


def test_ros2_db3_and_ros1_bag_sources(tmp_path) -> None:
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2

    clouds2 = _clouds(3, ROS2)
    with Writer2(tmp_path / "bag2", version=9) as w:
        conn = w.add_connection("/points", PC2, typestore=ROS2)
        other = w.add_connection("/chatter", "std_msgs/msg/String", typestore=ROS2)
        for i, (_, msg) in enumerate(clouds2):
            w.write(conn, (100 + i) * 10**9, ROS2.serialize_cdr(msg, PC2))
        w.write(
            other,
            100 * 10**9,
            ROS2.serialize_cdr(ROS2.types["std_msgs/msg/String"](data="hi"), "std_msgs/msg/String"),
        )
    db3 = next((tmp_path / "bag2").glob("*.db3"))
    clouds1 = _clouds(3, ROS1)
    with Writer1(tmp_path / "run.bag") as w:
        conn = w.add_connection("/points", PC2, typestore=ROS1)
        for i, (_, msg) in enumerate(clouds1):
            w.write(conn, (100 + i) * 10**9, ROS1.serialize_ros1(msg, PC2))
    for path, clouds in (
        (tmp_path / "bag2", clouds2),
        (db3, clouds2),
        (tmp_path / "run.bag", clouds1),
    ):
        with open_source(path) as src:
            assert src.topics() == {"/points": "PointCloud"}
            msgs = list(src.messages())
            assert [m.time for m in msgs] == [100.0, 101.0, 102.0]
            for m, (cols, _) in zip(msgs, clouds, strict=True):
                cloud = m.decode()
                np.testing.assert_array_equal(cloud.fields["intensity"], cols["intensity"])
            assert [m.time for m in src.messages(start=1.0)] == [101.0, 102.0]
            if path.name == "bag2":
                assert any("'/chatter' skipped" in w for w in src.warnings)


def test_ros2_mcap_source(tmp_path) -> None:
    from mcap.writer import Writer

    clouds = _clouds(3, ROS2)
    path = tmp_path / "ros2.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        schema = w.register_schema(PC2, "ros2msg", b"# definition omitted in this test")
        ch = w.register_channel("/lidar/points", "cdr", schema)
        for i, (_, msg) in enumerate(clouds):
            w.add_message(ch, (100 + i) * 10**9, ROS2.serialize_cdr(msg, PC2), (100 + i) * 10**9)
        w.finish()
    with open_source(path) as src:
        assert src.topics() == {"/lidar/points": "PointCloud"}
        msgs = list(src.messages())
    assert len(msgs) == 3
    for m, (cols, _) in zip(msgs, clouds, strict=True):
        assert m.topic == "/lidar/points"
        np.testing.assert_array_equal(m.decode().fields["x"], cols["x"])
