"""Length units of a cloud file: the scale to metres, and a guess from the cloud's own size.

A file carries no unit. A robot's sensor sees a scene metres across with points millimetres to
centimetres apart, so the extent and the point spacing of a cloud in the wrong unit are
implausible as metres: a SICK time-of-flight scan written in millimetres spans ~1,500 "metres"
with points ~5 "metres" apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["UNITS", "UnitsGuess", "guess_units"]

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}  # metres per unit

# What a sensor's cloud in metres looks like: up to _MAX_EXTENT m across, or up to
# _MAX_WIDE_EXTENT m (a lidar map) when its points are at most _MAX_SPACING m apart, and
# points at least _MIN_SPACING m apart (no depth sensor resolves a fiftieth of a millimetre).
_MIN_EXTENT = 0.05
_MAX_EXTENT = 200.0
_MAX_WIDE_EXTENT = 5000.0
_MIN_SPACING = 2e-5
_MAX_SPACING = 0.3
_TYPICAL_EXTENT = 4.0  # m: a room, or a table seen from a few metres
_SAMPLE = 10_000
_SEED = 0


@dataclass(frozen=True)
class UnitsGuess:
    """unit: "m", "cm" or "mm", the unit the cloud most plausibly is in. extent: robust
    diagonal (1st-99th percentile box) and spacing: median distance between neighbouring
    points, both in the file's units. others: the other non-metre units that fit too."""

    unit: str
    extent: float
    spacing: float
    others: tuple[str, ...] = ()  # other units that would be plausible too

    def message(self, name: str) -> str | None:
        """One line for the user when the cloud does not look like metres, else None."""
        if self.unit == "m":
            return None
        alternatives = "".join(f" (or --units {u})" for u in self.others)
        return (
            f"{name}: looks like {self.unit}, not metres (extent {self.extent:,.0f}, points "
            f"{self.spacing:.3g} apart, in the file's units); pass --units {self.unit}"
            f"{alternatives}"
        )


def _plausible_in_metres(extent: float, spacing: float) -> bool:
    if not (_MIN_SPACING <= spacing and _MIN_EXTENT <= extent <= _MAX_WIDE_EXTENT):
        return False
    return extent <= _MAX_EXTENT or spacing <= _MAX_SPACING


def guess_units(points: np.ndarray) -> UnitsGuess:
    """The unit a cloud is most plausibly in, from its extent and point spacing.

    points: (N, 3) float, finite, in the file's units. Metres whenever metres are plausible
    (so a cloud in metres is never flagged); else the plausible unit that makes the scene
    nearest a room's size; metres again when no unit is plausible (no guess).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2:
        return UnitsGuess("m", 0.0, 0.0)
    lo, hi = np.percentile(pts, [1.0, 99.0], axis=0)
    extent = float(np.linalg.norm(hi - lo))
    rng = np.random.default_rng(_SEED)
    sample = pts[rng.choice(len(pts), size=min(len(pts), _SAMPLE), replace=False)]
    from supportnode.geometry.nearest import neighbour_distances  # numba: not for a reader

    dist = neighbour_distances(sample, sample[: min(len(sample), 1000)], 2)
    # Spacing on a surface grows as 1/sqrt(density): scale the sample's back to all points.
    apart = dist[:, 1][dist[:, 1] > 0]  # repeated points (quantised depth) are no spacing
    if apart.size == 0:
        return UnitsGuess("m", extent, 0.0)
    spacing = float(np.median(apart)) * np.sqrt(len(sample) / len(pts))
    plausible = [u for u, s in UNITS.items() if _plausible_in_metres(extent * s, spacing * s)]
    if not plausible or "m" in plausible:
        return UnitsGuess("m", extent, spacing)
    # A scene 100x too large fits millimetres and centimetres both: first the one that makes
    # it nearest the size a sensor usually sees.
    plausible.sort(key=lambda u: abs(np.log(extent * UNITS[u] / _TYPICAL_EXTENT)))
    return UnitsGuess(plausible[0], extent, spacing, tuple(plausible[1:]))
