"""The heat method's far field: directions from gradients far below float64's square root."""

from __future__ import annotations

import numpy as np
import pytest

from manifold_sph import Surface
from manifold_sph.frames import unit_rows
from manifold_sph.geometry import GeodesicSolver
from manifold_sph.reference import shapes


def test_unit_rows_of_any_magnitude():
    rng = np.random.default_rng(3)
    v = rng.standard_normal((50, 3))
    ref = v / np.linalg.norm(v, axis=1, keepdims=True)
    for scale in (1e-300, 1e-170, 1.0, 1e170, 1e300):
        np.testing.assert_allclose(unit_rows(v * scale), ref, rtol=1e-14, atol=0)
    assert not unit_rows(np.zeros((2, 3))).any()


def test_heat_geodesic_whose_far_gradient_underflows_when_squared():
    """t = 0.002 of the mean cell: u falls to ~1e-180 at the antipode of a 6,000-point sphere, so |grad u|^2
    underflows there; the distances stay within 8e-3 (relative L2; 4.3e-3 measured, 2.1e-2 when the far
    field's directions are lost)."""
    c = shapes.sphere(6000)
    s = Surface(c.points, c.normals)
    m = s.mass_matrix().diagonal().mean()
    d = GeodesicSolver(s, method="heat", t=0.002 * m).distance(0)
    exact = np.arccos(np.clip(c.points @ c.points[0], -1, 1))
    assert np.linalg.norm(d - exact) / np.linalg.norm(exact) < 8e-3


def test_banded_heat_step_matches_the_direct_one(monkeypatch):
    """Above GEODESIC_DIRECT_MAX_N the geodesic's heat step is AMG-CG in bands: a single CG solve loses the far
    field (relative error 0.11 at 20,000 points), the bands keep it: within 10 % of the Cholesky result's error
    (6.2e-4 both, measured) and the same distances to 2e-3 of the diameter."""
    import manifold_sph.distributed.solve as S

    c = shapes.sphere(20000)
    s = Surface(c.points, c.normals, area="shepard")
    K, m = s.stiffness_matrix(), s.mass_matrix().diagonal()
    dx, dy = s.derivative_matrices()
    exact = np.arccos(np.clip(c.points @ c.points[0], -1, 1))
    direct, info = S.geodesic_from_matrices(K, m, dx, dy, s.u, s.v, c.points, np.array([0]))
    assert info["iterations"][0] == 0 and info["method"].startswith("cholesky")
    monkeypatch.setattr(S, "GEODESIC_DIRECT_MAX_N", 1000)
    banded, info = S.geodesic_from_matrices(K, m, dx, dy, s.u, s.v, c.points, np.array([0]))
    assert info["method"].startswith("jacobi-cg windows") and len(info["iterations"]) >= 3  # several bands on this sphere
    e_direct = np.linalg.norm(direct - exact) / np.linalg.norm(exact)
    e_band = np.linalg.norm(banded - exact) / np.linalg.norm(exact)
    assert e_direct < 1e-3 and e_band < 1.1 * e_direct
    assert np.abs(banded - direct).max() < 2e-3 * 2.0


def test_band_directions_rejects_bad_input():
    import pytest

    from manifold_sph.distributed.bands import band_directions

    with pytest.raises(ValueError, match="rhs"):
        band_directions(None, np.array([1.0, np.nan]), None)
    with pytest.raises(ValueError, match="rhs"):
        band_directions(None, np.zeros(4), None)
    with pytest.raises(ValueError, match="floor"):
        band_directions(None, np.ones(4), None, floor=2.0)


def test_voxel_windows_hold_every_particle_near_a_seed():
    """The 27 voxels around a seed's hold every particle within one voxel side of it (brute force), and no more
    than those voxels' particles."""
    from manifold_sph.distributed.bands import VoxelWindows

    rng = np.random.default_rng(5)
    pts = rng.uniform(-1, 1, size=(4000, 3)) * [3.0, 1.0, 0.5]
    cell = 0.37
    vw = VoxelWindows(pts, cell)
    for seeds in (np.array([0]), rng.choice(4000, 25, replace=False)):
        rows = vw.rows(vw.around(vw.keys[seeds]))
        near = np.flatnonzero(np.linalg.norm(pts[:, None] - pts[seeds][None], axis=2).min(axis=1) <= cell)
        assert np.isin(near, rows).all() and np.all(np.diff(rows) > 0)
        # nothing beyond the 27 voxels: every row's voxel is within one voxel of a seed's on each axis
        q = np.floor((pts - pts.min(axis=0)) / cell).astype(int)
        assert (np.abs(q[rows][:, None] - q[seeds][None]).max(axis=2).min(axis=1) <= 1).all()
    with pytest.raises(ValueError, match="voxels"):
        VoxelWindows(np.array([[0.0, 0, 0], [1e9, 0, 0]]), 1e-3)


