"""Test functions and vector fields with exact ambient derivatives (the thesis [1], docs/method.md section 5).

Scalar functions give ``value`` (N,), ``gradient`` (N, d) and ``hessian``
(N, d, d); vector fields give ``value`` (N, d) and ``jacobian`` (N, d, d) with
``jacobian[k, a, b] = dF_a / dx_b``. Combined with a shape of
:mod:`manifold_sph.reference.shapes` they give the exact surface references
(``f.laplace_beltrami(shape, x)`` etc.).

3D functions ([1] chapter 3): :data:`linear` ``x + y + z``, :data:`xyz`,
:data:`cos_xz_sin_y` ``cos(xz - sin y)``, :data:`z_cos_xy` ``z cos(xy)``.
Planar functions ([1] chapter 2; inputs (N, 2)): :data:`xy_2d`,
:data:`sin_pi_x_cos_pi_y`, and the field :data:`sin_pi_field_2d`
``(sin pi x, sin pi y)``.

Sphere fields ([1] sec. 3.3): ``F = F1 x_u + F2 x_v`` in the coordinate
basis of the parametrisation (1.14) of the unit sphere, with exact divergence
(3.13); see :class:`SphereField` and :func:`sphere_field`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_points, check_in

if TYPE_CHECKING:
    from .shapes import ImplicitShape

__all__ = [
    "ScalarFunction",
    "VectorField",
    "SphereField",
    "linear",
    "xyz",
    "cos_xz_sin_y",
    "z_cos_xy",
    "xy",
    "yz",
    "sin_x_plus_yz",
    "cos_z_minus_sin_xy",
    "xy_2d",
    "sin_pi_x_cos_pi_y",
    "sin_pi_field_2d",
    "SCALAR_FUNCTIONS",
    "PLANAR_FUNCTIONS",
    "PLANAR_FIELDS",
    "SPHERE_FIELDS",
    "scalar_function",
    "sphere_field",
    "sphere_basis",
]


class ScalarFunction:
    """A smooth function on R^d with exact gradient and Hessian.

    Parameters
    ----------
    name : str
    value, gradient, hessian : callable
        Vectorised callables of the columns ``x[:, 0], ..., x[:, d-1]`` (each
        (N,)) returning (N,), a list of d arrays, and a d x d nested list.
    dim : int
        2 (planar) or 3.
    expression : str
        Human-readable formula.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.array([[1.0, 2.0, 3.0]])
    >>> xyz.value(x).tolist(), xyz.gradient(x).tolist()
    ([6.0], [[6.0, 3.0, 2.0]])
    >>> xyz.hessian(x)[0].tolist()
    [[0.0, 3.0, 2.0], [3.0, 0.0, 1.0], [2.0, 1.0, 0.0]]
    """

    def __init__(
        self,
        name: str,
        value: Callable[..., ArrayLike],
        gradient: Callable[..., Sequence[ArrayLike]],
        hessian: Callable[..., Sequence[Sequence[ArrayLike]]],
        *,
        dim: int = 3,
        expression: str = "",
    ) -> None:
        self.name = name
        self.dim = dim
        self.expression = expression
        self._value = value
        self._gradient = gradient
        self._hessian = hessian

    def _cols(self, x: ArrayLike) -> tuple[np.ndarray, list[np.ndarray]]:
        x = as_points("x", x, dim=self.dim)
        return x, [x[:, a] for a in range(self.dim)]

    def value(self, x: ArrayLike) -> np.ndarray:
        """f(x), shape (N,)."""
        x, c = self._cols(x)
        return np.broadcast_to(np.asarray(self._value(*c), dtype=float), (len(x),)).copy()

    def gradient(self, x: ArrayLike) -> np.ndarray:
        """Ambient gradient, shape (N, d)."""
        x, c = self._cols(x)
        return np.stack([np.broadcast_to(g, (len(x),)) for g in self._gradient(*c)], axis=1).astype(float)

    def hessian(self, x: ArrayLike) -> np.ndarray:
        """Ambient Hessian, shape (N, d, d)."""
        x, c = self._cols(x)
        rows = [np.stack([np.broadcast_to(h, (len(x),)) for h in row], axis=1) for row in self._hessian(*c)]
        return np.stack(rows, axis=1).astype(float)

    def laplacian(self, x: ArrayLike) -> np.ndarray:
        """Ambient Laplacian (trace of the Hessian), shape (N,)."""
        return np.trace(self.hessian(x), axis1=1, axis2=2)

    def surface_gradient(self, shape: ImplicitShape, x: ArrayLike) -> np.ndarray:
        """Exact tangential gradient on ``shape`` at ``x``, (N, 3)."""
        return shape.surface_gradient(x, self.gradient(x))

    def laplace_beltrami(self, shape: ImplicitShape, x: ArrayLike) -> np.ndarray:
        """Exact Laplace-Beltrami on ``shape`` at ``x``, (N,)."""
        return shape.laplace_beltrami(x, self.gradient(x), self.hessian(x))

    def __repr__(self) -> str:
        return f"ScalarFunction({self.name!r}: {self.expression})"


class VectorField:
    """A smooth vector field on R^d with exact Jacobian ``J[k, a, b] = dF_a/dx_b``.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.array([[0.5, 0.0]])
    >>> sin_pi_field_2d.value(x).round(12).tolist(), sin_pi_field_2d.divergence(x).round(12).tolist()
    ([[1.0, 0.0]], [3.14159265359])
    """

    def __init__(
        self,
        name: str,
        value: Callable[..., Sequence[ArrayLike]],
        jacobian: Callable[..., Sequence[Sequence[ArrayLike]]],
        *,
        dim: int = 3,
        expression: str = "",
    ) -> None:
        self.name = name
        self.dim = dim
        self.expression = expression
        self._value = value
        self._jacobian = jacobian

    def _cols(self, x: ArrayLike) -> tuple[np.ndarray, list[np.ndarray]]:
        x = as_points("x", x, dim=self.dim)
        return x, [x[:, a] for a in range(self.dim)]

    def value(self, x: ArrayLike) -> np.ndarray:
        """F(x), shape (N, d)."""
        x, c = self._cols(x)
        return np.stack([np.broadcast_to(v, (len(x),)) for v in self._value(*c)], axis=1).astype(float)

    def jacobian(self, x: ArrayLike) -> np.ndarray:
        """Jacobian, shape (N, d, d), ``[k, a, b] = dF_a / dx_b``."""
        x, c = self._cols(x)
        rows = [np.stack([np.broadcast_to(h, (len(x),)) for h in row], axis=1) for row in self._jacobian(*c)]
        return np.stack(rows, axis=1).astype(float)

    def divergence(self, x: ArrayLike) -> np.ndarray:
        """Ambient divergence (trace of the Jacobian), shape (N,)."""
        return np.trace(self.jacobian(x), axis1=1, axis2=2)

    def surface_divergence(self, shape: ImplicitShape, x: ArrayLike) -> np.ndarray:
        """Exact divergence of the tangent projection of the field on ``shape``, (N,)."""
        return shape.divergence(x, self.value(x), self.jacobian(x))

    def __repr__(self) -> str:
        return f"VectorField({self.name!r}: {self.expression})"


# ----------------------------------------------------------------------------
# 3D scalar functions
# ----------------------------------------------------------------------------
_0 = 0.0
_1 = 1.0

linear = ScalarFunction(
    "linear",
    lambda x, y, z: x + y + z,
    lambda x, y, z: [_1, _1, _1],
    lambda x, y, z: [[_0, _0, _0], [_0, _0, _0], [_0, _0, _0]],
    expression="x + y + z",
)

xyz = ScalarFunction(
    "xyz",
    lambda x, y, z: x * y * z,
    lambda x, y, z: [y * z, x * z, x * y],
    lambda x, y, z: [[_0, z, y], [z, _0, x], [y, x, _0]],
    expression="x y z",
)


def _cxs_hess(x, y, z):
    u = x * z - np.sin(y)
    gu = [z, -np.cos(y), x]
    hu = [[_0, _0, _1], [_0, np.sin(y), _0], [_1, _0, _0]]
    c, s = np.cos(u), np.sin(u)
    return [[-c * gu[a] * gu[b] - s * hu[a][b] for b in range(3)] for a in range(3)]


cos_xz_sin_y = ScalarFunction(
    "cos_xz_sin_y",
    lambda x, y, z: np.cos(x * z - np.sin(y)),
    lambda x, y, z: [-np.sin(x * z - np.sin(y)) * g for g in (z, -np.cos(y), x)],
    _cxs_hess,
    expression="cos(x z - sin y)",
)


def _zcxy_hess(x, y, z):
    c, s = np.cos(x * y), np.sin(x * y)
    fxy = -z * (s + x * y * c)
    return [
        [-z * y * y * c, fxy, -y * s],
        [fxy, -z * x * x * c, -x * s],
        [-y * s, -x * s, _0],
    ]


z_cos_xy = ScalarFunction(
    "z_cos_xy",
    lambda x, y, z: z * np.cos(x * y),
    lambda x, y, z: [-z * y * np.sin(x * y), -z * x * np.sin(x * y), np.cos(x * y)],
    _zcxy_hess,
    expression="z cos(x y)",
)

# coordinate functions of the sphere fields of [1]
xy = ScalarFunction(
    "xy",
    lambda x, y, z: x * y,
    lambda x, y, z: [y, x, _0],
    lambda x, y, z: [[_0, _1, _0], [_1, _0, _0], [_0, _0, _0]],
    expression="x y",
)

yz = ScalarFunction(
    "yz",
    lambda x, y, z: y * z,
    lambda x, y, z: [_0, z, y],
    lambda x, y, z: [[_0, _0, _0], [_0, _0, _1], [_0, _1, _0]],
    expression="y z",
)


def _sxyz_hess(x, y, z):
    w = x + y * z
    gw = [_1, z, y]
    hw = [[_0, _0, _0], [_0, _0, _1], [_0, _1, _0]]
    s, c = np.sin(w), np.cos(w)
    return [[-s * gw[a] * gw[b] + c * hw[a][b] for b in range(3)] for a in range(3)]


sin_x_plus_yz = ScalarFunction(
    "sin_x_plus_yz",
    lambda x, y, z: np.sin(x + y * z),
    lambda x, y, z: [np.cos(x + y * z) * g for g in (_1, z, y)],
    _sxyz_hess,
    expression="sin(x + y z)",
)


def _czsxy_grad(x, y, z):
    v = z - np.sin(x * y)
    c = np.cos(x * y)
    return [-np.sin(v) * g for g in (-y * c, -x * c, _1)]


def _czsxy_hess(x, y, z):
    v = z - np.sin(x * y)
    c, s = np.cos(x * y), np.sin(x * y)
    gv = [-y * c, -x * c, _1]
    vxy = -c + x * y * s
    hv = [[y * y * s, vxy, _0], [vxy, x * x * s, _0], [_0, _0, _0]]
    cv, sv = np.cos(v), np.sin(v)
    return [[-cv * gv[a] * gv[b] - sv * hv[a][b] for b in range(3)] for a in range(3)]


cos_z_minus_sin_xy = ScalarFunction(
    "cos_z_minus_sin_xy",
    lambda x, y, z: np.cos(z - np.sin(x * y)),
    _czsxy_grad,
    _czsxy_hess,
    expression="cos(z - sin(x y))",
)

# ----------------------------------------------------------------------------
# planar functions and field ([1] chapter 2, domain [-1, 1]^2)
# ----------------------------------------------------------------------------
_PI = math.pi

xy_2d = ScalarFunction(
    "xy_2d",
    lambda x, y: x * y,
    lambda x, y: [y, x],
    lambda x, y: [[_0, _1], [_1, _0]],
    dim=2,
    expression="x y",
)


def _spcp_hess(x, y):
    f = np.sin(_PI * x) * np.cos(_PI * y)
    fxy = -_PI * _PI * np.cos(_PI * x) * np.sin(_PI * y)
    return [[-_PI * _PI * f, fxy], [fxy, -_PI * _PI * f]]


sin_pi_x_cos_pi_y = ScalarFunction(
    "sin_pi_x_cos_pi_y",
    lambda x, y: np.sin(_PI * x) * np.cos(_PI * y),
    lambda x, y: [_PI * np.cos(_PI * x) * np.cos(_PI * y), -_PI * np.sin(_PI * x) * np.sin(_PI * y)],
    _spcp_hess,
    dim=2,
    expression="sin(pi x) cos(pi y)   (Laplacian -2 pi^2 f)",
)

sin_pi_field_2d = VectorField(
    "sin_pi_field_2d",
    lambda x, y: [np.sin(_PI * x), np.sin(_PI * y)],
    lambda x, y: [[_PI * np.cos(_PI * x), _0], [_0, _PI * np.cos(_PI * y)]],
    dim=2,
    expression="(sin pi x, sin pi y)   (divergence pi (cos pi x + cos pi y))",
)

SCALAR_FUNCTIONS = {f.name: f for f in (linear, xyz, cos_xz_sin_y, z_cos_xy, xy, yz, sin_x_plus_yz, cos_z_minus_sin_xy)}
PLANAR_FUNCTIONS = {f.name: f for f in (xy_2d, sin_pi_x_cos_pi_y)}
PLANAR_FIELDS = {sin_pi_field_2d.name: sin_pi_field_2d}


def scalar_function(name: str) -> ScalarFunction:
    """Look up a 3D or planar test function by name.

    Examples
    --------
    >>> scalar_function("z_cos_xy").expression
    'z cos(x y)'
    """
    table = {**SCALAR_FUNCTIONS, **PLANAR_FUNCTIONS}
    check_in("name", name, table)
    return table[name]


# ----------------------------------------------------------------------------
# sphere fields in the coordinate basis of (1.14)
# ----------------------------------------------------------------------------
_POLE_TOL = 1e-12
_SPHERE_TOL = 1e-8


def _sphere_points(x, check_unit: bool) -> np.ndarray:
    x = as_points("x", x)
    s = np.hypot(x[:, 0], x[:, 1])
    if np.any(s <= _POLE_TOL):
        idx = np.flatnonzero(s <= _POLE_TOL)
        raise ValueError(
            f"x holds {idx.size} point(s) on the polar axis (x = y = 0), where the basis x_u, x_v "
            f"of (1.14) is undefined (first indices {idx[:5].tolist()})"
        )
    if check_unit:
        err = np.abs(np.linalg.norm(x, axis=1) - 1.0)
        if np.any(err > _SPHERE_TOL):
            i = int(np.argmax(err))
            raise ValueError(
                f"x must lie on the unit sphere (| |x| - 1 | <= {_SPHERE_TOL:g}), "
                f"but point {i} is off by {err[i]:.3g}"
            )
    return x


def sphere_basis(x: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coordinate basis of (1.14)-(1.16) written in x, y, z on the unit sphere.

    With ``s = sin u = sqrt(x^2 + y^2)``: ``x_u = (x z / s, y z / s, -s)``,
    ``x_v = (-y, x, 0)``, ``cot u = z / s``. Undefined at the poles (s = 0).

    Returns
    -------
    x_u, x_v : ndarray, shape (N, 3)
    cot_u : ndarray, shape (N,)

    Examples
    --------
    >>> import numpy as np
    >>> xu, xv, cot = sphere_basis(np.array([[0.0, 1.0, 0.0]]))
    >>> xu.tolist(), xv.tolist(), cot.tolist()
    ([[0.0, 0.0, -1.0]], [[-1.0, 0.0, 0.0]], [0.0])
    """
    x = _sphere_points(x, check_unit=False)
    X, Y, Z = x[:, 0], x[:, 1], x[:, 2]
    s = np.hypot(X, Y)
    xu = np.stack([X * Z / s, Y * Z / s, -s], axis=1)
    xv = np.stack([-Y, X, np.zeros_like(X)], axis=1)
    return xu, xv, Z / s


