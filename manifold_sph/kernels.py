"""Radial SPH smoothing kernels (docs/method.md section 1; references [1], [2] there).

A kernel is radial: ``W_h(x) = alpha_d(h) * w(R)`` with ``R = |x| / h`` and
support ``R < kappa``. Each kernel class provides the dimensionless profile
``w`` and its analytic derivatives ``dw``, ``d2w`` and ``dw_over_R``, the
normalisation ``alpha`` (computed numerically, checked against the closed
forms of ``closed_form_alpha``), and the dimensional ``value``, ``gradient``
and ``hessian`` of ``W_h``.

Kernels available (see :data:`KERNELS`):

========== ========================================= =======
name       profile w(R)                              kappa
========== ========================================= =======
quintic    quintic spline, [1] eq. 2.12               3
cubic      cubic spline (Monaghan M4), [2] eq. 2.9    2
gaussian   exp(-R^2) truncated, [2] eq. 2.13          3
wendland2  Wendland C2, (1 - R/2)^4 (2R + 1)           2
quartic    [2] eq. 2.10 ("quadratic spline")           2
========== ========================================= =======

Examples
--------
>>> k = get_kernel("quintic")
>>> round(k.alpha(2) * 478 * np.pi / 7, 12)
1.0
>>> k.gradient(np.array([[0.0, 0.0]]), 1.0)
array([[0., 0.]])
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import ArrayLike
from scipy import special

from ._validation import as_points, check_finite, check_in, check_int, check_positive

__all__ = [
    "Kernel",
    "QuinticSpline",
    "CubicSpline",
    "Gaussian",
    "WendlandC2",
    "QuarticSpline",
    "KERNELS",
    "get_kernel",
]

#: Surface measure of the unit sphere S^(d-1): length 2 of the two "ends" in
#: 1D, circumference 2 pi in 2D, area 4 pi in 3D.
_SPHERE = {1: 2.0, 2: 2.0 * math.pi, 3: 4.0 * math.pi}


def _as_R(R) -> np.ndarray:
    """Return ``R`` as a float64 array (no validation: internal fast path)."""
    return np.asarray(R, dtype=np.float64)


def _check_dim(d) -> int:
    d = check_int("d", d)
    check_in("d", d, (1, 2, 3))
    return d


def _check_h(h: ArrayLike) -> float | np.ndarray:
    """Return ``h`` as a float (scalar input) or a finite positive float64 array."""
    if np.ndim(h) == 0 and not isinstance(h, np.ndarray):
        if isinstance(h, np.generic):
            h = h.item()
        return check_positive("h", h)
    try:
        arr = np.asarray(h, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"h must be a positive number or array of positive numbers, got {type(h).__name__}") from exc
    check_finite("h", arr)
    if np.any(arr <= 0):
        bad = float(arr[arr <= 0].ravel()[0])
        raise ValueError(f"h must be positive, but it holds {int((arr <= 0).sum())} value(s) <= 0 (e.g. {bad!r})")
    if arr.ndim == 0:
        return float(arr)
    return arr


@functools.lru_cache(maxsize=None)
def _radial_moment(cls: type, support: float, knots: tuple, d: int) -> float:
    """int_0^kappa R^(d-1) w(R) dR, integrated numerically piece by piece."""
    from scipy import integrate  # deferred: scipy.integrate (and scipy.optimize with it) is slow to import

    kern = cls() if support is None else cls(support=support)
    edges = sorted({0.0, float(kern.support), *(float(k) for k in knots if 0.0 < k < kern.support)})
    total = 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        val, _err = integrate.quad(
            lambda R: R ** (d - 1) * float(kern.w(R)), a, b, epsabs=0.0, epsrel=1e-13, limit=200
        )
        total += val
    return total


class Kernel:
    """Base class of radial SPH kernels ``W_h(x) = alpha_d(h) w(|x|/h)``.

    Subclasses set ``name``, ``support`` (kappa) and ``knots`` (interior
    break points of a piecewise profile) and implement ``_w``, ``_dw``,
    ``_d2w`` for ``0 <= R < kappa`` and, when ``dw/R`` would lose accuracy
    near ``R = 0``, ``_dw_over_R``. The public methods apply the support mask
    (everything is zero for ``R >= kappa``) and accept any array shape.

    Attributes
    ----------
    name : str
        Registry name (a key of :data:`KERNELS`).
    support : float
        kappa: ``w(R) == 0`` for ``R >= kappa``; the support radius of
        ``W_h`` is ``kappa * h``.
    knots : tuple of float
        Interior break points of the profile (empty for smooth profiles).

    Examples
    --------
    >>> k = CubicSpline()
    >>> k.w(np.array([0.0, 1.0, 2.0]))
    array([1.  , 0.25, 0.  ])
    >>> round(k.alpha(3) * np.pi, 12)
    1.0
    """

    name: str = ""
    support: float = 1.0
    knots: tuple[float, ...] = ()

    # -- profile (subclasses) -------------------------------------------------
    def _w(self, R):  # pragma: no cover - abstract
        raise NotImplementedError

    def _dw(self, R):  # pragma: no cover - abstract
        raise NotImplementedError

    def _d2w(self, R):  # pragma: no cover - abstract
        raise NotImplementedError

    def _dw_over_R(self, R):
        """dw/R for 0 <= R < kappa; default divides, with the limit d2w(0) at 0."""
        safe = np.where(R > 0, R, 1.0)
        return np.where(R > 0, self._dw(safe) / safe, self._d2w(np.zeros_like(R)))

    def _mask(self, R, f):
        R = _as_R(R)
        inside = (R >= 0) & (R < self.support)
        Rin = np.where(inside, R, 0.0)
        out = np.where(inside, f(Rin), 0.0)
        return out if out.ndim else out[()]

    # -- public profile -------------------------------------------------------
    def w(self, R: ArrayLike) -> np.ndarray:
        """Dimensionless profile ``w(R)``; zero for ``R >= support``.

        Parameters
        ----------
        R : array_like
            Non-negative scaled distances ``r / h``.

        Returns
        -------
        numpy.ndarray
            ``w(R)``, same shape as ``R``.

        Examples
        --------
        >>> QuinticSpline().w([0.0, 3.0])
        array([66.,  0.])
        """
        return self._mask(R, self._w)

    def dw(self, R: ArrayLike) -> np.ndarray:
        """First derivative ``dw/dR``; zero for ``R >= support``.

        Examples
        --------
        >>> CubicSpline().dw([0.0, 1.0])
        array([ 0.  , -0.75])
        """
        return self._mask(R, self._dw)

    def d2w(self, R: ArrayLike) -> np.ndarray:
        """Second derivative ``d2w/dR2``; zero for ``R >= support``.

        Examples
        --------
        >>> QuinticSpline().d2w([0.0])
        array([-120.])
        """
        return self._mask(R, self._d2w)

    def dw_over_R(self, R: ArrayLike) -> np.ndarray:
        """``dw(R) / R``, with its finite limit ``d2w(0)`` at ``R = 0``.

        Evaluated without division warnings (and, for the spline kernels,
        from an analytic factorisation that keeps full accuracy near 0).

        Examples
        --------
        >>> QuinticSpline().dw_over_R([0.0, 1e-12])
        array([-120., -120.])
        """
        return self._mask(R, self._dw_over_R)

    def profile(self, R: np.ndarray) -> np.ndarray:
        """:meth:`w` without validation, for arrays of non-negative ``R`` (the assembly's inner loop).

        Examples
        --------
        >>> QuinticSpline().profile(np.array([0.0, 3.5])).tolist()
        [66.0, 0.0]
        """
        return self.w(R)

    def radial_terms(self, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(w, w'/R, (w'' - w'/R) / R^2)`` at non-negative scaled distances, in one pass.

        The three radial factors of the kernel, its gradient (``x w'/R``) and
        its Hessian (``w'/R I + (w'' - w'/R) x x^T / R^2``). All vanish for
        ``R >= support``; the last is set to 0 at ``R = 0``, where it multiplies
        ``x x^T = 0``. No validation: the assembly's inner loop.

        Examples
        --------
        >>> w, q, t = QuinticSpline().radial_terms(np.array([0.0, 0.5, 3.0]))
        >>> w.tolist(), q.tolist(), t.tolist()
        ([66.0, 52.5625, 0.0], [-120.0, -96.25, 0.0], [0.0, 165.0, 0.0])
        """
        w = self.w(R)
        q = self.dw_over_R(R)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(R > 0, (self.d2w(R) - q) / (R * R), 0.0)
        return w, q, t

    # -- normalisation --------------------------------------------------------
    def _cache_key(self):
        return (type(self), None, self.knots)

    def moment(self, d: int) -> float:
        """``int_0^kappa R^(d-1) w(R) dR`` computed numerically (cached per d).

        Examples
        --------
        >>> round(QuinticSpline().moment(1), 10)
        60.0
        """
        d = _check_dim(d)
        cls, support, knots = self._cache_key()
        return _radial_moment(cls, support, knots, d)

    def alpha(self, d: int, h: ArrayLike = 1.0) -> float | np.ndarray:
        """Normalisation ``alpha_d(h) = 1 / (S_d h^d int_0^kappa R^(d-1) w dR)``.

        The radial integral is computed numerically with ``scipy.integrate.quad``
        (piecewise between knots, cached per dimension), so it holds for any
        profile; :meth:`closed_form_alpha` gives the closed forms to check it.

        Parameters
        ----------
        d : {1, 2, 3}
            Space dimension.
        h : float or array_like, optional
            Smoothing length(s), positive. An array gives an array.

        Returns
        -------
        float or numpy.ndarray

        Raises
        ------
        ValueError
            If ``d`` is not 1, 2 or 3 or ``h`` is not positive.

        Examples
        --------
        >>> k = QuinticSpline()
        >>> round(k.alpha(1, h=0.5) * 120 * 0.5, 12)
        1.0
        """
        d = _check_dim(d)
        h = _check_h(h)
        return 1.0 / (_SPHERE[d] * self.moment(d) * h**d)

    def closed_form_alpha(self, d: int, h: ArrayLike = 1.0) -> float | np.ndarray:
        """Closed-form ``alpha_d(h)`` where known.

        Raises
        ------
        NotImplementedError
            If the kernel has no closed form for ``d``.

        Examples
        --------
        >>> round(CubicSpline().closed_form_alpha(2) * 7 * np.pi / 10, 12)
        1.0
        """
        d = _check_dim(d)
        h = _check_h(h)
        c = self._closed_alpha_unit(d)
        if c is None:
            raise NotImplementedError(f"kernel {self.name!r} has no closed-form alpha for d={d}")
        return c / h**d

    def _closed_alpha_unit(self, d: int):
        return None

    # -- dimensional kernel ---------------------------------------------------
    def value(self, r: ArrayLike, h: ArrayLike, d: int) -> np.ndarray:
        """``W_h(r) = alpha_d(h) w(r / h)``.

        Parameters
        ----------
        r : array_like
            Non-negative distances.
        h : float or array_like
            Positive smoothing length(s), broadcastable against ``r``.
        d : {1, 2, 3}
            Space dimension (fixes the normalisation).

        Returns
        -------
        numpy.ndarray
            Kernel values, shape of ``broadcast(r, h)``.

        Examples
        --------
        >>> k = QuinticSpline()
        >>> round(float(k.value(0.0, 1.0, 1)), 12)
        0.55
        """
        d = _check_dim(d)
        h = _check_h(h)
        try:
            r = np.asarray(r, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"r must be a numeric array of distances, got {type(r).__name__}") from exc
        check_finite("r", r)
        if np.any(r < 0):
            raise ValueError(f"r must be non-negative distances, got minimum {float(r.min())!r}")
        return self.alpha(d, h) * self.w(r / h)

    def _prepare_x(self, x: ArrayLike, h: ArrayLike) -> tuple[np.ndarray, float | np.ndarray]:
        x = as_points("x", x, dim=(1, 2, 3))
        h = _check_h(h)
        if isinstance(h, np.ndarray) and h.shape != (x.shape[0],):
            raise ValueError(f"h must be a scalar or have shape ({x.shape[0]},) to match x, got shape {h.shape}")
        return x, h

    def gradient(self, x: ArrayLike, h: ArrayLike) -> np.ndarray:
        """Gradient of ``W_h`` with respect to ``x``.

        ``grad W_h(x) = alpha_d w'(R) / h * x / r = alpha_d / h^2 * (w'(R)/R) x``,
        which is 0 at ``x = 0``. For the SPH pair gradient ``grad_i W(x_i - x_j)``
        pass ``x = x_i - x_j``.

        Parameters
        ----------
        x : array_like, shape (P, d)
            Separation vectors, d in {1, 2, 3}.
        h : float or array_like of shape (P,)
            Positive smoothing length(s).

        Returns
        -------
        numpy.ndarray, shape (P, d)

        Examples
        --------
        >>> k = CubicSpline()
        >>> g = k.gradient(np.array([[1.0, 0.0]]), 1.0)
        >>> np.round(g * np.pi * 7 / 10, 12)
        array([[-0.75,  0.  ]])
        """
        x, h = self._prepare_x(x, h)
        d = x.shape[1]
        r = np.linalg.norm(x, axis=1)
        R = r / h
        coef = self.alpha(d, h) / np.square(h) * self.dw_over_R(R)
        return coef[:, None] * x + 0.0  # + 0.0 turns -0.0 into 0.0

    def hessian(self, x: ArrayLike, h: ArrayLike) -> np.ndarray:
        """Hessian of ``W_h`` with respect to ``x``.

        ``H = alpha_d [ w''/h^2 e e^T + w'/(h r) (I - e e^T) ]`` with ``e = x / r``;
        at ``r = 0`` the limit ``alpha_d w''(0) / h^2 I``.

        Parameters
        ----------
        x : array_like, shape (P, d)
            Separation vectors, d in {1, 2, 3}.
        h : float or array_like of shape (P,)
            Positive smoothing length(s).

        Returns
        -------
        numpy.ndarray, shape (P, d, d)

        Examples
        --------
        >>> k = CubicSpline()
        >>> H = k.hessian(np.zeros((1, 2)), 1.0)
        >>> np.round(H * np.pi * 7 / 10, 12)
        array([[[-3.,  0.],
                [ 0., -3.]]])
        """
        x, h = self._prepare_x(x, h)
        P, d = x.shape
        r = np.linalg.norm(x, axis=1)
        R = r / h
        scale = np.broadcast_to(self.alpha(d, h) / np.square(h), (P,))
        safe_r = np.where(r > 0, r, 1.0)
        e = np.where((r > 0)[:, None], x / safe_r[:, None], 0.0)
        eeT = e[:, :, None] * e[:, None, :]
        eye = np.eye(d)[None, :, :]
        w2 = np.broadcast_to(self.d2w(R), (P,))
        w1r = np.broadcast_to(self.dw_over_R(R), (P,))
        H = w2[:, None, None] * eeT + w1r[:, None, None] * (eye - eeT)
        return scale[:, None, None] * H + 0.0

    def __repr__(self) -> str:
        return f"{type(self).__name__}(support={self.support})"


def _pos(a):
    return np.maximum(a, 0.0)


class QuinticSpline(Kernel):
    """Quintic spline, [1] eqs. 2.12-2.15, support kappa = 3.

    ``w = (3-R)^5 - 6(2-R)^5 + 15(1-R)^5`` on [0,1), ``(3-R)^5 - 6(2-R)^5`` on
    [1,2), ``(3-R)^5`` on [2,3), 0 after; written as
    ``(3-R)_+^5 - 6(2-R)_+^5 + 15(1-R)_+^5``. ``alpha_1 = 1/(120h)``,
    ``alpha_2 = 7/(478 pi h^2)``, ``alpha_3 = 1/(120 pi h^3)``.

    Note on d = 3: the value ``3/(359 pi h^3)`` widely quoted in the literature
    ([1] gives d = 1 and 2 only) is 0.28 % off. Since
    ``int_0^a R^2 (a-R)^5 dR = a^8/168``, the radial moment is
    ``(3^8 - 6*2^8 + 15)/168 = 5040/168 = 30`` exactly, so
    ``alpha_3 = 1/(4 pi * 30 h^3) = 1/(120 pi h^3)``; the numerical
    :meth:`alpha` agrees with this to round-off.

    Examples
    --------
    >>> k = QuinticSpline()
    >>> k.w([0.5, 1.5, 2.5])
    array([5.25625e+01, 7.40625e+00, 3.12500e-02])
    """

    name = "quintic"
    support = 3.0
    knots = (1.0, 2.0)

    def _w(self, R):
        return _pos(3 - R) ** 5 - 6 * _pos(2 - R) ** 5 + 15 * _pos(1 - R) ** 5

    def _dw(self, R):
        return -5 * _pos(3 - R) ** 4 + 30 * _pos(2 - R) ** 4 - 75 * _pos(1 - R) ** 4

    def _d2w(self, R):
        return 20 * _pos(3 - R) ** 3 - 120 * _pos(2 - R) ** 3 + 300 * _pos(1 - R) ** 3

    def _dw_over_R(self, R):
        # On [0, 1): w' = -120 R + 120 R^3 - 50 R^4 exactly, so w'/R is a polynomial.
        inner = -120.0 + 120.0 * R**2 - 50.0 * R**3
        safe = np.where(R >= 1.0, R, 1.0)
        return np.where(R < 1.0, inner, self._dw(safe) / safe)

    def profile(self, R: np.ndarray) -> np.ndarray:
        a = np.maximum(3.0 - R, 0.0)
        b = np.maximum(2.0 - R, 0.0)
        c = np.maximum(1.0 - R, 0.0)
        a2, b2, c2 = a * a, b * b, c * c
        return a2 * a2 * a - 6.0 * (b2 * b2 * b) + 15.0 * (c2 * c2 * c)

    def radial_terms(self, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # Fused: one set of powers of (3-R)_+, (2-R)_+, (1-R)_+ for all three factors.
        R = np.asarray(R, dtype=np.float64)
        a, b, c = np.maximum(3.0 - R, 0.0), np.maximum(2.0 - R, 0.0), np.maximum(1.0 - R, 0.0)
        a3, b3, c3 = a * a * a, b * b * b, c * c * c
        a4, b4 = a3 * a, b3 * b
        w = a4 * a - 6.0 * (b4 * b) + 15.0 * (c3 * c * c)
        d2w = 20.0 * a3 - 120.0 * b3 + 300.0 * c3
        inner = R < 1.0
        R2 = R * R
        # On [0, 1): w' = -120 R + 120 R^3 - 50 R^4 and w'' = -120 + 360 R^2 - 200 R^3, so
        # w'/R and (w'' - w'/R)/R^2 = 240 - 150 R are polynomials (no cancellation near 0).
        with np.errstate(divide="ignore", invalid="ignore"):
            q = np.where(inner, -120.0 + R2 * (120.0 - 50.0 * R), (30.0 * b4 - 5.0 * a4) / R)
            t = np.where(inner, 240.0 - 150.0 * R, (d2w - q) / R2)
        q[R >= 3.0] = 0.0
        t[(R >= 3.0) | (R == 0.0)] = 0.0
        return w, q, t

    def _closed_alpha_unit(self, d):
        return {1: 1.0 / 120.0, 2: 7.0 / (478.0 * math.pi), 3: 1.0 / (120.0 * math.pi)}[d]


class CubicSpline(Kernel):
    """Cubic spline (Monaghan M4), support kappa = 2.

    ``w = 1 - 1.5 R^2 + 0.75 R^3`` on [0,1), ``0.25 (2-R)^3`` on [1,2), 0 after;
    ``alpha_1 = 2/(3h)``, ``alpha_2 = 10/(7 pi h^2)``, ``alpha_3 = 1/(pi h^3)``.

    [2] eq. 2.9 writes the same spline in ``dbar = r/(alpha h)`` with
    scale factor ``alpha = 2`` (support ``dbar <= 1``):
    ``W(dbar) = 2/3 - 4 dbar^2 + 4 dbar^3`` (dbar <= 1/2),
    ``4/3 (1 - dbar)^3`` (1/2 <= dbar <= 1). With ``dbar = R/2`` this is
    ``2/3 - R^2 + R^3/2 = (2/3)(1 - 1.5R^2 + 0.75R^3)`` and
    ``(4/3)(2-R)^3/8 = (2/3) 0.25 (2-R)^3``: the profile of [2] is
    ``(2/3) w(R)``, identical after normalisation.

    Examples
    --------
    >>> CubicSpline().w([0.5, 1.5])
    array([0.71875, 0.03125])
    """

    name = "cubic"
    support = 2.0
    knots = (1.0,)

    def _w(self, R):
        return np.where(R < 1.0, 1.0 - 1.5 * R**2 + 0.75 * R**3, 0.25 * _pos(2 - R) ** 3)

    def _dw(self, R):
        return np.where(R < 1.0, -3.0 * R + 2.25 * R**2, -0.75 * _pos(2 - R) ** 2)

    def _d2w(self, R):
        return np.where(R < 1.0, -3.0 + 4.5 * R, 1.5 * _pos(2 - R))

    def _dw_over_R(self, R):
        safe = np.where(R >= 1.0, R, 1.0)
        return np.where(R < 1.0, -3.0 + 2.25 * R, -0.75 * _pos(2 - safe) ** 2 / safe)

    def _closed_alpha_unit(self, d):
        return {1: 2.0 / 3.0, 2: 10.0 / (7.0 * math.pi), 3: 1.0 / math.pi}[d]


class Gaussian(Kernel):
    """Gaussian ``w = exp(-R^2)`` truncated at ``R = kappa`` ([2] eq. 2.13).

    The normalisation is that of the truncated profile (the untruncated
    ``1/(pi^(d/2) h^d)`` of [2] is off by about ``exp(-kappa^2)``).
    Closed forms of the truncated moments: ``sqrt(pi)/2 erf(k)`` (d=1),
    ``(1 - exp(-k^2))/2`` (d=2), ``sqrt(pi)/4 erf(k) - k exp(-k^2)/2`` (d=3).
    Note ``w`` jumps by ``exp(-kappa^2)`` (1.2e-4 for kappa = 3) at the cut.

    Parameters
    ----------
    support : float, optional
        Truncation radius kappa (default 3; [2] suggests up to ~5).

    Examples
    --------
    >>> Gaussian().w([0.0, 3.0])
    array([1., 0.])
    """

    name = "gaussian"
    support = 3.0

    def __init__(self, support: float = 3.0) -> None:
        self.support = check_positive("support", support)

    def _cache_key(self):
        return (type(self), self.support, self.knots)

    def _w(self, R):
        return np.exp(-R * R)

    def _dw(self, R):
        return -2.0 * R * np.exp(-R * R)

    def _d2w(self, R):
        return (4.0 * R * R - 2.0) * np.exp(-R * R)

    def _dw_over_R(self, R):
        return -2.0 * np.exp(-R * R)

    def _closed_alpha_unit(self, d):
        k = self.support
        m = {
            1: math.sqrt(math.pi) / 2 * special.erf(k),
            2: (1.0 - math.exp(-k * k)) / 2,
            3: math.sqrt(math.pi) / 4 * special.erf(k) - k * math.exp(-k * k) / 2,
        }[d]
        return 1.0 / (_SPHERE[d] * m)


class WendlandC2(Kernel):
    """Wendland C2, ``w = (1 - R/2)^4 (2R + 1)`` on [0, 2), support kappa = 2.

    ``alpha_1 = 3/(4h)``, ``alpha_2 = 7/(4 pi h^2)``, ``alpha_3 = 21/(16 pi h^3)``.

    Examples
    --------
    >>> WendlandC2().w([0.0, 1.0, 2.0])
    array([1.    , 0.1875, 0.    ])
    """

    name = "wendland2"
    support = 2.0

    def _w(self, R):
        return _pos(1 - 0.5 * R) ** 4 * (2.0 * R + 1.0)

    def _dw(self, R):
        return -5.0 * R * _pos(1 - 0.5 * R) ** 3

    def _d2w(self, R):
        return _pos(1 - 0.5 * R) ** 2 * (10.0 * R - 5.0)

    def _dw_over_R(self, R):
        return -5.0 * _pos(1 - 0.5 * R) ** 3

    def _closed_alpha_unit(self, d):
        return {1: 3.0 / 4.0, 2: 7.0 / (4.0 * math.pi), 3: 21.0 / (16.0 * math.pi)}[d]


class QuarticSpline(Kernel):
    """The "quadratic spline" of [2] (eq. 2.10), a quartic in ``q = R / kappa``.

    ``w = 1 - 6q^2 + 8q^3 - 3q^4 = (1 - q)^3 (1 + 3q)`` for ``q < 1``. [2]
    writes it in ``dbar = r/(alpha h)``; here ``kappa`` plays the role of the
    scale factor alpha (default 2). For kappa = 2: ``alpha_1 = 5/(8h)``,
    ``alpha_2 = 5/(4 pi h^2)``, ``alpha_3 = 105/(128 pi h^3)`` (general kappa:
    moments ``kappa^d * (2/5, 1/10, 4/105)`` for d = 1, 2, 3).

    Parameters
    ----------
    support : float, optional
        kappa (default 2).

    Examples
    --------
    >>> QuarticSpline().w([0.0, 1.0, 2.0])
    array([1.    , 0.3125, 0.    ])
    """

    name = "quartic"
    support = 2.0

    def __init__(self, support: float = 2.0) -> None:
        self.support = check_positive("support", support)

    def _cache_key(self):
        return (type(self), self.support, self.knots)

    def _w(self, R):
        q = R / self.support
        return _pos(1 - q) ** 3 * (1.0 + 3.0 * q)

    def _dw(self, R):
        q = R / self.support
        return -12.0 * q * _pos(1 - q) ** 2 / self.support

    def _d2w(self, R):
        q = R / self.support
        return -12.0 * _pos(1 - q) * (1.0 - 3.0 * q) / self.support**2

    def _dw_over_R(self, R):
        q = R / self.support
        return -12.0 * _pos(1 - q) ** 2 / self.support**2

    def _closed_alpha_unit(self, d):
        m = {1: 2.0 / 5.0, 2: 1.0 / 10.0, 3: 4.0 / 105.0}[d] * self.support**d
        return 1.0 / (_SPHERE[d] * m)


#: Registry: kernel name -> class.
KERNELS: dict[str, type] = {
    cls.name: cls for cls in (QuinticSpline, CubicSpline, Gaussian, WendlandC2, QuarticSpline)
}


def get_kernel(kernel: str | Kernel | type[Kernel]) -> Kernel:
    """Return a :class:`Kernel` from a name or an instance.

    Parameters
    ----------
    kernel : str, Kernel or Kernel subclass
        A key of :data:`KERNELS` (case-insensitive), a kernel instance
        (returned as is) or a kernel class (instantiated with defaults).

    Returns
    -------
    Kernel

    Raises
    ------
    ValueError
        Unknown name; the message lists the valid names.
    TypeError
        Anything else.

    Examples
    --------
    >>> get_kernel("quintic").support
    3.0
    >>> get_kernel(CubicSpline()).name
    'cubic'
    """
    if isinstance(kernel, Kernel):
        return kernel
    if isinstance(kernel, type) and issubclass(kernel, Kernel) and kernel is not Kernel:
        return kernel()
    if isinstance(kernel, str):
        key = kernel.strip().lower()
        if key not in KERNELS:
            raise ValueError(f"kernel must be one of {sorted(KERNELS)!r}, got {kernel!r}")
        return KERNELS[key]()
    raise TypeError(f"kernel must be a kernel name (str) or a Kernel instance, got {type(kernel).__name__}")
