"""Tests of manifold_sph.kernels: normalisation, derivatives, limits, validation."""

import math

import numpy as np
import pytest
from scipy import integrate

from manifold_sph.kernels import (
    KERNELS,
    CubicSpline,
    Gaussian,
    Kernel,
    QuarticSpline,
    QuinticSpline,
    WendlandC2,
    get_kernel,
)

NAMES = sorted(KERNELS)
SPHERE = {1: 2.0, 2: 2.0 * math.pi, 3: 4.0 * math.pi}


@pytest.fixture(params=NAMES)
def kernel(request):
    return get_kernel(request.param)


def interior_R(k, n=400, margin=1e-3):
    """Sample points of [0, kappa) away from knots and the support edge."""
    R = np.linspace(0.01, k.support - 0.01, n)
    for knot in k.knots:
        R = R[np.abs(R - knot) > margin]
    return R


# --- registry ----------------------------------------------------------------


def test_registry_names_and_support():
    assert set(KERNELS) == {"quintic", "cubic", "gaussian", "wendland2", "quartic"}
    expected = {"quintic": 3.0, "cubic": 2.0, "gaussian": 3.0, "wendland2": 2.0, "quartic": 2.0}
    for name, kappa in expected.items():
        k = get_kernel(name)
        assert isinstance(k, Kernel)
        assert k.name == name
        assert k.support == kappa


def test_get_kernel_instance_and_class():
    k = Gaussian(support=4.0)
    assert get_kernel(k) is k
    assert isinstance(get_kernel(WendlandC2), WendlandC2)
    assert isinstance(get_kernel("  Quintic "), QuinticSpline)


def test_get_kernel_unknown_name_lists_valid_names():
    with pytest.raises(ValueError, match=r"kernel must be one of .*'cubic'.*'gaussian'.*'quartic'.*'quintic'.*'wendland2'.*got 'nope'"):
        get_kernel("nope")


def test_get_kernel_bad_type():
    with pytest.raises(TypeError, match="kernel must be a kernel name .* got int"):
        get_kernel(3)


# --- normalisation -------------------------------------------------------------


@pytest.mark.parametrize("d", [1, 2, 3])
def test_numerical_alpha_matches_closed_form(kernel, d):
    # quad on polynomial pieces is exact to round-off: 1e-12 relative.
    for h in (1.0, 0.37):
        assert kernel.alpha(d, h) == pytest.approx(kernel.closed_form_alpha(d, h), rel=1e-12, abs=0)


def test_quintic_closed_forms_exact_values():
    k = QuinticSpline()
    h = 0.5
    assert k.alpha(1, h) == pytest.approx(1 / (120 * h), rel=1e-12)
    assert k.alpha(2, h) == pytest.approx(7 / (478 * math.pi * h**2), rel=1e-12)
    # 3D: the exact moment int_0^3 R^2 w dR is 30 (the often quoted 3/(359 pi) is 0.28 % off, docs/method.md section 1).
    assert k.moment(3) == pytest.approx(30.0, rel=1e-12)
    assert k.alpha(3, h) == pytest.approx(1 / (120 * math.pi * h**3), rel=1e-12)
    assert abs(k.alpha(3) / (3 / (359 * math.pi)) - 1) > 2e-3


def test_cubic_closed_forms_exact_values():
    k = CubicSpline()
    assert k.alpha(1) == pytest.approx(2 / 3, rel=1e-12)
    assert k.alpha(2) == pytest.approx(10 / (7 * math.pi), rel=1e-12)
    assert k.alpha(3) == pytest.approx(1 / math.pi, rel=1e-12)


def test_gaussian_wider_truncation_approaches_untruncated_normalisation():
    k = Gaussian(support=6.0)
    for d in (1, 2, 3):
        assert k.alpha(d) == pytest.approx(1 / math.pi ** (d / 2), rel=1e-12)
        assert k.alpha(d) == pytest.approx(k.closed_form_alpha(d), rel=1e-12)


def test_quartic_other_support():
    k = QuarticSpline(support=3.0)
    for d in (1, 2, 3):
        assert k.alpha(d) == pytest.approx(k.closed_form_alpha(d), rel=1e-12)


