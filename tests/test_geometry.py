"""Curvature, geodesic distance and spectral descriptors against exact references."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from manifold_sph import Domain2D, Surface, geometry
from manifold_sph.reference import sampling, shapes


def rel(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def quiet(*args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return Surface(*args, **kw)


def test_sphere_curvatures_and_signs():
    s = Surface(shapes.sphere(4000, radius=2.0))
    assert np.allclose(s.mean_curvature(), 0.5, rtol=2e-3)
    assert np.allclose(s.mean_curvature("laplacian"), 0.5, rtol=2e-2)
    assert np.allclose(s.gaussian_curvature(), 0.25, rtol=4e-3)
    k1, k2, d1, d2 = s.principal_curvatures()
    assert np.all(k1 >= k2) and np.allclose(k2, 0.5, rtol=4e-3)
    assert np.allclose(np.einsum("ij,ij->i", d1, d2), 0, atol=1e-12)
    assert np.allclose(np.einsum("ij,ij->i", d1, s.normals), 0, atol=1e-12)
    assert np.allclose(np.linalg.norm(d1, axis=1), 1.0)
    flipped = Surface(s.points, -s.normals)  # inward normals: the signs follow them
    assert np.allclose(flipped.mean_curvature(), -0.5, rtol=2e-3)
    assert np.allclose(flipped.gaussian_curvature(), 0.25, rtol=4e-3)  # K does not depend on the orientation


@pytest.fixture(scope="module")
def tori():
    return [shapes.torus(n) for n in (5000, 20000)]


def test_torus_curvature_converges_at_second_order(tori):
    """Torus R = 0.8, r = 0.2, Poisson-disk, exact normals: H and K, fitted order >= 1.8 in h (measured 2.0)."""
    eH, eK = [], []
    for c in tori:
        s = Surface(c, scheme="msph")
        eH.append(rel(s.mean_curvature(), 0.5 * c.geometry.mean_curvature(c.points)))
        eK.append(rel(s.gaussian_curvature(), c.geometry.gaussian_curvature(c.points)))
    for e in (eH, eK):
        order = np.log(e[0] / e[1]) / np.log(2.0)  # N x 4: h / 2
        assert order > 1.8, (e, order)
    assert eH[1] < 5e-4 and eK[1] < 3e-3  # measured 3.6e-4 and 2.3e-3 at N = 20000


def test_torus_curvature_msph4_and_principal_directions(tori):
    c = tori[0]
    s = Surface(c, scheme="msph4")
    P = c.points
    assert rel(s.mean_curvature(), 0.5 * c.geometry.mean_curvature(P)) < 1e-4  # measured 2.0e-5
    assert rel(s.gaussian_curvature(), c.geometry.gaussian_curvature(P)) < 5e-4  # measured 1.0e-4
    k1, k2, d1, _ = s.principal_curvatures()
    exact = c.geometry.principal_curvatures(P)
    assert rel(k1, exact[:, 0]) < 1e-4 and rel(k2, exact[:, 1]) < 1e-3
    ephi = np.stack([-P[:, 1], P[:, 0], np.zeros(len(P))], axis=1)
    tube = np.cross(c.normals, ephi / np.linalg.norm(ephi, axis=1)[:, None])  # the direction of k1 = 1 / r
    ang = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", d1, tube)), 0, 1)))
    assert np.median(ang) < 0.1


def test_curvature_from_bare_points(tori):
    """Normals estimated from the points (degree-4 jets for msph4): "auto" takes H from the
    normals' gradient, more accurate than the Laplacian of the coordinates."""
    c = tori[1]
    s = quiet(c.points, scheme="msph4")
    assert s.normals_estimated
    H = 0.5 * c.geometry.mean_curvature(c.points)
    assert rel(s.mean_curvature(), H) < 1.5e-4  # measured 6.5e-5 (1.1e-4 from the Laplacian)
    assert rel(s.mean_curvature(), H) < rel(s.mean_curvature("laplacian"), H)
    K = c.geometry.gaussian_curvature(c.points)
    assert rel(s.gaussian_curvature(), K) < 1e-3  # degree-2 normals: 7.9e-3 at N = 40,000


def test_curvature_on_random_points():
    p = np.random.default_rng(0).standard_normal((8000, 3))
    p /= np.linalg.norm(p, axis=1)[:, None]
    s = quiet(p, p.copy(), scheme="msph")
    assert rel(s.mean_curvature(), np.ones(8000)) < 5e-3  # measured 1.6e-3
    assert rel(s.gaussian_curvature(), np.ones(8000)) < 1e-2


