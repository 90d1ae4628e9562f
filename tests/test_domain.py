"""Planar domain: exactness on polynomials, identities, invariance, mirroring, bad input."""


import numpy as np
import pytest

from manifold_sph import Domain2D

SCHEMES = ["standard", "cspm", "msph", "ncsph"]


def jittered(n=32, seed=0, jitter=0.35):
    """n x n jittered grid in [-1, 1]^2 (seeded)."""
    rng = np.random.default_rng(seed)
    g = (np.arange(n) + 0.5) / n * 2 - 1
    p = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    return p + rng.uniform(-jitter, jitter, p.shape) * (2 / n)


@pytest.fixture(scope="module")
def pts():
    return jittered()


@pytest.fixture(scope="module")
def domains(pts):
    return {s: Domain2D(pts, scheme=s, bounds=(-1, 1, -1, 1)) for s in SCHEMES}


def quadratic(p):
    x, y = p.T
    f = x**2 - 3 * x * y + 0.5 * y**2 + x - 2 * y + 1
    return f, np.stack([2 * x - 3 * y + 1, -3 * x + y - 2], 1), np.full(len(p), 3.0)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_constant_has_zero_derivatives(domains, scheme):
    d = domains[scheme]
    c = np.full(d.n_points, 2.5)
    assert np.abs(d.gradient(c)).max() < 1e-10
    assert np.abs(d.laplacian(c)).max() < 1e-9


@pytest.mark.parametrize("scheme", SCHEMES)
def test_matrices_equal_operators(domains, scheme, pts):
    d = domains[scheme]
    f = np.sin(3 * pts[:, 0]) * np.exp(pts[:, 1])
    F = np.stack([np.cos(pts[:, 1]), pts[:, 0] ** 3], 1)
    g = d.gradient(f)
    assert np.allclose((d.gradient_matrix() @ f).reshape(-1, 2), g, rtol=1e-12, atol=1e-12 * np.abs(g).max())
    div = d.divergence(F)
    assert np.allclose(d.divergence_matrix() @ F.ravel(), div, rtol=1e-12, atol=1e-12 * np.abs(div).max())
    lap = d.laplacian(f)
    assert np.allclose(d.laplacian_matrix() @ f, lap, rtol=1e-12, atol=1e-12 * np.abs(lap).max())
    assert d.gradient_matrix().shape == (2 * d.n_points, d.n_points)
    assert d.divergence_matrix().shape == (d.n_points, 2 * d.n_points)


def test_cspm_gradient_exact_on_linear(domains, pts):
    f = 1 + 2 * pts[:, 0] - 3 * pts[:, 1]
    for s in ("cspm", "ncsph", "msph"):
        assert np.abs(domains[s].gradient(f) - [2, -3]).max() < 1e-10, s


def test_msph_exact_on_quadratics(domains, pts):
    f, g, lap = quadratic(pts)
    d = domains["msph"]
    assert np.abs(d.gradient(f) - g).max() / np.abs(g).max() < 1e-10
    assert np.abs(d.laplacian(f) - lap).max() / 3.0 < 1e-9


def test_ncsph_laplacian_exact_on_quadratics(domains, pts):
    f, _, lap = quadratic(pts)
    assert np.abs(domains["ncsph"].laplacian(f) - lap).max() / 3.0 < 1e-9


def test_cspm_laplacian_not_exact_at_boundary(domains, pts):
    """CSPM's second derivatives use the (inexact) first derivatives: a documented limit."""
    f, _, lap = quadratic(pts)
    assert np.abs(domains["cspm"].laplacian(f) - lap).max() > 1e-3


@pytest.mark.parametrize("scheme", ["cspm", "msph", "ncsph"])
def test_rotation_translation_scaling(pts, scheme):
    theta = 0.7
    R = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    s, t = 2.5, np.array([3.0, -1.0])
    q = s * pts @ R.T + t
    f = np.sin(2 * pts[:, 0]) * np.cos(pts[:, 1])
    a = Domain2D(pts, scheme=scheme)
    b = Domain2D(q, scheme=scheme)
    ga, gb = a.gradient(f), b.gradient(f)
    assert np.allclose(gb, ga @ R.T / s, rtol=0, atol=1e-9 * np.abs(ga).max())
    la, lb = a.laplacian(f), b.laplacian(f)
    assert np.allclose(lb, la / s**2, rtol=0, atol=1e-9 * np.abs(la).max() / s**2)


def test_mirroring_helps_periodic_functions():
    p = jittered(40, seed=1)
    x, y = p.T
    f = np.sin(np.pi * x) * np.cos(np.pi * y)
    exact = -2 * np.pi**2 * f
    err = {}
    for mirror in (False, True):
        d = Domain2D(p, scheme="cspm", bounds=(-1, 1, -1, 1), mirror=mirror)
        err[mirror] = np.linalg.norm(d.laplacian(f) - exact) / np.linalg.norm(exact)
    assert err[True] < 0.2 * err[False]
    assert err[True] < 0.05


def test_mirror_matrix_columns_stay_within_particles():
    p = jittered(20, seed=2)
    d = Domain2D(p, scheme="msph", bounds=(-1, 1, -1, 1), mirror=True)
    L = d.laplacian_matrix()
    assert L.shape == (400, 400)
    # every particle sees a full neighbourhood through the ghosts
    assert d.neighborhood.counts.min() >= 0.6 * d.neighborhood.counts.mean()


