"""PDEs on point-cloud surfaces against exact solutions; stability; bad input."""

import numpy as np
import pytest
import scipy.sparse as sp

from manifold_sph import Domain2D, Surface, pde
from manifold_sph.reference import functions, shapes
from manifold_sph.reference.accuracy import exact_operators


@pytest.fixture(scope="module")
def sphere():
    return shapes.sphere(2000)


@pytest.fixture(scope="module")
def surf(sphere):
    return Surface(sphere)


def harmonics(x):
    X, Y, Z = x.T
    return [(1, Z), (2, X * Y), (3, X * Y * Z)]


def rel(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


@pytest.mark.parametrize("method, tol", [("crank-nicolson", 1.2e-2), ("implicit", 3e-2)])
def test_heat_decays_spherical_harmonics(surf, sphere, method, tol):
    """u = exp(-k l(l+1) t) Y_l; at N = 2000 the Laplacian error (~1.5e-2) bounds the accuracy."""
    for l, Y in harmonics(sphere.points):
        u = pde.heat(surf, Y, dt=2e-3, steps=50, diffusivity=1.0, method=method).u
        assert rel(u, np.exp(-l * (l + 1) * 0.1) * Y) < tol, l


def test_heat_explicit_matches_implicit_below_limit(surf, sphere):
    Y = sphere.points[:, 2]
    limit = pde.explicit_dt_limit(surf)
    dt = 0.5 * limit
    steps = int(0.05 / dt)
    ue = pde.heat(surf, Y, dt=dt, steps=steps, method="explicit").u
    assert rel(ue, np.exp(-2 * steps * dt) * Y) < 1e-2


def test_explicit_refuses_unstable_dt_with_limit(surf, sphere):
    limit = pde.explicit_dt_limit(surf, diffusivity=2.0)
    with pytest.raises(ValueError, match=f"stability limit {limit:.4g}"):
        pde.heat(surf, sphere.points[:, 2], dt=1.5 * limit, steps=3, diffusivity=2.0, method="explicit")
    wl = pde.explicit_dt_limit(surf, c=1.0, equation="wave")
    with pytest.raises(ValueError, match="centred wave scheme's stability limit"):
        pde.wave(surf, sphere.points[:, 2], dt=1.2 * wl, steps=3)


def test_spectral_radius_against_dense():
    s = Surface(shapes.sphere(300), neighbors=20)
    L = s.laplacian_matrix().toarray()
    assert pde.spectral_radius(s.laplacian_matrix()) == pytest.approx(np.abs(np.linalg.eigvals(L)).max(), rel=1e-5)


def test_fixed_source_is_held_and_snapshots(surf, sphere):
    north = int(np.argmax(sphere.points[:, 2]))
    out = pde.heat(surf, np.zeros(2000), dt=1e-2, steps=30, fixed=[north], fixed_values=1.0, every=10)
    assert out.snapshots.shape == (4, 2000)
    assert np.allclose(out.times, [0, 0.1, 0.2, 0.3])
    assert np.all(out.snapshots[1:, north] == 1.0)
    assert out.snapshots[-1].mean() > out.snapshots[1].mean() > 0  # heat flows in from the source
    mask = np.zeros(2000, bool)
    mask[north] = True
    u = pde.heat(surf, np.zeros(2000), dt=1e-2, steps=30, fixed=mask, fixed_values=[1.0]).u
    assert np.allclose(u, out.snapshots[-1])


def test_callback_sees_every_step(surf, sphere):
    seen = []
    pde.heat(surf, sphere.points[:, 0], dt=1e-3, steps=5, callback=lambda i, t, u: seen.append((i, round(t, 6))))
    assert seen == [(i, round(i * 1e-3, 6)) for i in range(1, 6)]


@pytest.mark.parametrize("jacobi_iters", [500, 1, 0])
def test_iterative_solver_matches_direct(surf, sphere, monkeypatch, jacobi_iters):
    # 500: Jacobi-BiCGSTAB; 1: it fails and multigrid takes over; 0 with multigrid
    # disabled: the LU fallback
    monkeypatch.setattr(pde, "JACOBI_MAXITER", jacobi_iters)
    if jacobi_iters == 0:
        import pyamg

        monkeypatch.setattr(pyamg, "ruge_stuben_solver", lambda A: 1 / 0)
    Y = sphere.points[:, 1]
    a = pde.heat(surf, Y, dt=1e-2, steps=5, solver="direct").u
    b = pde.heat(surf, Y, dt=1e-2, steps=5, solver="iterative").u
    assert np.abs(a - b).max() < 1e-8


def test_wave_phase_and_energy(surf, sphere):
    """u = cos(sqrt(l(l+1)) t) Y_l: phase error after one period < 1%, energy drift small."""
    dV = surf.dV
    for l, Y in harmonics(sphere.points):
        w = np.sqrt(l * (l + 1))
        T = 2 * np.pi / w
        dt = T / 400
        snaps = pde.wave(surf, Y, dt=dt, steps=400, every=1)
        a = snaps.snapshots @ (dV * Y) / np.dot(dV * Y, Y)
        # phase from the last zero crossing before T (a ~ cos(w t) crosses zero at 3T/4)
        t = snaps.times
        i = np.flatnonzero((a[:-1] < 0) & (a[1:] >= 0))[-1]
        t0 = t[i] - a[i] * (t[i + 1] - t[i]) / (a[i + 1] - a[i])
        assert abs(t0 / (0.75 * T) - 1) < 1e-2, l
        e0 = pde.wave_energy(surf, snaps.snapshots[0], snaps.snapshots[1], dt)
        e1 = pde.wave_energy(surf, snaps.snapshots[-2], snaps.snapshots[-1], dt)
        assert abs(e1 - e0) < 1e-3 * abs(e0)


def test_wave_initial_velocity(surf, sphere):
    Y = sphere.points[:, 2]
    w = np.sqrt(2.0)
    u = pde.wave(surf, np.zeros(2000), dt=1e-2, steps=100, v0=w * Y).u  # u = sin(w t) Y
    assert rel(u, np.sin(w * 1.0) * Y) < 2e-2


def test_poisson_within_twice_the_laplacian_error(surf, sphere):
    for name in ("cos_xz_sin_y", "xyz", "z_cos_xy"):
        f, _, lap = exact_operators(sphere, getattr(functions, name))
        dV = surf.dV
        rhs = lap - np.dot(dV, lap) / dV.sum()
        u = pde.poisson(surf, rhs)
        fe = f - np.dot(dV, f) / dV.sum()
        assert rel(u, fe) <= 2 * rel(surf.laplacian(f), lap), name
        assert abs(np.dot(dV, u)) < 1e-10


def test_poisson_rejects_nonzero_mean(surf):
    with pytest.raises(ValueError, match=r"rhs must have zero mean .* sum\(dV \* rhs\) = 12.5"):
        pde.poisson(surf, np.ones(2000))


def test_poisson_on_a_domain_needs_dirichlet():
    rng = np.random.default_rng(0)
    g = (np.arange(30) + 0.5) / 30
    p = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2) + rng.uniform(-0.005, 0.005, (900, 2))
    d = Domain2D(p, scheme="msph")
    with pytest.raises(ValueError, match="needs a boundary condition"):
        pde.poisson(d, np.ones(900), laplacian="strong")
    with pytest.raises(ValueError, match="rhs must have zero mean"):  # the Neumann problem needs a zero-mean rhs
        pde.poisson(d, np.ones(900), laplacian="stable")
    x, y = p.T
    exact = x**2 + y**2  # Lap = 4, msph is exact on quadratics
    edge = np.flatnonzero((x < 0.05) | (x > 0.95) | (y < 0.05) | (y > 0.95))
    u = pde.poisson(d, np.full(900, 4.0), dirichlet=(edge, exact[edge]), laplacian="strong")
    assert np.abs(u - exact).max() < 1e-8


