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


# --- accuracy guards: certificates outside their validated range, supports outside theirs ---

def test_staggered_layer_absorbs_a_source_that_leaves_the_checkerboard_mode_alone():
    from manifold_sph.spem.certify import SHARED_SOURCE_WIDTH, pulse, pulse_source

    # a point source on the B-grid puts half its pulse into the checkerboard mode, which the split layer
    # does not absorb (measured -6.0 / -8.4 dB on this square); the Gaussian source leaves it unexcited
    r = run_pml(cells=20, layout="staggered")
    assert r.reflection_normal_db < -65 and r.reflection_oblique_db < -65  # measured -72.0 / -79.0 dB
    assert r.certified
    lay = make_layout("staggered", (0.0, 0.02, 0.0, 0.02), 1e-3)
    src = pulse_source(lay, (0.01, 0.01), pulse(1e-3)[0])
    ij = np.round(lay.e[src.indices] / 1e-3).astype(int).sum(axis=1) % 2
    w = src.waveform.weights
    # the checkerboard content of the source is below 1e-3 of its smooth content
    assert abs(w[ij == 0].sum() - w[ij == 1].sum()) < 1e-3 * w.sum()
    assert SHARED_SOURCE_WIDTH == 1.5 and w.max() == 1.0
    assert len(pulse_source(make_layout("yee", (0.0, 0.02, 0.0, 0.02), 1e-3), (0.01, 0.01), pulse(1e-3)[0]).indices) == 1


def test_a_weak_layer_is_not_certified_and_the_default_is():
    from manifold_sph.spem.certify import PML_REFLECTION_LIMIT_DB

    weak = run_pml(cells=20, pml_cells=2, reflection=0.3)
    assert weak.reflection_normal_db > PML_REFLECTION_LIMIT_DB
    assert not weak.certified and "above the validated -40 dB" in weak.certificate_failures[0]
    assert list(weak.to_dict()["certificate_failures"]) == list(weak.certificate_failures)
    yee = run_pml(cells=20)
    assert yee.certified and yee.certificate_failures == ()


def test_energy_drift_outside_its_range_fails_the_certificate():
    import dataclasses

    from manifold_sph.spem.certify import certificate_failures

    r = run_cavity(n_radial=8)
    assert r.certified  # drift at round-off
    bad = dataclasses.replace(r, energy_drift=1e-3)
    assert "energy drifts by 0.001" in certificate_failures(bad)[0]
    assert certificate_failures(dataclasses.replace(r, energy_drift=None)) == ()  # not measured: nothing to fail


def test_cli_exits_3_with_the_reason_when_a_certificate_fails(monkeypatch, capsys):
    import manifold_sph.spem.cases as cases
    from manifold_sph.spem.cli import main

    weak = run_pml(cells=20, pml_cells=2, reflection=0.3)
    monkeypatch.setattr(cases, "run_case", lambda case, **kw: weak)
    assert main(["pml", "--json"]) == 3
    out = capsys.readouterr()
    assert json.loads(out.out)["reflection_normal_db"] == weak.reflection_normal_db  # the numbers are printed
    assert "not certified: the PML reflects" in out.err


def test_tez_pml_refused_outside_its_validated_support(capsys):
    from manifold_sph.spem import TEzPMLSolver, tez_layout, wall_closure_layout
    from manifold_sph.spem.cli import main
    from manifold_sph.spem.tez import TEZ_PML_H_RATIO_MAX

    lay = wall_closure_layout(tez_layout((-0.02, A + 0.02, -0.02, A + 0.02), A / 10))
    pml = PML(0.02, interior=(0.0, A, 0.0, A))
    TEzPMLSolver(lay, pml=pml, h_ratio=TEZ_PML_H_RATIO_MAX)  # the edge of the range runs
    with pytest.raises(ValueError, match=r"h_ratio = 1 is outside .* h_ratio <= 0\.8"):
        TEzPMLSolver(lay, pml=pml, h_ratio=1.0)
    TEzPMLSolver(lay, pml=pml, h_ratio=1.0, pml_check=False)
    TEzPMLSolver(lay, h_ratio=1.3)  # no layer, nothing to refuse
    assert main(["tez-scatter-pec", "--n-radial", "4", "--h-ratio", "1.3", "--json"]) == 2
    assert "h_ratio = 1.3" in capsys.readouterr().err


def test_tez_rectangle_adapts_its_walls_to_a_wide_support_and_refuses_outside_its_range(capsys):
    from manifold_sph.spem import run_tez_cavity
    from manifold_sph.spem.cli import main

    lattice = run_tez_cavity()
    wide = run_tez_cavity(h_ratio=1.3)
    # the plain walls at h/dr 1.3 gave 0.32 (36x the lattice's 9.1e-3); the closure walls 5.0e-2 (5.5x)
    assert wide.wall_closure and not lattice.wall_closure and wide.h_ratio == 1.3
    assert wide.error < 10 * lattice.error
    assert run_tez_cavity(h_ratio=1.3, wall_closure=False).error > 10 * lattice.error  # what the adaptation avoids
    with pytest.raises(ValueError, match=r"h_ratio = 1\.3 is outside .* 'jittered' \(h_ratio <= 1\.0"):
        run_tez_cavity(layout="jittered", h_ratio=1.3)
    with pytest.raises(ValueError, match=r"layout = 'poisson' is outside the validated range"):
        run_tez_cavity(layout="poisson")
    with pytest.raises(ValueError, match="h_ratio"):
        run_tez_cavity(h_ratio=-1.0)
    assert main(["tez-cavity", "--layout", "poisson", "--json"]) == 2
    assert "layout = 'poisson'" in capsys.readouterr().err


