"""A surface's noise model: sigma(r)^2 = a^2 + (b r^2)^2, fitted to its points' residuals.

A depth camera's error grows with the square of the range; ``b = 0`` without a sensor. The
spread about the voxels' planes is measured per range bin (robust sigma from the median
residual), and the model fitted to the bins by weighted least squares (see `band`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from supportnode.geometry.voxels import Labelled, VoxelGrid

# Range bins for the fit, metres wide; a bin needs this many points to count.
_BIN = 0.2
_BIN_MIN_POINTS = 50
# The noise is fitted to an even sample of at most this many of the labelled points.
_FIT_SAMPLES = 6_000
# Robust sigma from the median absolute residual of a normal distribution.
_MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class NoiseModel:
    """Per surface: sigma(r) = sqrt(a^2 + (b r^2)^2), metres (a: (S,) m, b: (S,) 1/m)."""

    a: np.ndarray
    b: np.ndarray

    def sigma(self, surface: np.ndarray, r: np.ndarray | float) -> np.ndarray:
        """(K,) noise of ``surface`` (K,) ids at range ``r`` (K,) or scalar, metres."""
        r2 = np.asarray(r, dtype=np.float64) ** 2
        return np.hypot(self.a[surface], self.b[surface] * r2)


def fit_noise(
    surface: np.ndarray, residual: np.ndarray, r: np.ndarray | None, n_surfaces: int
) -> NoiseModel:
    """The noise model of each surface from its labelled points.

    surface: (P,) int surface id of each labelled point; residual: (P,) float64 its distance
    to its voxel's plane, metres; r: (P,) its range from the sensor, metres, or None when the
    sensor is unknown (sigma then does not vary with range). Per range bin the robust sigma
    (1.4826 x the median residual) is taken, then ``a^2 + b^2 r^4`` fitted to the bins'
    variances by least squares weighted by their points, with a, b >= 0."""
    a = np.zeros(n_surfaces)
    b = np.zeros(n_surfaces)
    if len(surface) == 0:
        return NoiseModel(a, b)
    rb = np.zeros(len(surface), np.int64) if r is None else np.floor(r / _BIN).astype(np.int64)
    nb = int(rb.max()) + 1
    key = surface.astype(np.int64) * nb + rb
    order = np.argsort(key, kind="stable")
    key, res = key[order], residual[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    counts = np.diff(np.r_[starts, len(key)])
    # Each bin's middle residual in sorted order, selected rather than sorted (a lexsort by
    # bin and residual took 4x as long on a scan's sample): the same value.
    bins = zip(starts.tolist(), counts.tolist(), strict=True)
    med = np.array([np.partition(res[s : s + c], c // 2)[c // 2] for s, c in bins])
    sid, bin_ = key[starts] // nb, key[starts] % nb
    var = (_MAD_TO_SIGMA * med) ** 2
    r4 = ((bin_ + 0.5) * _BIN) ** 4
    for s in np.unique(sid):
        m = sid == s
        ok = m & (counts >= _BIN_MIN_POINTS)
        if not ok.any():
            ok = m & (counts == counts[m].max())
        a[s], b[s] = _fit_bins(var[ok], r4[ok], counts[ok].astype(np.float64), r is not None)
    return NoiseModel(a, b)


def _fit_bins(var: np.ndarray, r4: np.ndarray, w: np.ndarray, ranged: bool) -> tuple[float, float]:
    """(a, b) >= 0 of var = a^2 + b^2 r4, weighted least squares over the bins."""
    if not ranged or len(var) < 2 or np.ptp(r4) <= 0:
        return float(np.sqrt(np.average(var, weights=w))), 0.0
    design = np.stack([np.ones_like(r4), r4], axis=1) * np.sqrt(w)[:, None]
    (a2, b2), *_ = np.linalg.lstsq(design, var * np.sqrt(w), rcond=None)
    if b2 < 0:
        return float(np.sqrt(np.average(var, weights=w))), 0.0
    if a2 < 0:
        return 0.0, float(np.sqrt(np.sum(w * var * r4) / np.sum(w * r4 * r4)))
    return float(np.sqrt(a2)), float(np.sqrt(b2))


def fit_sample(
    grid: VoxelGrid,
    labels: np.ndarray,
    best: np.ndarray,
    r_voxel: np.ndarray | None,
    n: int,
    lab: Labelled | None = None,
) -> NoiseModel:
    """:func:`fit_noise` of the labelled points (``best``: their heights above the planes;
    lab: the labelled points, `VoxelGrid.labelled`, when known)."""
    lab = grid.labelled(labels) if lab is None else lab
    # Medians need no more than an even sample (a scan's table holds ~10^5 points).
    step = max(1, len(lab.at) // _FIT_SAMPLES)
    on, voxel = lab.at[::step], lab.vox[::step]
    r = None if r_voxel is None else r_voxel[voxel]
    return fit_noise(labels[on].astype(np.int64), np.abs(best[on]), r, n)