def test_alpha_array_h():
    k = CubicSpline()
    h = np.array([0.5, 1.0, 2.0])
    a = k.alpha(2, h)
    assert isinstance(a, np.ndarray) and a.shape == (3,)
    np.testing.assert_allclose(a, 10 / (7 * math.pi * h**2), rtol=1e-12)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_integrates_to_one_radial_quad(kernel, d):
    # Independent of alpha's implementation: integrate value() over r with quad.
    h = 0.7
    edges = [0.0, *[kn * h for kn in kernel.knots], kernel.support * h]
    total = 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        total += integrate.quad(lambda r: SPHERE[d] * r ** (d - 1) * float(kernel.value(r, h, d)), a, b, epsabs=0, epsrel=1e-12)[0]
    assert total == pytest.approx(1.0, abs=1e-10)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_integrates_to_one_grid_sum(kernel, d):
    # Cartesian midpoint grid sum over the line / square / cube containing the support.
    h = 1.0
    n = {1: 4001, 2: 401, 3: 121}[d]
    L = kernel.support * h
    t = np.linspace(-L, L, n)
    dx = t[1] - t[0]
    grids = np.meshgrid(*([t] * d), indexing="ij")
    r = np.sqrt(sum(g**2 for g in grids))
    total = kernel.value(r, h, d).sum() * dx**d
    # Smooth kernels: grid sum is spectrally accurate; the Gaussian jumps by
    # exp(-9) = 1.2e-4 at the cut, which bounds the grid error.
    tol = {1: 1e-6, 2: 1e-5, 3: 1e-4}[d] if kernel.name != "gaussian" else 2e-4
    assert total == pytest.approx(1.0, abs=tol)


# --- profile and derivatives -----------------------------------------------------


def test_profile_zero_at_and_beyond_support(kernel):
    R = kernel.support + np.array([0.0, 1e-12, 0.5, 10.0])
    for f in (kernel.w, kernel.dw, kernel.d2w, kernel.dw_over_R):
        np.testing.assert_array_equal(f(R), 0.0)
    assert kernel.value(kernel.support * 0.5, 0.5, 2) == 0.0


def test_profile_positive_and_decreasing_inside(kernel):
    R = np.linspace(0, kernel.support, 200, endpoint=False)
    w = kernel.w(R)
    assert np.all(w > 0)
    assert np.all(np.diff(w) < 0)


def test_scalar_in_scalar_out(kernel):
    assert np.ndim(kernel.w(0.5)) == 0
    assert np.shape(kernel.w(np.ones((2, 3)))) == (2, 3)


def test_dw_d2w_match_finite_differences(kernel):
    R = interior_R(kernel)
    eps = 1e-5
    fd1 = (kernel.w(R + eps) - kernel.w(R - eps)) / (2 * eps)
    fd2 = (kernel.w(R + eps) - 2 * kernel.w(R) + kernel.w(R - eps)) / eps**2
    scale = np.abs(kernel.w(0.0))
    # central differences: O(eps^2) truncation, O(1e-16/eps^2) round-off in fd2.
    np.testing.assert_allclose(kernel.dw(R), fd1, atol=1e-8 * scale)
    np.testing.assert_allclose(kernel.d2w(R), fd2, atol=2e-4 * scale)


def test_dw_over_R(kernel):
    R = interior_R(kernel)
    np.testing.assert_allclose(kernel.dw_over_R(R), kernel.dw(R) / R, rtol=1e-12, atol=1e-12)
    # limit at 0, no warnings, and continuity as R -> 0
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        at0 = kernel.dw_over_R(np.array([0.0, 1e-300, 1e-12, 1e-8]))
    assert at0[0] == pytest.approx(float(kernel.d2w(0.0)), rel=1e-14)
    np.testing.assert_allclose(at0[1:], at0[0], rtol=1e-7)


def test_first_derivative_zero_at_origin(kernel):
    assert kernel.dw(0.0) == 0.0


@pytest.mark.parametrize("name", ["quintic", "cubic"])
def test_derivatives_continuous_at_knots(name):
    k = get_kernel(name)
    eps = 1e-10
    for knot in k.knots:
        for f in (k.w, k.dw, k.d2w):
            left, right = f(knot - eps), f(knot + eps)
            assert left == pytest.approx(right, abs=1e-7), (f.__name__, knot)
    # at the support edge w and w' vanish continuously (C1 at least)
    for f in (k.w, k.dw):
        assert abs(f(k.support - 1e-8)) < 1e-7


def test_quintic_matches_seed_formula_pieces():
    k = QuinticSpline()
    R = np.array([0.3, 1.3, 2.3])
    expected = np.array([
        (3 - 0.3) ** 5 - 6 * (2 - 0.3) ** 5 + 15 * (1 - 0.3) ** 5,
        (3 - 1.3) ** 5 - 6 * (2 - 1.3) ** 5,
        (3 - 2.3) ** 5,
    ])
    np.testing.assert_allclose(k.w(R), expected, rtol=1e-13)
    expected_d2 = np.array([
        20 * 2.7**3 - 120 * 1.7**3 + 300 * 0.7**3,
        20 * 1.7**3 - 120 * 0.7**3,
        20 * 0.7**3,
    ])
    np.testing.assert_allclose(k.d2w(R), expected_d2, rtol=1e-12)


