"""A part held up by a narrow top is attached to it, not resting on it: one object.

A lamp's shade sits on its thin stem, but the stem enters the shade where no sensor sees
(under it, inside it): the shade's points and the stem's are apart, two components, and the
shade would stand on the stem as a box stands on a box. A box rests on its whole bottom; a
thing held at one narrow point would fall unless fixed there. So a component that floats
above its surface, its bottom at the top of another that stands on the surface and whose top
lies under it and is less than a third as wide as itself, is joined to it (a shade on a stem, a plate on a post, a sign on
its pole); on a wider top it rests, its own object (`support.supported_by`).

Points cp (M, 3) float64 metres, z up; labels (M,) int64, -1 none.
"""

from __future__ import annotations

import numpy as np

from supportnode.geometry.objects.support import CONTACT
from supportnode.kernels.components import label_edges
from supportnode.kernels.groups import label_boxes

# A holder narrower than this share of what it holds, where they meet, holds it fixed (the
# layer cuts' rule for what stands on a face: `layers._BASE_WIDTH`).
_NARROW = 1.0 / 3.0


def join_attached(
    cp: np.ndarray, lab: np.ndarray, support: np.ndarray, heights: dict[int, float]
) -> np.ndarray:
    """(M,) labels 0..K-1 (in their order) with each component held up by a narrow top
    joined to what holds it. support: (M,) the surface under each point (-1: none), whose
    heights (metres) are ``heights`` by surface id."""
    n = int(lab.max()) + 1 if len(lab) else 0
    if n < 2:
        return lab
    by_id = np.full(max(heights, default=-1) + 2, -np.inf)  # the last entry: support -1
    for sid, height in heights.items():
        by_id[sid] = height
    _, below = label_boxes(by_id[support][:, None], lab, n)
    base = np.where(np.isfinite(below[:, 0]), below[:, 0], np.nan)  # the highest under it
    lo, hi = label_boxes(cp, lab, n)
    bottom, top = lo[:, 2], hi[:, 2]
    raised = bottom - base > CONTACT  # NaN (no surface under it): not raised
    # Pairs (f, h): f raised, h standing on its surface (a post, not a fragment of what
    # stands: a convex segmentation's strip of a box's rim), h's top at f's bottom and below
    # f's top (as `supported_by`), their boxes overlapping.
    stands = bottom - base <= CONTACT
    meet = raised[:, None] & stands[None, :] & (np.abs(top[None, :] - bottom[:, None]) <= CONTACT)
    meet &= top[None, :] < top[:, None]
    meet &= np.all(
        (lo[None, :, :2] <= hi[:, None, :2]) & (hi[None, :, :2] >= lo[:, None, :2]), axis=2
    )
    np.fill_diagonal(meet, False)
    join = []
    for f, h in zip(*np.nonzero(meet), strict=True):
        rows = np.flatnonzero(lab == h)
        tip = cp[rows[cp[rows, 2] >= top[h] - CONTACT], :2]
        under = np.all((tip >= lo[f, :2]) & (tip <= hi[f, :2]), axis=1).all()
        if under and np.ptp(tip, axis=0).max() < _NARROW * (hi[f, :2] - lo[f, :2]).max():
            join.append((int(f), int(h)))
    if not join:
        return lab
    src, dst = np.array(join, np.int64).T
    comp = label_edges(n, src, dst)
    # Joined sets numbered in the order of their first members.
    first = np.full(n, n, np.int64)
    np.minimum.at(first, comp, np.arange(n))
    new_id = np.full(n + 1, -1, np.int64)  # the last entry: label -1's
    new_id[:n] = np.unique(first[comp], return_inverse=True)[1]
    return new_id[lab]
