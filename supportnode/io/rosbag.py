"""ROS recordings as scan sources: sensor_msgs/PointCloud2 -> `PointCloud`, and bag reading.

`pointcloud2_to_cloud` converts any PointCloud2 layout numpy can describe: every datatype
(INT8 .. FLOAT64), ``count`` > 1 (an (N, count) field), padding between and after fields,
``row_step`` > ``width * point_step``, big- and little-endian data, organised clouds
(``height`` > 1, NaN for missing returns: kept, the wire allows them). x, y, z must be FLOAT32 or
FLOAT64 with count 1; anything else raises `PointCloud2Error` naming the field and why. Other
fields that cannot travel (unknown datatype, name not an identifier after cleaning, more than 64
elements) are left out with a warning.

Reading uses the ``rosbags`` library (pure Python, no ROS install): ROS 1 ``.bag``, ROS 2 bags
(``.db3`` or ``.mcap`` files, or a bag folder with ``metadata.yaml``) through
``rosbags.highlevel.AnyReader``, and single CDR / ROS 1 messages from other MCAP files through
its typestores. It is imported only when a ROS recording is opened.
"""

from __future__ import annotations

import os
import re
from collections.abc import Collection, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from supportnode.errors import SupportNodeError
from supportnode.msgs import PointCloud

__all__ = [
    "DATATYPES",
    "POINTCLOUD2_TYPES",
    "BagMessage",
    "PointCloud2Error",
    "RosBag",
    "RosbagError",
    "deserialize_pointcloud2",
    "pointcloud2_to_cloud",
]

#: PointField datatype -> (numpy type code without byte order, ROS name).
DATATYPES: dict[int, tuple[str, str]] = {
    1: ("i1", "INT8"),
    2: ("u1", "UINT8"),
    3: ("i2", "INT16"),
    4: ("u2", "UINT16"),
    5: ("i4", "INT32"),
    6: ("u4", "UINT32"),
    7: ("f4", "FLOAT32"),
    8: ("f8", "FLOAT64"),
}
#: Type names of PointCloud2 in ROS 2 (and rosbags) and ROS 1 spelling.
POINTCLOUD2_TYPES = frozenset({"sensor_msgs/msg/PointCloud2", "sensor_msgs/PointCloud2"})
TF_TYPES = frozenset({"tf2_msgs/msg/TFMessage", "tf2_msgs/TFMessage"})
IMU_TYPES = frozenset({"sensor_msgs/msg/Imu", "sensor_msgs/Imu"})
_MAX_COLUMNS = 64
_NOT_IDENT = re.compile(r"[^A-Za-z0-9_]")
INSTALL_HINT = "install the ROS extra: pip install 'supportnode[ros]' (or: pip install rosbags)"


class PointCloud2Error(SupportNodeError):
    """A PointCloud2 message whose layout cannot be converted (names the field and why)."""


class RosbagError(SupportNodeError):
    """A ROS bag cannot be opened or read, or rosbags is not installed."""


def _rosbags() -> Any:
    try:
        import rosbags.typesys
    except ImportError as err:
        raise RosbagError(f"reading ROS recordings needs rosbags: {INSTALL_HINT}") from err
    return rosbags


def _clean_name(name: str) -> str:
    """A C identifier for a ROS field name (``rgb.r`` -> ``rgb_r``), or "" if none can be made."""
    out = _NOT_IDENT.sub("_", name)[:64]
    if out and out[0].isdigit():
        out = "_" + out[:63]
    return "" if not out.strip("_") else out


# (ros name, our name, byte offset in the point, count, little-endian dtype code)
_Field = tuple[str, str, int, int, str]