def test_interior_consistency_separates_the_adjoint_walls_from_an_inconsistent_interior():
    from manifold_sph.spem import disk_layout
    from manifold_sph.spem.certify import CONSISTENCY_LIMIT

    b = (0.0, A, 0.0, A)
    lattice = TMzSolver(yee_layout(b, A / 20), coupling="adjoint")
    # measured: 2.3e-2 over every row (next to the walls), 2.2e-14 two supports away from them
    assert lattice.consistency_residual() > 1e-2 and lattice.interior_consistency_residual() < 1e-12
    disk = TMzSolver(disk_layout((0.0, 0.0), A, A / 10), coupling="adjoint")
    assert disk.consistency_residual() > 1.0 and disk.interior_consistency_residual() < 1e-12  # 7.0 / 1.9e-14
    jit = make_layout("jittered", b, A / 20, seed=0)
    assert TMzSolver(jit, coupling="adjoint").interior_consistency_residual() > 1.0  # measured 5.0
    assert TMzSolver(jit).interior_consistency_residual() < CONSISTENCY_LIMIT  # sbp: 7.5e-9
    with pytest.raises(ValueError, match="margin"):
        lattice.consistency_residual(margin=-1.0)


def test_adjoint_cavity_is_certified_on_the_lattice_and_not_on_a_jittered_layout():
    lattice = run_cavity(n_radial=8, coupling="adjoint")
    assert lattice.certified and lattice.consistency > 1.0  # inconsistent only next to the wall
    jit = run_cavity(n_radial=8, coupling="adjoint", layout="jittered")
    # at 10 spacings per radius: error 0.57, 47x the lattice's (the sbp cavity 1.2e-2)
    assert jit.error > 10 * lattice.error
    assert not jit.certified and "interior consistency residual" in jit.certificate_failures[0]
    # the staggered disk's sbp correction is not exact in the interior (1.4e-2) and accurate (0.80x): certified
    stag = run_cavity(n_radial=10, layout="staggered")
    assert 1e-3 < stag.consistency_interior < 0.5 and stag.certified and stag.error < 1.2e-2


def test_tez_disk_refuses_supports_outside_its_range(capsys):
    from manifold_sph.spem import run_tez_circular_cavity
    from manifold_sph.spem.cases.cavity import TEZ_DISK_H_RATIO_MAX
    from manifold_sph.spem.cli import main

    assert TEZ_DISK_H_RATIO_MAX["yee"] == 1.5 and TEZ_DISK_H_RATIO_MAX["poisson"] == 1.3
    # measured at 10 spacings per radius: lattice h/dr 2.0 0.28 (11x the default's 2.5e-2), Poisson 1.5 0.36 (14x)
    with pytest.raises(ValueError, match=r"h_ratio = 2 is outside the validated range of the TEz disk .* <= 1\.5"):
        run_tez_circular_cavity(n_radial=6, h_ratio=2.0)
    with pytest.raises(ValueError, match=r"layout 'poisson' \(h_ratio <= 1\.3"):
        run_tez_circular_cavity(n_radial=6, layout="poisson", h_ratio=1.5)
    r = run_tez_circular_cavity(n_radial=6, spectrum_periods=1.0, h_ratio=2.0, support_check=False)
    assert r.h_ratio == 2.0
    assert main(["tez-disk", "--h-ratio", "2.0", "--json"]) == 2
    assert "h_ratio = 2 is outside" in capsys.readouterr().err


def test_jittered_disk_carries_the_jittered_support_and_balanced_poisson_needs_mimetic():
    from manifold_sph.spem import disk_layout

    assert disk_layout((0.0, 0.0), A, A / 10, kind="jittered").h_ratio == JITTER_H_RATIO
    r = run_cavity(n_radial=10, layout="jittered")
    assert r.error < 1.2e-2 and r.certified  # measured 8.2e-3 (the lattice 1.2e-2)
    with pytest.raises(ValueError, match=r"layout = 'poisson-balanced' is validated with coupling='mimetic' only"):
        run_cavity(n_radial=10, layout="poisson-balanced")


def test_cavity_refuses_supports_and_poisson_resolutions_outside_its_range(capsys):
    from manifold_sph.spem.cases.cavity import CAVITY_H_RATIO_MAX, CAVITY_POISSON_N_RADIAL_MAX
    from manifold_sph.spem.cli import main

    # measured: lattice at h/dr 4.0 (10 per radius) 0.30, 25x; Poisson "sbp" at 80 per radius 5.2e-3, 16x
    assert CAVITY_H_RATIO_MAX["yee"] == 2.0 and CAVITY_POISSON_N_RADIAL_MAX == 40
    with pytest.raises(ValueError, match=r"h_ratio = 4 is outside the validated range of the cavity .* <= 2\.0"):
        run_cavity(n_radial=10, h_ratio=4.0)
    with pytest.raises(ValueError, match=r"n_radial = 80 is outside .* n_radial <= 40"):
        run_cavity(n_radial=80, layout="poisson")
    assert run_cavity(n_radial=6, h_ratio=4.0, support_check=False).error > 0  # asked for explicitly
    assert main(["cavity", "--n-radial", "10", "--h-ratio", "5", "--json"]) == 2
    assert "h_ratio = 5 is outside" in capsys.readouterr().err
