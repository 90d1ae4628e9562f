"""The stencil fast path of the TMz step (``manifold_sph.spem.stencil``, ``TMzSolver(stencil=True)``).

Rows that repeat one stencil (to ``RTOL`` = 1e-13 of the operator's largest entry) are applied with
their pattern's weights, so the fields differ from the plain CSR step (``stencil=False``) by round-off:
these tests allow 3e-13 of the largest |field| after 200 steps (measured: 6e-14 on the Yee lattice,
5e-14 on the staggered one), and bit-for-bit equality where no row is snapped (jittered layouts) and
between the compiled and numpy steps (which apply the same weights).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from manifold_sph import _jit
from manifold_sph.spem import PML, Sinusoid, TMzSolver, make_layout, point_source, yee_layout
from manifold_sph.spem.constants import EPS0, MU0
from manifold_sph.spem.stencil import RTOL, find_runs

A = 0.032
DR = 1e-3
TOL = 3e-13


def _solver(layout, stencil, **kw):
    """A lattice with a PML, a soft and a hard source, a lossy and a dielectric region."""
    lay = make_layout(layout, (0, A, 0, A), DR, seed=1)
    srcs = [point_source(lay.e, (0.010, 0.016), Sinusoid(1.5e10), kind="soft"),
            point_source(lay.e, (0.022, 0.016), Sinusoid(1.0e10), kind="hard")]
    return TMzSolver(lay, sources=srcs, sigma=lambda p: 0.5 * (p[:, 0] > 0.024), eps_r=lambda p: 1.0 + 3.0 * (p[:, 1] > 0.024),
                     pml=PML(0.005, interior=(0.005, 0.027, 0.005, 0.027)), stencil=stencil, **kw)


def _fields(s, steps=200):
    s.run(steps)
    return s.e_field.copy(), s.hx.copy(), s.hy.copy()


def _rel(a, b):
    return float(np.abs(a - b).max() / np.abs(b).max())


@pytest.mark.parametrize("layout", ["yee", "staggered"])
def test_stencil_step_equals_the_csr_step_to_round_off_on_lattices_with_pml_sources_and_losses(layout):
    fast, plain = _solver(layout, True), _solver(layout, False)
    pl = fast._step_plan()
    # in runs: the rows off the PML corners (one coefficient per PML line; measured 79 % / 100 %)
    assert pl.e.covered + pl.h.covered > 0.75 * (pl.e.n_rows + pl.h.n_rows)
    stencil_rows = pl.e.run_len[pl.e.run_w[:, 0] < 0].sum()
    assert stencil_rows > 0.4 * pl.e.n_rows  # the vacuum interior at least (PML lines: their own patterns)
    for a, b in zip(_fields(fast), _fields(plain)):
        assert np.abs(b).max() > 1e-3  # the sources drove the field
        assert _rel(a, b) < TOL


def test_jittered_layout_has_almost_no_stencil_rows_and_the_same_numbers_bit_for_bit():
    fast, plain = _solver("jittered", True), _solver("jittered", False)
    pl = fast._step_plan()
    assert (pl.e.run_w[:, 0] < 0).sum() == 0 and (pl.h.run_w[:, 0] < 0).sum() == 0  # no repeated stencil
    assert pl.e.covered + pl.h.covered < 0.1 * (pl.e.n_rows + pl.h.n_rows)
    for a, b in zip(_fields(fast), _fields(plain)):
        np.testing.assert_array_equal(a, b)  # weighted runs and CSR rows keep every row's own weights


def test_pml_corners_and_graded_materials_run_as_weighted_runs():
    lay = yee_layout((0, A, 0, A), DR)
    s = TMzSolver(lay, eps_r=lambda p: 1.0 + 100.0 * p[:, 0] * p[:, 1], pml=PML(0.005, interior=(0.005, 0.027, 0.005, 0.027)))
    pl = s._step_plan()
    assert (pl.e.run_c >= 0).any() and pl.e.covered == pl.e.n_rows  # every E row in a run, each its own eps
    assert pl.h.covered > 0.9 * pl.h.n_rows
    plain = TMzSolver(lay, eps_r=lambda p: 1.0 + 100.0 * p[:, 0] * p[:, 1], stencil=False,
                      pml=PML(0.005, interior=(0.005, 0.027, 0.005, 0.027)))
    start = np.exp(-((lay.e[:, 0] - 0.012) ** 2 + (lay.e[:, 1] - 0.016) ** 2) / 0.003**2)
    for t in (s, plain):
        t.set_initial(start)
    for a, b in zip(_fields(s, 150), _fields(plain, 150)):
        assert _rel(a, b) < TOL


def test_compiled_and_numpy_stencil_steps_agree_bit_for_bit(monkeypatch):
    if not _jit.ENABLED:
        pytest.skip("the compiled kernels are off")
    out = []
    for enabled in (True, False):
        monkeypatch.setattr(_jit, "ENABLED", enabled)
        out.append(_fields(_solver("yee", True), 120))
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)


def test_snapped_weights_stay_within_the_stated_tolerance():
    s = _solver("yee", True)
    pl = s._step_plan()
    Dx, Dy, Dhx, Dhy = s._step_operators()
    for snapped, D in ((Dx, s.Dx_e), (Dy, s.Dy_e), (Dhx, s.Dy_hx), (Dhy, s.Dx_hy)):
        dev = abs(sp.csr_matrix(snapped) - sp.csr_matrix(D)).max()
        assert dev < RTOL * abs(D).max()
    assert pl.e.coef.shape[1] == 4 and pl.h.coef.shape[1] == 2


def test_set_dt_rebuilds_the_runs_and_the_step_still_matches_csr():
    fast, plain = _solver("yee", True), _solver("yee", False)
    fast.run(20)
    plain.run(20)
    old = fast._step_plan()
    for s in (fast, plain):
        s.set_dt(0.5 * s.dt)
    assert fast._step_plan() is not old
    for a, b in zip(_fields(fast, 100), _fields(plain, 100)):
        assert _rel(a, b) < TOL


def test_threaded_stencil_step_gives_the_same_numbers(monkeypatch):
    from manifold_sph.spem import tmz as solver

    monkeypatch.setattr(solver, "THREADED_STEP", 100)  # thread this small lattice too
    out = []
    for workers in (1, 2):
        s = _solver("yee", True, workers=workers)
        out.append(_fields(s, 60))
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)


def test_h_is_updated_in_place_only_when_nobody_else_holds_it():
    lay = yee_layout((0, 0.03, 0, 0.03), DR)
    s = TMzSolver(lay)
    s.set_initial(np.exp(-((lay.e[:, 0] - 0.015) ** 2 + (lay.e[:, 1] - 0.015) ** 2) / 0.005**2))
    s.run(3)
    buf = id(s.hx.base)
    s.run(2)
    assert id(s.hx.base) == buf  # no other reference: the same buffer
    kept_x, kept_y = s.hx, s.hy[5:9]
    vx, vy = kept_x.copy(), kept_y.copy()
    s.run(3)
    np.testing.assert_array_equal(kept_x, vx)  # a kept array keeps its step's values, as with the numpy step
    np.testing.assert_array_equal(kept_y, vy)
    assert s.hx is not kept_x


def test_stencil_step_keeps_the_sbp_energy_on_a_lattice():
    lay = yee_layout((0, 0.03, 0, 0.03), DR)
    s = TMzSolver(lay, eps_r=lambda p: 1.0 + 3.0 * (p[:, 0] > 0.015))
    fr = s.free
    s.set_initial(np.exp(-((lay.e[:, 0] - 0.01) ** 2 + (lay.e[:, 1] - 0.015) ** 2) / 0.004**2))

    def energy():  # eps E^n.E^n + mu H^{n-1/2}.H^{n+1/2}, with the operators the step applies
        _, _, Dhx, Dhy = s._step_operators()
        ez = s.e_field
        hxp, hyp = s.hx + s.db_x * (Dhx @ ez), s.hy - s.db_y * (Dhy @ ez)
        return (EPS0 * (s.eps_r[fr] * ez[fr] ** 2).sum() + MU0 * (s.mu_r_x * s.hx * hxp).sum()
                + MU0 * (s.mu_r_y * s.hy * hyp).sum())

    w = []
    for _ in range(5):
        s.run(400)
        w.append(energy())
    assert np.ptp(w) / w[0] < 1e-9  # measured ~1e-14


def test_find_runs_on_a_difference_operator_with_a_boundary_row():
    n = 12
    D = sp.diags([-np.ones(n), np.ones(n - 1)], [0, 1], shape=(n, n)).tolil()
    D[n - 1, n - 2], D[n - 1, n - 1] = -1.0, 1.0  # a one-sided last row
    D = D.tocsr()
    D.data[3 * 2] *= 1 + 1e-15  # round-off on one row's weight: still the same stencil
    coefs = np.ones((n, 1))
    r = find_runs([D], np.arange(n), coefs)
    assert r.run_row.tolist() == [0] and r.run_len.tolist() == [n - 1] and r.rest.tolist() == [n - 1]
    assert r.offsets[0].tolist() == [0, 1] and r.weights[0].tolist() == [-1.0, 1.0]
    coefs[5] = 2.0  # another coefficient splits the run
    r = find_runs([D], np.arange(n), coefs, min_run=2)
    assert r.run_len.tolist() == [5, 5] and sorted(r.rest.tolist()) == [5, 11]
    # rows with the same offsets but other weights: a weighted run, each row's own weights
    W = sp.diags([-np.arange(1.0, n + 1), np.arange(1.0, n)], [0, 1], shape=(n, n)).tocsr()
    r = find_runs([W[: n - 1]], np.arange(n - 1), np.ones((n - 1, 1)))
    assert r.run_w[:, 0].tolist() == [0] and r.row_weights[0][: n - 1].tolist() == (-np.arange(1.0, n)).tolist()
    # ... and their own coefficients (a graded material, a PML corner)
    c = np.linspace(1.0, 2.0, n - 1)[:, None]
    r = find_runs([W[: n - 1]], np.arange(n - 1), c)
    assert r.run_c.tolist() == [0] and np.array_equal(r.row_coef, c) and len(r.rest) == 0
    r = find_runs([W[: n - 1]], np.arange(n - 1), np.ones((n - 1, 1)), row_weights=False)
    assert r.covered == 0 and len(r.rest) == n - 1


def test_bad_arguments_are_refused_with_clear_errors():
    D = sp.eye(4, format="csr")
    with pytest.raises(ValueError, match="targets must have shape"):
        find_runs([D], np.arange(3), np.ones((4, 1)))
    with pytest.raises(ValueError, match="every operator in mats must have 4 rows"):
        find_runs([D, sp.eye(5, format="csr")], np.arange(4), np.ones((4, 1)))
    with pytest.raises(ValueError, match="rtol must be"):
        find_runs([D], np.arange(4), np.ones((4, 1)), rtol=0.1)
    with pytest.raises(ValueError, match="coefs must have shape"):
        find_runs([D], np.arange(4), np.ones(4))
    with pytest.raises(TypeError, match="stencil must be a bool"):
        TMzSolver(yee_layout((0, 0.01, 0, 0.01), DR), stencil="yes")
