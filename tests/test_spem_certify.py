"""The PML certificate (:mod:`manifold_sph.spem.certify`): the sub-problem cut out of a reference solver, the
reflection measured on probes, and the plane wave and waveguide that report it."""

import numpy as np
import pytest

from manifold_sph.spem import (
    C0,
    PML,
    TMzSolver,
    make_layout,
    pml_certificate,
    point_source,
    restricted,
    run_planewave,
    run_pml,
    run_waveguide,
    yee_layout,
)
from manifold_sph.spem.certify import inside_box, pml_probe, pulse, pulse_problem

DR = 1e-3
A = 40 * DR  # reference square; the kept box leaves 8 spacings on every side
BOX = (8 * DR, A - 8 * DR, 8 * DR, A - 8 * DR)


def _bump_pair(name, pml=None):
    """A reference solver with a smooth bump (radius 4 spacings) at the centre, and its restriction to BOX."""
    lay = make_layout(name, (0.0, A, 0.0, A), DR, seed=1)
    ref = TMzSolver(lay)
    keep = inside_box(lay.e, BOX, 1e-6 * DR)
    sub = restricted(ref, keep, pml=pml)
    r = np.hypot(*(lay.e - A / 2).T)
    e0 = np.where(r < 4 * DR, np.cos(np.pi * r / (8 * DR)) ** 4, 0.0)
    ref.set_initial(e0)
    sub.set_initial(e0[keep])
    return ref, sub, keep


@pytest.mark.parametrize("name, tol", [("yee", 1e-9), ("jittered", 1e-4)])
def test_restricted_reproduces_the_reference_until_the_wave_reaches_the_cut(name, tol):
    ref, sub, keep = _bump_pair(name)
    assert sub.dt == ref.dt and sub.n_e == int(keep.sum()) < ref.n_e
    # the front (bump edge + c t) stops 4 spacings short of the cut, 12 spacings from the centre
    n = int(np.ceil(4 * DR / C0 / ref.dt))
    ref.run(n)
    sub.run(n)
    scale = np.abs(ref.e_field).max()
    diff = np.abs(ref.e_field[keep] - sub.e_field).max() / scale
    assert diff <= tol  # measured 2.8e-11 (yee), 1.8e-5 (jittered: the precursor of its stiffest modes)
    # the cut is a PEC wall: once the echo is back the two differ at O(1) (the comparison sees it)
    m = int(np.ceil(14 * DR / C0 / ref.dt))
    ref.run(m)
    sub.run(m)
    assert np.abs(ref.e_field[keep] - sub.e_field).max() / np.abs(ref.e_field).max() > 1e-2  # measured 1.7 / 0.83


def test_restricted_keeps_every_weight_of_the_kept_rows():
    lay = make_layout("jittered", (0.0, A, 0.0, A), DR, seed=1)
    ref = TMzSolver(lay)
    keep = inside_box(lay.e, BOX, 1e-6 * DR)
    sub = restricted(ref, keep)
    rows = keep[ref.free]
    # the kept E rows, restricted to the H columns they see, are the reference's rows
    assert abs(ref.Dx_e[rows]).sum() == pytest.approx(abs(sub.Dx_e).sum(), rel=1e-14)
    assert abs(ref.Dy_e[rows]).sum() == pytest.approx(abs(sub.Dy_e).sum(), rel=1e-14)
    np.testing.assert_array_equal(sub.eps_r, ref.eps_r[keep])
    np.testing.assert_array_equal(sub.layout.e, lay.e[keep])


def test_restricted_conserves_energy_without_a_layer_and_loses_it_with_one():
    ref, sub, keep = _bump_pair("jittered")
    w0 = sub.energy()
    sub.run(400)
    assert abs(sub.energy() / w0 - 1) < 1e-10  # measured 2.2e-16: a principal part of an energy-conserving pair
    pml = PML(6 * DR, interior=(14 * DR, A - 14 * DR, 14 * DR, A - 14 * DR))
    _, lossy, _ = _bump_pair("jittered", pml=pml)
    w0 = lossy.energy()
    lossy.run(400)
    assert lossy.energy() < 0.05 * w0  # the layer absorbs: measured 1.0e-2


