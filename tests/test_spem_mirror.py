"""Mirror (PMC) walls of the TMz solver: the folded derivatives, the certificate, energy, the plane wave."""

import numpy as np
import pytest

from manifold_sph.spem import TMzSolver, jitter, yee_layout
from manifold_sph.spem.cases import run_planewave
from manifold_sph.spem.certify import CONSISTENCY_LIMIT
from manifold_sph.spem.constants import EPS0, MU0
from manifold_sph.spem.layouts import Layout, make_layout
from manifold_sph.spem.mirror import folded_gradient

DR = 0.01
PLANES = (-0.5 * DR, 0.2 + 0.5 * DR)


def _box(jittered=False):
    """A 0.2 x 0.2 box, PEC at bottom and top only, mirror planes half a spacing beyond the side columns."""
    lay = yee_layout((0.0, 0.2, 0.0, 0.2), DR)
    fixed = (np.abs(lay.e[:, 1]) < 1e-9) | (np.abs(lay.e[:, 1] - 0.2) < 1e-9)
    lay = Layout(lay.e, lay.hx, lay.hy, DR, lay.name, fixed, lay.bounds)
    return jitter(lay, 0.2, seed=3) if jittered else lay


@pytest.mark.parametrize("jittered", [False, True])
def test_folded_derivatives_are_exact_on_fields_even_or_odd_about_the_planes(jittered):
    lay = _box(jittered)
    e, hx, hy = lay.e, lay.hx, lay.hy
    e, hxr = (p[(p[:, 1] > 2 * DR) & (p[:, 1] < 0.2 - 2 * DR)] for p in (e, hx))  # rows away from the bottom and top
    kw = dict(planes=PLANES, spacing=DR, y_range=(0.0, 0.2))
    h = 0.7 * DR
    left, right = e[:, 0] < 0.1, e[:, 0] >= 0.1
    # Hy odd about each plane: x - m is exact where only plane m is in reach
    Dx = folded_gradient(e, hy, h, 0, odd=True, **kw)
    for m, rows in zip(PLANES, (left, right)):
        np.testing.assert_allclose((Dx @ (hy[:, 0] - m))[rows], 1.0, atol=1e-9)
    # Hx even: functions of y only (and constants) have the exact gradient (0, f'(y)), walls included
    Dy = folded_gradient(e, hx, h, 1, odd=False, **kw)
    np.testing.assert_allclose(Dy @ (3.0 + 2.0 * hx[:, 1]), 2.0, atol=1e-9)
    # E even, H rows
    ecols = lay.e
    hyr = hy[(hy[:, 1] > 2 * DR) & (hy[:, 1] < 0.2 - 2 * DR)]
    np.testing.assert_allclose(folded_gradient(hyr, ecols, h, 0, odd=False, **kw) @ (3.0 + 2.0 * ecols[:, 1]), 0.0,
                               atol=1e-9)
    np.testing.assert_allclose(folded_gradient(hxr, ecols, h, 1, odd=False, **kw) @ (1.0 - ecols[:, 1]), -1.0, atol=1e-9)
    # the fold is really there: x + 1 is not odd about the left plane, and the rows next to it miss it
    side = e[:, 0] < 0.5 * DR
    assert np.abs((Dx @ (hy[:, 0] + 1.0))[side] - 1.0).min() > 10.0


@pytest.mark.parametrize("jittered, limit", [(False, 1e-9), (True, CONSISTENCY_LIMIT)])
def test_the_certificate_measures_mirror_compatible_fields_and_passes(jittered, limit):
    lay = _box(jittered)
    s = TMzSolver(lay, mirror=PLANES)
    assert s.consistency_residual() < limit  # lattice: round-off (3e-14); jittered: measured 1.6e-8
    assert s.interior_consistency_residual() < limit