def pointcloud2_to_cloud(
    msg: Any, *, seq: int = 0, warnings: list[str] | None = None
) -> PointCloud:
    """Convert a sensor_msgs/PointCloud2 (any object with its fields, e.g. a rosbags message)
    to a `PointCloud`: one little-endian column per field, N = height * width points in row
    order, stamp in seconds, frame_id from the header. ``seq``: used when the header has none
    (ROS 2). Fields left out are described in ``warnings`` (when given). Raises PointCloud2Error.
    """
    data = msg.data if isinstance(msg.data, np.ndarray) else np.frombuffer(msg.data, np.uint8)
    data = np.ascontiguousarray(data).view(np.uint8).reshape(-1)
    _check_layout(msg, data)
    keep = _kept_fields(list(msg.fields), int(msg.point_step), warnings)
    cols = _columns(msg, data, keep)
    header_seq = getattr(msg.header, "seq", None)
    coords = {k: cols.pop(k) for k in ("x", "y", "z")}  # x, y, z first, as on the wire
    return PointCloud(
        stamp=_seconds(msg.header.stamp),
        frame_id=str(msg.header.frame_id),
        fields={**coords, **cols},
        seq=int(header_seq) if header_seq is not None else seq,
    )


def _check_layout(msg: Any, data: np.ndarray) -> None:
    """x, y and z present; steps and the data's size consistent with height x width points."""
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    n = height * width
    names = [f.name for f in msg.fields]
    for axis in ("x", "y", "z"):
        if axis not in names:
            raise PointCloud2Error(
                f"PointCloud2 has no field '{axis}' (fields: {', '.join(names) or 'none'})"
            )
    if n and point_step <= 0:
        raise PointCloud2Error(f"PointCloud2 point_step is {point_step}")
    if n and row_step < width * point_step:
        raise PointCloud2Error(
            f"PointCloud2 row_step {row_step} is less than width {width} x point_step {point_step}"
        )
    need = row_step * (height - 1) + width * point_step if n else 0
    if data.size < need:
        raise PointCloud2Error(
            f"PointCloud2 data has {data.size} bytes, {height} rows of row_step {row_step} "
            f"need {need}"
        )


def _field_problem(f: Any, point_step: int) -> str | None:
    """Why field ``f`` cannot be converted (None: it can), before its name is considered."""
    name, offset, count = str(f.name), int(f.offset), int(f.count)
    xyz = name in ("x", "y", "z")
    kind = DATATYPES.get(int(f.datatype))
    if kind is None:
        return f"has unknown datatype {int(f.datatype)} (known: 1 INT8 .. 8 FLOAT64)"
    if xyz and kind[0] not in ("f4", "f8"):
        return f"has datatype {kind[1]}; x, y and z must be FLOAT32 or FLOAT64"
    if xyz and count != 1:
        return f"has count {count}; x, y and z must have count 1"
    if count < 1 or count > _MAX_COLUMNS:
        return f"has count {count} (1 to {_MAX_COLUMNS} supported)"
    if offset < 0 or offset + np.dtype(kind[0]).itemsize * count > point_step:
        size = np.dtype(kind[0]).itemsize * count
        return f"at offset {offset} with {size} bytes extends past point_step {point_step}"
    return None


def _kept_fields(fields: list[Any], point_step: int, warnings: list[str] | None) -> list[_Field]:
    """The fields to convert; a bad x, y or z raises, any other bad field is left out with a
    warning."""
    keep: list[_Field] = []
    seen: set[str] = set()
    for f in fields:
        name = str(f.name)
        xyz = name in ("x", "y", "z")
        problem = _field_problem(f, point_step)
        clean = name if xyz else _clean_name(name)
        if problem is None and not clean:
            problem = "has a name that is not an identifier"
        if problem is None and clean in seen:
            problem = f"is a second field named '{clean}'"
        if problem is not None:
            if xyz:
                raise PointCloud2Error(f"PointCloud2 field '{name}' {problem}")
            if warnings is not None:
                warnings.append(f"PointCloud2 field '{name}' left out: it {problem}")
            continue
        seen.add(clean)
        keep.append((name, clean, int(f.offset), int(f.count), DATATYPES[int(f.datatype)][0]))
    return keep


