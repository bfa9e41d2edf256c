"""Colours the live views share (RGBA, 0..1), so Foxglove and Rerun show the same scene."""

# Safe surfaces green, the others orange (not red: unsafe is not an error).
SAFE_COLOR = (0.20, 0.80, 0.25, 1.0)
UNSAFE_COLOR = (1.00, 0.55, 0.00, 1.0)
DISC_COLOR = (0.25, 0.55, 1.00, 0.35)
OBSTACLE_COLOR = (0.90, 0.20, 0.20, 0.55)
LOOSE_OBSTACLE_COLOR = (0.60, 0.60, 0.60, 0.45)  # on no surface
