"""Vertical lines' ends in one compiled pass against the numpy grouping it replaced."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.kernels.lines import HASH_X, HASH_Y, column_ends


def _hashes(p: np.ndarray) -> np.ndarray:
    bits = np.ascontiguousarray(p).view(np.uint64)
    return (((bits[:, 0] * HASH_X) ^ (bits[:, 1] * HASH_Y)) >> np.uint64(32)).astype(np.uint32)


def _reference(p: np.ndarray) -> np.ndarray:
    """The numpy grouping: two stable 16-bit radix passes over the hashes, runs of equal x, y
    bits in that order, each run's points strictly between its least and greatest z dropped."""
    bits = np.ascontiguousarray(p).view(np.uint64)
    x, y = bits[:, 0], bits[:, 1]
    h = _hashes(p)
    order = np.argsort(h.astype(np.uint16), kind="stable")
    order = order[np.argsort((h >> np.uint32(16)).astype(np.uint16)[order], kind="stable")]
    xs, ys = np.take(x, order), np.take(y, order)
    new_line = np.empty(len(p), dtype=bool)
    new_line[0] = True
    np.not_equal(xs[1:], xs[:-1], out=new_line[1:])
    new_line[1:] |= ys[1:] != ys[:-1]
    first = np.flatnonzero(new_line)
    run = np.diff(first, append=len(p))
    z = np.take(p[:, 2], order)
    inner = (z > np.repeat(np.minimum.reduceat(z, first), run)) & (
        z < np.repeat(np.maximum.reduceat(z, first), run)
    )
    keep = np.empty(len(p), dtype=bool)
    keep[order] = ~inner
    return keep


@settings(max_examples=80, deadline=None)
@given(
    lines=st.integers(1, 60),
    per=st.integers(1, 12),
    loose=st.integers(0, 50),
    nan=st.booleans(),
    seed=st.integers(0, 10_000),
)
def test_ends_match_the_numpy_grouping(lines, per, loose, nan, seed):
    rng = np.random.default_rng(seed)
    xy = np.round(rng.uniform(-1, 1, (lines, 2)), 2)  # repeated x, y: lines meet on a grid
    p = np.c_[np.repeat(xy, per, axis=0), np.round(rng.uniform(0, 1, lines * per), 2)]
    p = np.concatenate([p, rng.uniform(-1, 1, (loose, 3))])
    p[:, :2] *= rng.choice([1.0, -1.0], (len(p), 1))  # -0.0 and 0.0 are two lines, as bits
    if nan:
        p[rng.integers(0, len(p), 2), 2] = np.nan
    p = p[rng.permutation(len(p))]  # lines interleaved in input order
    np.testing.assert_array_equal(column_ends(p), _reference(p))


def test_a_hash_collision_splits_interleaved_lines_into_runs():
    # Two lines whose x, y hash alike, their points alternating: the numpy grouping saw
    # runs of one point each and kept all of them; so does the kernel.
    rng = np.random.default_rng(3)
    cand = np.c_[rng.uniform(0, 1, (1 << 18, 2)), np.zeros(1 << 18)]
    h = _hashes(cand)
    order = np.argsort(h, kind="stable")
    same = np.flatnonzero(h[order][1:] == h[order][:-1])
    a, b = cand[order[same[0]], :2], cand[order[same[0] + 1], :2]
    p = np.array([[*a, 0.0], [*b, 0.0], [*a, 0.5], [*b, 0.5], [*a, 1.0], [*b, 1.0]])
    assert column_ends(p).all() and _reference(p).all()
    one_line = np.array([[*a, 0.0], [*a, 0.5], [*a, 1.0], [*b, 0.0]])
    assert column_ends(one_line).tolist() == [True, False, True, True]


def test_empty_single_and_one_line():
    assert column_ends(np.zeros((0, 3))).shape == (0,)
    assert column_ends(np.array([[0.1, 0.2, 0.3]])).tolist() == [True]
    p = np.c_[np.zeros((5, 2)), [0.3, 0.1, 0.5, 0.1, 0.2]]
    assert column_ends(p).tolist() == [False, True, True, True, False]
