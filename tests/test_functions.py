"""Tests of manifold_sph.reference.functions: exact derivatives and the sphere fields of [1] (docs/method.md)."""

import math

import numpy as np
import pytest

from manifold_sph.reference import functions as fn
from manifold_sph.reference.shapes import Sphere

F3 = list(fn.SCALAR_FUNCTIONS.values())
F2 = list(fn.PLANAR_FUNCTIONS.values())


def _fd_derivative(func, x, h=1e-5):
    """Central differences of func (N,) -> (N, ...) along each coordinate: (N, ..., d)."""
    cols = []
    for a in range(x.shape[1]):
        e = np.zeros(x.shape[1])
        e[a] = h
        cols.append((func(x + e) - func(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("f", F3 + F2, ids=lambda f: f.name)
def test_gradient_and_hessian_vs_finite_differences(f):
    rng = np.random.default_rng(0)
    x = rng.uniform(-1.2, 1.2, (200, f.dim))
    v, g, H = f.value(x), f.gradient(x), f.hessian(x)
    assert v.shape == (200,) and g.shape == (200, f.dim) and H.shape == (200, f.dim, f.dim)
    # central differences, h = 1e-5: truncation ~1e-10 * f''', rounding ~1e-11
    np.testing.assert_allclose(_fd_derivative(f.value, x), g, atol=1e-8)
    np.testing.assert_allclose(_fd_derivative(f.gradient, x), H, atol=1e-8)
    np.testing.assert_allclose(H, np.swapaxes(H, 1, 2), atol=0)
    np.testing.assert_allclose(f.laplacian(x), np.trace(H, axis1=1, axis2=2))


def test_closed_forms():
    x = np.array([[0.3, -0.7, 1.1], [1.0, 2.0, -0.5]])
    X, Y, Z = x.T
    np.testing.assert_allclose(fn.linear.value(x), X + Y + Z)
    np.testing.assert_allclose(fn.xyz.value(x), X * Y * Z)
    np.testing.assert_allclose(fn.cos_xz_sin_y.value(x), np.cos(X * Z - np.sin(Y)))
    np.testing.assert_allclose(fn.z_cos_xy.value(x), Z * np.cos(X * Y))
    p = np.array([[0.25, -0.4], [0.9, 0.1]])
    f = fn.sin_pi_x_cos_pi_y
    np.testing.assert_allclose(f.laplacian(p), -2 * math.pi**2 * f.value(p), rtol=1e-14)
    np.testing.assert_allclose(fn.xy_2d.gradient(p), p[:, ::-1])
    F = fn.sin_pi_field_2d
    np.testing.assert_allclose(F.value(p), np.sin(math.pi * p))
    np.testing.assert_allclose(F.divergence(p), math.pi * np.cos(math.pi * p).sum(axis=1), rtol=1e-14)
    np.testing.assert_allclose(_fd_derivative(F.value, p), F.jacobian(p), atol=1e-8)


# ----------------------------------------------------------------------------
# sphere fields ([1] eqs. 1.14, 1.16, 3.13)
# ----------------------------------------------------------------------------
def _uv(u, v):
    return np.stack([np.sin(u) * np.cos(v), np.sin(u) * np.sin(v), np.cos(u)], axis=-1)


@pytest.mark.parametrize("name", sorted(fn.SPHERE_FIELDS))
def test_sphere_field_basis_and_divergence_in_coordinates(name):
    """div F = (1/sin u) [d_u(sin u F1) + d_v(sin u F2)], F1, F2 evaluated at x(u, v)."""
    F = fn.sphere_field(name)
    rng = np.random.default_rng(1)
    u = rng.uniform(0.2, math.pi - 0.2, 300)
    v = rng.uniform(-math.pi, math.pi, 300)
    x = _uv(u, v)
    # basis (1.16)
    xu, xv, cot = fn.sphere_basis(x)
    np.testing.assert_allclose(xu, np.stack([np.cos(u) * np.cos(v), np.cos(u) * np.sin(v), -np.sin(u)], -1), atol=1e-14)
    np.testing.assert_allclose(xv, np.stack([-np.sin(u) * np.sin(v), np.sin(u) * np.cos(v), 0 * u], -1), atol=1e-14)
    np.testing.assert_allclose(cot, 1 / np.tan(u), rtol=1e-12)
    f1, f2 = F.coefficients(x)
    np.testing.assert_allclose(F.value(x), f1[:, None] * xu + f2[:, None] * xv, atol=1e-14)
    h = 1e-5

    def G(a, b):
        g1, g2 = F.coefficients(_uv(a, b))
        return np.sin(a) * g1, np.sin(a) * g2

    du = (G(u + h, v)[0] - G(u - h, v)[0]) / (2 * h)
    dv = (G(u, v + h)[1] - G(u, v - h)[1]) / (2 * h)
    np.testing.assert_allclose(F.exact_divergence(x), (du + dv) / np.sin(u), atol=1e-8)


@pytest.mark.parametrize("name", sorted(fn.SPHERE_FIELDS))
def test_sphere_field_jacobian_and_generic_divergence(name):
    F = fn.sphere_field(name)
    s = Sphere()
    x = s.sample(1500, "fibonacci").points
    x = x[np.hypot(x[:, 0], x[:, 1]) > 0.1]
    # jacobian of the extension off the sphere, by finite differences
    np.testing.assert_allclose(_fd_derivative(F.value, x, h=1e-6), F.jacobian(x), atol=1e-7)
    generic = s.divergence(x, F.value(x), F.jacobian(x))
    np.testing.assert_allclose(generic, F.exact_divergence(x), rtol=1e-11, atol=1e-11)


def test_sphere_field_values():
    x = np.array([[0.6, 0.0, 0.8], [0.0, -0.6, 0.8]])
    lin = fn.sphere_field("linear")
    # F1 = F2 = x + y + z = 1.4 and 0.2; x_u = (xz, yz, -s)/s ..., x_v = (-y, x, 0)
    np.testing.assert_allclose(lin.value(x)[0], 1.4 * (np.array([0.8, 0.0, -0.6]) + np.array([0.0, 0.6, 0.0])))
    # divergence at (0.6, 0, 0.8): grad F1 . x_u + grad F2 . x_v + F1 cot u
    exact = (0.8 + 0.0 - 0.6) + (-0.0 + 0.6) + 1.4 * 0.8 / 0.6
    np.testing.assert_allclose(lin.exact_divergence(x[:1]), [exact], rtol=1e-14)


def test_sphere_field_singular_at_poles():
    F = fn.sphere_field("linear")
    # the divergence grows like 1/sin u towards the poles (F1 = 1 at the north pole)
    u = np.array([1e-2, 1e-4])
    d = F.exact_divergence(_uv(u, 0 * u))
    assert d[1] > 50 * d[0] > 0
    with pytest.raises(ValueError, match=r"on the polar axis \(x = y = 0\)"):
        F.value(np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]))
    with pytest.raises(ValueError, match="on the polar axis"):
        F.exact_divergence(np.array([[0.0, 0.0, -1.0]]))
    with pytest.raises(ValueError, match="must lie on the unit sphere"):
        F.exact_divergence(np.array([[2.0, 0.0, 0.0]]))


# ----------------------------------------------------------------------------
# lookups and bad input
# ----------------------------------------------------------------------------
def test_lookups():
    assert fn.scalar_function("xyz") is fn.xyz
    assert fn.scalar_function("sin_pi_x_cos_pi_y") is fn.sin_pi_x_cos_pi_y
    assert set(fn.SPHERE_FIELDS) == {"linear", "nonlinear", "trigonometric"}
    assert fn.sphere_field("nonlinear").F1 is fn.xy and fn.sphere_field("nonlinear").F2 is fn.yz
    with pytest.raises(ValueError, match=r"name must be one of \[.*'xyz'.*\], got 'xyzw'"):
        fn.scalar_function("xyzw")
    with pytest.raises(ValueError, match=r"name must be one of \['linear', 'nonlinear', 'trigonometric'\]"):
        fn.sphere_field("cubic")


def test_bad_input():
    with pytest.raises(ValueError, match=r"x must have shape \(N, 3\), got shape \(4, 2\)"):
        fn.xyz.value(np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"x must have shape \(N, 2\), got shape \(4, 3\)"):
        fn.xy_2d.gradient(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="x must be finite"):
        fn.z_cos_xy.hessian([[0.0, np.nan, 1.0]])
    with pytest.raises(TypeError, match="x must be a numeric array"):
        fn.linear.value("abc")
    with pytest.raises(ValueError, match=r"x must have shape \(N, 2\)"):
        fn.sin_pi_field_2d.jacobian(np.zeros(3))
