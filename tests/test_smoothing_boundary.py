"""Smoothing open surfaces: fits at a rim widened where their neighbourhood is one-sided.

Uniformly random samples of a spherical cap (polar angle up to 60 degrees) with Gaussian noise of
0.5 ``h1`` per coordinate, ``h1`` the sample's mean distance from a point to its nearest other point;
the distance to the sphere is exact. Measured numbers are quoted in each test (docs/geometry.md).
"""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from manifold_sph import geometry
from manifold_sph.geometry import smoothing
from manifold_sph.geometry.smoothing import JET_WIDTH, RIM_RANGE, local_spacing, rim_offset

RIM = np.radians(60.0)


def random_cap(n, seed):
    """``n`` points uniformly random on the unit sphere's cap ``theta <= 60 deg``, their spacing ``h1``
    and their distance to the rim along the sphere."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(np.cos(RIM), 1.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    s = np.sqrt(1.0 - z * z)
    P = np.c_[s * np.cos(phi), s * np.sin(phi), z]
    h1 = float(cKDTree(P).query(P, k=2)[0][:, 1].mean())
    return P, h1, RIM - np.arccos(z), rng


def sphere_distance(X):
    return np.abs(np.linalg.norm(X, axis=1) - 1.0)


def test_rim_offset_sees_one_sided_neighbourhoods():
    """On a clean cap, fits over the default radius (about 9 ``h1``): the centroid offset is about a
    quarter of the radius at the rim and about 0.05 farther inside than the radius (measured, two
    samples: median 0.24-0.25 within 0.5 ``h1`` of the rim, 0.05 beyond 16 ``h1``, 95th percentile
    0.10 there); it does not change under scaling and rotation."""
    P, h1, to_rim, _ = random_cap(3000, 0)
    radius = JET_WIDTH * local_spacing(P)
    m = rim_offset(P, P, radius, count=250)
    assert np.median(m[to_rim < 0.5 * h1]) > RIM_RANGE[1]
    assert np.median(m[to_rim > 16 * h1]) < 0.6 * RIM_RANGE[0]
    assert np.percentile(m[to_rim > 16 * h1], 90) < RIM_RANGE[0]
    Q = np.linalg.qr(np.random.default_rng(1).standard_normal((3, 3)))[0]
    assert np.allclose(rim_offset(3.0 * P @ Q.T, P @ Q.T, 3.0 * radius, count=250), m, atol=1e-9)


def test_smoothing_reduces_the_noise_at_the_rim_of_an_open_surface(monkeypatch):
    """Cap of 3,000 points, seed 2: mean distance to the sphere of the points within 5 ``h1`` of the
    rim reduced 3.80x (2.94x with the same fits and no rim widening, ``RIM_WIDER = 1``); the whole
    cloud 4.62x (4.40x). Over seeds 0-4: 2.98x-4.72x at the rim against 2.70x-3.46x, every seed
    better (docs/geometry.md). Tolerances: 3.4x at the rim, 1.15 times the reduction without rim
    widening, 4.5x for the whole cloud."""
    P, h1, to_rim, rng = random_cap(3000, 2)
    noisy = P + 0.5 * h1 * rng.standard_normal(P.shape)
    near = to_rim < 5.0 * h1
    before = sphere_distance(noisy)
    after = sphere_distance(geometry.smooth(noisy).points)
    assert before[near].mean() / after[near].mean() > 3.4
    assert before.mean() / after.mean() > 4.5
    monkeypatch.setattr(smoothing, "RIM_WIDER", 1.0)
    one_sided = sphere_distance(geometry.smooth(noisy).points)
    assert one_sided[near].mean() > 1.15 * after[near].mean()


def test_smoothing_barely_moves_a_clean_open_cloud():
    """The clean cap, seed 2: mean distance to the sphere after smoothing 4e-6 ``h1`` (4e-6 within 3
    ``h1`` of the rim), largest displacement 1.5e-5 ``h1``. Tolerance 1e-3 ``h1``."""
    P, h1, to_rim, _ = random_cap(3000, 2)
    out = geometry.smooth(P).points
    assert sphere_distance(out).mean() < 1e-3 * h1
    assert sphere_distance(out)[to_rim < 3.0 * h1].mean() < 1e-3 * h1
    assert np.abs(out - P).max() < 1e-3 * h1


def test_rim_building_blocks_reject_bad_input_and_fit_chosen_rows():
    from manifold_sph.geometry.smoothing import jet_heights

    P, h1, _, _ = random_cap(400, 3)
    r = np.full(400, 6.0 * h1)
    with pytest.raises(ValueError, match="radius"):
        rim_offset(P, P, -r, count=20)
    with pytest.raises(ValueError, match="normals"):
        rim_offset(P, P[:10], r, count=20)
    with pytest.raises(ValueError, match="count"):
        rim_offset(P, P, r, count=0)
    with pytest.raises(ValueError, match="rows"):
        jet_heights(P, P, r, count=20, rows=np.array([0, 400]))
    rows = np.array([3, 50, 399])
    full, part = jet_heights(P, P, r, count=40, sigma=0.1 * h1), jet_heights(P, P, r, count=40, sigma=0.1 * h1, rows=rows)
    for a, b in zip(full, part):
        assert np.array_equal(a[rows], b[rows])
        assert not np.any(np.delete(b, rows, axis=0))
