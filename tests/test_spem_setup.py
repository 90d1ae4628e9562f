"""The sbp correction's normal equations: the fast solve gives the operators of the direct one.

``operators.normal_solve`` picks the fastest installed factorisation (CHOLMOD's supernodal Cholesky through
``cvxopt``, then ``cholespy``, then SuperLU). Every one factorises the same regularised matrix, so the corrected
operators may differ only by round-off, amplified by the near-null multiplier fields of the correction. Stated
tolerance (docs/spem.md, "Set-up of the sbp correction"): the corrected derivative matrices within 1e-6 of the
largest entry, the stable step within 1e-6 relative, the consistency residuals within 1e-8 absolute. Measured on
the jittered box below (625 E particles, the correction moves the entries by 0.62 of the largest): supernodal and
cholespy against SuperLU 3e-11 / 5e-11 in the operators, the same stable step, residuals within 4e-12; on the
0.25 m plane wave's normal equations (96,861 unknowns) the corrections differ by 6e-8 (supernodal) and 3e-7
(cholespy) of their largest entry from SuperLU's.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.sparse as sp

import manifold_sph.spem.operators as operators
from manifold_sph.spem import TMzSolver, make_layout
from manifold_sph.spem.operators import normal_solve, supernodal_available

A = 0.1


def _solver(method, monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(operators, "normal_solve", functools.partial(normal_solve, method=method))
        return TMzSolver(make_layout("jittered", (0.0, A, 0.0, A), A / 24, seed=3), coupling="sbp", sbp_layers=None)


def _rel(a, b):
    return float(abs(a - b).max() / abs(b).max())


@pytest.mark.parametrize("method", ["supernodal", "cholesky", "auto"])
def test_fast_normal_solve_keeps_the_operators(method, monkeypatch):
    if method == "supernodal" and not supernodal_available():
        pytest.skip("cvxopt not installed")
    ref = _solver("lu", monkeypatch)
    fast = _solver(method, monkeypatch)
    for name in ("Dx_e", "Dy_e", "Dx_hy", "Dy_hx"):
        assert _rel(getattr(fast, name), getattr(ref, name)) < 1e-6, name
    assert abs(fast.dt / ref.dt - 1.0) < 1e-6
    assert abs(fast.consistency_residual() - ref.consistency_residual()) < 1e-8
    assert abs(fast.interior_consistency_residual() - ref.interior_consistency_residual()) < 1e-8
    # the tolerance is a small fraction of the correction itself (measured 0.62 of the largest entry)
    plain = operators.cross_gradient(ref.layout.e[ref.free], ref.layout.hy, ref.h)[0]
    assert _rel(ref.Dx_e, plain) > 0.1


@pytest.mark.skipif(not supernodal_available(), reason="cvxopt not installed")
def test_supernodal_matches_superlu_on_a_normal_matrix():
    rng = np.random.default_rng(0)
    A_ = sp.random(300, 900, density=0.02, random_state=1, format="csr") + sp.hstack([sp.identity(300), sp.csr_matrix((300, 600))])
    AAt = (A_ @ A_.T).tocsc()
    b = rng.standard_normal(300)
    x = normal_solve(AAt, b, method="supernodal")
    y = normal_solve(AAt, b, method="lu")
    assert np.allclose(x, y, rtol=1e-10, atol=1e-12 * abs(y).max())


@pytest.mark.skipif(not supernodal_available(), reason="cvxopt not installed")
def test_supernodal_refuses_an_indefinite_matrix_and_auto_falls_back():
    M = sp.csc_matrix(np.array([[1.0, 2.0], [2.0, 1.0]]))
    with pytest.raises(ArithmeticError):
        normal_solve(M, np.ones(2), method="supernodal")
    assert np.allclose(M @ normal_solve(M, np.ones(2)), 1.0)


def test_normal_solve_rejects_an_unknown_method():
    with pytest.raises(ValueError, match="method"):
        normal_solve(sp.identity(2, format="csc"), np.ones(2), method="qr")
