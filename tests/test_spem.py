"""Tests of manifold_sph.spem: operators, solver checks, the five cases, lattice analysis."""

from __future__ import annotations

import math

import numpy as np
import pytest

from manifold_sph.spem import (
    C0,
    EPS0,
    PML,
    Layout,
    Sinusoid,
    Source,
    TMzSolver,
    cross_gradient,
    jitter,
    make_layout,
    point_source,
    sigma_max,
    yee_layout,
)
from manifold_sph.spem.analysis import (
    measured_phase_velocity,
    null_mode_response,
    phase_velocity,
    ppw_for_phase_error,
    yee_fdtd_phase_velocity,
)
from manifold_sph.spem.cases import (
    cavity_exact,
    cavity_frequency,
    guided_exact,
    peak_frequency,
    run_cavity,
    run_line1d,
    run_planewave,
    run_pml,
    run_waveguide,
)


# --------------------------------------------------------------------------- operators
@pytest.mark.parametrize("d", [1, 2])
def test_fpm_differentiates_linear_fields_exactly_on_random_sets(d):
    rng = np.random.default_rng(1)
    rows, cols = rng.random((300, d)), rng.random((400, d))
    a = np.arange(1.0, d + 1.0)
    f = 0.7 + cols @ a
    D = cross_gradient(rows, cols, 0.1 if d == 2 else 0.02, kernel="quintic")
    for k in range(d):
        np.testing.assert_allclose(D[k] @ f, a[k], atol=1e-9)


@pytest.mark.parametrize("form", ["cspm", "diagonal"])
def test_cspm_and_diagonal_forms_exact_on_symmetric_lattice_but_not_on_random(form):
    lay = yee_layout((0.0, 1.0, 0.0, 1.0), 0.1)
    e = lay.e[~lay.e_fixed]
    f = 2.0 * lay.hy[:, 0] - 3.0 * lay.hy[:, 1]
    Dx = cross_gradient(e, lay.hy, 0.07, form=form)[0]
    np.testing.assert_allclose(Dx @ f, 2.0, atol=1e-10)
    rng = np.random.default_rng(0)
    rows, cols = rng.random((200, 2)), rng.random((300, 2))
    Dx = cross_gradient(rows, cols, 0.1, form=form)[0]
    assert np.abs(Dx @ (2.0 * cols[:, 0]) - 2.0).max() > 0.1  # the Shepard centre is only zeroth order


def test_cross_gradient_rejects_isolated_rows_and_empty_sets():
    with pytest.raises(ValueError, match=r"1 of 2 E particles have fewer than 3 neighbours among the H particles"):
        cross_gradient(np.array([[0.0, 0.0], [5.0, 5.0]]), np.array([[0.1, 0.0], [0.0, 0.1], [-0.1, -0.1]]), 0.2,
                       row_name="E particles", col_name="H particles")
    with pytest.raises(ValueError, match="H particles is empty"):
        cross_gradient(np.zeros((3, 2)), np.zeros((0, 2)), 0.2, col_name="H particles")
    with pytest.raises(ValueError, match="form must be one of"):
        cross_gradient(np.zeros((3, 2)), np.ones((3, 2)), 0.2, form="sph")


# --------------------------------------------------------------------------- solver input checks
def test_cfl_refuses_unstable_dt_with_the_limit_in_the_message():
    lay = yee_layout((0, 0.1, 0, 0.1), 0.01)
    limit = 0.7 * 0.01 / (math.sqrt(2) * C0)
    TMzSolver(lay, dt=limit)  # exactly at the limit is accepted
    with pytest.raises(ValueError, match=r"violates the CFL condition S = sqrt\(2\) c dt / h_min = 1\.100 > 1.*use dt <= 1\.651e-11 s"):
        TMzSolver(lay, dt=1.1 * limit)
    with pytest.raises(ValueError, match="courant must be at most 1"):
        TMzSolver(lay, courant=1.5)