def test_screened_poisson(surf, sphere):
    for l, Y in harmonics(sphere.points):
        u = pde.screened_poisson(surf, (1 + 0.5 * l * (l + 1)) * Y, alpha=0.5)
        assert rel(u, Y) < 1.5e-2


def test_helmholtz_hodge_recovers_potentials(sphere, surf):
    x, n = sphere.points, sphere.normals
    gphi = sphere.geometry.surface_gradient(x, functions.cos_xz_sin_y.gradient(x))
    cog = np.cross(n, sphere.geometry.surface_gradient(x, functions.xyz.gradient(x)))
    d = pde.helmholtz_hodge(surf, gphi + cog + 0.3 * n)  # the normal part is discarded
    assert rel(d.gradient, gphi) < 3e-2
    assert rel(d.cogradient, cog) < 3e-2
    assert np.linalg.norm(d.harmonic) < 3e-2 * np.linalg.norm(gphi + cog)


def test_implicit_heat_does_not_grow(surf):
    # 300 steps to t = 0.3 (1000 before): a mode with eigenvalue +5 would already grow 4.5x
    u0 = np.random.default_rng(0).standard_normal(2000)
    u = pde.heat(surf, u0, dt=1e-3, steps=300, method="implicit").u
    assert np.abs(u).max() <= np.abs(u0).max()
    assert np.all(np.isfinite(u))


