"""PDEs on point-cloud surfaces against exact solutions; stability; bad input."""

import warnings

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
    """The strong form's implicit steps (not symmetric): 500: Jacobi-BiCGSTAB; 1: it fails and
    multigrid takes over; 0 with multigrid disabled: the LU fallback."""
    from manifold_sph.pde import time_stepping

    monkeypatch.setattr(time_stepping, "JACOBI_MAXITER", jacobi_iters)
    if jacobi_iters == 0:
        import pyamg

        monkeypatch.setattr(pyamg, "ruge_stuben_solver", lambda A: 1 / 0)
    Y = sphere.points[:, 1]
    a = pde.heat(surf, Y, dt=1e-2, steps=5, solver="direct", laplacian="strong")
    b = pde.heat(surf, Y, dt=1e-2, steps=5, solver="iterative", laplacian="strong")
    assert (a.solver, b.solver) == ("lu", "bicgstab")
    assert np.abs(a.u - b.u).max() < 1e-8


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


def test_random_points_have_growing_modes_and_auto_steps_the_stable_laplacian():
    """On uniformly random samples the scheme's Laplacian has growing modes (it is accurate there, but
    time steps with it grow without bound): 'auto' steps with the stable one, without a warning."""
    s = Surface(shapes.sphere(800, sampling="random", seed=1), area="shepard", neighbors=27)
    assert s.laplacian_form == "strong"
    assert pde.spectrum_right_edge(s.laplacian_matrix(form="strong"), 2)[0].real > 1.0
    assert not pde.strong_form_decays(s)
    u0 = np.random.default_rng(2).standard_normal(800)
    sol = pde.heat(s, u0, dt=1e-3, steps=200)
    assert sol.laplacian == "stable" and np.abs(sol.u).max() <= np.abs(u0).max()
    assert "growing modes" in s.report()["pde_laplacian"].detail


