"""``SupportSurfaces`` and ``ObstacleClusters``: detection results, one buffer per attribute.

Per-item attributes travel as columns (one little-endian buffer each, row i = item i); variable-
length parts (outline rings, subsampled points) as one concatenated buffer plus CSR offsets.
The same checks run on encode (so a node never sends what its peers reject) and on decode.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from supportnode.msgs._wire import (
    FLOAT_DTYPES,
    Check,
    Decodable,
    Header,
    Limits,
    encode_frames,
    expect_type,
)

__all__ = ["ObstacleCluster", "ObstacleClusters", "SupportSurface", "SupportSurfaces"]

# (buffer name, dtype string, shape after the item axis)
Schema = tuple[tuple[str, str, tuple[int, ...]], ...]

SURFACE_COLUMNS: Schema = (
    ("id", "<i8", ()),
    ("height", "<f8", ()),
    ("normal", "<f8", (3,)),
    ("area", "<f8", ()),
    ("flatness", "<f8", ()),
    ("point_count", "<i8", ()),
    ("free_area", "<f8", ()),
    ("disc_center", "<f8", (2,)),
    ("disc_radius", "<f8", ()),
    ("safe", "|u1", ()),
)
CLUSTER_COLUMNS: Schema = (
    ("id", "<i8", ()),
    ("surface_id", "<i8", ()),
    ("centroid", "<f8", (3,)),
    ("bbox_min", "<f8", (3,)),
    ("bbox_max", "<f8", (3,)),
    ("obb_center", "<f8", (3,)),
    ("obb_size", "<f8", (3,)),
    ("obb_yaw", "<f8", ()),
    ("height", "<f8", ()),
    ("point_count", "<i8", ()),
)
# A unit normal may be off by this much (float32 senders, rounding).
_UNIT_TOLERANCE = 1e-3


@dataclass(eq=False)
class SupportSurface:
    """One support surface on the wire. Lengths in metres in the message's frame, z up.

    free_area, disc_center and disc_radius are NaN when free space was not computed;
    disc_center is NaN when nothing is free (disc_radius 0).
    """

    id: int  # stable id (the tracker's), unique within a message
    height: float
    normal: np.ndarray  # (3,) float64 unit
    area: float  # m^2
    outline: list[np.ndarray]  # rings (K, 2) x, y, largest first; counter-clockwise bound,
    # clockwise are holes (as `Surface.outline`)
    free_area: float = math.nan  # m^2
    disc_center: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))  # (2,) x, y
    disc_radius: float = math.nan
    flatness: float = 0.0  # rms distance of the points to the fitted plane
    point_count: int = 0
    safe: bool = False  # set by the node's safety rules; False when not evaluated


@dataclass(eq=False)
class ObstacleCluster:
    """One obstacle cluster on the wire. Lengths in metres in the message's frame, z up."""

    id: int  # stable id, unique within a message
    surface_id: int | None  # id of the supporting surface; None (wire: -1) when on none
    centroid: np.ndarray  # (3,) float64
    bbox_min: np.ndarray  # (3,) float64, axis-aligned box
    bbox_max: np.ndarray  # (3,) float64
    obb_center: np.ndarray  # (3,) float64, oriented box (yaw only)
    obb_size: np.ndarray  # (3,) float64 length, width, height
    obb_yaw: float  # radians, direction of the length axis
    height: float  # top above the supporting surface
    point_count: int
    points: np.ndarray | None = None  # (M, 3) subsampled points, float32 or float64
    supported_by: int = -1  # id of the cluster it stands on, -1 when on its surface


