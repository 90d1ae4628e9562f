"""The heat method's far field: directions from gradients far below float64's square root."""

from __future__ import annotations

import numpy as np

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