class SphereField:
    """Tangent field ``F = F1 x_u + F2 x_v`` on the unit sphere ([1] eq. 3.10).

    ``F1``, ``F2`` are functions of (x, y, z); ``x_u``, ``x_v`` the coordinate
    basis (1.16) of the parametrisation (1.14) (``u`` polar angle, ``v``
    azimuth), see :func:`sphere_basis`. The exact divergence is eq. (3.13) with
    ``sqrt(det g) = sin u``:

        ``div_S F = grad F1 . x_u + grad F2 . x_v + F1 cot u``.

    The field and its divergence are SINGULAR at the poles of the
    parametrisation (x = y = 0): the basis is undefined there, ``|x_v| = sin u``
    vanishes and ``F1 cot u`` diverges like ``1 / sin u`` unless ``F1`` vanishes.
    Points exactly on the polar axis are rejected; compare with numerical
    operators away from the poles.

    :meth:`jacobian` is that of the extension ``x_u(x) = (x z/s, y z/s, -s)``,
    ``x_v(x) = (-y, x, 0)`` off the sphere, so the generic implicit formula
    ``Sphere().divergence(x, F.value(x), F.jacobian(x))`` applies (and agrees).

    Examples
    --------
    >>> import numpy as np
    >>> F = sphere_field("nonlinear")
    >>> x = np.array([[0.6, 0.0, 0.8]])
    >>> F.coefficients(x)[1].tolist()   # F2 = yz
    [0.0]
    >>> F.exact_divergence(x).round(12).tolist()   # grad(yz) . x_v = z x
    [0.48]
    """

    def __init__(self, name: str, F1: ScalarFunction, F2: ScalarFunction) -> None:
        self.name = name
        self.F1 = F1
        self.F2 = F2
        self.expression = f"({F1.expression}) x_u + ({F2.expression}) x_v"

    def coefficients(self, x: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """``(F1, F2)`` at ``x``, each (N,)."""
        x = _sphere_points(x, check_unit=False)
        return self.F1.value(x), self.F2.value(x)

    def value(self, x: ArrayLike) -> np.ndarray:
        """``F1 x_u + F2 x_v``, (N, 3); ``x`` off the polar axis."""
        xu, xv, _ = sphere_basis(x)
        f1, f2 = self.coefficients(x)
        return f1[:, None] * xu + f2[:, None] * xv

    def jacobian(self, x: ArrayLike) -> np.ndarray:
        """Ambient Jacobian of the extension, (N, 3, 3), ``[k, a, b] = dF_a/dx_b``."""
        x = _sphere_points(x, check_unit=False)
        X, Y, Z = x[:, 0], x[:, 1], x[:, 2]
        s = np.hypot(X, Y)
        s3 = s**3
        Dxu = np.empty((len(x), 3, 3))
        Dxu[:, 0] = np.stack([Z * Y * Y / s3, -X * Y * Z / s3, X / s], axis=1)
        Dxu[:, 1] = np.stack([-X * Y * Z / s3, Z * X * X / s3, Y / s], axis=1)
        Dxu[:, 2] = np.stack([-X / s, -Y / s, np.zeros_like(X)], axis=1)
        Dxv = np.zeros((len(x), 3, 3))
        Dxv[:, 0, 1] = -1.0
        Dxv[:, 1, 0] = 1.0
        xu, xv, _ = sphere_basis(x)
        f1, f2 = self.coefficients(x)
        g1, g2 = self.F1.gradient(x), self.F2.gradient(x)
        return (
            xu[:, :, None] * g1[:, None, :]
            + f1[:, None, None] * Dxu
            + xv[:, :, None] * g2[:, None, :]
            + f2[:, None, None] * Dxv
        )

    def exact_divergence(self, x: ArrayLike) -> np.ndarray:
        """Eq. (3.13) on the unit sphere: ``grad F1 . x_u + grad F2 . x_v + F1 cot u``, (N,).

        Raises
        ------
        ValueError
            If a point is on the polar axis or off the unit sphere (by > 1e-8).
        """
        x = _sphere_points(x, check_unit=True)
        xu, xv, cot = sphere_basis(x)
        return (
            np.einsum("ni,ni->n", self.F1.gradient(x), xu)
            + np.einsum("ni,ni->n", self.F2.gradient(x), xv)
            + self.F1.value(x) * cot
        )

    def __repr__(self) -> str:
        return f"SphereField({self.name!r}: {self.expression})"


SPHERE_FIELDS = {
    "linear": SphereField("linear", linear, linear),
    "nonlinear": SphereField("nonlinear", xy, yz),
    "trigonometric": SphereField("trigonometric", sin_x_plus_yz, cos_z_minus_sin_xy),
}


def sphere_field(name: str) -> SphereField:
    """The sphere fields of [1]: "linear", "nonlinear" or "trigonometric".

    ``(F1, F2) = (x+y+z, x+y+z)``, ``(xy, yz)``, ``(sin(x+yz), cos(z - sin(xy)))``.

    Examples
    --------
    >>> sphere_field("trigonometric").expression
    '(sin(x + y z)) x_u + (cos(z - sin(x y))) x_v'
    >>> sphere_field("cubic")
    Traceback (most recent call last):
    ...
    ValueError: name must be one of ['linear', 'nonlinear', 'trigonometric'], got 'cubic'
    """
    check_in("name", name, SPHERE_FIELDS)
    return SPHERE_FIELDS[name]