@dataclass(eq=False)
class SupportSurfaces(Decodable):
    """Every support surface of one detection."""

    TYPE: ClassVar[str] = "SupportSurfaces"

    stamp: float  # seconds
    frame_id: str
    seq: int = 0
    surfaces: list[SupportSurface] = field(default_factory=list)

    @classmethod
    def from_detection(cls, *args: Any, **kwargs: Any) -> SupportSurfaces:
        """Old name of `supportnode.detection.messages.surfaces_message` (same arguments),
        kept for callers written before the wire stopped knowing geometry; imported on call,
        so that ``import supportnode.msgs`` loads no geometry."""
        from supportnode.detection.messages import surfaces_message

        return surfaces_message(*args, **kwargs)

    def encode(self, topic: str | bytes) -> list[bytes | memoryview]:
        """``[topic, header, *columns, surface_rings, ring_offsets, outline]``."""
        chk = _encode_check(topic)
        s = self.surfaces
        cols = _columns(
            chk,
            SURFACE_COLUMNS,
            len(s),
            {
                "id": [x.id for x in s],
                "height": [x.height for x in s],
                "normal": [x.normal for x in s],
                "area": [x.area for x in s],
                "flatness": [x.flatness for x in s],
                "point_count": [x.point_count for x in s],
                "free_area": [x.free_area for x in s],
                "disc_center": [x.disc_center for x in s],
                "disc_radius": [x.disc_radius for x in s],
                "safe": [bool(x.safe) for x in s],
            },
        )
        rings = [[np.asarray(r) for r in x.outline] for x in s]
        flat = [r for rs in rings for r in rs]
        for r in flat:
            if r.ndim != 2 or r.shape[1] != 2:
                chk.fail(f"outline ring has shape {r.shape}, expected (K, 2)")
        dtype = np.float32 if flat and all(r.dtype == np.float32 for r in flat) else np.float64
        outline = np.concatenate(flat).astype(dtype, copy=False) if flat else np.zeros((0, 2))
        cols["surface_rings"] = np.concatenate([[0], np.cumsum([len(rs) for rs in rings])])
        cols["ring_offsets"] = np.concatenate([[0], np.cumsum([len(r) for r in flat])])
        cols["outline"] = outline
        for k in ("surface_rings", "ring_offsets"):
            cols[k] = cols[k].astype("<i8")
        _check_surfaces(chk, cols, None)
        return encode_frames(
            topic, self.TYPE, self.stamp, self.frame_id, self.seq, list(cols.items())
        )

    @classmethod
    def _from_parsed(
        cls, header: Header, buffers: dict[str, np.ndarray], limits: Limits
    ) -> SupportSurfaces:
        chk = Check(header.topic)
        expect_type(chk, header, cls.TYPE)
        c = _check_surfaces(chk, buffers, limits)
        sr, ro, outline = c["surface_rings"], c["ring_offsets"], c["outline"]
        out = []
        for i in range(len(c["id"])):
            rings = [outline[ro[j] : ro[j + 1]] for j in range(sr[i], sr[i + 1])]
            out.append(
                SupportSurface(
                    id=int(c["id"][i]),
                    height=float(c["height"][i]),
                    normal=np.array(c["normal"][i], dtype=np.float64),
                    area=float(c["area"][i]),
                    outline=rings,
                    free_area=float(c["free_area"][i]),
                    disc_center=np.array(c["disc_center"][i], dtype=np.float64),
                    disc_radius=float(c["disc_radius"][i]),
                    flatness=float(c["flatness"][i]),
                    point_count=int(c["point_count"][i]),
                    safe=bool(c["safe"][i]),
                )
            )
        return cls(stamp=header.stamp, frame_id=header.frame_id, seq=header.seq, surfaces=out)


