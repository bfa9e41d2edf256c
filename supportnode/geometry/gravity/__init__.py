"""Gravity alignment without an IMU: the up axis of a cloud from its planes.

:func:`estimate_gravity` (in :mod:`.estimate`) is the entry; :mod:`.families` finds the
families of parallel planes, :mod:`.cues` gathers what says a family is up, :mod:`.choice`
picks one.
"""

from supportnode.geometry.gravity.estimate import (
    GravityEstimate,
    apply_rotation,
    estimate_gravity,
    rotation_to_z,
)

__all__ = ["GravityEstimate", "apply_rotation", "estimate_gravity", "rotation_to_z"]
