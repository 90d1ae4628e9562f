"""Normal estimation: PCA accuracy, consistent and outward orientation, confidence, bad input."""

import numpy as np
import pytest

from manifold_sph import shapes
from manifold_sph.normals import estimate_normals, orient_normals, pca_normals


def dots(a, b):
    return np.einsum("ij,ij->i", a, b)


@pytest.mark.parametrize(
    "cloud, min_dot",
    [
        (shapes.sphere(2000), 0.999),
        (shapes.torus(3000), 0.98),
        (shapes.double_torus(3000), 0.93),
        (shapes.sphere(3000, sampling="variable", density_ratio=4), 0.995),
    ],
    ids=["sphere", "torus", "double_torus", "variable_sphere"],
)
def test_estimated_normals_are_accurate_and_outward(cloud, min_dot):
    n = estimate_normals(cloud.points)
    assert n.shape == cloud.points.shape
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    d = dots(n, cloud.normals)
    assert d.min() > min_dot  # every normal outward and close to the exact one


def test_pca_normal_error_decreases_with_resolution():
    errs = []
    for n in (1000, 4000):
        c = shapes.sphere(n)
        est, _ = pca_normals(c.points, k=12)
        errs.append(np.degrees(np.arccos(np.clip(np.abs(dots(est, c.normals)), 0, 1))).max())
    assert errs[1] < 0.6 * errs[0]  # O(h): halving the spacing roughly halves the error


def test_orientation_recovers_random_flips_on_two_components():
    a = shapes.sphere(800)
    b = shapes.torus(1500, center=(4.0, 0.0, 0.0))
    p = np.vstack([a.points, b.points])
    exact = np.vstack([a.normals, b.normals])
    signs = np.where(np.random.default_rng(1).random(len(p)) < 0.5, -1.0, 1.0)[:, None]
    n, labels = orient_normals(p, signs * exact)
    np.testing.assert_allclose(n, exact, atol=1e-12)
    assert labels.max() + 1 == 2
    assert np.array_equal(np.unique(labels[:800]), [labels[0]])


def test_consistent_is_consistent_and_none_is_raw():
    c = shapes.torus(2000)
    n = estimate_normals(c.points, orient="consistent")
    d = dots(n, c.normals)
    assert (d > 0).all() or (d < 0).all()
    raw = estimate_normals(c.points, orient="none", method="pca")
    pca, _ = pca_normals(c.points, k=16)
    np.testing.assert_allclose(raw, pca)


def test_viewpoint_orientation():
    c = shapes.sphere(500)
    n = estimate_normals(c.points, orient=[0.0, 0.0, 0.0])  # towards the centre: inward
    assert dots(n, c.normals).max() < -0.99


def test_flat_patch_is_oriented_deterministically():
    rng = np.random.default_rng(0)
    p = np.c_[rng.uniform(size=(300, 2)), np.zeros(300)]
    n = estimate_normals(p)
    np.testing.assert_allclose(n, np.tile([0.0, 0.0, 1.0], (300, 1)), atol=1e-12)


def test_confidence_separates_flat_from_isotropic():
    rng = np.random.default_rng(0)
    flat = np.c_[rng.uniform(size=(400, 2)), 1e-4 * rng.standard_normal(400)]
    blob = rng.standard_normal((400, 3))
    _, cf = estimate_normals(flat, return_confidence=True)
    _, cb = estimate_normals(blob, return_confidence=True)
    assert cf.min() > 0.99
    assert np.median(cb) < 0.6
    assert ((0 <= cb) & (cb <= 1)).all()


@pytest.mark.parametrize("noise", [0.1, 0.3])
def test_noisy_sphere_normals_stay_outward(noise):
    c = shapes.sphere(3000, sampling="poisson")
    spacing = np.sqrt(4 * np.pi / 3000)
    p = c.points + noise * spacing * np.random.default_rng(2).standard_normal(c.points.shape)
    radial = p / np.linalg.norm(p, axis=1)[:, None]
    for k, slope, measured in ((None, 30, (2.5, 8.3)), (24, 12, (1.1, 3.5))):
        n = estimate_normals(p, k=k)
        assert dots(n, radial).min() > 0.5  # all outward
        # mean error (degrees); the default k = 12 fits the noise, a larger k averages it
        assert np.degrees(np.arccos(np.clip(dots(n, radial), -1, 1))).mean() < slope * noise + 0.5, measured


def test_deterministic():
    p = shapes.torus(1000).points
    np.testing.assert_array_equal(estimate_normals(p), estimate_normals(p))


@pytest.mark.parametrize(
    "args, kwargs, exc, match",
    [
        ((np.zeros((5, 2)),), {}, ValueError, r"points must have shape \(N, 3\)"),
        ((np.full((20, 3), np.nan),), {}, ValueError, "points must be finite"),
        ((np.random.default_rng(0).random((20, 3)),), {"k": 2}, ValueError, "k must be at least 3"),
        ((np.random.default_rng(0).random((20, 3)),), {"k": 21}, ValueError, "k must be at most the number of points 20"),
        ((np.random.default_rng(0).random((20, 3)),), {"k": 5.5}, TypeError, "k must be an integer"),
        ((np.random.default_rng(0).random((20, 3)),), {"orient": "inward"}, ValueError, "orient must be one of"),
        ((np.random.default_rng(0).random((20, 3)),), {"orient": [1.0, 2.0]}, ValueError, r"viewpoint of shape \(3,\)"),
        ((np.zeros((2, 3)),), {}, ValueError, "at least 3 points"),
    ],
)
def test_bad_input(args, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        estimate_normals(*args, **kwargs)


def test_orient_normals_shape_mismatch():
    p = np.random.default_rng(0).random((20, 3))
    with pytest.raises(ValueError, match=r"normals must have shape \(20, 3\)"):
        orient_normals(p, p[:10])