def _columns(msg: Any, data: np.ndarray, keep: list[_Field]) -> dict[str, np.ndarray]:
    """One little-endian column per kept field: (N,) or (N, count)."""
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    order = ">" if bool(msg.is_bigendian) else "<"
    n = height * width
    cols: dict[str, np.ndarray] = {}
    if n:
        layout = np.dtype(
            {
                "names": [k[1] for k in keep],
                "formats": [(order + k[4], (k[3],)) if k[3] > 1 else order + k[4] for k in keep],
                "offsets": [k[2] for k in keep],
                "itemsize": point_step,
            }
        )
        # One strided view of the whole buffer (rows row_step apart): no copy until the columns.
        points = np.ndarray(
            (height, width), dtype=layout, buffer=data, strides=(row_step, point_step)
        )
    for _, clean, _, count, code in keep:
        if n:
            col = np.ascontiguousarray(points[clean]).reshape((n, count) if count > 1 else (n,))
            col = col.astype(np.dtype("<" + code) if code not in ("i1", "u1") else code, copy=False)
        else:
            col = np.zeros(
                (0, count) if count > 1 else (0,), dtype=np.dtype(code).newbyteorder("<")
            )
        if clean in ("rgb", "rgba") and code == "f4" and count == 1:
            col = col.view("<u4")  # PCL packs colour bits into a float: our convention is <u4
        cols[clean] = col
    return cols


_TYPESTORES: dict[str, Any] = {}


def _typestore(encoding: str) -> Any:
    """The default ROS 2 (Humble) or ROS 1 (Noetic) typestore; PointCloud2 is the same in all."""
    if encoding not in _TYPESTORES:
        _rosbags()
        from rosbags.typesys import Stores, get_typestore

        store = Stores.ROS1_NOETIC if encoding == "ros1" else Stores.ROS2_HUMBLE
        _TYPESTORES[encoding] = get_typestore(store)
    return _TYPESTORES[encoding]


def deserialize_pointcloud2(data: bytes | memoryview, encoding: str) -> Any:
    """A PointCloud2 message from its serialised bytes: ``encoding`` "cdr" (ROS 2) or "ros1".
    Raises PointCloud2Error when the bytes are not a PointCloud2."""
    store = _typestore(encoding)
    try:
        if encoding == "ros1":
            return store.deserialize_ros1(bytes(data), "sensor_msgs/msg/PointCloud2")
        return store.deserialize_cdr(bytes(data), "sensor_msgs/msg/PointCloud2")
    except Exception as err:  # rosbags raises SerdeError, struct errors, IndexError ...
        raise PointCloud2Error(f"PointCloud2 does not deserialise ({err})") from err


@dataclass
class BagMessage:
    """One message of a bag: topic, ROS type, bag time (ns) and serialised bytes."""

    topic: str
    msgtype: str
    log_time: int
    rawdata: bytes
    connection: Any


