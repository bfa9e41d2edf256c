"""Supported objects: the points on no surface clustered into objects, split where they
touch, each with the surface (and the object) it stands on, described by boxes and hulls.

`_core` holds the voxel and k-NN clustering, the footprint splits and the descriptions;
`convexity` the local-convexity segmentation (``objects.method = "convex"``).
"""

from supportnode.geometry.objects._core import (
    Cluster,
    Components,
    ObjectResult,
    Segmentation,
    cluster_objects,
    describe_objects,
    detect_objects,
    segment_objects,
    split_objects,
)

__all__ = [
    "Cluster",
    "Components",
    "ObjectResult",
    "Segmentation",
    "cluster_objects",
    "describe_objects",
    "detect_objects",
    "segment_objects",
    "split_objects",
]
