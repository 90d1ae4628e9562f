"""The shared sparse solvers (manifold_sph.solvers) against scipy's spsolve on the package's own K and M."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from manifold_sph import Surface
from manifold_sph.reference import shapes
from manifold_sph.solvers import (
    NotPositiveDefiniteError,
    SolverConvergenceError,
    cholesky_available,
    linear_solver,
    spd_solver,
)

METHODS = ["amg"] + (["cholesky"] if cholesky_available() else [])


@pytest.fixture(scope="module")
def km():
    """K and M of a uniformly random sphere (non-uniform spacing), N = 3000."""
    s = Surface(shapes.sphere(3000, sampling="random", seed=3))
    return s.stiffness_matrix().tocsr(), s.mass_matrix().diagonal()


def _rel(x, y):
    return np.linalg.norm(x - y) / np.linalg.norm(y)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("dt", [1e-4, 1e-1])
def test_heat_matrix_matches_spsolve(km, method, dt):
    K, m = km
    A = (sp.diags(m) + dt * K).tocsr()
    b = m * np.random.default_rng(0).standard_normal(m.size)
    ref = spla.spsolve(A.tocsc(), b)
    s = spd_solver(A, method=method, rtol=1e-12)
    x = s.solve(b)
    assert s.method == method
    # direct: round-off; CG to rtol 1e-12 on a matrix of condition <= 1e3 here: error <= 1e-9
    assert _rel(x, ref) < (1e-12 if method == "cholesky" else 1e-9)
    assert s.info.residual < 1e-11
    assert s.info.solves == 1
    if method == "amg":
        assert 1 <= s.info.iterations <= 40
    # a second right-hand side reuses the set-up; several columns at once
    B = np.random.default_rng(1).standard_normal((m.size, 3))
    X = s.solve(B)
    assert X.shape == (m.size, 3)
    assert _rel(X, spla.spsolve(A.tocsc(), B)) < (1e-12 if method == "cholesky" else 1e-9)
    assert s.info.solves == 4


@pytest.mark.parametrize("method", METHODS)
def test_pinned_stiffness_matches_spsolve(km, method):
    """K with a few values held (the geodesic Poisson solve): SPD, condition ~ N."""
    K, m = km
    free = np.ones(m.size, bool)
    free[[0, 1000, 2000]] = False
    Kf = K[free][:, free].tocsr()
    b = m[free] * np.cos(np.arange(free.sum()))
    ref = spla.spsolve(Kf.tocsc(), b)
    x = spd_solver(Kf, method=method, rtol=1e-12).solve(b)
    assert _rel(x, ref) < (1e-11 if method == "cholesky" else 1e-8)


def test_scale_free(km):
    """The same system in other units (scaled by 1e-150): same relative accuracy and iterations."""
    K, m = km
    A = (sp.diags(m) + 1e-2 * K).tocsr()
    b = m.copy()
    ref = spd_solver(A, method="amg")
    x = ref.solve(b)
    for c in (1e-150, 1e150):
        s = spd_solver(A * c, method="amg")
        y = s.solve(b)
        assert _rel(y * c, x) < 1e-8
        assert s.info.iterations == ref.info.iterations
        if cholesky_available():
            assert _rel(spd_solver(A * c, method="cholesky").solve(b) * c, x) < 1e-8


def test_zero_rhs_and_x0(km):
    K, m = km
    A = (sp.diags(m) + 1e-2 * K).tocsr()
    s = spd_solver(A, method="amg")
    assert np.all(s.solve(np.zeros(m.size)) == 0)
    x = s.solve(m)
    s.solve(m, x0=x)
    assert s.info.iterations <= 1


def test_auto_and_info(km):
    K, m = km
    s = spd_solver(sp.diags(m) + K)
    assert s.method == ("cholesky" if cholesky_available() else "amg")
    s.solve(m)
    d = s.info.to_dict()
    assert d["method"] == s.method and d["n"] == m.size and d["setup_seconds"] >= 0
    assert "SolveInfo(" in repr(s.info)


def test_errors(km):
    K, m = km
    with pytest.raises(ValueError, match="square"):
        spd_solver(sp.random(5, 4, density=0.5))
    with pytest.raises(TypeError, match="sparse matrix"):
        spd_solver([[1.0]])
    bad = sp.diags(np.array([1.0, np.nan, 1.0]))
    with pytest.raises(ValueError, match="finite"):
        spd_solver(bad)
    with pytest.raises(NotPositiveDefiniteError, match="symmetric"):
        spd_solver(sp.diags([-1.0, 2.0, -0.5], [-1, 0, 1], shape=(20, 20)))
    with pytest.raises(NotPositiveDefiniteError, match="semi-definite"):
        spd_solver(K)  # singular: K @ 1 == 0 (zero diagonal rows of isolated points, or a zero pivot)
    with pytest.raises(ValueError, match="method"):
        spd_solver(sp.identity(3), method="lu")
    with pytest.raises(ValueError, match="rtol"):
        spd_solver(sp.identity(3), rtol=2.0)
    s = spd_solver(sp.identity(3), method="amg")
    with pytest.raises(ValueError, match=r"b must have shape \(3,\)"):
        s.solve(np.ones(4))
    with pytest.raises(ValueError, match="b must be finite"):
        s.solve(np.array([1.0, np.inf, 0.0]))


@pytest.mark.skipif(not cholesky_available(), reason="cholespy not installed")
def test_indefinite_refused_by_cholesky(km):
    K, m = km
    A = (K - sp.diags(0.5 * K.diagonal())).tocsr()  # symmetric, positive diagonal, indefinite
    with pytest.raises(NotPositiveDefiniteError, match="not positive definite"):
        spd_solver(A, method="cholesky")


def test_cg_nonconvergence_is_an_error(km):
    K, _ = km
    A = (K - sp.diags(0.5 * K.diagonal())).tocsr()
    with pytest.raises(SolverConvergenceError, match="not positive definite"):
        spd_solver(A, method="amg").solve(np.ones(A.shape[0]))
    A = (sp.diags(1e-6 * K.diagonal()) + K).tocsr()  # SPD, condition ~1e8: 2 iterations are not enough
    with pytest.raises(SolverConvergenceError, match="relative residual"):
        spd_solver(A, method="amg", maxiter=2).solve(np.cos(np.arange(A.shape[0])))


def test_linear_solver_fallbacks(km):
    K, m = km
    n = m.size
    # non-symmetric: LU, equal to spsolve
    A = (sp.diags(m) + 1e-2 * K).tocsr() + sp.diags(0.1 * m[1:], 1)
    b = np.sin(np.arange(n))
    s = linear_solver(A)
    assert s.method == "lu"
    assert _rel(s.solve(b), spla.spsolve(A.tocsc(), b)) < 1e-12
    # symmetric indefinite: LU, by the failed factorisation or the stalled CG
    B = (K - sp.diags(0.5 * K.diagonal())).tocsr()
    s = linear_solver(B, maxiter=20)
    x = s.solve(b)
    assert s.method == "lu"
    assert _rel(x, spla.spsolve(B.tocsc(), b)) < 1e-8
    # SPD: the SPD path
    assert linear_solver(sp.diags(m) + K).method in ("cholesky", "amg")
    with pytest.raises(ValueError, match="singular"):
        linear_solver(sp.csr_matrix((3, 3)) + sp.diags([1.0, 0.0, 1.0]), method="lu")