@dataclass(eq=False)
class ObstacleClusters(Decodable):
    """Every obstacle cluster of one detection."""

    TYPE: ClassVar[str] = "ObstacleClusters"

    stamp: float  # seconds
    frame_id: str
    seq: int = 0
    clusters: list[ObstacleCluster] = field(default_factory=list)

    @classmethod
    def from_detection(cls, *args: Any, **kwargs: Any) -> ObstacleClusters:
        """Old name of `supportnode.detection.messages.obstacles_message` (same arguments),
        kept for callers written before the wire stopped knowing geometry; imported on call."""
        from supportnode.detection.messages import obstacles_message

        return obstacles_message(*args, **kwargs)

    def encode(self, topic: str | bytes) -> list[bytes | memoryview]:
        """``[topic, header, *columns]`` plus ``points, point_offsets`` when any cluster has
        points (clusters with ``points=None`` then send zero points)."""
        chk = _encode_check(topic)
        cs = self.clusters
        cols = _columns(
            chk,
            CLUSTER_COLUMNS,
            len(cs),
            {
                "id": [c.id for c in cs],
                "surface_id": [-1 if c.surface_id is None else c.surface_id for c in cs],
                "centroid": [c.centroid for c in cs],
                "bbox_min": [c.bbox_min for c in cs],
                "bbox_max": [c.bbox_max for c in cs],
                "obb_center": [c.obb_center for c in cs],
                "obb_size": [c.obb_size for c in cs],
                "obb_yaw": [c.obb_yaw for c in cs],
                "height": [c.height for c in cs],
                "point_count": [c.point_count for c in cs],
            },
        )
        if any(c.supported_by != -1 for c in cs):  # OPTIONAL buffer: absent = all -1
            cols["supported_by"] = np.array([c.supported_by for c in cs], dtype="<i8")
        if any(c.points is not None for c in cs):
            pts = [np.zeros((0, 3)) if c.points is None else np.asarray(c.points) for c in cs]
            for p in pts:
                if p.ndim != 2 or p.shape[1] != 3:
                    chk.fail(f"cluster points have shape {p.shape}, expected (M, 3)")
            f32 = all(p.dtype == np.float32 for p in pts if len(p))
            cols["points"] = np.concatenate(pts).astype(np.float32 if f32 else np.float64)
            cols["point_offsets"] = np.concatenate([[0], np.cumsum([len(p) for p in pts])])
            cols["point_offsets"] = cols["point_offsets"].astype("<i8")
        _check_clusters(chk, cols, None)
        return encode_frames(
            topic, self.TYPE, self.stamp, self.frame_id, self.seq, list(cols.items())
        )

    @classmethod
    def _from_parsed(
        cls, header: Header, buffers: dict[str, np.ndarray], limits: Limits
    ) -> ObstacleClusters:
        chk = Check(header.topic)
        expect_type(chk, header, cls.TYPE)
        c = _check_clusters(chk, buffers, limits)
        pts, off = c.get("points"), c.get("point_offsets")
        by = c.get("supported_by")
        out = []
        for i in range(len(c["id"])):
            sid = int(c["surface_id"][i])
            out.append(
                ObstacleCluster(
                    id=int(c["id"][i]),
                    surface_id=None if sid == -1 else sid,
                    centroid=np.array(c["centroid"][i], dtype=np.float64),
                    bbox_min=np.array(c["bbox_min"][i], dtype=np.float64),
                    bbox_max=np.array(c["bbox_max"][i], dtype=np.float64),
                    obb_center=np.array(c["obb_center"][i], dtype=np.float64),
                    obb_size=np.array(c["obb_size"][i], dtype=np.float64),
                    obb_yaw=float(c["obb_yaw"][i]),
                    height=float(c["height"][i]),
                    point_count=int(c["point_count"][i]),
                    points=None if pts is None or off is None else pts[off[i] : off[i + 1]],
                    supported_by=-1 if by is None else int(by[i]),
                )
            )
        return cls(stamp=header.stamp, frame_id=header.frame_id, seq=header.seq, clusters=out)


def _encode_check(topic: str | bytes) -> Check:
    name = topic if isinstance(topic, str) else topic.decode("utf-8", "replace")
    return Check(name, prefix="cannot encode: ")


def _columns(
    chk: Check, schema: Schema, n: int, values: dict[str, list[Any]]
) -> dict[str, np.ndarray]:
    """Column arrays (n, *tail) of the schema's dtypes from per-item values."""
    cols = {}
    for name, dtype, tail in schema:
        try:
            a = np.array(values[name], dtype=dtype).reshape((n, *tail))
        except (TypeError, ValueError, OverflowError) as err:
            chk.fail(f"'{name}' values do not form an ({n}, {tail}) {dtype} column: {err}")
        cols[name] = a
    return cols


def _check_columns(
    chk: Check, buffers: Mapping[str, np.ndarray], schema: Schema, limit: int | None, what: str
) -> dict[str, np.ndarray]:
    """The schema's columns, all of one length n <= limit, ids unique."""
    n = len(chk.array(buffers, schema[0][0], frozenset({schema[0][1]}), schema[0][2]))
    if limit is not None and n > limit:
        chk.fail(f"{n} {what} exceeds max_{what} {limit}")
    cols = {}
    for name, dtype, tail in schema:
        cols[name] = chk.array(buffers, name, frozenset({dtype}), tail)
        chk.length(cols[name], name, n, f"one row per {what[:-1]}")
    if len(np.unique(cols["id"])) != n:
        chk.fail("buffer 'id' has duplicate ids")
    return cols


def _not_negative(chk: Check, a: np.ndarray, name: str) -> None:
    # NaN compares False, so NaN passes here; callers decide where NaN is allowed.
    if bool(np.any(a < 0)):
        chk.fail(f"buffer '{name}' has negative values")