def test_bad_materials_layouts_and_sources():
    lay = yee_layout((0, 0.1, 0, 0.1), 0.01)
    with pytest.raises(ValueError, match=r"eps_r must be finite and positive at every particle, got -2\.0 at particle 0"):
        TMzSolver(lay, eps_r=-2.0)
    with pytest.raises(ValueError, match=r"sigma must be finite and non-negative"):
        TMzSolver(lay, sigma=-1.0)
    with pytest.raises(ValueError, match=r"eps_r must be a scalar or an array of shape \(121,\)"):
        TMzSolver(lay, eps_r=np.ones(3))
    with pytest.raises(ValueError, match="Hx particles is empty"):
        Layout(lay.e, np.zeros((0, 2)), lay.hy, 0.01)
    far = Layout(np.vstack([lay.e, [[5.0, 5.0]]]), lay.hx, lay.hy, 0.01, e_fixed=np.r_[lay.e_fixed, False])
    with pytest.raises(ValueError, match=r"1 of 82 E particles have fewer than 3 neighbours among the Hy particles"
                                         r".*index 81 at \[5\.0, 5\.0\]"):
        TMzSolver(far)
    with pytest.raises(ValueError, match="kind must be one of"):
        Source([0], Sinusoid(1e9), kind="magic")
    with pytest.raises(TypeError, match="layout must be a Layout"):
        TMzSolver(lay.e)
    with pytest.raises(ValueError, match=r"dr = 1\.0 is too large for bounds \(0\.0, 1\.0, 0\.0, 1\.0\)"):
        yee_layout((0, 1, 0, 1), 1)


# --------------------------------------------------------------------------- physics checks
def test_pec_cavity_conserves_energy_and_fixed_particles_stay_zero():
    lay = yee_layout((0, 0.1, 0, 0.1), 0.004)
    s = TMzSolver(lay)
    r = np.hypot(lay.e[:, 0] - 0.05, lay.e[:, 1] - 0.05)
    s.set_initial(np.exp(-((r / 0.015) ** 2)))
    peaks = []
    for _ in range(5):
        s.run(200)
        peaks.append(np.abs(s.e_field).max())
    assert np.all(s.e_field[lay.e_fixed] == 0.0)
    assert max(peaks) < 1.0  # bounded (no growth) over 1000 steps


def test_line1d_matches_the_travelling_sine_within_one_percent():
    r = run_line1d()  # the sizes of [2]: [0, pi], 1.8 GHz, dr = 1.66e-3, t = 4.75 ns
    assert r.error <= 1e-2
    assert r.error <= 5e-3  # measured 3.1e-3


def test_cavity_matches_bessel_series_within_1_percent_and_resonance_within_half_percent():
    assert float(cavity_exact(np.array([0.0]), 0.0)[0]) == pytest.approx(1.0, abs=1e-4)
    assert cavity_frequency() == pytest.approx(362.8e6, rel=1e-3)
    r = run_cavity(n_radial=20, spectrum_periods=10.0)
    assert r.error <= 0.01  # measured 2.4e-3 (sbp, the denser conforming wall; 3.9e-3 before it)
    assert r.f1_error <= 0.005  # measured 5.2e-4 (1.5e-3 before the denser wall)


@pytest.mark.slow
def test_cavity_converges_from_20_to_40_spacings_per_radius():
    r = run_cavity(n_radial=20)
    full = run_cavity(n_radial=40)
    assert full.error <= 0.002  # measured 1.26e-3: order 1.6 from 3.9e-3
    assert full.error < 0.5 * r.error


def test_cavity_eps_r_option_changes_the_period():
    r = run_cavity(n_radial=12, eps_r=4.0, r0=0.05)
    assert r.f1_exact == pytest.approx(cavity_frequency(0.05, 4.0))
    assert r.error <= 0.02


