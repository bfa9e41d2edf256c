"""Supported objects: the points on no surface clustered into objects, split where they
touch, each with the surface (and the object) it stands on, described by boxes and hulls.

Modules, by stage:
- `detect`: the entry points (cluster_objects, split_objects, segment_objects,
  describe_objects, detect_objects); `result`: their result types.
- `clusters`: the ``knn`` and ``voxel`` clustering, dropping small clusters, ordering them;
  `convexity`: the local-convexity segmentation (``objects.method = "convex"``);
  `neighbours`: the 26-neighbourhood's offsets.
- `support_lookup`: the surface under each point and each cluster.
- `split`: splitting touching objects, at a footprint neck (`split_footprint`), a step of the
  top height (`split_step`) or concave creases (`split_concave`); `raster`: the 2-D raster
  operations they use.
- `describe`: the clusters' descriptions, with `hull` (footprint hull, volume, oriented box)
  and `support` (the object each object stands on).
- `arrays`: grouping and reduction helpers.
"""

from supportnode.geometry.objects.detect import (
    cluster_objects,
    convex_components,
    describe_objects,
    detect_objects,
    segment_objects,
    split_objects,
)
from supportnode.geometry.objects.result import Cluster, Components, ObjectResult, Segmentation

__all__ = [
    "Cluster",
    "Components",
    "ObjectResult",
    "Segmentation",
    "cluster_objects",
    "convex_components",
    "describe_objects",
    "detect_objects",
    "segment_objects",
    "split_objects",
]