@pytest.mark.parametrize(
    "call, exc, match",
    [
        (lambda s: pde.heat(s, np.ones(3), dt=1e-3, steps=1), ValueError, r"u0 must have shape \(2000,\)"),
        (lambda s: pde.heat(s, np.ones(2000), dt=0.0, steps=1), ValueError, "dt must be a finite positive number"),
        (lambda s: pde.heat(s, np.ones(2000), dt=1e-3, steps=0), ValueError, "steps must be at least 1"),
        (lambda s: pde.heat(s, np.ones(2000), dt=1e-3, steps=1, method="rk4"), ValueError, "method must be one of"),
        (lambda s: pde.heat(s, np.ones(2000), dt=1e-3, steps=1, fixed=[5000]), ValueError, r"fixed indices must lie in \[0, 2000\)"),
        (lambda s: pde.heat(s, np.ones(2000), dt=1e-3, steps=1, fixed=[1, 2], fixed_values=[1.0]), ValueError,
         r"fixed_values must be a scalar or have shape \(2,\)"),
        (lambda s: pde.heat(s, np.full(2000, np.nan), dt=1e-3, steps=1), ValueError, "u0 must be finite"),
        (lambda s: pde.heat("sphere", np.ones(2000), dt=1e-3, steps=1), TypeError, "surface must be a Surface or Domain2D"),
        (lambda s: pde.wave(s, np.ones(2000), dt=1e-3, steps=1, c=-1.0), ValueError, "c must be a finite positive number"),
        (lambda s: pde.screened_poisson(s, np.ones(2000), alpha=0), ValueError, "alpha must be a finite positive number"),
        (lambda s: pde.heat(s, np.ones(2000), dt=1e-3, steps=1, laplacian=sp.identity(5)), ValueError,
         r"laplacian must have shape \(2000, 2000\)"),
        (lambda s: pde.heat(s, np.ones(2000)), ValueError, r"heat needs a duration: reach=.*t_end=.*dt= and steps= \(got none\)"),
        (lambda s: pde.heat(s, np.ones(2000), dt=1e-3), ValueError, r"heat needs a duration.*\(got dt=0.001\)"),
        (lambda s: pde.wave(s, np.ones(2000), steps=10), ValueError, r"wave needs a duration.*\(got steps=10\)"),
        (lambda s: pde.heat(s, np.ones(2000), reach=0.1, t_end=1.0), ValueError, "reach= or as t_end=, not both"),
        (lambda s: pde.heat(s, np.ones(2000), t_end=1.0, dt=0.1, steps=10), ValueError, "fix the duration already"),
        (lambda s: pde.heat(s, np.ones(2000), reach=-1.0), ValueError, "reach must be a finite positive number"),
        (lambda s: pde.heat(s, np.ones(2000), t_end=float("inf")), ValueError, "t_end must be a finite positive number"),
        (lambda s: pde.heat(s, np.ones(2000), reach=0.1, progress="yes"), TypeError, "progress must be"),
        (lambda s: pde.heat(s, np.ones(2000), reach=0.1, callback="print"), TypeError,
         r"callback must be a callable callback\(step, t, u\) or None, got str"),
        (lambda s: pde.heat(s, np.ones(2000), reach=1e4, method="explicit"), ValueError, "explicit steps.*use method='implicit'"),
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
        u = pde.heat(s, Y, dt=1e-3, steps=100, method="crank-nicolson", laplacian="strong").u
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
        pde.wave(s, z, 0.01, 3)
    with pytest.raises(TypeError):
        pde.heat(s, z, dt=0.01, steps=3, k=2.0)  # k is a count in this package, never a diffusivity


# ----------------------------------------------------------------------------- natural units
MODELS = __import__("pathlib").Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "models"


def random_sphere(n, seed=0, noise=0.0):
    """Uniformly random points on the unit sphere, moved off it by ``noise`` spacings (Gaussian)."""
    rng = np.random.default_rng(seed)
    p = rng.standard_normal((n, 3))
    p /= np.linalg.norm(p, axis=1)[:, None]
    return p + noise * np.sqrt(4 * np.pi / n) * rng.standard_normal((n, 3))


def hot_spot(points, width=0.1):
    """A Gaussian bump of ``width`` times the cloud's diameter at the point farthest along x + y + z."""
    c = points[np.argmax(points.sum(axis=1))]
    d = 2 * np.linalg.norm(points - points.mean(axis=0), axis=1).max()
    return np.exp(-(np.linalg.norm(points - c, axis=1) / (width * d)) ** 2)


@pytest.mark.parametrize("scale", [0.125, 329.0])
def test_reach_means_the_same_on_any_scale(scale):
    """The README's call on clouds 0.25 and 658 across gives the unit cloud's solution: not flat, not unmoved."""
    p = random_sphere(1500, seed=5)
    u0 = hot_spot(p)
    ref = pde.heat(Surface(p, p.copy()), u0, reach=0.1)
    sol = pde.heat(Surface(scale * p, p.copy()), u0, reach=0.1)
    assert rel(sol.u, ref.u) < 1e-8
    assert sol.times[-1] == pytest.approx(ref.times[-1] * scale**2, rel=1e-12)
    assert sol.dt == pytest.approx(ref.dt * scale**2, rel=1e-12)
    assert 0.05 < sol.u.max() / u0.max() < 0.8  # spread, not flattened: the peak fell
    assert np.ptp(sol.u) > 0.05 * np.ptp(u0)
    w = pde.wave(Surface(scale * p, p.copy()), u0, reach=0.25)
    w_ref = pde.wave(Surface(p, p.copy()), u0, reach=0.25)
    D = 2 * np.linalg.norm(p - p.mean(axis=0), axis=1).max()
    assert rel(w.u, w_ref.u) < 1e-8 and w.times[-1] == pytest.approx(0.25 * D * scale, rel=1e-12)


def test_reach_gives_the_heat_kernel_width():
    """reach r runs to t = (r D)^2 / (2 k): Y_1 then decays as exp(-2 k t)."""
    c = shapes.sphere(2000)
    s = Surface(c)
    z = c.points[:, 2]
    D = pde.cloud_diameter(s)
    sol = pde.heat(s, z, reach=0.3, diffusivity=2.0, method="crank-nicolson")
    t = (0.3 * D) ** 2 / 4.0
    assert sol.times[-1] == pytest.approx(t, rel=1e-12)
    assert rel(sol.u, np.exp(-2 * 2.0 * t) * z) < 5e-3


def test_dt_chosen_from_the_spacing_and_the_stability_limit(surf, sphere):
    z = sphere.points[:, 2]
    h2 = pde.cloud_spacing(surf) ** 2
    short = pde.heat(surf, z, t_end=3 * h2)  # at least MIN_STEPS
    assert short.times.size == 2 and short.dt == pytest.approx(3 * h2 / pde.MIN_STEPS)
    mid = pde.heat(surf, z, t_end=40.5 * h2)  # about one spacing of diffusion a step
    assert mid.dt == pytest.approx(40.5 * h2 / 41)
    long = pde.heat(surf, z, t_end=1e4 * h2)  # at most MAX_STEPS
    assert long.dt == pytest.approx(1e4 * h2 / pde.MAX_STEPS)
    limit = pde.explicit_dt_limit(surf)
    ex = pde.heat(surf, z, t_end=0.01, method="explicit")
    assert ex.dt <= pde.EXPLICIT_SAFETY * limit and ex.times.size == 2
    assert round(0.01 / ex.dt) == int(np.ceil(0.01 / (pde.EXPLICIT_SAFETY * limit)))  # the fewest steps that fit
    assert rel(ex.u, np.exp(-0.02) * z) < 1e-2
    w = pde.wave(surf, z, t_end=0.5)
    assert w.dt <= pde.EXPLICIT_SAFETY * pde.explicit_dt_limit(surf, equation="wave")
    assert rel(w.u, np.cos(np.sqrt(2) * 0.5) * z) < 1e-2
    given = pde.heat(surf, z, t_end=0.0105, dt=1e-3)  # dt lowered to land on t_end
    assert given.times[-1] == pytest.approx(0.0105) and given.dt == pytest.approx(0.0105 / 11)
    by_steps = pde.heat(surf, z, t_end=0.01, steps=4)
    assert by_steps.dt == pytest.approx(0.0025)


@pytest.mark.parametrize("kind", ["random", "noisy", "model"])
def test_reach_on_irregular_and_real_clouds(kind):
    """Uniformly random, noisy (0.3 spacings) and a real model's vertices (bare points): heat conserves
    sum(M u), stays within the initial range, spreads the hot spot without flattening it."""
    if kind == "model":
        path = MODELS / "cow.obj"
        if not path.exists():
            pytest.skip("../shared/data/models not here")
        import trimesh

        p = np.unique(np.asarray(trimesh.load(path, process=False).vertices, dtype=np.float64), axis=0)
    else:
        p = random_sphere(3000, seed=2, noise=0.3 if kind == "noisy" else 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the build's one summary (sparse parts, fallbacks)
        s = Surface(p)
    u0 = hot_spot(p)
    sol = pde.heat(s, u0, reach=0.1)
    assert sol.laplacian == "stable" if kind != "random" else sol.laplacian in ("strong", "stable")
    if sol.laplacian == "stable":
        m = s.mass_matrix().diagonal()
        assert abs(m @ sol.u - m @ u0) < 1e-9 * (m @ u0)
        assert sol.u.min() >= -1e-12 and sol.u.max() <= u0.max() + 1e-12
    assert 0.02 < sol.u.max() / u0.max() < 0.9
    assert np.ptp(sol.u) > 0.02 * np.ptp(u0)


def test_progress_bar_on_request_only(surf, sphere, capsys):
    pde.heat(surf, sphere.points[:, 2], reach=0.05)
    assert capsys.readouterr().err == ""
    pde.heat(surf, sphere.points[:, 2], reach=0.05, progress=True)
    err = capsys.readouterr().err
    assert "heat" in err and "step" in err
    pde.wave(surf, sphere.points[:, 2], reach=0.05, progress=True)
    assert "wave" in capsys.readouterr().err


# ----------------------------------------------------------------------------- SPD solvers
@pytest.fixture(scope="module")
def rand2500():
    p = random_sphere(2500, seed=11)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the build's summary (a few sparse points)
        return Surface(p, p.copy())


@pytest.mark.parametrize("method", ["implicit", "crank-nicolson"])
def test_stable_steps_on_spd_solvers_match_a_sparse_lu(rand2500, method):
    import scipy.sparse.linalg as spla

    s = rand2500
    K, M = s.stiffness_matrix(), s.mass_matrix()
    m = M.diagonal()
    u0 = hot_spot(s.points)
    theta = 1.0 if method == "implicit" else 0.5
    dt, steps = 2e-3, 6
    lu = spla.splu((M + theta * dt * K).tocsc())
    ref = u0.copy()
    for _ in range(steps):
        ref = lu.solve(m * ref - (1 - theta) * dt * (K @ ref))
    for solver, name, tol in (("direct", "cholesky", 1e-11), ("iterative", "amg", 1e-8), ("auto", "cholesky", 1e-11)):
        sol = pde.heat(s, u0, dt=dt, steps=steps, method=method, laplacian="stable", solver=solver)
        assert sol.solver == name
        assert np.abs(sol.u - ref).max() < tol * np.abs(ref).max(), solver


def test_fixed_particles_with_spd_steps(rand2500):
    s = rand2500
    north = int(np.argmax(s.points[:, 2]))
    a = pde.heat(s, np.zeros(2500), dt=1e-2, steps=20, fixed=[north], fixed_values=1.0, laplacian="stable", solver="direct")
    b = pde.heat(s, np.zeros(2500), dt=1e-2, steps=20, fixed=[north], fixed_values=1.0, laplacian="stable", solver="iterative")
    assert a.u[north] == 1.0 and np.abs(a.u - b.u).max() < 1e-8
    assert 0 <= a.u.min() and a.u.max() <= 1.0  # maximum principle with a held source


def test_symmetric_user_matrix_takes_the_spd_path(rand2500):
    s = rand2500
    L = -s.stiffness_matrix()  # symmetric, negative semi-definite: I - dt L is SPD
    sol = pde.heat(s, hot_spot(s.points), dt=1e-3, steps=3, laplacian=L)
    assert sol.laplacian == "matrix" and sol.solver in ("cholesky", "amg")


def test_stable_poisson_pinned_spd_matches_the_bordered_system(rand2500):
    """One particle pinned per piece, SPD solve, then zero mean: the bordered saddle-point solution."""
    s = rand2500
    K, m = s.stiffness_matrix(), s.mass_matrix().diagonal()
    x = s.points
    f = x[:, 0] * x[:, 1] + x[:, 2] ** 3
    f -= (m @ f) / m.sum()
    n = s.n_points
    A = sp.bmat([[K, sp.csr_matrix(np.ones((n, 1)))], [sp.csr_matrix(m[None, :]), None]], format="csc")
    ref = sp.linalg.spsolve(A, np.append(-m * f, 0.0))[:n]
    for solver in ("direct", "iterative"):
        u = pde.poisson(s, f, laplacian="stable", solver=solver)
        assert np.abs(u - ref).max() < 1e-8 * np.abs(ref).max(), solver
        assert abs(m @ u) < 1e-10 * (m @ np.abs(u))
    # a mean inside the tolerance is removed (the range of K), not thrown at the pinned particle
    u = pde.poisson(s, f + 1e-4 * np.abs(f).max(), laplacian="stable", tol=1e-2)
    assert np.abs(u - ref).max() < 1e-8 * np.abs(ref).max()


def test_poisson_accuracy_with_the_stable_laplacian_on_random_points(rand2500):
    x = rand2500.points
    m = rand2500.mass_matrix().diagonal()
    f = x.prod(axis=1)
    f -= (m @ f) / m.sum()  # xyz's mean over random cells is not exactly 0
    u = pde.poisson(rand2500, -12 * f, laplacian="stable")
    assert rel(u, f) < 0.03  # second order; 2500 random points