def test_peak_frequency_reads_a_sinusoid():
    dt = 1e-11
    t = np.arange(4000) * dt
    assert peak_frequency(np.cos(2 * np.pi * 3.1e8 * t), dt) == pytest.approx(3.1e8, rel=1e-3)


def test_waveguide_error_below_0p2_percent():
    r = run_waveguide()  # full size: 80 particles per wavelength, t = 4.1 ns, line x ~ 0.244 m
    assert r.error <= 0.002  # measured 3.6e-4


def test_guided_exact_tends_to_the_mode_and_is_causal():
    fc = 3e8
    u = guided_exact(Sinusoid(3.6e8, ramp=3.0), np.array([0.5, 15.0]), 40e-9, cutoff=fc)
    w, wc = 2 * np.pi * 3.6e8, 2 * np.pi * fc
    assert u[0] == pytest.approx(np.sin(w * 40e-9 - np.sqrt(w**2 - wc**2) / C0 * 0.5), abs=0.02)
    assert u[1] == 0.0  # the front (speed c) has not reached 15 m


def test_planewave_reduced_within_1_percent_without_alternating_rows():
    for layout in ("yee", "staggered"):
        r = run_planewave(size=0.2, ppw=20, layout=layout)
        assert r.error <= 0.01, layout  # measured 4.2e-3 / 4.3e-3
        assert r.adjacent_line_difference <= 0.01, layout  # measured 5.5e-4 / 1.1e-3


@pytest.mark.slow
def test_pml_reflection_below_minus_60_db_and_a_weak_layer_is_detected():
    r = run_pml(cells=30)
    assert r.reflection_normal_db <= -60  # measured -94.3 dB (sbp; direct -94.3)
    assert r.reflection_oblique_db <= -60  # measured -88.7 dB (sbp and direct)
    weak = run_pml(cells=30, pml_cells=2, reflection=0.3)
    assert weak.reflection_normal_db > -40


def test_sigma_max_formula():
    delta, n, R0 = 0.1, 3, 1e-6
    assert sigma_max(delta, n, R0) == pytest.approx(-math.log(R0) * (n + 1) * EPS0 * C0 / (2 * delta))
    with pytest.raises(ValueError, match="reflection must be below 1"):
        sigma_max(0.1, 3, 2.0)


def test_adjoint_coupling_keeps_a_jittered_layout_bounded():
    lay = jitter(yee_layout((0, 0.05, 0, 0.05), 0.0025), 0.2, seed=1)
    r = np.hypot(lay.e[:, 0] - 0.025, lay.e[:, 1] - 0.025)
    ez0 = np.exp(-((r / 0.006) ** 2)) * ~lay.e_fixed
    s = TMzSolver(lay, coupling="adjoint")
    s.set_initial(ez0)
    s.run(1500)
    assert np.abs(s.e_field).max() < 1.0


# --------------------------------------------------------------------------- lattice analysis
def test_staggered_layout_has_the_null_modes_and_yee_does_not():
    st, yee = null_mode_response("staggered"), null_mode_response("yee")
    assert st["dx_row_alternating"] < 1e-12 and st["dx_checkerboard"] < 1e-12
    assert yee["dx_row_alternating"] > 0.5 and yee["dx_checkerboard"] > 0.5


def _yee_fdtd_phase_velocity_measured(ppw, courant=1 / math.sqrt(2)):
    """A small periodic Yee FDTD solver (units c = dx = 1), wave along x.

    Starts from a standing wave; the projection a_n = sum Ez cos(kx) obeys
    a_{n+1} + a_{n-1} = 2 cos(w dt) a_n exactly, which gives w by least squares.
    """
    n = int(round(ppw * 6))
    k = 2 * np.pi * 6 / n
    dt = courant
    x = np.arange(n)
    ez, hy = np.cos(k * x), np.zeros(n)
    a = []
    for _ in range(400):
        a.append(ez @ np.cos(k * x))
        hy += dt * (np.roll(ez, -1) - ez)
        ez += dt * (hy - np.roll(hy, 1))
    a = np.array(a)
    cos_wdt = (a[1:-1] @ (a[2:] + a[:-2])) / (2 * a[1:-1] @ a[1:-1])
    return np.arccos(cos_wdt) / dt / k, n / 6