def _check_surfaces(
    chk: Check, buffers: Mapping[str, np.ndarray], limits: Limits | None
) -> dict[str, np.ndarray]:
    """Every rule of a SupportSurfaces message (limits None: no size limits, as on encode)."""
    c = _check_columns(
        chk, buffers, SURFACE_COLUMNS, None if limits is None else limits.max_surfaces, "surfaces"
    )
    for name in ("height", "normal", "area", "flatness"):
        chk.finite(c[name], name)
    for name in ("area", "flatness", "point_count"):
        _not_negative(chk, c[name], name)
    with np.errstate(over="ignore"):  # huge components: norm inf, rejected below
        norm = np.linalg.norm(c["normal"], axis=1)
    if bool(np.any(np.abs(norm - 1.0) > _UNIT_TOLERANCE)):
        chk.fail("buffer 'normal' has vectors that are not unit length")
    # Free space: NaN means not computed; infinities and negative values are never valid.
    for name in ("free_area", "disc_radius", "disc_center"):
        if bool(np.any(np.isinf(c[name]))):
            chk.fail(f"buffer '{name}' has infinite values")
    for name in ("free_area", "disc_radius"):
        _not_negative(chk, c[name], name)
    r = c["disc_radius"]
    nan_centre = np.isnan(c["disc_center"]).any(axis=1)
    if bool(np.any(nan_centre & ~(np.isnan(r) | (r == 0)))):
        chk.fail("disc_center is NaN where disc_radius is neither 0 nor NaN")
    if bool(np.any(c["safe"] > 1)):
        chk.fail("buffer 'safe' has values other than 0 and 1")
    sr = chk.array(buffers, "surface_rings", frozenset({"<i8"}))
    ro = chk.array(buffers, "ring_offsets", frozenset({"<i8"}))
    outline = chk.array(buffers, "outline", FLOAT_DTYPES, (2,))
    if limits is not None:
        for name, a in (("ring_offsets", ro[1:]), ("outline", outline)):
            if len(a) > limits.max_polygon_vertices:
                chk.fail(
                    f"{len(a)} {'rings' if name == 'ring_offsets' else 'outline vertices'} "
                    f"exceed max_polygon_vertices {limits.max_polygon_vertices}"
                )
    if len(ro) < 1:
        chk.fail("buffer 'ring_offsets' is empty (needs at least [0])")
    chk.offsets(sr, "surface_rings", len(c["id"]), len(ro) - 1)
    chk.offsets(ro, "ring_offsets", len(ro) - 1, len(outline))
    chk.finite(outline, "outline")
    c.update(surface_rings=sr, ring_offsets=ro, outline=outline)
    return c


def _check_clusters(
    chk: Check, buffers: Mapping[str, np.ndarray], limits: Limits | None
) -> dict[str, np.ndarray]:
    """Every rule of an ObstacleClusters message (limits None: no size limits, as on encode)."""
    c = _check_columns(
        chk, buffers, CLUSTER_COLUMNS, None if limits is None else limits.max_clusters, "clusters"
    )
    for name, _, _ in CLUSTER_COLUMNS[2:]:
        chk.finite(c[name], name)
    if bool(np.any(c["surface_id"] < -1)):
        chk.fail("buffer 'surface_id' has values below -1 (-1 means: on no surface)")
    for name in ("obb_size", "point_count"):
        _not_negative(chk, c[name], name)
    if bool(np.any(c["bbox_min"] > c["bbox_max"])):
        chk.fail("bbox_min exceeds bbox_max")
    has = ("points" in buffers, "point_offsets" in buffers)
    if has[0] != has[1]:
        chk.fail("buffers 'points' and 'point_offsets' must come together")
    if has[0]:
        pts = chk.array(buffers, "points", FLOAT_DTYPES, (3,))
        if limits is not None and len(pts) > limits.max_points:
            chk.fail(
                f"{len(pts)} cluster points exceeds max_points {limits.max_points}",
                "too_many_points",
            )
        off = chk.array(buffers, "point_offsets", frozenset({"<i8"}))
        chk.offsets(off, "point_offsets", len(c["id"]), len(pts))
        chk.finite(pts, "points")
        c.update(points=pts, point_offsets=off)
    if "supported_by" in buffers:
        by = chk.array(buffers, "supported_by", frozenset({"<i8"}))
        if by.shape != c["id"].shape:
            chk.fail(f"buffer 'supported_by' has shape {by.shape}, expected {c['id'].shape}")
        if bool(np.any((by != -1) & ~np.isin(by, c["id"]))):
            chk.fail("buffer 'supported_by' names a cluster id not in the message (-1: none)")
        c["supported_by"] = by
    return c
