"""The levels' counts outside the turned box of what rises, compiled, against the footprint
computed level by level (`geometry.objects.rising`)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.geometry.objects.rising import footprint
from supportnode.kernels.turned import outside_turned


def reference(xy, a, b, u, slab):
    out = []
    for ai, bi, ui in zip(a, b, u, strict=True):
        if ui >= len(xy):
            out.append(0)
            continue
        fp = footprint(xy[ui:], slab)
        out.append(int(np.count_nonzero(~fp.inside(xy[ai:bi]))))
    return np.array(out, np.int64)


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(1, 300),
    levels=st.integers(0, 6),
    kind=st.sampled_from(["uniform", "turned box", "line", "rounded"]),
    seed=st.integers(0, 10_000),
)
def test_counts_match_the_footprint_level_by_level(n, levels, kind, seed):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-0.2, 0.2, (n, 2))
    if kind == "turned box":
        t = rng.uniform(0, np.pi)
        rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        xy = (rng.uniform(-1, 1, (n, 2)) * [0.1, 0.05]) @ rot.T
    elif kind == "line":
        xy[:, 1] = 0.3 * xy[:, 0]
    elif kind == "rounded":
        xy = np.round(xy, 1)
    u = np.sort(rng.integers(0, n + 1, levels))[::-1]  # highest level first
    a = np.array([rng.integers(0, ui + 1) for ui in u], np.int64)
    b = np.array([rng.integers(ai, ui + 1) for ai, ui in zip(a, u, strict=True)], np.int64)
    np.testing.assert_array_equal(outside_turned(xy, a, b, u, 0.005), reference(xy, a, b, u, 0.005))


def test_a_rim_under_a_turned_box_lies_outside_it():
    # The lower box's top corners around a box turned 45 degrees: inside the upper box's
    # axis-aligned box, outside its turned one.
    g = np.stack(np.meshgrid(np.linspace(-0.1, 0.1, 21), np.linspace(-0.1, 0.1, 21)), -1)
    rim = g.reshape(-1, 2)
    t = np.radians(45)
    rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    upper = (np.stack(np.meshgrid(*[np.linspace(-0.07, 0.07, 8)] * 2), -1).reshape(-1, 2)) @ rot.T
    xy = np.concatenate([rim, upper])
    n_rim = len(rim)
    count = outside_turned(xy, np.array([0]), np.array([n_rim]), np.array([n_rim]), 0.005)
    assert count[0] >= 0.4 * n_rim  # the four corners
    lo, hi = upper.min(0) - 0.005, upper.max(0) + 0.005
    assert np.all((rim >= lo) & (rim <= hi), axis=1).mean() > 0.9  # all but the box's edge


def test_levels_out_of_order_or_range_are_refused():
    xy = np.zeros((4, 2))
    with pytest.raises(ValueError, match="highest first"):
        outside_turned(xy, np.array([0, 0]), np.array([1, 1]), np.array([1, 2]), 0.005)
    with pytest.raises(ValueError, match="outside the points"):
        outside_turned(xy, np.array([0]), np.array([9]), np.array([2]), 0.005)
    assert outside_turned(xy, np.zeros(0, int), np.zeros(0, int), np.zeros(0, int), 0.005).size == 0