def test_stabilized_laplacians_have_left_half_plane_spectra():
    """On uniformly random samples the corrected Laplacian has growing modes; the stabilised ones do not."""
    s = Surface(shapes.sphere(800, sampling="random", seed=1), area="shepard", neighbors=27)
    assert pde.spectrum_right_edge(s.laplacian_matrix(), 2)[0].real > 1.0
    # "taylor": every Gershgorin disc in Re <= 0 (non-negative off-diagonals, zero row sums): a proof
    T = pde.stabilized_laplacian(s, "taylor").toarray()
    radius = np.abs(T).sum(axis=1) - np.abs(np.diag(T))
    assert np.all(np.diag(T) + radius <= 1e-12 * np.abs(T).max())
    # "weak": -M^-1 G^T M G is similar to the symmetric M^1/2 L M^-1/2, negative semi-definite
    W = pde.stabilized_laplacian(s, "weak").toarray()
    r = np.sqrt(s.dV)
    S = r[:, None] * W / r[None, :]
    np.testing.assert_allclose(S, S.T, rtol=0, atol=1e-10 * np.abs(S).max())
    assert np.linalg.eigvalsh(0.5 * (S + S.T)).max() < 1e-8 * np.abs(S).max()  # dense symmetric: fast
    for L in (T, W):
        u = pde.heat(s, np.random.default_rng(2).standard_normal(800), dt=1e-3, steps=200, laplacian=sp.csr_matrix(L)).u
        assert np.all(np.isfinite(u))
    T = pde.stabilized_laplacian(s, "taylor")
    off = T - sp.diags(T.diagonal())
    assert off.data.min() >= 0  # an M-matrix: I - dt L obeys the maximum principle


@pytest.mark.parametrize(
    "call, exc, match",
    [
        (lambda s: pde.heat(s, np.ones(3), 1e-3, 1), ValueError, r"u0 must have shape \(2000,\)"),
        (lambda s: pde.heat(s, np.ones(2000), 0.0, 1), ValueError, "dt must be a finite positive number"),
        (lambda s: pde.heat(s, np.ones(2000), 1e-3, 0), ValueError, "steps must be at least 1"),
        (lambda s: pde.heat(s, np.ones(2000), 1e-3, 1, method="rk4"), ValueError, "method must be one of"),
        (lambda s: pde.heat(s, np.ones(2000), 1e-3, 1, fixed=[5000]), ValueError, r"fixed indices must lie in \[0, 2000\)"),
        (lambda s: pde.heat(s, np.ones(2000), 1e-3, 1, fixed=[1, 2], fixed_values=[1.0]), ValueError, r"fixed_values must be a scalar or have shape \(2,\)"),
        (lambda s: pde.heat(s, np.full(2000, np.nan), 1e-3, 1), ValueError, "u0 must be finite"),
        (lambda s: pde.heat("sphere", np.ones(2000), 1e-3, 1), TypeError, "surface must be a Surface or Domain2D"),
        (lambda s: pde.wave(s, np.ones(2000), 1e-3, 1, c=-1.0), ValueError, "c must be a finite positive number"),
        (lambda s: pde.screened_poisson(s, np.ones(2000), alpha=0), ValueError, "alpha must be a finite positive number"),
        (lambda s: pde.heat(s, np.ones(2000), 1e-3, 1, laplacian=sp.identity(5)), ValueError, r"laplacian must have shape \(2000, 2000\)"),
    ],
)
def test_bad_input(surf, call, exc, match):
    with pytest.raises(exc, match=match):
        call(surf)


@pytest.mark.slow
def test_targets_at_8672():
    """Issue targets on the unit sphere, N = 8672, default scheme."""
    c = shapes.sphere(8672)
    s = Surface(c)
    for l, Y in harmonics(c.points):
        u = pde.heat(s, Y, dt=1e-3, steps=100, method="crank-nicolson").u
        assert rel(u, np.exp(-l * (l + 1) * 0.1) * Y) <= 5e-3
    x, n = c.points, c.normals
    gphi = c.shape.surface_gradient(x, functions.cos_xz_sin_y.gradient(x))
    cog = np.cross(n, c.shape.surface_gradient(x, functions.xyz.gradient(x)))
    d = pde.helmholtz_hodge(s, gphi + cog)
    assert rel(d.gradient, gphi) <= 1e-2 and rel(d.cogradient, cog) <= 1e-2
    u0 = np.random.default_rng(0).standard_normal(8672)
    u = pde.heat(s, u0, dt=1e-3, steps=10000, method="implicit").u
    assert np.abs(u).max() <= np.abs(u0).max()


def test_options_are_keyword_only():
    s = Surface(shapes.sphere(500), area="shepard")
    z = s.points[:, 2]
    with pytest.raises(TypeError):
        pde.heat(s, z, 0.01, 3, 1.0, "implicit")
    with pytest.raises(TypeError):
        pde.heat(s, z, dt=0.01, steps=3, k=2.0)  # k is a count in this package, never a diffusivity
