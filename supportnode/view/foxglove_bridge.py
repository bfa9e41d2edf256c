"""Our decoded messages as Foxglove messages (pure: no sockets, no files).

    bridge = Bridge(map_frame="map")
    for item in bridge.convert(msg, topic="surfaces"):   # Item(topic, message, stamp)
        channel_for(item.topic).log(item.message)

What each message becomes (Foxglove topic names are the wire topics, ``T`` below):

- PointCloud on T -> ``foxglove.PointCloud`` on T (packed little-endian float32 x, y, z and the
  cloud's other 1-D numeric fields, in the cloud's frame) and, when the scan has a pose, a
  ``foxglove.FrameTransform`` map frame -> cloud frame on ``tf``, so the scan lands in the map;
- SupportSurfaces on T -> ``foxglove.SceneUpdate`` on T: one entity ``surface/<id>`` per surface
  (outline rings as closed lines at the surface height, green when ``safe`` else orange; the
  largest free disc as a thin cylinder; a label "id height area");
- ObstacleClusters on T -> ``foxglove.SceneUpdate`` on T: one entity ``obstacle/<id>`` per cluster
  (its oriented box as a cube, a label with the id and supporting surface) and, when the clusters
  carry points, a ``foxglove.PointCloud`` on ``T/points`` with a ``cluster`` id field;
- Diagnostics on T -> a JSON message on T (counters, latencies, gauges: plottable) and a
  ``foxglove.Log`` on ``T/log``.

Entities of ids that vanished since the previous message of the same topic are deleted in the
same SceneUpdate (SceneEntityDeletion), so the view never keeps ghosts; present entities are
replaced by id. Lengths are metres, angles radians, times seconds (Foxglove: sec + nsec).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from foxglove.messages import SceneEntity, SceneEntityDeletion, SceneEntityDeletionType, SceneUpdate

from supportnode.msgs import Diagnostics, Message, ObstacleClusters, PointCloud, SupportSurfaces
from supportnode.view.foxglove_messages import (
    DIAGNOSTICS_SCHEMA,
    cluster_entity,
    cluster_points,
    diagnostics_json,
    diagnostics_log,
    quaternion_from_yaw,
    scan_pointcloud,
    scan_transform,
    surface_entity,
    timestamp,
)

# The converters stay importable from here (their old home).
__all__ = [
    "DIAGNOSTICS_SCHEMA",
    "Bridge",
    "Item",
    "cluster_entity",
    "cluster_points",
    "diagnostics_json",
    "diagnostics_log",
    "quaternion_from_yaw",
    "scan_pointcloud",
    "scan_transform",
    "surface_entity",
    "timestamp",
]


@dataclass(frozen=True)
class Item:
    """One message to log: ``message`` is a foxglove message object, or a dict for the JSON
    channel (schema `DIAGNOSTICS_SCHEMA`); ``stamp`` is the source message's stamp, seconds."""

    topic: str
    message: Any
    stamp: float


def _scene(entities: list[SceneEntity], vanished: Iterable[str], stamp: float) -> SceneUpdate:
    """Deletions (of ``vanished`` entity ids) first, as Foxglove applies them, then entities."""
    deletions = [
        SceneEntityDeletion(
            timestamp=timestamp(stamp), type=SceneEntityDeletionType.MatchingId, id=i
        )
        for i in sorted(vanished)
    ]
    return SceneUpdate(deletions=deletions, entities=entities)


_DEFAULT_TOPICS = {
    "PointCloud": "scan",
    "SupportSurfaces": "surfaces",
    "ObstacleClusters": "obstacles",
    "Diagnostics": "diagnostics",
}


@dataclass
class Bridge:
    """Converts a stream of messages; remembers, per topic, the entity ids last shown so that
    vanished ones are deleted. ``map_frame``: parent frame of the scans' poses."""

    map_frame: str = "map"
    tf_topic: str = "tf"
    shown: dict[str, set[str]] = field(default_factory=dict)  # topic -> entity ids on screen

    def convert(self, msg: Message, topic: str | None = None) -> list[Item]:
        """Foxglove items for ``msg`` received on ``topic`` (default: the type's usual topic)."""
        topic = topic or _DEFAULT_TOPICS[type(msg).__name__]
        if isinstance(msg, PointCloud):
            items = [Item(topic, scan_pointcloud(msg), msg.stamp)]
            tf = scan_transform(msg, self.map_frame)
            if tf is not None:
                items.append(Item(self.tf_topic, tf, msg.stamp))
            return items
        if isinstance(msg, SupportSurfaces):
            ents = [surface_entity(s, msg.stamp, msg.frame_id) for s in msg.surfaces]
            ids = [f"surface/{s.id}" for s in msg.surfaces]
            return [Item(topic, self._update(topic, ents, ids, msg.stamp), msg.stamp)]
        if isinstance(msg, ObstacleClusters):
            ents = [cluster_entity(c, msg.stamp, msg.frame_id) for c in msg.clusters]
            ids = [f"obstacle/{c.id}" for c in msg.clusters]
            items = [Item(topic, self._update(topic, ents, ids, msg.stamp), msg.stamp)]
            points = cluster_points(msg)
            if points is not None:
                items.append(Item(f"{topic}/points", points, msg.stamp))
            return items
        if isinstance(msg, Diagnostics):
            return [
                Item(topic, diagnostics_json(msg), msg.stamp),
                Item(f"{topic}/log", diagnostics_log(msg), msg.stamp),
            ]
        raise TypeError(f"cannot show a {type(msg).__name__} message")

    def _update(
        self, topic: str, entities: list[SceneEntity], ids: list[str], stamp: float
    ) -> SceneUpdate:
        now = set(ids)
        vanished = self.shown.get(topic, set()) - now
        self.shown[topic] = now
        return _scene(entities, vanished, stamp)