class RosBag:
    """A ROS 1 ``.bag``, ROS 2 ``.db3``/``.mcap`` file or ROS 2 bag folder, via rosbags.

    ``topics``: topic -> (ROS type, message count). `messages` yields every message in bag-time
    order; `pointcloud` converts a PointCloud2 one.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = os.fspath(path)
        _rosbags()
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        p = Path(self.path)
        if not p.exists():
            raise RosbagError(f"{self.path}: no such file or folder")
        is_ros1 = p.suffix == ".bag"
        # ROS 2 bags from before Iron may carry no type definitions: assume Humble's.
        store = get_typestore(Stores.ROS1_NOETIC if is_ros1 else Stores.ROS2_HUMBLE)
        try:
            self._reader = AnyReader([p], default_typestore=store)
            self._reader.open()
        except Exception as err:  # AnyReaderError, sqlite errors, yaml errors, struct errors
            raise RosbagError(f"{self.path}: cannot read as a ROS bag ({_one_line(err)})") from err
        self.topics: dict[str, tuple[str, int]] = {}
        for c in self._reader.connections:
            old = self.topics.get(c.topic, (c.msgtype, 0))
            self.topics[c.topic] = (c.msgtype, old[1] + int(c.msgcount))
        self.start_time = int(self._reader.start_time) if self._reader.message_count else None
        self.end_time = int(self._reader.end_time) if self._reader.message_count else None
        self.message_count = int(self._reader.message_count)
        self.warnings: list[str] = []

    def messages(
        self,
        topics: Collection[str] | None = None,
        start: int | None = None,
        end: int | None = None,
    ) -> Iterator[BagMessage]:
        """Messages on ``topics`` (None: all) with ``start <= bag time < end`` (ns). A read error
        ends the iteration with a warning (what was read before it stands)."""
        conns = [c for c in self._reader.connections if topics is None or c.topic in topics]
        if not conns:
            return
        try:
            for c, t, raw in self._reader.messages(connections=conns, start=start, stop=end):
                yield BagMessage(c.topic, c.msgtype, int(t), raw, c)
        except Exception as err:  # truncated or corrupt bag data
            self.warnings.append(f"{self.path}: read error, stopping here ({_one_line(err)})")

    def pointcloud(
        self, m: BagMessage, seq: int = 0, warnings: list[str] | None = None
    ) -> PointCloud:
        """Convert a PointCloud2 `BagMessage`. Raises PointCloud2Error."""
        try:
            msg = self._reader.deserialize(m.rawdata, m.msgtype)
        except Exception as err:
            raise PointCloud2Error(f"PointCloud2 does not deserialise ({_one_line(err)})") from err
        return pointcloud2_to_cloud(msg, seq=seq, warnings=warnings)

    def poser(self, fixed_frame: str | None, tolerance: float) -> Any:
        """A `ScanPoser` from every tf and IMU message of the bag, or None when it has no tf."""
        from supportnode.io.posing import ImuSample, ScanPoser
        from supportnode.io.tf import TfBuffer

        tf_topics = {t for t, (typ, _) in self.topics.items() if typ in TF_TYPES}
        if not tf_topics:
            return None
        imu_topics = {t for t, (typ, _) in self.topics.items() if typ in IMU_TYPES}
        tf, imu = TfBuffer(), []
        for m in self.messages(tf_topics | imu_topics):
            try:
                msg: Any = self._reader.deserialize(m.rawdata, m.msgtype)
            except Exception as err:
                self.warnings.append(
                    f"{self.path}: topic {m.topic!r}: skipped a message ({_one_line(err)})"
                )
                continue
            if m.msgtype in IMU_TYPES:
                a = msg.linear_acceleration
                imu.append(
                    ImuSample(
                        _seconds(msg.header.stamp),
                        str(msg.header.frame_id),
                        np.array([a.x, a.y, a.z]),
                    )
                )
                continue
            for ts in msg.transforms:
                t, q = ts.transform.translation, ts.transform.rotation
                tf.add(
                    str(ts.header.frame_id),
                    str(ts.child_frame_id),
                    _seconds(ts.header.stamp),
                    np.array([t.x, t.y, t.z]),
                    np.array([q.x, q.y, q.z, q.w]),
                    static=m.topic.rstrip("/").endswith("tf_static"),
                )
        return ScanPoser(tf, fixed_frame, tolerance, imu)

    def close(self) -> None:
        """Close the bag (idempotent)."""
        if getattr(self._reader, "stack", None) is not None:
            self._reader.close()

    def __enter__(self) -> RosBag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _seconds(stamp: Any) -> float:
    """A ROS time (sec, nanosec in ROS 2; sec, nsec in ROS 1 through rosbags: nanosec) in s."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split()) or type(err).__name__
    return text if len(text) <= 120 else text[:117] + "..."
