"""Which plane family is up, and which way: the choice without a hint."""

from __future__ import annotations

import numpy as np

from supportnode.errors import AlignmentError
from supportnode.geometry.gravity.cues import Evidence, gather
from supportnode.geometry.gravity.families import Family

_FRAME_CONE_DEG = 70.0
_OFF_FRAME = 0.3


def fmt_vector(v: np.ndarray) -> str:
    """A direction as the config's list syntax, e.g. ``[0.00,-0.82,-0.57]``."""
    return "[" + ",".join(f"{x:.2f}" for x in np.asarray(v).reshape(3) + 0.0) + "]"


def _frame_prior(up: np.ndarray) -> float:
    """1 where a sensor held upright puts up in its own frame, else _OFF_FRAME.

    Clouds here are in a sensor's frame (or a world frame, z up). The two conventions
    (REP 103): a body or lidar frame is z up, a camera's optical frame y down, z forward; a
    sensor is mounted with little roll and pitched at most ~70 deg, so up lies within
    _FRAME_CONE_DEG of +z or of -y. Up along x (the image's right) is a camera rolled on its
    side. Soft: a lone plane family outside both still wins (a camera looking straight down)."""
    cos = np.cos(np.radians(_FRAME_CONE_DEG))
    return 1.0 if (up[2] >= cos or -up[1] >= cos) else _OFF_FRAME


def _score(fam: Family, ev: Evidence) -> tuple[float, float]:
    """(score, sign) of a family: area, parallel planes, obliquity, perpendicular structure
    and how clearly the sign is voted."""
    # Sign: things rest on the up side of support planes; the sensor looks down on them.
    # The resting cue holds for any cloud; the sensor cue only where a sensor is at
    # `sensor`, so it counts half.
    scale = min(1.0, (ev.on + ev.under) / (0.2 * fam.members.size))
    vote = ev.rest_vote * scale + 0.5 * ev.sensor_vote
    sign = 1.0 if vote >= 0 else -1.0
    score = (
        fam.members.size
        * (1.0 + 0.5 * min(len(ev.planes) - 1, 4))
        * (0.5 + ev.oblique)
        * (0.2 + ev.perp)
        * (0.25 + 0.75 * min(abs(vote), 1.0))
        * _frame_prior(sign * fam.axis)
    )
    return score, sign


def choose_up(
    fams: list[Family], ds: np.ndarray, normals: np.ndarray, sensor: np.ndarray, voxel: float
) -> tuple[np.ndarray, str, Family]:
    """The up axis (signed, (3,)) among the families and one line saying why.

    Raises AlignmentError when the best is a single bare plane: nothing rests on it, nothing
    stands across it, so it is a wall as much as a floor."""
    n_total = ds.shape[0]
    scored = []
    for fam in fams:
        ev = gather(fam, ds, normals, sensor, voxel)
        score, sign = _score(fam, ev)
        scored.append((score, sign, fam, ev))
    scored.sort(key=lambda s: -s[0])
    _, sign, fam, ev = scored[0]
    rests = ev.on if sign > 0 else ev.under
    if len(ev.planes) <= 1 and ev.perp < 0.02 and rests < 0.01 * n_total:
        side = (sensor - ds[fam.members].mean(axis=0)) @ fam.axis
        toward = fam.axis if side > 0 else -fam.axis
        raise AlignmentError(
            "no horizontal surface in view: only one bare plane "
            f"({fam.members.size} of {n_total} normals) with nothing on it or across it, a "
            "wall as much as a floor; if it is the floor or a table, pass "
            f"--set gravity.up_hint={fmt_vector(toward)} (its normal toward the sensor), "
            "else the up direction you know"
        )
    k = len(fams) - 1
    others = f"; chosen over {k} other plane famil{'y' if k == 1 else 'ies'}" if k else ""
    why = (
        f"{len(ev.planes)} parallel plane(s) of {fam.members.size} normals, {rests} points "
        f"resting on them, {ev.perp:.0%} of normals across them, sensor vote "
        f"{ev.sensor_vote * sign:+.2f}{others}"
    )
    return sign * fam.axis, why, fam