def test_collinear_neighbourhoods_fall_back_without_nan():
    rng = np.random.default_rng(5)
    line = np.stack([np.linspace(0, 1, 40), np.zeros(40)], 1)
    blob = rng.uniform(2, 3, size=(300, 2))
    p = np.concatenate([line, blob])
    with pytest.warns(RuntimeWarning, match="fell back"):
        d = Domain2D(p, scheme="ncsph", neighbors=20)
    assert set(range(40)) <= set(d.fallback["standard"].tolist())  # every particle of the line
    fell = np.concatenate(list(d.fallback.values()))
    others = fell[fell >= 40]  # and blob particles only where their system is bad
    assert np.all((d.neighborhood.counts[others] < 6) | (d.condition[others] > d.max_condition))
    assert np.all(np.isfinite(d.laplacian_matrix().data))
    assert np.all(d.scheme_used[np.setdiff1d(np.arange(340), fell)] == "ncsph")


@pytest.mark.parametrize(
    "args, kwargs, exc, match",
    [
        ((np.random.default_rng(0).random((20, 3)),), {}, ValueError, r"points must be planar for a Domain2D.*extents"),
        ((np.zeros((20, 4)),), {}, ValueError, r"points must have shape \(N, 2\) or \(N, 3\), got shape \(20, 4\)"),
        ((np.full((20, 2), np.nan),), {}, ValueError, "points must be finite"),
        ((jittered(3),), {}, ValueError, "at least 10 points"),
        ((np.zeros((20, 2)),), {}, ValueError, "points must be distinct"),
        ((jittered(8),), {"mirror": True}, ValueError, "mirror=True needs bounds"),
        ((jittered(8),), {"bounds": (0, 1, 0, 1)}, ValueError, "lie inside bounds"),
        ((jittered(8),), {"bounds": (1, 0, 0, 1)}, ValueError, "xmin < xmax"),
        ((jittered(8),), {"scheme": "sph9"}, ValueError, "scheme must be one of"),
        ((jittered(8),), {"kernel": "box"}, ValueError, "quintic"),
        ((jittered(8),), {"neighbors": 3}, ValueError, "neighbors must be at least 6"),
        ((jittered(8),), {"neighbors": 2.5}, TypeError, "neighbors must be an integer"),
        ((jittered(8),), {"area": "magic"}, ValueError, "area must be one of"),
        ((jittered(8),), {"area": "geometric"}, ValueError, "needs the total surface area"),
        ((jittered(8),), {"h": "big"}, ValueError, "h must be None, 'adaptive'"),
    ],
)
def test_bad_input(args, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        Domain2D(*args, **kwargs)


def test_isolated_point_is_an_error():
    p = np.concatenate([jittered(10), [[50.0, 50.0]]])
    with pytest.raises(ValueError, match=r"1 particle\(s\) have no neighbour"):
        Domain2D(p, h=0.05)


def test_field_shape_errors(domains):
    d = domains["cspm"]
    with pytest.raises(ValueError, match=r"f must have shape \(1024,\), got shape \(3,\)"):
        d.laplacian(np.ones(3))
    with pytest.raises(ValueError, match=r"F must have shape \(1024, 2\)"):
        d.divergence(np.ones((1024, 3)))
    with pytest.raises(ValueError, match="f must be finite"):
        d.gradient(np.full(1024, np.inf))


@pytest.mark.parametrize("n", [1007, 4029])
def test_poisson_square_exactness(n):
    """Issue targets on Poisson-disk points of [-1, 1]^2 without mirroring: msph exact on
    quadratics (gradient and Laplacian), ncsph's Laplacian too, cspm's gradient on linear ones."""
    from manifold_sph.reference import shapes

    p = shapes.square(n, sampling="poisson", seed=0)
    f, g, lap = quadratic(p)
    msph = Domain2D(p, scheme="msph")
    assert np.abs(msph.gradient(f) - g).max() / np.abs(g).max() < 1e-10
    for d in (msph, Domain2D(p, scheme="ncsph")):
        err = np.abs(d.laplacian(f) - lap)
        # exact up to rounding: a few boundary stencils have weights summing to ~1e5 in
        # magnitude, so the rounding floor there is ~1e-15 * sum_j |w_ij f_j|
        floor = abs(d.laplacian_matrix()) @ np.abs(f)
        assert np.all(err <= 1e-10 * 3.0 + 1e-13 * floor)
        assert err.max() / 3.0 < 1e-9
    lin = 0.5 - p[:, 0] + 4 * p[:, 1]
    assert np.abs(Domain2D(p, scheme="cspm").gradient(lin) - [-1, 4]).max() < 1e-10 * 4


def test_mirrored_domain_pickles():
    import pickle

    p = jittered(15, seed=3)
    d = Domain2D(p, scheme="cspm", bounds=(-1, 1, -1, 1), mirror=True)
    f = np.sin(np.pi * p[:, 0]) * p[:, 1]
    d2 = pickle.loads(pickle.dumps(d))
    assert np.array_equal(d2.laplacian(f), d.laplacian(f))
    assert np.array_equal(d2.gradient(f), d.gradient(f))