def _near_plane_residuals(s, lay, within):
    """Worst consistency residual (times dr) of the x pair (odd Hy columns) and of all four operators, over the
    rows within ``within`` of a mirror plane, on the mirror-compatible linear fields."""
    worst_x = worst = 0.0
    for D, cols, axis, rows in ((s.Dx_e, lay.hy, 0, lay.e[s.free]), (s.Dy_e, lay.hx, 1, lay.e[s.free]),
                                (s.Dx_hy, lay.e, 0, lay.hy), (s.Dy_hx, lay.e, 1, lay.hx)):
        near = np.abs(rows[:, [0]] - np.array(PLANES)[None, :]).min(axis=1) < within
        for f, target, mask in s._consistency_fields(rows, cols, axis, cols is not lay.e and axis == 0):
            r = float((np.abs(D @ f - target) * DR)[mask & near].max(initial=0.0))
            worst = max(worst, r)
            if axis == 0:
                worst_x = max(worst_x, r)
    return worst_x, worst


@pytest.mark.parametrize("seed", [0, 1, 3])
def test_sbp_pair_fitted_on_mirror_fields_is_consistent_next_to_the_planes_of_a_jittered_layout(seed):
    # sbp_pair(planes=): the rows and columns next to a plane are fitted on the mirror-compatible linear fields,
    # which the folded rows meet (1, y for Ez and Hx; x - m for Hy); fitted on plain linear fields they read
    # 2.3e-7 to 7.6e-7 on the x pair (seeds 3 / 1 / 0); fitted on the mirror fields 1.4e-10 to 3.1e-10 (x pair), 2.4e-8 at worst
    # (the y pair, as far from the planes: the regularised solve's level)
    lay = jitter(_box(), 0.2, seed=seed)
    s = TMzSolver(lay, mirror=PLANES)
    worst_x, worst = _near_plane_residuals(s, lay, 2 * DR)
    assert worst_x < 1e-8
    assert worst < 1e-7


@pytest.mark.parametrize("seed", [0, 1, 3])
def test_mirror_walls_keep_the_stable_step_of_a_jittered_layout_near_the_lattice(seed):
    # the stable step over the lattice's (same box, same planes): measured 0.56 / 0.75 / 0.74 (seeds 0 / 1 / 3);
    # fitted on plain linear fields next to the planes 0.14 / 0.12 / 0.26
    lattice = TMzSolver(_box(), mirror=PLANES).dt_stable
    s = TMzSolver(jitter(_box(), 0.2, seed=seed), mirror=PLANES)
    assert s.dt_stable > 0.45 * lattice


def test_sbp_pair_mirror_conditions_need_degree_one():
    from manifold_sph.spem.operators import cross_gradient, sbp_pair

    lay = _box()
    D = cross_gradient(lay.e, lay.hx, DR)[1]
    with pytest.raises(ValueError, match="degree=2"):
        sbp_pair(D, lay.e, lay.hx, 1, np.ones(len(lay.e)), np.ones(len(lay.hx)), scale=DR, degree=2, planes=PLANES,
                 reach=2 * DR)
    for planes, reach in (((np.nan, 1.0), 2 * DR), (PLANES, -DR), (PLANES, np.inf)):
        with pytest.raises(ValueError, match="planes must be finite x values and reach a finite length"):
            sbp_pair(D, lay.e, lay.hx, 1, np.ones(len(lay.e)), np.ones(len(lay.hx)), scale=DR, planes=planes, reach=reach)


@pytest.mark.parametrize("jittered", [False, True])
def test_mirrored_sbp_pair_is_skew_adjoint_and_conserves_the_leapfrog_energy(jittered):
    lay = _box(jittered)
    s = TMzSolver(lay, mirror=PLANES)
    fr = s.free
    for D, G in ((s.Dx_e, s.Dx_hy), (s.Dy_e, s.Dy_hx)):
        adj = -G[:, fr].T
        assert abs(D - adj).max() <= 1e-12 * abs(D).max()
    e = lay.e
    # a pulse touching both mirror walls
    s.set_initial(np.exp(-(((e[:, 0] - 0.02) ** 2 + (e[:, 1] - 0.1) ** 2) / 0.03**2)))

    def modified_energy():  # sum eps E^n E^n + mu H^{n-1/2} H^{n+1/2} (unit volumes): conserved exactly by leap-frog
        ez = s.e_field
        hxp, hyp = s.hx + s.db_x * (s.Dy_hx @ ez), s.hy - s.db_y * (s.Dx_hy @ ez)
        return EPS0 * (ez[fr] ** 2).sum() + MU0 * ((s.hx * hxp).sum() + (s.hy * hyp).sum())

    w = []
    for _ in range(4):
        s.run(150)
        w.append(modified_energy())
    assert np.ptp(w) / w[0] < 1e-10


