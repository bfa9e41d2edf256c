"""Support surfaces: horizontal regions a robot can stand, land or put things on.

Two methods share one result type:
- ``seed``: Algorithm 1 of the report as published (voxels with more than ``p_min`` points, grown
  through horizontally adjacent voxels of the same height layer, regions of ``psi_min`` voxels).
- ``planar`` (default): per-voxel plane fits from moments; only flat, near-horizontal voxels grow;
  growth may cross height layers within ``max_step`` (flat objects lying on a surface, raised
  by a step, are cut out again); minimum area and width in metres.

On a depth camera's view (`band`) each surface measures its noise (`noise`: sigma by range)
and takes the points within its noise band, not within a fixed tolerance.
"""

from supportnode.geometry.surfaces.detect import detect_surfaces
from supportnode.geometry.surfaces.footprint import (
    cells_outline,
    cells_outlines,
    footprint_width,
    footprint_widths,
)
from supportnode.geometry.surfaces.result import Surface, SurfaceResult

__all__ = [
    "Surface",
    "SurfaceResult",
    "cells_outline",
    "cells_outlines",
    "detect_surfaces",
    "footprint_width",
    "footprint_widths",
]
