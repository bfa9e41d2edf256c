"""The node's voxel map: posed scans merged into per-voxel moments and kept points.

``store`` (`VoxelMap`: slots, moments, kept points, change stamp), ``hash`` (packed key ->
slot), ``keys`` (packing and the coordinate range), ``scan`` (a scan's voxels and plane fits),
``merge`` (moments, evidence, kept points), ``clearing`` (free space along the rays),
``forget`` (radius, age, cap). Pure: numpy in, numpy out; no sockets, files or printing.
"""

from supportnode.map.hash import KeyHash
from supportnode.map.keys import coordinate_range, pack_keys, unpack_keys
from supportnode.map.store import REPRESENTATIONS, Touched, VoxelMap

__all__ = [
    "REPRESENTATIONS",
    "KeyHash",
    "Touched",
    "VoxelMap",
    "coordinate_range",
    "pack_keys",
    "unpack_keys",
]