def test_restricted_bad_input():
    s = TMzSolver(yee_layout((0.0, 0.02, 0.0, 0.02), DR))
    with pytest.raises(TypeError, match="solver"):
        restricted("solver", np.ones(3, bool))
    with pytest.raises(ValueError, match="keep"):
        restricted(s, np.ones(3, bool))
    with pytest.raises(ValueError, match="keep"):
        restricted(s, np.ones(s.n_e))  # not bool
    with pytest.raises(TypeError, match="pml"):
        restricted(s, np.ones(s.n_e, bool), pml="all")
    with pytest.raises(ValueError, match="coupling"):
        restricted(TMzSolver(yee_layout((0.0, 0.02, 0.0, 0.02), DR), coupling="direct"), np.ones(s.n_e, bool))
    src = TMzSolver(s.layout, sources=[point_source(s.layout.e, (0.001, 0.01), pulse(DR)[0], kind="soft")])
    with pytest.raises(ValueError, match="source"):
        restricted(src, s.layout.e[:, 0] > 0.005)


def test_certificate_of_the_yee_layer_is_below_minus_85_db_and_a_weak_layer_is_seen():
    cert = pml_certificate("yee", pml_cells=10)
    assert cert.normal_db <= -85 and cert.oblique_db <= -85  # measured -94.0 / -93.2 dB
    assert cert.worst_db == max(cert.normal_db, cert.oblique_db)
    assert set(cert.to_dict()) >= {"normal_db", "oblique_db", "layout", "pml_cells", "h_ratio", "coupling"}
    weak = pml_certificate("yee", pml_cells=2, reflection=0.3)
    assert weak.normal_db > -40  # the same measurement fails a layer that does not absorb
    assert pml_certificate("yee", pml_cells=10) is cert  # cached per configuration


def test_run_pml_measures_below_minus_85_db_on_the_yee_layout():
    r = run_pml(cells=20)
    assert r.reflection_normal_db <= -85 and r.reflection_oblique_db <= -85  # measured -94.0 / -93.2 dB
    assert r.reference_particles > r.particles and r.consistency < 1e-10  # the reference's operators


def test_staggered_probes_sit_on_the_source_sublattice():
    for cells in (20, 21, 30, 31):
        _, probes, c, _, _ = pulse_problem(cells, 10, DR, 3, 1e-6, "staggered")
        parity = np.round((probes - np.asarray(c)) / DR).sum(axis=1) % 2
        np.testing.assert_array_equal(parity, 0)


def test_pml_probe_gives_none_where_the_pulse_never_arrives():
    lay = yee_layout((0.0, 0.03, 0.0, 0.03), DR)
    ref = TMzSolver(lay, sources=[point_source(lay.e, (0.015, 0.015), pulse(DR)[0], kind="soft")])
    sub = restricted(ref, inside_box(lay.e, (0.005, 0.025, 0.005, 0.025), 1e-6 * DR))
    db, seconds = pml_probe(sub, ref, [[0.016, 0.015], [0.024, 0.024]], 3)  # 3 steps: nothing reaches the corner
    assert db[0] is not None and db[1] is None and seconds > 0


def test_planewave_and_waveguide_report_their_layers_reflection():
    r = run_planewave(size=0.1, ppw=20, pml_cells=8)
    assert r.pml_reflection_db <= -80  # measured -85.5 dB
    assert r.to_dict()["pml_reflection_db"] == r.pml_reflection_db
    assert run_planewave(size=0.1, ppw=20, pml_cells=8, certify=False).pml_reflection_db is None
    w = run_waveguide(ppw=40)
    assert w.pml_reflection_db <= -55  # a 5-cell layer: measured -63.1 dB
