"""A surface's noise band: the noise measured by range, which points it keeps, raised patches."""

from __future__ import annotations

import numpy as np
import pytest

from supportnode.geometry.surfaces import detect_surfaces
from supportnode.geometry.surfaces.noise import fit_noise
from supportnode.params import SurfaceParams
from supportnode.sim.tabletop import case


@pytest.mark.parametrize("a, b", [(0.0012, 0.0004), (0.002, 0.0), (0.0, 0.0015)])
def test_noise_model_recovers_sigma_by_range(a, b):
    rng = np.random.default_rng(0)
    r = rng.uniform(0.5, 2.0, 200_000)
    sigma = np.hypot(a, b * r**2)
    residual = np.abs(rng.normal(0.0, sigma))
    model = fit_noise(np.zeros(len(r), np.int64), residual, r, 1)
    for rr in (0.6, 1.0, 1.8):
        want = np.hypot(a, b * rr**2)
        assert model.sigma(np.array([0]), rr)[0] == pytest.approx(want, rel=0.1)


def test_noise_model_without_a_sensor_is_one_sigma_per_surface():
    rng = np.random.default_rng(1)
    surface = np.repeat([0, 1], 50_000)
    residual = np.abs(rng.normal(0.0, np.where(surface == 0, 0.001, 0.004)))
    model = fit_noise(surface, residual, None, 2)
    np.testing.assert_allclose(model.b, 0.0)
    np.testing.assert_allclose(model.a, [0.001, 0.004], rtol=0.05)
    assert fit_noise(np.zeros(0, np.int64), np.zeros(0), None, 3).a.tolist() == [0, 0, 0]


def _table(noise: float, n: int = 300_000, seed: int = 0) -> np.ndarray:
    """A dense 1 m square table at z = 0 seen from 1 m above its centre."""
    rng = np.random.default_rng(seed)
    p = np.c_[rng.uniform(-0.5, 0.5, (n, 2)), np.zeros(n)]
    p[:, 2] += rng.normal(0.0, noise, n)
    return p


def test_a_dense_noisy_table_is_labelled_within_its_band():
    """A depth camera's table (1.5 mm noise, a point every ~2 mm): the band decides, about
    3.5 sigma wide, and keeps all but its tails."""
    pts = _table(0.0015)
    res = detect_surfaces(pts, SurfaceParams(), sensor_origin=np.array([0.0, 0.0, 1.0]))
    (table,) = res.surfaces
    assert table.band == (3.5, 0.003)
    assert np.hypot(*table.noise) == pytest.approx(0.0015, rel=0.2)
    assert table.band_width(1.0) == pytest.approx(3.5 * 0.0015, rel=0.2)
    assert (res.labels == 0).mean() > 0.99


def test_a_raised_patch_of_the_band_is_not_the_surface():
    """A sheet 5 mm thick, 12 cm square, lying on the table: within the band point by point,
    three sigma above it on average; it leaves the table, the table stays."""
    pts = _table(0.0015)
    sheet = (np.abs(pts[:, 0] - 0.2) < 0.06) & (np.abs(pts[:, 1]) < 0.06)
    pts[sheet, 2] += 0.005
    res = detect_surfaces(pts, SurfaceParams(), sensor_origin=np.array([0.0, 0.0, 1.0]))
    assert (res.labels[sheet] == -1).mean() > 0.9
    assert (res.labels[~sheet] == 0).mean() > 0.99


def test_a_sparse_noise_free_cloud_keeps_the_tolerance():
    """A thinly sampled, exact table (a simulator's sampled map): k-NN normals can vet its
    points, so its band is the tolerance (1 cm), as without a band."""
    pts = _table(0.0, n=20_000)
    res = detect_surfaces(pts, SurfaceParams())
    (table,) = res.surfaces
    assert table.band == (0.0, 0.01)
    off = detect_surfaces(pts, SurfaceParams(band_sigmas=0.0))
    np.testing.assert_array_equal(res.labels, off.labels)


@pytest.mark.slow
def test_a_kinect_view_keeps_the_table_and_leaves_the_objects_feet():
    """A simulated Kinect view of three boxes: the table is labelled to its noise, the boxes'
    points are not table (their feet go to them in the objects stage)."""
    c = case("boxes_at_0.5m", seed=0)
    ok = np.isfinite(c.cloud.points[:, 0])
    pts = c.cloud.points[ok].astype(np.float64)
    res = detect_surfaces(pts, SurfaceParams(), sensor_origin=c.cloud.sensor_pose[:3, 3])
    table = c.cloud.surface[ok] == c.scene.surface_names.index("table")
    on = res.labels == np.bincount(res.labels[table & (res.labels >= 0)]).argmax()
    assert (on & table).sum() / table.sum() > 0.97
    objects = c.cloud.object[ok] >= 0
    assert (on & objects).sum() / objects.sum() < 0.02
