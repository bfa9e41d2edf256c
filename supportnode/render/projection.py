"""The picture's geometry: orthographic views of the 3-D scene, boxes, rings, extents, limits.

Every view is an orthographic projection onto the picture plane (top, side and oblique differ
only in azimuth and elevation), so ``ax.transData`` maps projected metres to pixels exactly.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from supportnode.errors import SupportNodeError
from supportnode.render.source import Frame

# (azimuth, elevation) in degrees of the direction the camera looks from, as in mplot3d.
VIEWS: dict[str, tuple[float, float]] = {
    "top": (-90.0, 90.0),  # looking down; x right, y up
    "side": (-90.0, 0.0),  # from -y; x right, z up
    "oblique": (-60.0, 30.0),  # front right, 30 degrees above the horizon
}
COLOR_MODES = ("class", "id")
# Points beyond these percentiles (each end, each picture axis) do not set the picture's extent.
_ROBUST_PERCENT = 2.0


def view_basis(view: str) -> np.ndarray:
    """(3, 3) rows: picture x, picture y and depth (towards the camera) in world coordinates."""
    if view not in VIEWS:
        raise SupportNodeError(f"unknown view {view!r} (expected {', '.join(VIEWS)})")
    az, el = (math.radians(v) for v in VIEWS[view])
    towards = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    right = np.array([-math.sin(az), math.cos(az), 0.0])
    up = np.cross(towards, right)
    return np.round(np.vstack([right, up, towards]), 12)  # exact 0/1 for top and side


def project(points: np.ndarray, view: str) -> np.ndarray:
    """(N, 3) world metres -> (N, 2) picture-plane metres in `view` (what ax.transData takes)."""
    out: np.ndarray = np.asarray(points, dtype=np.float64).reshape(-1, 3) @ view_basis(view)[:2].T
    return out


def obb_corners(o: dict[str, Any]) -> np.ndarray:
    """(8, 3) corners of an object's yaw-only oriented box: bottom four CCW, then top four."""
    c = np.asarray(o["obb_center"], dtype=np.float64)
    half = np.asarray(o["obb_size"], dtype=np.float64) / 2.0
    yaw = float(o["obb_yaw"])
    ca, sa = math.cos(yaw), math.sin(yaw)
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64) * half[:2]
    xy = local @ np.array([[ca, sa], [-sa, ca]]) + c[:2]
    bottom = np.c_[xy, np.full(4, c[2] - half[2])]
    top = np.c_[xy, np.full(4, c[2] + half[2])]
    return np.vstack([bottom, top])


BOX_EDGES = [(i, (i + 1) % 4) for i in range(4)]
BOX_EDGES += [(i + 4, (i + 1) % 4 + 4) for i in range(4)] + [(i, i + 4) for i in range(4)]


def nice_length(span: float) -> float:
    """A 1-2-5 length close to a fifth of `span` for the scale bar."""
    target = max(span / 5.0, 1e-6)
    base = 10.0 ** math.floor(math.log10(target))
    return max(m * base for m in (1.0, 2.0, 5.0) if m * base <= target)


def fit_limits(
    lo: np.ndarray, hi: np.ndarray, box_w: float, box_h: float
) -> tuple[tuple[float, float], tuple[float, float]]:
    """Limits around [lo, hi] with a margin, widened along one axis to the axes' pixel aspect so
    one metre is as long across as up (the axes box then never moves: predictable pixels)."""
    span = np.maximum(hi - lo, 1e-3)
    lo, hi = lo - 0.04 * span, hi + 0.04 * span
    span = hi - lo
    scale = max(span[0] / box_w, span[1] / box_h)  # metres per pixel
    mid = (lo + hi) / 2.0
    half = np.array([box_w, box_h]) * scale / 2.0
    return (mid[0] - half[0], mid[0] + half[0]), (mid[1] - half[1], mid[1] + half[1])


def extent(frame: Frame, basis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Picture-plane box (lo, hi), metres: the central points (every point, not only the drawn
    ones) and the surfaces found. Robust percentiles, so that a few far returns (a depth
    camera's 10 m outliers) do not shrink the scene into a corner; they are drawn at the edge."""
    parts = [r @ basis[:2].T for s in frame.result["surfaces"] for r in rings3(s)]
    if len(frame.points):
        xy = frame.points @ basis[:2].T
        lo, hi = np.percentile(xy, [_ROBUST_PERCENT, 100 - _ROBUST_PERCENT], axis=0)
        margin = 0.1 * (hi - lo)  # the central points and a little more, within the data
        lo, hi = np.maximum(lo - margin, xy.min(0)), np.minimum(hi + margin, xy.max(0))
        parts.append(np.vstack([lo, hi]))
    central = np.vstack(parts) if parts else np.zeros((1, 2))
    lo, hi = central.min(axis=0), central.max(axis=0)
    # objects inside that box count whole (a box is not cut at the edge), far ones do not
    for o in frame.result["objects"]:
        corners = obb_corners(o) @ basis[:2].T
        if np.all((corners.mean(0) >= lo) & (corners.mean(0) <= hi)):
            lo, hi = np.minimum(lo, corners.min(0)), np.maximum(hi, corners.max(0))
    return lo, hi


def rings3(s: dict[str, Any]) -> list[np.ndarray]:
    """A surface's outline rings, closed, as (K+1, 3) polylines at its height (outer first)."""
    h = float(s["height"])
    out = []
    for ring in s.get("outline", []):
        r = np.asarray(ring, dtype=np.float64).reshape(-1, 2)
        r = np.vstack([r, r[:1]])
        out.append(np.c_[r, np.full(len(r), h)])
    return out
