"""A detection as the node's result messages (detection ids; the safe rule without tracking)."""

from __future__ import annotations

from supportnode.detection.policy import is_safe
from supportnode.msgs import ObstacleClusters, SupportSurfaces
from supportnode.params import SafeParams
from supportnode.pipeline import Detection

__all__ = ["detection_messages"]


def detection_messages(
    detection: Detection, safe: SafeParams, stamp: float, frame_id: str, seq: int = 0
) -> tuple[SupportSurfaces, ObstacleClusters | None]:
    """SupportSurfaces (``safe`` by `is_safe`, one detection: no hits to count) and
    ObstacleClusters (None when objects were not detected) of one detection."""
    surfaces = detection.surfaces.surfaces
    msg_s = SupportSurfaces.from_detection(
        surfaces,
        detection.free_space,
        stamp,
        frame_id,
        seq,
        safe=[is_safe(s, safe) for s in surfaces],
    )
    if detection.objects is None:
        return msg_s, None
    return msg_s, ObstacleClusters.from_detection(detection.objects.clusters, stamp, frame_id, seq)
