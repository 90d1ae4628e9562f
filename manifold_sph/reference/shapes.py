"""Implicit surfaces with exact differential-geometry references (the base class and
the formulas: :mod:`manifold_sph.reference.implicit`).

Shapes: :class:`Sphere`, :class:`Torus` ([1] eq. 1.15), :class:`DoubleTorus`
("Bitoro" in [1], genus 2) and :class:`Sausage` (a bent capsule whose two
ends nearly touch). The functions :func:`sphere`, :func:`torus`,
:func:`double_torus` and :func:`sausage` return sampled
:class:`~manifold_sph.pointcloud.PointCloud` objects with exact normals;
:func:`square` samples the planar domain of [1], chapter 2.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_points, check_finite, check_int, check_positive
from ..pointcloud import MIN_POINTS, PointCloud
from . import sampling as _sampling
from .implicit import AREA_CACHE, AXIS_MIN, TINY, ImplicitShape, as_center
from .sampling import square

__all__ = [
    "ImplicitShape",
    "Sphere",
    "Torus",
    "DoubleTorus",
    "Sausage",
    "sphere",
    "torus",
    "double_torus",
    "sausage",
    "square",
    "thin_torus",
    "ring_sphere",
    "flat_ellipsoid",
    "SHAPES",
]

#: Areas of default shapes whose numerical estimate takes seconds (see :meth:`DoubleTorus.area`).
_KNOWN_AREAS: dict = {("double_torus", 0.04): 6.530906747343963}


# ----------------------------------------------------------------------------
# sphere
# ----------------------------------------------------------------------------
class Sphere(ImplicitShape):
    """Sphere of radius ``radius`` about ``center``.

    ``phi = (|x - c|^2 - r^2) / (2 r)``, so ``|grad phi| = 1`` on the surface.
    Area ``4 pi r^2``; ``div n = 2 / r``. Projection is the exact closest point.
    The "variable" sampling coordinate is ``s = (z - c_z) / r``.

    Examples
    --------
    >>> import numpy as np
    >>> s = Sphere(radius=2.0)
    >>> x = np.array([[0.0, 0.0, 2.0], [2.0, 0.0, 0.0]])
    >>> s.mean_curvature(x).round(12).tolist()
    [1.0, 1.0]
    >>> s.normal(x).round(12).tolist()
    [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]
    """

    name = "sphere"
    samplings = _sampling.SPHERE_SAMPLINGS
    default_sampling = "fibonacci"
    area_is_exact = True

    def __init__(self, radius: float = 1.0, center: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        self.radius = check_positive("radius", radius)
        self.center = as_center(center)
        self._mesh_spacing = self.radius / 10
        self._max_step = self.radius

    def _params(self):
        return {"radius": self.radius, "center": tuple(self.center.tolist())}

    def _key(self):
        return ("sphere", self.radius, *self.center.tolist())

    def _phi(self, x):
        d = x - self.center
        return (np.einsum("ni,ni->n", d, d) - self.radius**2) / (2 * self.radius)

    def _grad(self, x):
        return (x - self.center) / self.radius

    def _hess(self, x):
        return np.broadcast_to(np.eye(3) / self.radius, (len(x), 3, 3)).copy()

    @property
    def bounds(self) -> tuple[float, ...]:
        c, r = self.center, self.radius
        return (c[0] - r, c[0] + r, c[1] - r, c[1] + r, c[2] - r, c[2] + r)

    @property
    def area(self) -> float:
        """Exact area ``4 pi r^2``."""
        return 4.0 * math.pi * self.radius**2

    def axis_coordinate(self, x: ArrayLike) -> np.ndarray:
        x = as_points("x", x)
        return np.clip((x[:, 2] - self.center[2]) / self.radius, -1.0, 1.0)

    def project(self, x: ArrayLike, tol: float = 1e-13, maxiter: int = 50) -> np.ndarray:
        """Closest point ``c + r (x - c) / |x - c|`` (exact; ``tol``, ``maxiter`` unused)."""
        x = as_points("x", x)
        check_positive("tol", tol)
        check_int("maxiter", maxiter, minimum=1)
        d = x - self.center
        dn = np.linalg.norm(d, axis=1)
        if np.any(dn <= TINY):
            raise ValueError("cannot project the sphere's center onto the sphere")
        return self.center + self.radius * d / dn[:, None]

    def project_near(self, x: np.ndarray) -> np.ndarray:
        return self.project(x)

    def uniform_random_points(self, n: int, rng: np.random.Generator) -> np.ndarray:
        g = rng.standard_normal((n, 3))
        return self.center + self.radius * g / np.linalg.norm(g, axis=1)[:, None]

    def fibonacci_points(self, n: int) -> np.ndarray:
        return self.center + self.radius * _sampling.fibonacci_sphere(n)


# ----------------------------------------------------------------------------
# torus
# ----------------------------------------------------------------------------
class Torus(ImplicitShape):
    """Ring torus about the z axis: tube radius ``r`` around a circle of radius ``R``.

    Parametrisation ([1] eq. 1.15): ``((R + r cos t) cos p, (R + r cos t) sin p,
    r sin t)``. ``phi = ((rho - R)^2 + z^2 - r^2) / (2 r)`` with ``rho`` the
    distance to the z axis. Area ``4 pi^2 R r``; principal curvatures ``1 / r``
    and ``cos t / (R + r cos t)``. Projection is the exact closest point.
    The "variable" sampling coordinate is ``s = (z - c_z) / r``.

    Examples
    --------
    >>> import numpy as np
    >>> t = Torus(R=0.8, r=0.2)
    >>> x = np.array([[1.0, 0.0, 0.0], [0.6, 0.0, 0.0]])   # outer and inner equator
    >>> t.principal_curvatures(x).round(10).tolist()
    [[5.0, 1.0], [5.0, -1.6666666667]]
    >>> round(t.area, 10) == round(4 * np.pi**2 * 0.8 * 0.2, 10)
    True
    """

    name = "torus"
    area_is_exact = True

    def __init__(self, R: float = 0.8, r: float = 0.2, center: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        self.R = check_positive("R", R)
        self.r = check_positive("r", r)
        if not self.r < self.R:
            raise ValueError(f"r must be smaller than R for a ring torus, got r={r!r} >= R={R!r}")
        self.center = as_center(center)
        self._mesh_spacing = self.r / 5
        self._max_step = self.r

    def _params(self):
        return {"R": self.R, "r": self.r, "center": tuple(self.center.tolist())}

    def _key(self):
        return ("torus", self.R, self.r, *self.center.tolist())

    def _rho(self, d):
        return np.maximum(np.hypot(d[:, 0], d[:, 1]), AXIS_MIN)

    def _phi(self, x):
        d = x - self.center
        rho = self._rho(d)
        return ((rho - self.R) ** 2 + d[:, 2] ** 2 - self.r**2) / (2 * self.r)

    def _grad(self, x):
        d = x - self.center
        rho = self._rho(d)
        k = (rho - self.R) / rho
        return np.stack([k * d[:, 0], k * d[:, 1], d[:, 2]], axis=1) / self.r

    def _hess(self, x):
        d = x - self.center
        rho = self._rho(d)
        H = np.zeros((len(x), 3, 3))
        a = 1 - self.R / rho
        b = self.R / rho**3
        H[:, 0, 0] = a + b * d[:, 0] ** 2
        H[:, 1, 1] = a + b * d[:, 1] ** 2
        H[:, 0, 1] = H[:, 1, 0] = b * d[:, 0] * d[:, 1]
        H[:, 2, 2] = 1.0
        return H / self.r

    @property
    def bounds(self) -> tuple[float, ...]:
        c, e = self.center, self.R + self.r
        return (c[0] - e, c[0] + e, c[1] - e, c[1] + e, c[2] - self.r, c[2] + self.r)

    @property
    def area(self) -> float:
        """Exact area ``4 pi^2 R r``."""
        return 4.0 * math.pi**2 * self.R * self.r

    def axis_coordinate(self, x: ArrayLike) -> np.ndarray:
        x = as_points("x", x)
        return np.clip((x[:, 2] - self.center[2]) / self.r, -1.0, 1.0)

    def project(self, x: ArrayLike, tol: float = 1e-13, maxiter: int = 50) -> np.ndarray:
        """Exact closest point on the torus (``tol``, ``maxiter`` unused)."""
        x = as_points("x", x)
        check_positive("tol", tol)
        check_int("maxiter", maxiter, minimum=1)
        d = x - self.center
        rho = np.hypot(d[:, 0], d[:, 1])
        if np.any(rho <= TINY):
            raise ValueError("cannot project points on the torus axis: every circle point is closest")
        core = np.zeros_like(d)
        core[:, 0] = self.R * d[:, 0] / rho
        core[:, 1] = self.R * d[:, 1] / rho
        e = d - core
        en = np.linalg.norm(e, axis=1)
        if np.any(en <= TINY):
            raise ValueError("cannot project points on the torus core circle: every tube point is closest")
        return self.center + core + self.r * e / en[:, None]

    def project_near(self, x: np.ndarray) -> np.ndarray:
        return self.project(x)

    def parametrization(self, t: ArrayLike, p: ArrayLike) -> np.ndarray:
        """Points of eq. (1.15): ``t`` around the tube, ``p`` around the z axis, (N, 3)."""
        t = np.asarray(t, dtype=float)
        p = np.asarray(p, dtype=float)
        w = self.R + self.r * np.cos(t)
        return self.center + np.stack([w * np.cos(p), w * np.sin(p), self.r * np.sin(t)], axis=-1)

    def uniform_random_points(self, n: int, rng: np.random.Generator) -> np.ndarray:
        # area element r (R + r cos t) dt dp: rejection in t
        out = np.empty(0)
        while out.size < n:
            m = 2 * (n - out.size) + 16
            t = rng.uniform(0, 2 * math.pi, m)
            keep = rng.random(m) * (self.R + self.r) <= self.R + self.r * np.cos(t)
            out = np.concatenate([out, t[keep]])
        t = out[:n]
        p = rng.uniform(0, 2 * math.pi, n)
        return self.parametrization(t, p)


# ----------------------------------------------------------------------------
# double torus ("Bitoro")
# ----------------------------------------------------------------------------
class DoubleTorus(ImplicitShape):
    """Genus-2 surface ``(x (x-1)^2 (x-2) + y^2)^2 + z^2 = c`` ("Bitoro" in [1]).

    With ``g(x, y) = x (x-1)^2 (x-2) + y^2`` the surface is a tube of half-height
    ``sqrt(c)`` around the figure-eight curve ``g = 0`` (lobes over x in [0, 1]
    and [1, 2], crossing at (1, 0)). It is smooth for every ``0 < c < 1/16``
    (``grad phi`` vanishes on it only if ``c = 0`` or ``c = 1/16``, where the
    holes ``g < -sqrt(c)`` close: ``min g = -1/4``), and has genus 2 there.

    The default ``c = 0.04`` keeps the holes well open (each about 0.33 long in
    x and 0.45 wide in y), the tube half-height is ``sqrt(c) = 0.2`` and its
    half-width in the plane ranges from ``sqrt(c)/2 = 0.1`` (at the ends x ~ 0
    and x ~ 2, where ``|grad g| = 2``) upwards; ``|grad phi| >= 0.17`` on the
    surface (no pinch). The flattened ends carry the largest principal
    curvature, about 22 (radius 0.046): at the 3070 points of [1] with 27
    neighbours (``rho_s = 0.135``) the kernel support spans about three
    curvature radii there. Smaller c makes that worse (c = 0.01: 41) and
    c -> 1/16 closes the holes; 0.04 is the compromise. The area (6.53091) is
    a numerical estimate: the marching-cubes mesh (spacing ``sqrt(c)/10``),
    projected onto the surface, subdivided twice and Richardson-extrapolated
    (``_numerical_area``; the same procedure gets the sphere and torus areas to
    1e-7 relative, and halving the grid spacing changes the estimate by 6e-10).
    The "variable" sampling coordinate is ``s = (x - 1) / x_half`` (one handle
    against the other).

    Examples
    --------
    >>> import numpy as np
    >>> dt = DoubleTorus()
    >>> x = dt.project(np.array([[1.0, 0.5, 0.3], [0.0, 0.0, 0.1]]))
    >>> bool(np.abs(dt.phi(x)).max() < 1e-14)
    True
    >>> round(dt.area, 4)
    6.5309
    """

    name = "double_torus"

    def __init__(self, c: float = 0.04) -> None:
        c = check_positive("c", c)
        if not c < 1.0 / 16.0:
            raise ValueError(f"c must be in (0, 1/16) for a smooth genus-2 surface, got {c!r}")
        self.c = c
        sc = math.sqrt(c)
        self._mesh_spacing = sc / 10
        self._max_step = sc / 2
        # extent: p(x) = s^4 - s^2 = sqrt(c) at the ends, y^2 <= sqrt(c) + 1/4
        s_end = math.sqrt((1 + math.sqrt(1 + 4 * sc)) / 2)
        self._x_half = s_end
        self._y_half = math.sqrt(sc + 0.25)
        self._z_half = sc

    def _params(self):
        return {"c": self.c}

    def _key(self):
        return ("double_torus", self.c)

    @staticmethod
    def _g(x):
        s = x[:, 0] - 1.0
        s2 = s * s
        return s2 * s2 - s2 + x[:, 1] ** 2, s, s2

    def _phi_grad(self, x):
        g, s, s2 = self._g(x)
        gx = 4 * s2 * s - 2 * s
        gy = 2 * x[:, 1]
        phi = g * g + x[:, 2] ** 2 - self.c
        return phi, np.stack([2 * g * gx, 2 * g * gy, 2 * x[:, 2]], axis=1)

    def _phi(self, x):
        g, _, _ = self._g(x)
        return g * g + x[:, 2] ** 2 - self.c

    def _grad(self, x):
        return self._phi_grad(x)[1]

    def _hess(self, x):
        g, s, s2 = self._g(x)
        gx = 4 * s2 * s - 2 * s
        gy = 2 * x[:, 1]
        gxx = 12 * s2 - 2
        H = np.zeros((len(x), 3, 3))
        H[:, 0, 0] = 2 * (gx * gx + g * gxx)
        H[:, 1, 1] = 2 * (gy * gy + 2 * g)
        H[:, 0, 1] = H[:, 1, 0] = 2 * gx * gy
        H[:, 2, 2] = 2.0
        return H

    @property
    def bounds(self) -> tuple[float, ...]:
        return (1 - self._x_half, 1 + self._x_half, -self._y_half, self._y_half, -self._z_half, self._z_half)

    @property
    def area(self) -> float:
        """Numerical area (projected marching-cubes mesh, Richardson-extrapolated).

        The default shape's value is stored (:data:`_KNOWN_AREAS`): the procedure takes about 2 s,
        paid otherwise by every process that samples it.
        """
        known = _KNOWN_AREAS.get(self._key())
        return known if known is not None else self._numerical_area()

    def axis_coordinate(self, x: ArrayLike) -> np.ndarray:
        x = as_points("x", x)
        return np.clip((x[:, 0] - 1.0) / self._x_half, -1.0, 1.0)


# ----------------------------------------------------------------------------
# sausage
# ----------------------------------------------------------------------------
class Sausage(ImplicitShape):
    """A bent capsule along a circular arc whose two ends nearly touch.

    With ``rho`` the distance to the circle of radius ``arc_radius`` in the
    xy-plane and ``theta = atan2(y, x)`` in (-pi, pi],

        ``phi = (rho / tube_radius)^2 + (theta / theta0)^power - 1``.

    The cross-section at angle ``theta`` is a circle of radius
    ``a(theta) = tube_radius sqrt(1 - (theta/theta0)^power)``: a tube of radius
    ``tube_radius`` that closes smoothly at the tips ``theta = +-theta0`` (a bent
    super-ellipsoid). ``phi`` is C-infinity on a neighbourhood of the surface; the
    branch cut of ``atan2`` (theta = pi) lies in the gap between the ends, where
    ``phi >= (pi/theta0)^power - 1 > 0``.

    Defaults: ``arc_radius = 1``, ``tube_radius = 0.25``, ``power = 16``,
    ``theta0 = pi - 0.045``. Area 9.4837 (quadrature, :attr:`area`); the tips
    have radius of curvature ``tube_radius^2 power / (2 theta0 arc_radius)``
    = 0.161 and the largest principal curvature on the surface is about 6.8
    (the "region of high curvature" of [1]). The gap between the two ends,
    :attr:`gap`, is 0.0896. For ``N = 2652`` points with 27 neighbours per
    support disc, ``rho_s = sqrt(27 area / (pi N)) = 0.1753``, so the gap is
    ``0.51 rho_s``: a plain radius search joins the ends, while the normals of
    the facing end caps point at each other (``n_i . n_j < 0``) so the normal
    test of docs/method.md section 2.1 separates them. The "variable" sampling
    coordinate is ``s = theta / theta0`` (one end against the other).

    Examples
    --------
    >>> s = Sausage()
    >>> round(s.gap, 4), round(s.area, 4)
    (0.0896, 9.4837)
    >>> import numpy as np
    >>> s.arc_angle(np.array([[0.0, 1.0, 0.0]])).round(6).tolist()
    [1.570796]
    """

    name = "sausage"

    def __init__(
        self, arc_radius: float = 1.0, tube_radius: float = 0.25, theta0: float = math.pi - 0.045, power: int = 16
    ) -> None:
        self.arc_radius = check_positive("arc_radius", arc_radius)
        self.tube_radius = check_positive("tube_radius", tube_radius)
        if not self.tube_radius < self.arc_radius:
            raise ValueError(
                f"tube_radius must be smaller than arc_radius, got tube_radius={tube_radius!r} >= "
                f"arc_radius={arc_radius!r}"
            )
        theta0 = check_positive("theta0", theta0)
        if not theta0 < math.pi:
            raise ValueError(f"theta0 must be in (0, pi) so the ends leave a gap, got {theta0!r}")
        self.theta0 = theta0
        power = check_int("power", power, minimum=2)
        if power % 2:
            raise ValueError(f"power must be an even integer (phi smooth across theta = 0), got {power}")
        self.power = power
        self._mesh_spacing = self.tube_radius / 8
        self._max_step = self.tube_radius / 2

    def _params(self):
        return {"arc_radius": self.arc_radius, "tube_radius": self.tube_radius, "theta0": self.theta0, "power": self.power}

    def _key(self):
        return ("sausage", self.arc_radius, self.tube_radius, self.theta0, self.power)

    def arc_angle(self, x: ArrayLike) -> np.ndarray:
        """``theta = atan2(y, x)`` in (-pi, pi]: the ends are near ``+theta0`` and ``-theta0``."""
        x = as_points("x", x)
        return np.arctan2(x[:, 1], x[:, 0])

    def axis_coordinate(self, x: ArrayLike) -> np.ndarray:
        return np.clip(self.arc_angle(x) / self.theta0, -1.0, 1.0)

    def _parts(self, x):
        q = np.maximum(np.hypot(x[:, 0], x[:, 1]), AXIS_MIN)
        th = np.arctan2(x[:, 1], x[:, 0])
        return q, th

    def _phi_grad(self, x):
        q = np.maximum(np.hypot(x[:, 0], x[:, 1]), AXIS_MIN)
        th = np.arctan2(x[:, 1], x[:, 0])
        r2 = self.tube_radius**2
        dq = q - self.arc_radius
        t = th / self.theta0
        tp1 = t ** (self.power - 1)
        phi = (dq * dq + x[:, 2] ** 2) / r2 + tp1 * t - 1.0
        k = 2 * dq / (q * r2)
        bt = self.power * tp1 / (self.theta0 * q * q)  # dB/dtheta / q^2
        grad = np.stack([k * x[:, 0] - bt * x[:, 1], k * x[:, 1] + bt * x[:, 0], 2 * x[:, 2] / r2], axis=1)
        return phi, grad

    def _phi(self, x):
        q = np.hypot(x[:, 0], x[:, 1])
        th = np.arctan2(x[:, 1], x[:, 0])
        rho2 = (q - self.arc_radius) ** 2 + x[:, 2] ** 2
        return rho2 / self.tube_radius**2 + (th / self.theta0) ** self.power - 1.0

    def _grad(self, x):
        return self._phi_grad(x)[1]

    def _hess(self, x):
        q, th = self._parts(x)
        X, Y = x[:, 0], x[:, 1]
        r2 = self.tube_radius**2
        Rc = self.arc_radius
        p = self.power
        t = th / self.theta0
        bt = p * t ** (p - 1) / self.theta0
        btt = p * (p - 1) * t ** (p - 2) / self.theta0**2
        q2 = q * q
        q4 = q2 * q2
        H = np.zeros((len(x), 3, 3))
        a = 2 * (1 - Rc / q) / r2
        b = 2 * Rc / (q2 * q * r2)
        tx, ty = -Y / q2, X / q2  # grad theta
        hxx, hxy, hyy = 2 * X * Y / q4, (Y * Y - X * X) / q4, -2 * X * Y / q4  # Hess theta
        H[:, 0, 0] = a + b * X * X + btt * tx * tx + bt * hxx
        H[:, 1, 1] = a + b * Y * Y + btt * ty * ty + bt * hyy
        H[:, 0, 1] = H[:, 1, 0] = b * X * Y + btt * tx * ty + bt * hxy
        H[:, 2, 2] = 2 / r2
        return H

    @property
    def bounds(self) -> tuple[float, ...]:
        e = self.arc_radius + self.tube_radius
        return (-e, e, -e, e, -self.tube_radius, self.tube_radius)

    # -- parametrisation (theta, alpha) and its area density ---------------------------
    def _a2(self, theta):
        return self.tube_radius**2 * (1 - (theta / self.theta0) ** self.power)

    def parametrization(self, theta: ArrayLike, alpha: ArrayLike) -> np.ndarray:
        """Surface point at arc angle ``theta`` (|theta| <= theta0) and tube angle ``alpha``."""
        theta = np.asarray(theta, dtype=float)
        alpha = np.asarray(alpha, dtype=float)
        a = np.sqrt(np.maximum(self._a2(theta), 0.0))
        q = self.arc_radius + a * np.cos(alpha)
        return np.stack([q * np.cos(theta), q * np.sin(theta), a * np.sin(alpha)], axis=-1)

    def _area_density(self, theta, alpha):
        """``|x_theta x x_alpha| = sqrt(a^2 (Rc + a cos alpha)^2 + (a a')^2)`` (bounded)."""
        a2 = np.maximum(self._a2(theta), 0.0)
        a = np.sqrt(a2)
        t = theta / self.theta0
        aap = -0.5 * self.tube_radius**2 * self.power * t ** (self.power - 1) / self.theta0
        return np.sqrt(a2 * (self.arc_radius + a * np.cos(alpha)) ** 2 + aap**2)

    @property
    def area(self) -> float:
        """Area by quadrature of the parametrisation (accurate to ~1e-12 relative).

        ``theta = theta0 (1 - u^2)`` removes the square-root behaviour at the tips;
        Gauss-Legendre in ``u`` (200 nodes) and the trapezoidal rule in ``alpha``
        (128 nodes, spectrally accurate for periodic integrands); 50 x 64 nodes
        already give the same value to 1e-15.
        """
        key = ("area",) + self._key()
        if key not in AREA_CACHE:
            from scipy.special import roots_legendre

            u, w = roots_legendre(200)
            u = 0.5 * (u + 1)
            w = 0.5 * w
            theta = self.theta0 * (1 - u * u)
            alpha = np.linspace(0, 2 * math.pi, 128, endpoint=False)
            J = self._area_density(theta[:, None], alpha[None, :])
            inner = J.mean(axis=1) * 2 * math.pi
            # two halves (theta > 0 and < 0), d theta = 2 theta0 u du
            AREA_CACHE[key] = float(2 * np.sum(w * inner * 2 * self.theta0 * u))
        return AREA_CACHE[key]

    @property
    def gap(self) -> float:
        """Smallest distance in space between the two ends (across theta = pi).

        The ends are mirror images in the plane y = 0, so the gap is twice the
        smallest ``y`` of the end with ``theta > pi/2``; on each cross-section
        that is the innermost point, ``y = (Rc - a(theta)) sin(theta)``, minimised
        over ``theta`` (dense grid, then golden-section refinement).
        """
        from scipy.optimize import minimize_scalar

        def y(th):
            return (self.arc_radius - np.sqrt(np.maximum(self._a2(th), 0.0))) * np.sin(th)

        lo = max(math.pi / 2, self.theta0 - math.pi / 2)
        grid = np.linspace(lo, self.theta0, 4001)
        i = int(np.argmin(y(grid)))
        a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        if b > a:
            res = minimize_scalar(y, bounds=(a, b), method="bounded", options={"xatol": 1e-14})
            best = min(float(res.fun), float(y(grid[i])))
        else:
            best = float(y(grid[i]))
        return 2.0 * best

    @property
    def tips(self) -> np.ndarray:
        """The two tips (theta = +theta0 and -theta0), shape (2, 3)."""
        return self.parametrization(np.array([self.theta0, -self.theta0]), np.zeros(2))

    def uniform_random_points(self, n: int, rng: np.random.Generator) -> np.ndarray:
        # rejection in (theta, alpha) with the bounded area density
        r, Rc = self.tube_radius, self.arc_radius
        bound = math.hypot(r * (Rc + r), 0.5 * r * r * self.power / self.theta0)
        th_all, al_all = np.empty(0), np.empty(0)
        while th_all.size < n:
            m = 3 * (n - th_all.size) + 16
            th = rng.uniform(-self.theta0, self.theta0, m)
            al = rng.uniform(0, 2 * math.pi, m)
            keep = rng.random(m) * bound <= self._area_density(th, al)
            th_all = np.concatenate([th_all, th[keep]])
            al_all = np.concatenate([al_all, al[keep]])
        return self.project(self.parametrization(th_all[:n], al_all[:n]))


SHAPES = {"sphere": Sphere, "torus": Torus, "double_torus": DoubleTorus, "sausage": Sausage}


# ----------------------------------------------------------------------------
# sampled clouds
# ----------------------------------------------------------------------------
def sphere(
    n: int,
    radius: float = 1.0,
    center: ArrayLike = (0.0, 0.0, 0.0),
    sampling: str = "fibonacci",
    seed: int | np.random.Generator | None = 0,
    density_ratio: float = 4.0,
) -> PointCloud:
    """Sample a sphere (see :meth:`ImplicitShape.sample`).

    Samplings: "fibonacci" (golden-spiral lattice, deterministic, ``seed``
    unused), "poisson", "random", "variable".

    Examples
    --------
    >>> cloud = sphere(100)
    >>> len(cloud), cloud.geometry.name
    (100, 'sphere')
    >>> import numpy as np
    >>> float(np.abs(np.linalg.norm(cloud.points, axis=1) - 1).max()) < 1e-15
    True
    """
    return Sphere(radius, center).sample(n, sampling, seed=seed, density_ratio=density_ratio)


def torus(
    n: int,
    R: float = 0.8,
    r: float = 0.2,
    center: ArrayLike = (0.0, 0.0, 0.0),
    sampling: str = "poisson",
    seed: int | np.random.Generator | None = 0,
    density_ratio: float = 4.0,
) -> PointCloud:
    """Sample a torus ([1]: ``R = 0.8``, ``r = 0.2``, 4800 points).

    Examples
    --------
    >>> cloud = torus(200, seed=1)
    >>> len(cloud), cloud.geometry.name
    (200, 'torus')
    """
    return Torus(R, r, center).sample(n, sampling, seed=seed, density_ratio=density_ratio)


def double_torus(
    n: int, c: float = 0.04, sampling: str = "poisson", seed: int | np.random.Generator | None = 0, density_ratio: float = 4.0
) -> PointCloud:
    """Sample the genus-2 :class:`DoubleTorus` ("Bitoro" in [1], 3070 points).

    Examples
    --------
    >>> cloud = double_torus(300)
    >>> len(cloud), cloud.geometry.name
    (300, 'double_torus')
    """
    return DoubleTorus(c).sample(n, sampling, seed=seed, density_ratio=density_ratio)


def sausage(
    n: int,
    arc_radius: float = 1.0,
    tube_radius: float = 0.25,
    theta0: float = math.pi - 0.045,
    power: int = 16,
    sampling: str = "poisson",
    seed: int | np.random.Generator | None = 0,
    density_ratio: float = 4.0,
) -> PointCloud:
    """Sample the bent capsule :class:`Sausage` ([1]: 2652 points).

    Examples
    --------
    >>> cloud = sausage(300)
    >>> len(cloud), cloud.geometry.name
    (300, 'sausage')
    """
    return Sausage(arc_radius, tube_radius, theta0, power).sample(n, sampling, seed=seed, density_ratio=density_ratio)


# ----------------------------------------------------------------------------
# hostile samplings: what real scans and meshes deliver (thin parts, scan lines)
# ----------------------------------------------------------------------------
def thin_torus(
    around: int = 5,
    along: int = 150,
    R: float = 1.0,
    r: float = 0.05,
    jitter: float = 0.3,
    seed: int | np.random.Generator | None = 0,
) -> PointCloud:
    """A thin torus tube sampled only ``around`` points around (a tail, a handle, a cable).

    ``along`` rings of ``around`` points on a staggered grid (alternate rings turned by half a
    step), each point jittered by ``jitter`` grid steps in both directions; exact normals.
    Normal estimators that fit the whole neighbourhood reach across such a tube.

    Examples
    --------
    >>> cloud = thin_torus(seed=1)
    >>> len(cloud), cloud.geometry.name
    (750, 'torus')
    """
    around = check_int("around", around, minimum=3)
    along = check_int("along", along, minimum=3)
    R, r = check_positive("R", R), check_positive("r", r)
    if r >= R:
        raise ValueError(f"r must be smaller than R for a ring torus, got r={r} and R={R}")
    jitter = float(check_finite("jitter", np.asarray(jitter, dtype=np.float64)))
    if not 0.0 <= jitter < 1.0:
        raise ValueError(f"jitter must be in [0, 1), got {jitter}")
    rng = _sampling.as_rng(seed)
    i = np.arange(along)[:, None]
    u = (i + jitter * (rng.random((along, around)) - 0.5)) * 2 * np.pi / along
    v = (np.arange(around)[None, :] + jitter * (rng.random((along, around)) - 0.5) + 0.5 * (i % 2)) * 2 * np.pi / around
    u, v = u.ravel(), v.ravel()
    n = np.c_[np.cos(u) * np.cos(v), np.sin(u) * np.cos(v), np.sin(v)]
    return PointCloud(np.c_[R * np.cos(u), R * np.sin(u), 0 * u] + r * n, n, geometry=Torus(R, r))


def ring_sphere(
    rings: int = 12,
    per_ring: int = 80,
    jitter: float = 0.1,
    seed: int | np.random.Generator | None = 0,
) -> PointCloud:
    """The unit sphere sampled on ``rings`` latitude rings of ``per_ring`` points (scan lines).

    Rings at polar angles ``(j + 1/2) pi / rings``; points at equal longitudes, each shifted by
    up to ``jitter`` radians. With the defaults the points are about 6 times denser along the
    rings than across them at the equator, and the k-nearest-neighbour graph falls apart into
    bands of rings; the polar caps inside the first and last rings are empty.

    Examples
    --------
    >>> cloud = ring_sphere()
    >>> len(cloud), cloud.geometry.name
    (960, 'sphere')
    """
    rings = check_int("rings", rings, minimum=2)
    per_ring = check_int("per_ring", per_ring, minimum=3)
    jitter = float(check_finite("jitter", np.asarray(jitter, dtype=np.float64)))
    if not 0.0 <= jitter < 2 * np.pi:
        raise ValueError(f"jitter must be in [0, 2 pi) radians, got {jitter}")
    rng = _sampling.as_rng(seed)
    th = (np.arange(rings) + 0.5) / rings * np.pi
    T, Ph = np.meshgrid(th, np.arange(per_ring) * 2 * np.pi / per_ring, indexing="ij")
    Ph = Ph + jitter * rng.random(Ph.shape)
    n = np.c_[(np.sin(T) * np.cos(Ph)).ravel(), (np.sin(T) * np.sin(Ph)).ravel(), np.cos(T).ravel()]
    return PointCloud(n, n, geometry=Sphere(1.0))


def flat_ellipsoid(n: int = 2000, thickness: float = 1.0, seed: int | np.random.Generator | None = 0) -> PointCloud:
    """A thin closed slab: the ellipsoid with semi-axes 1, 0.6 and ``thickness`` spacings.

    The spacing is ``sqrt(2 pi 0.6 / n)``; ``n`` area-uniform random points (rejection sampling
    of the mapped sphere) and the exact outward normals. Propagated orientations tend to carry
    the sign wrongly around the rim of such a slab.

    Examples
    --------
    >>> cloud = flat_ellipsoid(500, seed=1)
    >>> len(cloud), bool(abs(cloud.points[:, 2]).max() <= (2 * np.pi * 0.6 / 500) ** 0.5)  # one spacing
    (500, True)
    """
    n = check_int("n", n, minimum=MIN_POINTS)
    thickness = check_positive("thickness", thickness)
    rng = _sampling.as_rng(seed)
    axes = np.array([1.0, 0.6, thickness * np.sqrt(2 * np.pi * 0.6 / n)])
    pts = np.zeros((0, 3))
    while len(pts) < n:
        u = rng.standard_normal((4 * n, 3))
        u /= np.linalg.norm(u, axis=1)[:, None]
        g = np.linalg.norm(u / axes, axis=1)  # area element of the map u -> axes * u, up to a constant
        pts = np.vstack([pts, (u * axes)[rng.random(4 * n) < g / g.max()]])
    pts = pts[:n]
    nrm = pts / axes**2
    return PointCloud(pts, nrm / np.linalg.norm(nrm, axis=1)[:, None])
