"""The eigenvalue solver (manifold_sph.spectrum, Surface.eigs): one contract for every size and method."""

import warnings

import numpy as np
import pytest
import scipy.linalg as sla

from manifold_sph import ManifoldSPHWarning, Surface
from manifold_sph.reference import shapes
from manifold_sph.spectrum import DENSE_MAX_N, Eigenpairs, stable_eigenpairs


def quiet_surface(*args, **kw):
    """A Surface built without the build's own warnings (the tests here are about eigs)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return Surface(*args, **kw)


@pytest.fixture(scope="module")
def rand():
    c = shapes.sphere(1800, sampling="random", seed=5)  # above DENSE_MAX_N: "auto" is iterative
    s = quiet_surface(c.points, c.normals)
    return s.stiffness_matrix(), s.mass_matrix().diagonal()


@pytest.fixture(scope="module")
def reference(rand):
    """All eigenvalues, by LAPACK on the dense pencil."""
    K, m = rand
    return sla.eigh(K.toarray(), np.diag(m), eigvals_only=True)


@pytest.mark.parametrize("method", ["dense", "shift-invert", "lobpcg"])
def test_methods_agree_with_dense_lapack(rand, reference, method):
    K, m = rand
    k = 4 if method == "lobpcg" else 12
    ev = stable_eigenpairs(K, m, k, method=method, tol=1e-6)
    assert ev.method == method
    # LOBPCG to residual 1e-6 (eigenvalue error ~ residual^2): 1e-9; the others round-off
    np.testing.assert_allclose(ev.values[1:], reference[1:k], rtol=1e-9)
    assert abs(ev.values[0]) < 1e-10
    V = ev.vectors
    np.testing.assert_allclose(V.T @ (m[:, None] * V), np.eye(k), atol=1e-7)
    np.testing.assert_allclose(K @ V, m[:, None] * V * ev.values, atol=1e-6 * ev.values.max())


@pytest.mark.parametrize("method", ["dense", "shift-invert"])
def test_sigma_gives_the_nearest_for_every_method(rand, reference, method):
    K, m = rand
    ref = reference
    want = np.sort(ref[np.argsort(np.abs(ref - 20.0))[:6]])
    ev = stable_eigenpairs(K, m, 6, sigma=20.0, method=method)
    np.testing.assert_allclose(ev.values, want, rtol=1e-9)
    assert ev.sigma == 20.0


def test_sigma_contract_is_the_same_below_and_above_the_dense_size():
    """Issue 38 item 5: at or below 1,500 points sigma was ignored."""
    for n in (DENSE_MAX_N - 500, DENSE_MAX_N + 500):
        lam = quiet_surface(shapes.sphere(n)).eigs(5, sigma=6.0).values
        assert np.all(np.abs(lam - 6.0) < 0.1), (n, lam)  # the l = 2 cluster, 6 = l (l + 1)


def test_scale_free_and_refused_out_of_range():
    c = shapes.sphere(800)
    ref = quiet_surface(c.points, c.normals).eigs(8).values
    for scale in (1e-100, 1e60):
        lam = quiet_surface(c.points * scale, c.normals).eigs(8).values * scale**2
        np.testing.assert_allclose(lam, ref, rtol=1e-8, atol=1e-12)
    with pytest.raises(ValueError, match=r"points: the mean area element .* outside \[1e-280"):
        quiet_surface(c.points * 1e-141, c.normals).eigs(8)  # built (spacing 1e-142), areas below eigs' range
    with pytest.raises(ValueError, match=r"points span 2e-155 .* less than 1e-145"):
        quiet_surface(c.points * 1e-155, c.normals)  # refused at the build, before any fit


def test_components_largest_all_and_by_particle():
    a, b = shapes.sphere(2000), shapes.sphere(300, radius=0.3)
    s = quiet_surface(np.vstack([a.points, b.points + 10]), np.vstack([a.normals, b.normals]))
    with pytest.warns(ManifoldSPHWarning, match="300 of 2300 particles .* left out"):
        ev = s.eigs(4)
    assert ev.excluded.tolist() == list(range(2000, 2300)) and ev.n_components == 2
    np.testing.assert_allclose(ev.values, [0, 2, 2, 2], atol=2e-2)
    assert np.all(ev.vectors[2000:] == 0)
    with pytest.warns(ManifoldSPHWarning, match="first 2 eigenvalues are 0"):
        lam = s.eigs(4, component="all").values
    assert np.all(lam[:2] < 1e-9) and lam[2] > 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        small = s.eigs(3, component=2100)  # the small sphere, radius 0.3: 2 / 0.09
    np.testing.assert_allclose(small.values[1:], 2 / 0.09, rtol=3e-2)
    assert small.excluded.size == 2000
    with pytest.raises(ValueError, match="component must be a particle index"):
        s.eigs(3, component=5000)
    with pytest.raises(ValueError, match=r"minus 1 \(299\) in the chosen connected piece"):
        s.eigs(299, component=2100)


def test_result_behaves_as_the_pair(rand):
    K, m = rand
    ev = stable_eigenpairs(K, m, 3)
    lam, V = ev
    assert isinstance(ev, Eigenpairs) and len(ev) == 2
    assert ev[0] is lam and ev[1] is V
    assert set(ev.to_dict()) == {"values", "vectors", "excluded", "n_components", "sigma", "method"}
    assert "Eigenpairs(values=<array (3,)" in repr(ev)


def test_refine_with_more_pairs_than_the_subspace_gains():
    """Issue 38 item 13: a complex pair of Ritz values made the Ritz basis rank-deficient (LinAlgError)."""
    c = shapes.sphere(200)
    ev = quiet_surface(c.points, c.normals).eigs(160, refine=True)
    assert ev.values.shape == (160,) and ev.method == "dense+refined"
    V = ev.vectors
    m = quiet_surface(c.points, c.normals).mass_matrix().diagonal()
    np.testing.assert_allclose(V.T @ (m[:, None] * V), np.eye(160), atol=1e-8)


def test_bad_arguments(rand):
    K, m = rand
    with pytest.raises(ValueError, match="method"):
        stable_eigenpairs(K, m, 3, method="arpack")
    with pytest.raises(ValueError, match="m must be"):
        stable_eigenpairs(K, -m, 3)
    with pytest.raises(TypeError, match="component"):
        stable_eigenpairs(K, m, 3, component=1.5)
    with pytest.raises(ValueError, match="lobpcg"):
        stable_eigenpairs(K, m, 3, sigma=10.0, method="lobpcg")
