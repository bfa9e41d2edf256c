"""A part held up at one narrow point is one object with what holds it (attached.py); a part
resting on a wide top is its own object on it."""

from __future__ import annotations

import numpy as np
from sparse_scenes import box_faces, detect_parts, table_surface, whole

TABLE = 0.75
SPACING = 0.02


def _shade(centre, r, z0, z1, rng) -> np.ndarray:
    """The side of a lamp shade (a cone's frustum, narrow at the top), no bottom: its inside
    is hidden from above."""
    n = rng.poisson(2 * np.pi * r * (z1 - z0) / SPACING**2)
    z = rng.uniform(z0, z1, n)
    rr = r * (1.0 - 0.6 * (z - z0) / (z1 - z0))
    a = rng.uniform(0, 2 * np.pi, n)
    return np.c_[centre[0] + rr * np.cos(a), centre[1] + rr * np.sin(a), z]


def test_a_shade_on_a_hidden_stem_is_one_object_with_its_base():
    rng = np.random.default_rng(0)
    foot = box_faces((-0.07, -0.07, TABLE), (0.07, 0.07, TABLE + 0.02), rng, SPACING)
    h = np.arange(TABLE + 0.02, TABLE + 0.18, 0.01)  # the stem, up to the shade's rim height
    stem = np.c_[np.zeros(len(h)), np.zeros(len(h)), h]
    shade = _shade((0.0, 0.0), 0.11, TABLE + 0.18, TABLE + 0.3, rng)
    res, (lamp, top) = detect_parts([np.r_[foot, stem], shade], table_surface(TABLE))
    assert whole(lamp) == whole(top)
    assert res.clusters[whole(lamp)].supported_by == -1


def test_only_a_narrow_holder_joins_what_it_holds():
    """Two components apart, the upper one's bottom at the lower one's top: joined when the
    lower one's top is a post (narrow), kept apart when it is a crate's rim (wide)."""
    from supportnode.geometry.objects.attached import join_attached

    rng = np.random.default_rng(1)
    # A crate's four walls (no top seen), 30 cm wide; a box over its middle, 1 cm above.
    crate = box_faces((-0.15, -0.15, TABLE), (0.15, 0.15, TABLE + 0.1), rng, SPACING)
    crate = crate[crate[:, 2] < TABLE + 0.1 - 1e-9]
    box = box_faces((-0.05, -0.05, TABLE + 0.11), (0.05, 0.05, TABLE + 0.2), rng, SPACING)
    # A post 1.5 cm wide under a plate 20 cm wide, elsewhere.
    h = np.arange(TABLE, TABLE + 0.1, 0.01)
    post = np.c_[np.full(len(h), 1.0), np.zeros(len(h)), h]
    plate = box_faces((0.9, -0.1, TABLE + 0.105), (1.1, 0.1, TABLE + 0.12), rng, SPACING)
    plate = plate[plate[:, 2] > TABLE + 0.105]  # its underside unseen
    cp = np.concatenate([crate, box, post, plate])
    lab = np.repeat(np.arange(4), [len(crate), len(box), len(post), len(plate)])
    out = join_attached(cp, lab, np.zeros(len(cp), np.int64), {0: TABLE})
    sizes = np.cumsum([0, len(crate), len(box), len(post), len(plate)])
    first = out[sizes[:-1]]
    assert len(np.unique(first[:2])) == 2  # the box rests on the crate: its own object
    assert first[2] == first[3]  # the plate is fixed on its post
    assert sorted(np.unique(out).tolist()) == [0, 1, 2]
    # Nothing under either: nothing is held (no surface, no support).
    np.testing.assert_array_equal(join_attached(cp, lab, np.full(len(cp), -1, np.int64), {}), lab)