def test_windowed_heat_step_equals_the_whole_cloud_solve():
    """A band's solve on the window around its seed gives the whole cloud's solution where the bands use it (values
    above 1e-8 of the largest) to 1e-9 relatively, and zero outside the window."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    from manifold_sph.distributed.bands import WindowedHeat

    rng = np.random.default_rng(2)
    g = np.stack(np.meshgrid(np.arange(240.0), np.arange(240.0)), axis=-1).reshape(-1, 2)
    P = np.c_[g + rng.uniform(-0.3, 0.3, g.shape), np.zeros(len(g))]  # a jittered square of 240 spacings
    s = Surface(P, np.tile([0.0, 0.0, 1.0], (len(P), 1)), area="shepard")
    K, m = s.stiffness_matrix(), s.mass_matrix().diagonal()
    t = 4 * m.mean()
    A = (sp.diags(m) + t * K).tocsc()
    heat = WindowedHeat(A, P, t)
    b = np.zeros(m.size)
    b[np.argmin(np.linalg.norm(P - [120.0, 120.0, 0.0], axis=1))] = 1.0  # the middle: the window is 192 spacings wide
    w = heat.solve(b)
    assert 0 < heat.info.rows < 0.7 * m.size and heat.info.iterations > 0  # a window, not the cloud
    assert not w[np.linalg.norm(P - P[b > 0], axis=1) > 2 * 64 * np.sqrt(3)].any()
    full = spsolve(A, b)
    kept = full > 1e-8 * full.max()
    assert np.all(np.abs(w[kept] - full[kept]) <= 1e-9 * full[kept] + 1e-13 * full.max())


def test_band_solvers_reject_bad_input():
    import scipy.sparse as sp

    from manifold_sph.distributed.bands import VoxelWindows, WindowedHeat, jacobi_cg

    P = np.random.default_rng(0).uniform(size=(20, 3))
    A = sp.identity(20, format="csr")
    with pytest.raises(ValueError, match="points"):
        VoxelWindows(np.r_[P[:-1], [[np.nan, 0, 0]]], 0.5)
    with pytest.raises(ValueError, match="points"):
        VoxelWindows(P[:, :2], 0.5)
    with pytest.raises(ValueError, match="cell"):
        VoxelWindows(P, 0.0)
    with pytest.raises(ValueError, match="origin"):
        VoxelWindows(P, 0.5, origin=[0.0, 0.0])
    with pytest.raises(ValueError, match="t must"):
        WindowedHeat(A, P, -1.0)
    with pytest.raises(ValueError, match="one row per row of A"):
        WindowedHeat(A, P[:10], 1.0)
    with pytest.raises(ValueError, match="square"):
        WindowedHeat(sp.random(20, 10, format="csr"), P, 1.0)
    with pytest.raises(ValueError, match="b must"):
        WindowedHeat(A, P, 1.0).solve(np.ones(5))
    with pytest.raises(ValueError, match="b"):
        jacobi_cg(A, np.full(20, np.inf), 1e-12, 10)
    with pytest.raises(ValueError, match="rtol"):
        jacobi_cg(A, np.ones(20), 2.0, 10)
    with pytest.raises(ValueError, match="maxiter"):
        jacobi_cg(A, np.ones(20), 1e-12, 0)
    with pytest.raises(ValueError, match="positive diagonal"):
        jacobi_cg(-A, np.ones(20), 1e-12, 10)
    x, its = jacobi_cg(2 * A, np.ones(20), 1e-12, 10)  # the identity's multiple: one iteration
    assert its == 1 and np.allclose(x, 0.5)