def test_mirror_refusals_name_the_problem():
    lay = _box()
    with pytest.raises(ValueError, match="mimetic"):
        TMzSolver(lay, mirror=PLANES, coupling="mimetic")
    with pytest.raises(ValueError, match="spacings from a mirror plane"):
        TMzSolver(lay, mirror=(0.0, 0.2 + 0.5 * DR))  # the E column x = 0 lies on the plane
    with pytest.raises(ValueError, match="outside the planes"):
        TMzSolver(lay, mirror=(0.05 + 0.5 * DR, 0.2 + 0.5 * DR))
    with pytest.raises(ValueError, match="one or two finite"):
        TMzSolver(lay, mirror=(np.nan,))
    with pytest.raises(ValueError, match="side"):
        run_planewave(size=0.05, ppw=10, side="pec")


def test_shared_h_particles_are_folded_even_for_hx_and_odd_for_hy():
    # staggered: Ez at the nodes (PEC side columns here), H shared at the cell centres: the same particles
    # are folded with the even sign for the y derivative (Hx) and the odd sign for the x derivative (Hy)
    lay = make_layout("staggered", (0.0, 0.2, 0.0, 0.2), DR)
    s = TMzSolver(lay, mirror=PLANES)
    assert s.consistency_residual() < CONSISTENCY_LIMIT


def test_planewave_error_is_lower_with_mirror_walls_than_with_side_layers_on_the_lattice():
    mirror = run_planewave(size=0.25, ppw=40)
    layers = run_planewave(size=0.25, ppw=40, side="pml")
    assert mirror.side == "mirror" and layers.side == "pml"
    assert mirror.error < 0.8 * layers.error  # measured 1.54e-3 against 2.18e-3
    assert mirror.steps == layers.steps
    assert mirror.certificate_failures == ()


def test_planewave_error_is_lower_with_mirror_walls_than_with_side_layers_on_a_jittered_layout():
    # 0.2 m square at 20 per wavelength, seed 0 (at 0.15 m / 30 per wavelength the two are within 12 %:
    # the side layers' grazing error grows with the square, docs/spem.md)
    mirror = run_planewave(size=0.2, ppw=20, layout="jittered")
    layers = run_planewave(size=0.2, ppw=20, layout="jittered", side="pml")
    assert mirror.error < 0.85 * layers.error  # measured 7.82e-3 against 1.02e-2
    assert mirror.steps <= layers.steps  # measured 74 against 75
    assert mirror.certificate_failures == ()


def test_staggered_planewave_keeps_side_layers_and_refuses_mirror_walls():
    assert run_planewave(size=0.05, ppw=10, layout="staggered").side == "pml"
    with pytest.raises(ValueError, match="staggered"):
        run_planewave(size=0.05, ppw=10, layout="staggered", side="mirror")


def test_cli_planewave_sides(capsys):
    import json

    from manifold_sph.spem.cli import main

    for extra, side in (([], "mirror"), (["--sides", "pml"], "pml")):
        assert main(["planewave", "--size", "0.05", "--ppw", "10", "--json", *extra]) == 0
        assert json.loads(capsys.readouterr().out)["side"] == side
    assert main(["planewave", "--size", "0.05", "--ppw", "10", "--layout", "staggered", "--sides", "mirror"]) == 2
    assert "staggered" in capsys.readouterr().err
    assert main(["cavity", "--sides", "pml"]) == 2  # planewave only
