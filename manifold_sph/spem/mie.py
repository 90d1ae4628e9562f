"""Plane-wave scattering by circular cylinders: the exact Bessel (Mie) series of both polarisations.

A unit plane wave travelling along +x, ``Ez_inc`` (TMz) or ``Hz_inc`` (TEz) ``= Re(exp(i (k x - w t)))``,
meets a cylinder of radius ``a`` centred at the origin:

``"pec"``
    a perfect conductor (TMz: ``Ez = 0`` on ``r = a``; TEz: tangential E zero, ``dHz/dr = 0``);
``"dielectric"``
    a homogeneous dielectric ``eps_r`` (``mu_r = 1``);
``"coated"`` (TMz)
    a PEC core of radius ``b`` in a dielectric shell ``b < r < a``.

With the time convention ``exp(-i w t)`` the scattered field is
``sum_n i^n a_n H_n^(1)(k r) exp(i n theta)`` and the field in a dielectric
``sum_n i^n c_n F_n(r) exp(i n theta)``, ``F_n = J_n(k1 r)`` (dielectric) or
``J_n(k1 r) Y_n(k1 b) - Y_n(k1 r) J_n(k1 b)`` (coated, zero on the core),
``k1 = k sqrt(eps_r)``.

TMz (:func:`mie_coefficients`): continuity of ``Ez`` and ``dEz/dr`` at ``r = a`` gives

    a_n = (k1 F_n' J_n(ka) - k J_n'(ka) F_n) / (k F_n H_n'(ka) - k1 F_n' H_n(ka)),
    c_n = (2 i / (pi a)) / (k F_n H_n'(ka) - k1 F_n' H_n(ka))

(``F_n, F_n'`` at ``r = a``, the prime a derivative with respect to the
argument; the second from the Wronskian), and ``a_n = -J_n(ka) / H_n(ka)``
for the PEC cylinder.

TEz (:func:`tez_mie_coefficients`, ``Ey_inc = eta0 Hz_inc``): the tangential
``E_theta`` is proportional to ``(1/eps) dHz/dr``, so continuity of ``Hz`` and of
``(1/eps) dHz/dr`` at ``r = a`` gives, with ``q = k1 / eps_r`` and ``F = J_n(k1 a)``,

    b_n = (q F' J_n(ka) - k J_n'(ka) F) / (k F H_n'(ka) - q F' H_n(ka)),
    d_n = (2 i / (pi a)) / (k F H_n'(ka) - q F' H_n(ka)),

and ``b_n = -J_n'(ka) / H_n'(ka)`` for the PEC cylinder (``H = H^(1)``; the
engineering convention ``exp(+j w t)`` writes the same with ``H^(2)``).

Examples
--------
>>> pts = np.array([[0.1, 0.0], [0.0, 0.15]])
>>> es = scattered_field(pts, "pec", freq=1e9, radius=0.1)
>>> inc = np.exp(1j * wavenumber(1e9) * pts[:, 0])
>>> bool(abs(es[0] + inc[0]) < 1e-12)  # Ez = 0 on the conductor
True
>>> b, d = tez_mie_coefficients("dielectric", 1e9, 0.1, eps_r=1.0)  # no contrast, no scattering
>>> bool(np.abs(b).max() < 1e-14), bool(np.allclose(d, 1.0))
(True, True)
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import h1vp, hankel1, jv, jvp, yv, yvp

from .._validation import as_points, check_in, check_int, check_positive
from .constants import C0

__all__ = ["SCATTERERS", "TEZ_SCATTERERS", "wavenumber", "check_scatterer", "check_tez_scatterer", "mie_coefficients",
           "incident_field", "scattered_field", "total_field", "tez_mie_coefficients", "tez_scattered_field",
           "tez_total_field"]


#: The scatterers of :func:`run_scattering`.
SCATTERERS = ("pec", "dielectric", "coated")


#: The scatterers of :func:`run_tez_scattering`.
TEZ_SCATTERERS = ("pec", "dielectric")


def wavenumber(freq: float, eps_r: float = 1.0) -> float:
    """``k = 2 pi f sqrt(eps_r) / c0`` (rad/m).

    >>> round(wavenumber(C0), 6)
    6.283185
    """
    freq = check_positive("freq", freq)
    eps_r = check_positive("eps_r", eps_r)
    return 2.0 * math.pi * freq * math.sqrt(eps_r) / C0


def check_scatterer(kind: str, radius: float, eps_r: float,
                    core_radius: float | None) -> tuple[str, float, float, float | None]:
    kind = check_in("kind", kind, SCATTERERS)
    radius = check_positive("radius", radius)
    eps_r = check_positive("eps_r", eps_r)
    if kind == "coated":
        core_radius = check_positive("core_radius", core_radius)
        if core_radius >= radius:
            raise ValueError(f"core_radius must be below radius = {radius}, got {core_radius}")
    return kind, radius, eps_r, core_radius


def _n_terms(ka, eps_r):
    x = ka * max(1.0, math.sqrt(eps_r))
    return int(math.ceil(x + 4.0 * x ** (1.0 / 3.0) + 10))


def mie_coefficients(kind: str, freq: float, radius: float, *, eps_r: float = 4.0, core_radius: float | None = None,
                     n_terms: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Series coefficients ``(a_n, c_n)``, ``n = 0..N``, of the module docstring (``c_n`` zero for PEC).

    Parameters
    ----------
    kind : {"pec", "dielectric", "coated"}
    freq : float
        Frequency (Hz).
    radius : float
        Cylinder radius ``a`` (m).
    eps_r : float
        Relative permittivity of the dielectric or the shell (ignored for "pec").
    core_radius : float, optional
        PEC core radius ``b < a`` ("coated" only).
    n_terms : int, optional
        Highest order N (default ``x + 4 x^(1/3) + 10``, ``x = k a max(1, sqrt(eps_r))``).

    Examples
    --------
    >>> a, c = mie_coefficients("dielectric", 1e9, 0.1, eps_r=1.0)  # no contrast, no scattering
    >>> bool(np.abs(a).max() < 1e-14), bool(np.allclose(c, 1.0))
    (True, True)
    """
    kind, radius, eps_r, core_radius = check_scatterer(kind, radius, eps_r, core_radius)
    k = wavenumber(freq)
    ka = k * radius
    N = _n_terms(ka, eps_r) if n_terms is None else check_int("n_terms", n_terms, minimum=0)
    n = np.arange(N + 1)
    J, Jp = jv(n, ka), jvp(n, ka)
    H, Hp = hankel1(n, ka), h1vp(n, ka)
    if kind == "pec":
        return -J / H, np.zeros(N + 1, dtype=complex)
    k1 = k * math.sqrt(eps_r)
    x = k1 * radius
    if kind == "dielectric":
        F, Fp = jv(n, x), jvp(n, x)
    else:
        xb = k1 * core_radius
        F = jv(n, x) * yv(n, xb) - yv(n, x) * jv(n, xb)
        Fp = jvp(n, x) * yv(n, xb) - yvp(n, x) * jv(n, xb)
    den = k * F * Hp - k1 * Fp * H
    return (k1 * Fp * J - k * Jp * F) / den, (2j / (math.pi * radius)) / den


