"""The voxel neighbourhood both segmentations link over."""

from __future__ import annotations

from supportnode.kernels.offsets import FORWARD_26

__all__ = ["FORWARD_26"]
