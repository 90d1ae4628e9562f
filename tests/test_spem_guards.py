"""What certifies a SPEM run, and the settings it refuses or adapts: consistency, energy, PML range, h per layout."""

import json

import numpy as np
import pytest

from manifold_sph.spem import PML, TMzSolver, jitter, make_layout, run_cavity, run_pml, yee_layout
from manifold_sph.spem.layouts import JITTER_H_RATIO, POISSON_SBP_H_RATIO
from manifold_sph.spem.tmz import PML_H_RATIO_MAX

A = 0.1


def test_consistency_residual_tells_consistent_couplings_from_the_adjoint_one():
    lay = jitter(yee_layout((0.0, A, 0.0, A), A / 10), 0.2, seed=1)
    assert TMzSolver(lay).consistency_residual() < 1e-8  # sbp: exact for linear fields
    assert TMzSolver(lay, coupling="adjoint").consistency_residual() > 0.1  # O(1) on irregular layouts
    assert TMzSolver(yee_layout((0.0, A, 0.0, A), A / 10), coupling="direct").consistency_residual() < 1e-12


def test_cavity_reports_its_certificates():
    r = run_cavity(n_radial=8)
    assert r.consistency < 1e-6 and r.energy_drift < 1e-12  # sbp: consistent, energy conserved to round-off
    d = r.to_dict()
    assert json.loads(json.dumps(d))["energy_drift"] == r.energy_drift


def test_energy_is_conserved_by_the_compiled_step_on_an_irregular_layout():
    lay = make_layout("jittered", (0.0, A, 0.0, A), A / 12, seed=2)
    s = TMzSolver(lay)
    x, y = lay.e[:, 0], lay.e[:, 1]
    s.set_initial(np.sin(np.pi * x / A) * np.sin(2 * np.pi * y / A))
    w0 = s.energy()
    s.run(300)
    assert abs(s.energy() / w0 - 1) < 1e-10


def test_layouts_carry_their_smoothing_length():
    b = (0.0, A, 0.0, A)
    assert yee_layout(b, A / 10).h_ratio is None and TMzSolver(yee_layout(b, A / 10)).h == pytest.approx(0.7 * A / 10)
    jit = make_layout("jittered", b, A / 10)
    assert jit.h_ratio == JITTER_H_RATIO and TMzSolver(jit).h == pytest.approx(JITTER_H_RATIO * A / 10)
    poi = make_layout("poisson", b, A / 16, seed=1)
    assert poi.h_ratio == POISSON_SBP_H_RATIO and TMzSolver(poi).h == pytest.approx(POISSON_SBP_H_RATIO * A / 16)
    assert TMzSolver(jit, h_ratio=1.0).h == pytest.approx(A / 10)  # an explicit h_ratio wins
    assert TMzSolver(poi, coupling="mimetic").h == pytest.approx(1.5 * A / 16)  # the coupling's own default


def test_pml_refused_outside_its_validated_support():
    lay = yee_layout((-0.02, A + 0.02, -0.02, A + 0.02), A / 20)
    pml = PML(0.02, interior=(0.0, A, 0.0, A))
    TMzSolver(lay, pml=pml, h_ratio=PML_H_RATIO_MAX)  # the edge of the range runs
    with pytest.raises(ValueError, match=r"h_ratio = 1\.3 is outside .* h_ratio <= 0\.8"):
        TMzSolver(lay, pml=pml, h_ratio=1.3)
    TMzSolver(lay, pml=pml, h_ratio=1.3, pml_check=False)  # asked for explicitly
    TMzSolver(lay, pml=pml, h_ratio=1.3, coupling="mimetic", mimetic_fast=True)  # not a lattice-type coupling


def test_cli_pml_with_a_wide_support_stops_with_the_range(capsys):
    from manifold_sph.spem.cli import main

    assert main(["pml", "--h-ratio", "1.3", "--json"]) == 2
    err = capsys.readouterr().err
    assert "h_ratio <= 0.8" in err and "-15 dB at 1.3" in err


def test_pml_case_runs_where_the_reference_domain_is_the_stiffer_one():
    # at h/dr 0.8 the larger reference domain has the smaller stable step: one dt within both limits
    r = run_pml(cells=24, pml_cells=8, h_ratio=0.8)
    # the consistency is the larger reference domain's operators' (measured 2.0e-5 at h/dr 0.8)
    assert r.reflection_normal_db < -40 and r.consistency < 1e-4


def test_tez_cavity_on_a_jittered_layout_takes_the_wall_closure_by_default():
    from manifold_sph.spem import run_tez_cavity

    lattice = run_tez_cavity()
    jit = run_tez_cavity(layout="jittered")
    # measured 1.9e-2 in 684 steps (lattice 9.1e-3 in 540); the plain walls gave 0.89 in 180,480 steps
    assert jit.error < 5 * lattice.error and jit.steps < 2 * lattice.steps
    with pytest.raises(TypeError, match="wall_closure"):
        run_tez_cavity(wall_closure="yes")