def _series(coef, radial, theta):
    """``sum_n i^n coef_n radial_n exp(i n theta)`` over n in Z, with ``coef_{-n} radial_{-n} = (-1)^n ...``."""
    n = np.arange(len(coef))
    w = np.where(n == 0, 1.0, 2.0) * (1j ** n) * coef
    return (radial * w[None, :] * np.cos(np.outer(theta, n))).sum(axis=1)


def _outside_series(p: np.ndarray, coef: np.ndarray, freq: float, radius: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The scattered series outside the cylinder (both polarisations): ``(out, inside, r, theta, incident)``,
    ``out`` filled where ``r >= radius`` and left for the caller inside."""
    k = wavenumber(freq)
    r = np.hypot(p[:, 0], p[:, 1])
    th = np.arctan2(p[:, 1], p[:, 0])
    n = np.arange(len(coef))
    out = np.empty(len(p), dtype=complex)
    outside = r >= radius
    if outside.any():
        out[outside] = _series(coef, hankel1(n[None, :], k * r[outside, None]), th[outside])
    return out, ~outside, r, th, np.exp(1j * k * p[:, 0])


def incident_field(points: ArrayLike, freq: float) -> np.ndarray:
    """Incident phasor ``exp(i k x)`` at ``points`` (P, 2)."""
    p = as_points("points", points, dim=2)
    return np.exp(1j * wavenumber(freq) * p[:, 0])


def scattered_field(points: ArrayLike, kind: str, *, freq: float, radius: float, eps_r: float = 4.0,
                    core_radius: float | None = None, n_terms: int | None = None) -> np.ndarray:
    """Exact scattered phasor ``Ez_s = Ez - Ez_inc`` (time factor ``exp(-i w t)``) at ``points`` (P, 2).

    Outside the cylinder the Hankel series; inside a dielectric (or the
    coated cylinder's shell) the interior series minus the incident wave;
    inside a conductor ``-Ez_inc``.

    Examples
    --------
    >>> p = np.array([[0.0999999, 0.0], [0.1000001, 0.0]])  # either side of the interface
    >>> e = scattered_field(p, "dielectric", freq=1e9, radius=0.1, eps_r=4.0)
    >>> bool(abs(e[0] - e[1]) < 1e-5)
    True
    """
    kind, radius, eps_r, core_radius = check_scatterer(kind, radius, eps_r, core_radius)
    p = as_points("points", points, dim=2)
    a_n, c_n = mie_coefficients(kind, freq, radius, eps_r=eps_r, core_radius=core_radius, n_terms=n_terms)
    out, inside, r, th, inc = _outside_series(p, a_n, freq, radius)
    k, n = wavenumber(freq), np.arange(len(a_n))
    if kind == "pec":
        out[inside] = -inc[inside]
        return out
    if kind == "coated":
        core = inside & (r <= core_radius)
        out[core] = -inc[core]
        inside = inside & ~core
    if inside.any():
        k1r = k * math.sqrt(eps_r) * r[inside, None]
        if kind == "dielectric":
            F = jv(n[None, :], k1r)
        else:
            xb = k * math.sqrt(eps_r) * core_radius
            F = jv(n[None, :], k1r) * yv(n, xb)[None, :] - yv(n[None, :], k1r) * jv(n, xb)[None, :]
        out[inside] = _series(c_n, F, th[inside]) - inc[inside]
    return out


def total_field(points: ArrayLike, kind: str, *, freq: float, radius: float, eps_r: float = 4.0,
                core_radius: float | None = None, n_terms: int | None = None) -> np.ndarray:
    """Exact total phasor ``Ez = Ez_inc + Ez_s`` at ``points`` (P, 2) (zero in a conductor).

    >>> p = np.array([[0.1, 0.0], [0.0, -0.1], [0.0, 0.0]])
    >>> np.abs(total_field(p, "pec", freq=1e9, radius=0.1)).max() < 1e-12
    np.True_
    """
    return incident_field(points, freq) + scattered_field(points, kind, freq=freq, radius=radius, eps_r=eps_r,
                                                          core_radius=core_radius, n_terms=n_terms)


def check_tez_scatterer(kind: str, radius: float, eps_r: float) -> tuple[str, float, float]:
    kind = check_in("kind", kind, TEZ_SCATTERERS)
    radius = check_positive("radius", radius)
    eps_r = check_positive("eps_r", eps_r)
    return kind, radius, eps_r


def tez_mie_coefficients(kind: str, freq: float, radius: float, *, eps_r: float = 4.0,
                         n_terms: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """TEz series coefficients ``(b_n, d_n)``, ``n = 0..N``, of the module docstring (``d_n`` zero for PEC).

    Parameters
    ----------
    kind : {"pec", "dielectric"}
    freq : float
        Frequency (Hz).
    radius : float
        Cylinder radius ``a`` (m).
    eps_r : float
        Relative permittivity of the dielectric (ignored for "pec").
    n_terms : int, optional
        Highest order N (default ``x + 4 x^(1/3) + 10``, ``x = k a max(1, sqrt(eps_r))``).

    Returns
    -------
    (ndarray, ndarray)
        Complex ``b_n`` (scattered) and ``d_n`` (interior).

    Examples
    --------
    >>> b, _ = tez_mie_coefficients("pec", 1e9, 0.1)
    >>> from scipy.special import jvp, h1vp
    >>> bool(abs(b[0] + jvp(0, wavenumber(1e9) * 0.1) / h1vp(0, wavenumber(1e9) * 0.1)) < 1e-15)
    True
    """
    kind, radius, eps_r = check_tez_scatterer(kind, radius, eps_r)
    k = wavenumber(freq)
    ka = k * radius
    N = _n_terms(ka, eps_r) if n_terms is None else check_int("n_terms", n_terms, minimum=0)
    n = np.arange(N + 1)
    J, Jp = jv(n, ka), jvp(n, ka)
    H, Hp = hankel1(n, ka), h1vp(n, ka)
    if kind == "pec":
        return -Jp / Hp, np.zeros(N + 1, dtype=complex)
    k1 = k * math.sqrt(eps_r)
    q = k1 / eps_r
    F, Fp = jv(n, k1 * radius), jvp(n, k1 * radius)
    den = k * F * Hp - q * Fp * H
    return (q * Fp * J - k * Jp * F) / den, (2j / (math.pi * radius)) / den


def tez_scattered_field(points: ArrayLike, kind: str, *, freq: float, radius: float, eps_r: float = 4.0,
                        n_terms: int | None = None) -> np.ndarray:
    """Exact scattered phasor ``Hz_s = Hz - Hz_inc`` (time factor ``exp(-i w t)``) at ``points`` (P, 2).

    Outside the cylinder the Hankel series; inside the dielectric the
    interior series minus the incident wave; inside the conductor ``-Hz_inc``
    (no field there).

    Examples
    --------
    >>> p = np.array([[0.1 - 1e-9, 0.0], [0.1 + 1e-9, 0.0]])  # either side of the interface
    >>> h = tez_scattered_field(p, "dielectric", freq=1e9, radius=0.1, eps_r=4.0)
    >>> bool(abs(h[0] - h[1]) < 1e-6)
    True
    """
    kind, radius, eps_r = check_tez_scatterer(kind, radius, eps_r)
    p = as_points("points", points, dim=2)
    b_n, d_n = tez_mie_coefficients(kind, freq, radius, eps_r=eps_r, n_terms=n_terms)
    out, inside, r, th, inc = _outside_series(p, b_n, freq, radius)
    k, n = wavenumber(freq), np.arange(len(b_n))
    if kind == "pec":
        out[inside] = -inc[inside]
    elif inside.any():
        out[inside] = _series(d_n, jv(n[None, :], k * math.sqrt(eps_r) * r[inside, None]), th[inside]) - inc[inside]
    return out


def tez_total_field(points: ArrayLike, kind: str, *, freq: float, radius: float, eps_r: float = 4.0,
                    n_terms: int | None = None) -> np.ndarray:
    """Exact total phasor ``Hz = Hz_inc + Hz_s`` at ``points`` (P, 2) (zero inside a conductor).

    >>> p = np.array([[0.05, 0.0], [0.0, -0.2]])
    >>> h = tez_total_field(p, "pec", freq=1e9, radius=0.1)
    >>> bool(abs(h[0]) < 1e-15), bool(abs(h[1]) > 0.1)
    (True, True)
    """
    p = as_points("points", points, dim=2)
    return np.exp(1j * wavenumber(freq) * p[:, 0]) + tez_scattered_field(p, kind, freq=freq, radius=radius,
                                                                           eps_r=eps_r, n_terms=n_terms)