def test_cubic_equals_seed2_eq29_up_to_constant():
    # [2] eq. 2.9 in dbar = r / (2h): W = (2/3) w_M4(R).
    def seed(dbar):
        return np.where(dbar <= 0.5, 2 / 3 - 4 * dbar**2 + 4 * dbar**3,
                        np.where(dbar <= 1, 4 / 3 - 4 * dbar + 4 * dbar**2 - 4 / 3 * dbar**3, 0.0))

    R = np.linspace(0, 2.5, 101)
    np.testing.assert_allclose(seed(R / 2), 2 / 3 * CubicSpline().w(R), atol=1e-14)


def test_quartic_matches_seed2_eq210():
    q = np.linspace(0, 1.2, 61)
    seed = np.where(q <= 1, 1 - 6 * q**2 + 8 * q**3 - 3 * q**4, 0.0)
    np.testing.assert_allclose(QuarticSpline().w(2 * q), seed, atol=1e-14)


# --- dimensional kernel ----------------------------------------------------------


@pytest.mark.parametrize("d", [1, 2, 3])
def test_h_scaling(kernel, d):
    r = np.linspace(0, 4, 50)
    for h in (0.3, 2.5):
        np.testing.assert_allclose(kernel.value(r, h, d), kernel.value(r / h, 1.0, d) / h**d, rtol=1e-13, atol=0)


def test_value_array_h_broadcast(kernel):
    r = np.array([0.1, 0.5, 1.0])
    h = np.array([0.5, 1.0, 2.0])
    expected = [float(kernel.value(ri, hi, 2)) for ri, hi in zip(r, h)]
    np.testing.assert_allclose(kernel.value(r, h, 2), expected, rtol=1e-14)


def _fd_gradient(k, x, h, eps=1e-6):
    d = x.shape[1]
    g = np.zeros_like(x)
    for a in range(d):
        e = np.zeros(d)
        e[a] = eps
        g[:, a] = (k.value(np.linalg.norm(x + e, axis=1), h, d) - k.value(np.linalg.norm(x - e, axis=1), h, d)) / (2 * eps)
    return g


def _random_x(k, d, h, n=200, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, d))
    x /= np.linalg.norm(x, axis=1)[:, None]
    R = rng.uniform(0.05, k.support - 0.05, n)
    # keep away from knots, where the second derivative of the cubic jumps
    for knot in k.knots:
        R = np.where(np.abs(R - knot) < 1e-3, R + 2e-3, R)
    return x * (R * h)[:, None]


@pytest.mark.parametrize("d", [2, 3])
def test_gradient_matches_fd_of_value(kernel, d):
    h = 0.8
    x = _random_x(kernel, d, h)
    g = kernel.gradient(x, h)
    assert g.shape == x.shape
    scale = kernel.alpha(d, h) * abs(float(kernel.w(0.0))) / h
    np.testing.assert_allclose(g, _fd_gradient(kernel, x, h), atol=1e-7 * scale)


@pytest.mark.parametrize("d", [2, 3])
def test_hessian_matches_fd_of_gradient_and_value(kernel, d):
    h = 0.8
    x = _random_x(kernel, d, h, seed=1)
    H = kernel.hessian(x, h)
    assert H.shape == (x.shape[0], d, d)
    np.testing.assert_allclose(H, np.swapaxes(H, 1, 2), atol=0)
    eps = 1e-6
    fd = np.zeros_like(H)
    for b in range(d):
        e = np.zeros(d)
        e[b] = eps
        fd[:, :, b] = (kernel.gradient(x + e, h) - kernel.gradient(x - e, h)) / (2 * eps)
    scale = kernel.alpha(d, h) * abs(float(kernel.d2w(0.0))) / h**2
    np.testing.assert_allclose(H, fd, atol=1e-6 * scale)
    # trace = Laplacian = second derivative of value along r plus (d-1) w'/(h r)
    eps = 1e-4
    lap_fd = np.zeros(x.shape[0])
    for b in range(d):
        e = np.zeros(d)
        e[b] = eps
        v = lambda y: kernel.value(np.linalg.norm(y, axis=1), h, d)
        lap_fd += (v(x + e) - 2 * v(x) + v(x - e)) / eps**2
    np.testing.assert_allclose(np.trace(H, axis1=1, axis2=2), lap_fd, atol=1e-5 * scale)