def test_yee_fdtd_reference_formula_matches_a_small_yee_solver_and_method_md():
    for ppw in (8.0, 10.0, 12.5):
        v, ppw_exact = _yee_fdtd_phase_velocity_measured(ppw)
        assert v == pytest.approx(yee_fdtd_phase_velocity(ppw_exact, courant=1 / math.sqrt(2)), abs=1e-9)
        assert v < 1.0
    assert 9.0 <= ppw_for_phase_error(0.01, fdtd=True) <= 10.0  # docs/method.md section 7: about 9-10 cells


def test_particles_per_wavelength_for_one_percent_phase_error():
    yee = ppw_for_phase_error(0.01, "yee")
    stag = ppw_for_phase_error(0.01, "staggered")
    wide = ppw_for_phase_error(0.01, "yee", h_ratio=1.5)
    assert 10 < yee < 14  # measured 12.1
    assert 15 < stag < 20  # measured 17.2
    assert wide > 30  # measured 35.6: wide kernels cost particles (the source needed ~40)
    assert phase_velocity(20, 0.0, "yee") < 1.0  # lagging, like FDTD


# --------------------------------------------------------------------------- slow, full size
@pytest.mark.slow
def test_planewave_full_size_yee_within_1_percent():
    r = run_planewave(ppw=40, layout="yee")
    assert r.error <= 0.01
    assert r.adjacent_line_difference <= 0.02


@pytest.mark.slow
def test_pml_full_size():
    r = run_pml()
    assert r.reflection_normal_db <= -60


@pytest.mark.slow
def test_source_truncated_line_excites_alternating_lines_on_the_staggered_layout_only():
    # the set-up of [2]: the line source covers only the interior, its ends diffract
    st = run_planewave(size=0.2, ppw=20, layout="staggered", source_span="interior")
    yee = run_planewave(size=0.2, ppw=20, layout="yee", source_span="interior")
    assert st.alternating_amplitude > 5 * yee.alternating_amplitude  # measured 3.5e-2 vs 4.1e-3


def test_two_workers_give_identical_fields():
    lay = yee_layout((0, 0.05, 0, 0.05), 0.0025)
    r = np.hypot(lay.e[:, 0] - 0.025, lay.e[:, 1] - 0.025)
    out = []
    for w in (1, 2):
        s = TMzSolver(lay, workers=w)
        s.set_initial(np.exp(-((r / 0.006) ** 2)))
        s.run(50)
        out.append(s.e_field)
    np.testing.assert_array_equal(out[0], out[1])