def test_geodesic_distance_sphere():
    c = shapes.sphere(4000)
    s = Surface(c, scheme="msph4")
    P = c.points
    d = s.geodesic_distance(0)
    exact = np.arccos(np.clip(P @ P[0], -1, 1))
    assert d[0] == 0 and rel(d, exact) < 2e-3  # measured 9.6e-4
    two = s.geodesic_distance([0, 1234])
    exact2 = np.minimum(exact, np.arccos(np.clip(P @ P[1234], -1, 1)))
    assert rel(two, exact2) < 3e-2  # measured 2.2e-2 (the kink where the fronts meet, smoothed over t)
    # the factorisations are reused: the same answer again
    assert np.array_equal(s.geodesic_distance(0), d)


def test_geodesic_distance_converges():
    errs = []
    for n in (2500, 10000):
        c = shapes.sphere(n)
        d = Surface(c, scheme="msph4").geodesic_distance(7)
        errs.append(rel(d, np.arccos(np.clip(c.points @ c.points[7], -1, 1))))
    assert errs[1] < 0.7 * errs[0], errs  # measured 1.3e-3 -> 4.6e-4


def test_geodesic_distance_on_random_points_and_disconnected_clouds():
    p = np.random.default_rng(1).standard_normal((3000, 3))
    p /= np.linalg.norm(p, axis=1)[:, None]
    s = quiet(np.vstack([p, p + [5.0, 0, 0]]), np.vstack([p, p]), scheme="msph")
    d = s.geodesic_distance(0)
    exact = np.arccos(np.clip(p @ p[0], -1, 1))
    assert rel(d[:3000], exact) < 4e-2  # measured 2.2e-2 ("weak" divergence; the strong one gave 19)
    assert np.all(np.isinf(d[3000:]))  # the other sphere holds no source


def test_bad_input():
    s = Surface(shapes.sphere(1000))
    with pytest.raises(ValueError, match=r"sources must lie in \[0, 1000\), got \[1000\]"):
        s.geodesic_distance(1000)
    with pytest.raises(TypeError, match="sources must be integer particle indices"):
        s.geodesic_distance(0.5)
    with pytest.raises(ValueError, match="sources must hold at least one"):
        s.geodesic_distance([])
    with pytest.raises(ValueError, match="t must be a finite positive number"):
        s.geodesic_distance(0, t=-1.0)
    with pytest.raises(ValueError, match="divergence must be one of"):
        s.geodesic_distance(0, divergence="exact")
    with pytest.raises(ValueError, match="method must be one of"):
        s.mean_curvature("quadric")
    with pytest.raises(TypeError, match="surface must be a Surface, got Domain2D"):
        geometry.shape_operator(Domain2D(sampling.square(200, seed=0)))
    with pytest.raises(ValueError, match="times must be a non-empty 1-D array of positive"):
        geometry.heat_kernel_signature(s, [0.1, -1.0], k=10)
    with pytest.raises(ValueError, match="energies must be a non-empty 1-D array of finite"):
        geometry.wave_kernel_signature(s, [np.nan], k=10)
    with pytest.raises(TypeError, match="k must be an integer"):
        geometry.heat_kernel_signature(s, [0.1], k=2.5)


def test_spectral_descriptors():
    """On a sphere every point is alike: HKS and WKS are constant across points."""
    s = Surface(shapes.sphere(2000))
    t = np.array([0.01, 0.1, 1.0])
    H = geometry.heat_kernel_signature(s, t, k=36)
    assert H.shape == (2000, 3) and np.all(H > 0)
    assert np.all(H.std(axis=0) < 0.02 * H.mean(axis=0))
    # k(x, x, t) -> 1 / area for large t; the first 36 eigenpairs give the exact value at t = 1 to 1e-3
    assert np.isclose(H[:, 2].mean(), sum((2 * l + 1) * np.exp(-l * (l + 1)) for l in range(6)) / (4 * np.pi), rtol=1e-2)
    Hs = geometry.heat_kernel_signature(s, t, k=36, scale=True)
    assert np.allclose(s.mass_matrix().diagonal() @ Hs / s.mass_matrix().diagonal().sum(), 1.0)
    W = geometry.wave_kernel_signature(s, k=36, n_energies=20)
    assert W.shape == (2000, 20) and np.all(np.isfinite(W))
    assert np.all(W.std(axis=0) < 0.05 * W.mean(axis=0))