def test_gradient_direction_and_pair_convention():
    k = QuinticSpline()
    x = np.array([[1.0, 0.0], [0.0, 2.0]])
    g = k.gradient(x, 1.0)
    # W decreases outward: gradient points towards the origin
    assert g[0, 0] < 0 and g[0, 1] == 0 and g[1, 1] < 0 and g[1, 0] == 0
    assert g[0, 0] == pytest.approx(k.alpha(2) * float(k.dw(1.0)), rel=1e-14)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_origin_limits_and_continuity(kernel, d):
    h = 0.6
    x0 = np.zeros((1, d))
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        g0 = kernel.gradient(x0, h)
        H0 = kernel.hessian(x0, h)
    np.testing.assert_array_equal(g0, 0.0)
    limit = kernel.alpha(d, h) * float(kernel.d2w(0.0)) / h**2 * np.eye(d)
    np.testing.assert_allclose(H0[0], limit, rtol=1e-14, atol=0)
    rng = np.random.default_rng(3)
    direction = rng.normal(size=d)
    direction /= np.linalg.norm(direction)
    for r in (1e-4, 1e-6, 1e-9):
        H = kernel.hessian((r * direction)[None, :], h)[0]
        # H(r) - H(0) = O(r) for the splines (w'' is linear near 0), O(r^2) otherwise
        assert np.max(np.abs(H - limit)) <= 10 * r / h * np.max(np.abs(limit))


def test_gradient_hessian_array_h(kernel):
    x = _random_x(kernel, 2, 1.0, n=5)
    h = np.array([0.9, 1.0, 1.1, 1.2, 1.3])
    g = kernel.gradient(x, h)
    H = kernel.hessian(x, h)
    for i in range(5):
        np.testing.assert_allclose(g[i], kernel.gradient(x[i:i + 1], float(h[i]))[0], rtol=1e-14)
        np.testing.assert_allclose(H[i], kernel.hessian(x[i:i + 1], float(h[i]))[0], rtol=1e-14)


def test_one_dimensional_gradient():
    k = CubicSpline()
    x = np.array([[-0.5], [0.5]])
    g = k.gradient(x, 1.0)
    assert g[0, 0] == pytest.approx(-g[1, 0])
    assert g[1, 0] == pytest.approx(k.alpha(1) * float(k.dw(0.5)))


# --- bad input -------------------------------------------------------------------


def test_alpha_bad_dimension(kernel):
    with pytest.raises(ValueError, match=r"d must be one of \[1, 2, 3\], got 4"):
        kernel.alpha(d=4)
    with pytest.raises(TypeError, match="d must be an integer, got float"):
        kernel.alpha(2.0)
    with pytest.raises(ValueError, match=r"d must be one of"):
        kernel.value(0.5, 1.0, 0)


def test_negative_h(kernel):
    with pytest.raises(ValueError, match=r"h must be a finite positive number, got -1.0"):
        kernel.alpha(2, -1.0)
    with pytest.raises(ValueError, match=r"h must be a finite positive number, got 0"):
        kernel.value(0.5, 0, 2)
    with pytest.raises(ValueError, match=r"h must be positive, but it holds 1 value\(s\) <= 0"):
        kernel.gradient(np.ones((3, 2)), np.array([1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match="h must be finite"):
        kernel.alpha(2, np.array([1.0, np.nan]))


def test_bad_points_and_distances(kernel):
    with pytest.raises(ValueError, match=r"x must have shape \(N, 1\) or \(N, 2\) or \(N, 3\), got shape \(3, 4\)"):
        kernel.gradient(np.ones((3, 4)), 1.0)
    with pytest.raises(ValueError, match=r"x must have shape .*got shape \(3,\)"):
        kernel.hessian(np.ones(3), 1.0)
    with pytest.raises(ValueError, match=r"h must be a scalar or have shape \(3,\) to match x, got shape \(2,\)"):
        kernel.gradient(np.ones((3, 2)), np.ones(2))
    with pytest.raises(ValueError, match="r must be non-negative distances, got minimum -0.5"):
        kernel.value(np.array([0.1, -0.5]), 1.0, 2)
    with pytest.raises(ValueError, match="x must be finite"):
        kernel.gradient(np.array([[np.inf, 0.0]]), 1.0)


def test_bad_support_parameter():
    with pytest.raises(ValueError, match="support must be a finite positive number, got -2"):
        Gaussian(support=-2)


def test_closed_form_missing_raises():
    class Flat(Kernel):
        name = "flat"
        support = 1.0

        def _w(self, R):
            return np.ones_like(R)

        def _dw(self, R):
            return np.zeros_like(R)

        def _d2w(self, R):
            return np.zeros_like(R)

    k = Flat()
    with pytest.raises(NotImplementedError, match="kernel 'flat' has no closed-form alpha for d=2"):
        k.closed_form_alpha(2)
    # the numerical alpha still works for any profile: 1 / (pi r^2) for the unit disc
    assert k.alpha(2) == pytest.approx(1 / math.pi, rel=1e-12)