# --------------------------------------------------------------------------- CLI
def test_cli_json_and_pictures(tmp_path, capsys):
    import json

    from manifold_sph.spem.cli import main

    assert main(["cavity", "--n-radial", "10", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {"case", "particles", "steps", "seconds", "error"} <= set(out)
    assert out["case"] == "cavity" and out["error"] < 0.02
    png, gif = tmp_path / "f.png", tmp_path / "f.gif"
    assert main(["line1d", "--png", str(png), "--gif", str(gif), "--frames", "3"]) == 0
    assert png.stat().st_size > 0 and gif.stat().st_size > 0
    capsys.readouterr()
    assert main(["line1d", "--png", str(png)]) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err
    assert main(["cavity", "--ppw", "10"]) == 2
    assert "--ppw does not apply to case 'cavity'" in capsys.readouterr().err
    assert main(["pml", "--png", str(tmp_path / "p.png")]) == 2


def test_kronecker_system_imposes_values_and_reuses_its_factorisation():
    from manifold_sph.spem import KroneckerSystem

    rng = np.random.default_rng(3)
    lay = jitter(yee_layout((0, 1, 0, 1), 0.05), 0.2, seed=2)
    k = KroneckerSystem(lay.e, h=0.05)
    lu = k.lu
    for trial in range(3):
        f = rng.standard_normal(len(lay.e))
        u = k.nodal(f)
        np.testing.assert_allclose(k.values(u), f, atol=1e-10)
        assert not np.allclose(u, f)  # nodal parameters differ from the values (no Kronecker delta)
    assert k.lu is lu
    with pytest.raises(ValueError, match=r"values must have shape \(441,\)"):
        k.nodal(np.ones(3))


def test_staggered_layout_decouples_into_two_e_sublattices():
    # B-grid: E(i, j) talks to E(i +- 1, j +- 1) only, so a point source never reaches the other parity
    out = {}
    for name in ("staggered", "yee"):
        lay = make_layout(name, (0, 0.04, 0, 0.04), 1e-3)
        src = point_source(lay.e, (0.02, 0.02), Sinusoid(1.5e10), kind="soft")
        s = TMzSolver(lay, sources=[src])
        s.run(150)
        ij = np.round(lay.e / 1e-3).astype(int)
        odd = (ij.sum(axis=1) % 2) == 1
        out[name] = np.abs(s.e_field[odd]).max() / np.abs(s.e_field).max()
    assert out["staggered"] < 1e-12
    assert out["yee"] > 0.1


def test_measured_phase_velocity_matches_the_lattice_symbols():
    for layout in ("yee", "staggered"):
        v, ppw = measured_phase_velocity(layout, 4, cells=40)
        assert v == pytest.approx(phase_velocity(ppw, math.pi / 4, layout), abs=1e-4)  # measured: equal to 1e-5


@pytest.mark.slow
def test_sbp_coupling_is_stable_and_consistent_on_irregular_layouts():
    a = 0.1
    lay = jitter(yee_layout((0, a, 0, a), a / 40), 0.2, seed=1)
    s = TMzSolver(lay, coupling="sbp", h_ratio=1.0)
    assert s.dt <= s.dt_stable
    e = lay.e
    s.set_initial(np.sin(np.pi * e[:, 0] / a) * np.sin(np.pi * e[:, 1] / a))
    s.run(3000)
    assert np.abs(s.e_field).max() < 1.5  # bounded; "direct" grows by > 1e10 here
    v, ppw = measured_phase_velocity("jittered", 2, cells=40, coupling="sbp", h_ratio=0.8)
    assert abs(v - 1) < 0.01  # measured -0.34 % at 28 particles per wavelength (-1.54 % at 14: second order)


def test_materials_conductivity_damping_and_eps_mu_symmetry():
    a = 0.1
    lay = yee_layout((0, a, 0, a), a / 20)
    e = lay.e
    mode = np.sin(np.pi * e[:, 0] / a) * np.sin(np.pi * e[:, 1] / a)
    fields = []
    for eps_r, mu_r in ((4.0, 1.0), (1.0, 4.0)):
        s = TMzSolver(lay, eps_r=eps_r, mu_r=mu_r)
        s.set_initial(mode)
        s.run(300)
        fields.append(s.e_field)
    np.testing.assert_allclose(fields[0], fields[1], atol=1e-12)  # Ez depends on eps_r mu_r only
    # a weak uniform conductor damps the mode energy as exp(-sigma t / eps): amplitude exp(-sigma t / (2 eps))
    sigma = 0.05
    lossless, lossy = TMzSolver(lay), TMzSolver(lay, sigma=sigma)
    amp = []
    for s in (lossless, lossy):
        s.set_initial(mode)
        series = s.run(2000, probes=np.arange(len(e))).probes @ mode
        amp.append(np.abs(series[-400:]).max())
    expected = math.exp(-sigma * lossy.t / (2 * EPS0))
    assert amp[1] / amp[0] == pytest.approx(expected, rel=0.02)


def test_line1d_with_the_source_wide_kernel_needs_a_source_region():
    single = run_line1d(h=3e-3)  # the h/dr = 1.81 of [2] with one driven particle
    region = run_line1d(h=3e-3, source_width=6e-3)  # exact outgoing wave imposed within 2h
    assert single.error > 0.3  # measured 0.60: the lone particle radiates weakly
    assert region.error < 0.05  # measured 0.038, the wide kernel's dispersion (v/c = 0.998)


@pytest.mark.slow
def test_planewave_on_a_jittered_layout_with_sbp_coupling():
    r = run_planewave(size=0.2, ppw=20, layout="jittered", coupling="sbp", h_ratio=0.8)
    assert r.error <= 0.02  # measured 1.02e-2 (Yee lattice: 4.2e-3); "direct" is refused on this layout
    assert r.certified and r.pml_reflection_db < -60  # the layer on lattice particles: measured -87.6 dB


# --------------------------------------------------------------------------- mimetic coupling (issue 21 item 2)
def test_mimetic_operators_are_skew_adjoint_second_order_gradient_and_consistent_divergence():
    from manifold_sph.spem.mimetic import mimetic_operators

    lay = make_layout("poisson", (0.0, 1.0, 0.0, 1.0), 0.1, seed=1)
    free = ~lay.e_fixed
    ops = mimetic_operators(lay.e, free, [(lay.hy, 0), (lay.hx, 1)], h=0.15, scale=0.1)
    # conditions met to the accuracy of the (ill-conditioned) least-squares solve: measured ~2e-8
    assert ops.residual < 1e-6 and ops.vol_e[free].min() > 0 and min(v.min() for v in ops.vol_h) > 0
    e = lay.e
    q = 1.0 + e[:, 0] ** 2 - 2.0 * e[:, 0] * e[:, 1] + 0.5 * e[:, 1] ** 2 + e[:, 0] ** 2 * e[:, 1]
    for (G, D), axis, vh in zip(ops.pairs, (0, 1), ops.vol_h):
        h = lay.hy if axis == 0 else lay.hx
        x, y = h[:, 0], h[:, 1]
        exact = 2.0 * x - 2.0 * y + 2.0 * x * y if axis == 0 else -2.0 * x + y + x * x
        np.testing.assert_allclose(G @ q, exact, atol=1e-6)  # G exact for cubic fields
        np.testing.assert_allclose(D @ (3.0 - h[:, 0] + 2.0 * h[:, 1]), -1.0 if axis == 0 else 2.0, atol=1e-6)
        # D is exactly the negative adjoint of G in the volume inner products (energy conservation)
        adj = -(G[:, np.flatnonzero(free)].T.multiply(vh[None, :]).toarray() / ops.vol_e[free][:, None])
        np.testing.assert_allclose(D.toarray(), adj, rtol=1e-12, atol=1e-12 * abs(adj).max())


def test_mimetic_coupling_conserves_the_volume_weighted_leapfrog_energy_on_a_poisson_layout():
    a = 0.1
    lay = make_layout("poisson", (0.0, a, 0.0, a), a / 12, seed=2)
    s = TMzSolver(lay, coupling="mimetic", eps_r=lambda p: 1.0 + 3.0 * (p[:, 0] > a / 2))
    assert s.h == pytest.approx(1.5 * lay.dr)  # the coupling's default h_ratio
    fr, e = s.free, lay.e
    s.set_initial(np.exp(-(((e[:, 0] - a / 3) ** 2 + (e[:, 1] - a / 2) ** 2) / (0.1 * a) ** 2)))

    def modified_energy():  # sum V_E eps E^n.E^n + V_H mu H^{n-1/2}.H^{n+1/2}: conserved exactly
        ez = s.e_field
        hxp, hyp = s.hx + s.db_x * (s.Dy_hx @ ez), s.hy - s.db_y * (s.Dx_hy @ ez)
        return (EPS0 * (s.vol_e * s.eps_r[fr] * ez[fr] ** 2).sum() + (s.vol_hx * s.mu_r_x * s.hx * hxp).sum() * 4e-7 * np.pi
                + (s.vol_hy * s.mu_r_y * s.hy * hyp).sum() * 4e-7 * np.pi)

    w = []
    for _ in range(5):
        s.run(400)
        w.append(modified_energy())
    assert np.ptp(w) / w[0] < 1e-9  # measured ~1e-15


def test_mimetic_phase_error_is_second_order_where_sbp_is_not_on_a_poisson_layout():
    # TM22 mode of a unit PEC square, 14 spacings per side (9.9 particles per wavelength), seed 1
    v, ppw = measured_phase_velocity("poisson", 2, cells=14, coupling="mimetic", h_ratio=1.5, steps=400, seed=1)
    assert ppw == pytest.approx(9.9, abs=0.1)
    assert abs(v - 1) < 0.03  # measured -1.77 % (sbp: -2.85 %, then +0.38 % and +1.14 % at 28 and 56: no convergence)


@pytest.mark.slow
@pytest.mark.parametrize("layout", ["jittered", "poisson"])
def test_mimetic_phase_error_converges_at_second_order_on_irregular_layouts(layout):
    v1, _ = measured_phase_velocity(layout, 2, cells=14, coupling="mimetic", steps=400, seed=1)
    v2, ppw = measured_phase_velocity(layout, 2, cells=28, coupling="mimetic", steps=400, seed=1)
    # measured at 9.9 / 19.8 particles per wavelength: jittered -0.80 % / -0.03 %, poisson -1.77 % / -0.27 %
    # (the target is 0.5 % at 20; the spatial and leap-frog errors partly cancel at 19.8, so the ratio
    # overstates the order: at least second order is what is asserted)
    assert abs(v2 - 1) < 0.005
    assert math.log2(abs(v1 - 1) / abs(v2 - 1)) >= 1.8


def test_mimetic_refuses_too_small_supports_with_a_clear_error():
    lay = make_layout("poisson", (0.0, 0.1, 0.0, 0.1), 0.01, seed=1)
    with pytest.raises(ValueError, match="neighbours.*increase h_ratio"):
        TMzSolver(lay, coupling="mimetic", h_ratio=0.6)


@pytest.mark.parametrize("layout, coupling", [("yee", "sbp"), ("poisson", "sbp"), ("jittered", "adjoint")])
def test_compiled_step_gives_the_numpy_steps_numbers(monkeypatch, layout, coupling):
    """The compiled leap-frog step (one pass per half step) against the numpy one: the same numbers,
    bit for bit, with a hard and a soft source, a PML and a lossy dielectric."""
    from manifold_sph import _jit

    if not _jit.ENABLED:
        pytest.skip("the compiled kernels are off")
    a = 0.04
    lay = make_layout(layout, (0, a, 0, a), 1e-3, seed=1)
    fields = []
    for enabled in (True, False):
        monkeypatch.setattr(_jit, "ENABLED", enabled)
        srcs = [point_source(lay.e, (0.015, 0.02), Sinusoid(1.5e10), kind="soft"),
                point_source(lay.e, (0.025, 0.02), Sinusoid(1.0e10), kind="hard")]
        s = TMzSolver(lay, coupling=coupling, h_ratio=1.5, sources=srcs, sigma=lambda p: 0.5 * (p[:, 0] > 0.03),
                      eps_r=lambda p: 1.0 + 3.0 * (p[:, 1] > 0.03), pml=PML(0.006, interior=(0.006, 0.034, 0.006, 0.034)),
                      pml_check=False)
        s.run(120)
        fields.append((s.e_field.copy(), s.hx.copy(), s.hy.copy()))
    for x, y in zip(*fields):
        np.testing.assert_array_equal(x, y)
    assert np.abs(fields[0][0]).max() > 0.1  # the sources did drive the field
