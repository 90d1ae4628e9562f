"""Stability of leap-frog on SPEM operators: the CFL rule, the spectral radius bound, leap-frog growth.

Every SPEM solver steps ``y'' = L y`` by leap-frog, stable when ``dt <= 2 / sqrt(rho)``
(``rho`` the spectral radius of ``-L``, whose eigenvalues must be real and non-positive) and
within the CFL rule ``S = sqrt(2) c dt / h_min <= 1`` ([2] eq. 3.16). For the energy-conserving
couplings ``L`` is similar to a symmetric negative semi-definite matrix and :func:`spectral_radius_bound`
bounds ``rho`` from above with a stated failure probability; :func:`leapfrog_growth` gives the
per-step growth of a mode with any eigenvalue (complex ones grow whatever dt).

Examples
--------
>>> round(cfl_number(1e-11, 0.01), 4)
0.424
>>> leapfrog_growth([-1.0, 0.01], 1.0).round(4).tolist()
[1.0, 1.1051]
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from .._validation import check_int, check_positive
from .constants import C0

__all__ = ["cfl_number", "check_dt", "per_particle", "spectral_radius_bound", "leapfrog_growth", "STABILITY_MARGIN",
           "LANCZOS_STEPS", "LANCZOS_FAILURE", "DENSE_RADIUS", "SPECTRUM_TOL"]


#: Relative margin on the computed spectral radius in :meth:`TMzSolver.stability_limit` (the
#: smallest one: the Lanczos bound's own may be larger, see :func:`spectral_radius_bound`).
STABILITY_MARGIN = 5e-3


#: Lanczos steps of :func:`spectral_radius_bound` (the bound is then within about 0.2 % of the
#: radius for any size: 0.19 % at 10^4 unknowns, 0.22 % at 10^6).
LANCZOS_STEPS = 300


#: Probability that :func:`spectral_radius_bound` is below the spectral radius (random start).
LANCZOS_FAILURE = 1e-9


#: Up to this many unknowns :func:`spectral_radius_bound` computes every eigenvalue (dense).
DENSE_RADIUS = 400


#: Imaginary parts below this fraction of the spectral radius count as round-off.
SPECTRUM_TOL = 1e-10


def cfl_number(dt: float, h_min: float, c: float = C0) -> float:
    """``S = sqrt(2) c dt / h_min`` ([2] eq. 3.16), ``c`` the fastest wave speed (default c0).

    >>> round(cfl_number(1e-11, 0.01), 4)
    0.424
    >>> cfl_number(1e-11, 0.0)
    Traceback (most recent call last):
    ...
    ValueError: h_min must be a finite positive number, got 0.0
    """
    dt = check_positive("dt", dt)
    h_min = check_positive("h_min", h_min)
    c = check_positive("c", c)
    return math.sqrt(2.0) * c * dt / h_min


def per_particle(name: str, value: float | ArrayLike | Callable[[np.ndarray], ArrayLike], points: np.ndarray, *,
                 positive: bool = True, allow_zero: bool = False) -> np.ndarray:
    """A scalar, an (N,) array or a callable of the (N, d) points -> float64 (N,)."""
    n = len(points)
    v = value(points) if callable(value) else value
    try:
        arr = np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)).copy()
    except (ValueError, TypeError):
        raise ValueError(f"{name} must be a scalar or an array of shape ({n},), got shape {np.shape(v)}") from None
    bad = ~np.isfinite(arr) | ((arr < 0) if allow_zero else (arr <= 0)) if positive else ~np.isfinite(arr)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        kind = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{name} must be finite and {kind} at every particle, got {float(arr[k])!r} at particle {k}")
    return arr


def check_dt(dt: float | None, h_min: float, courant: float, c: float = C0) -> float:
    """The CFL step ``courant h_min / (sqrt(2) c)``, or ``dt`` checked against it (``c`` the fastest speed)."""
    limit = h_min / (math.sqrt(2.0) * c)
    if dt is None:
        courant = check_positive("courant", courant)
        if courant > 1:
            raise ValueError(f"courant must be at most 1 (CFL), got {courant}")
        return courant * limit
    dt = check_positive("dt", dt)
    S = cfl_number(dt, h_min, c)
    if S > 1.0 + 1e-12:
        speed = "" if c == C0 else f", c = {c:.4g} m/s the fastest wave speed in the materials"
        raise ValueError(
            f"dt = {dt:.4g} s violates the CFL condition S = sqrt(2) c dt / h_min = {S:.3f} > 1 "
            f"(h_min = {h_min:.4g} m{speed}); use dt <= {limit:.4g} s"
        )
    return dt


def spectral_radius_bound(S: sp.spmatrix, steps: int = LANCZOS_STEPS, failure: float = LANCZOS_FAILURE,
                          seed: int = 0) -> tuple[float, float]:
    """Estimate and upper bound of the spectral radius of a symmetric negative semi-definite ``S``.

    ``steps`` Lanczos steps on ``-S`` from a random start (``seed``) give its largest Ritz
    value ``theta`` (never above the radius). By Kuczynski and Wozniakowski (1992), with
    probability at least ``1 - failure`` the radius is below ``theta / (1 - e)``,
    ``sqrt(e) = ln(1.648 sqrt(n) / failure) / (2 steps - 1)``: a bound that does not depend on
    how the top of the spectrum is clustered (ARPACK to tol 1e-8 took 88 s on a 200 x 200
    lattice, whose top eigenvalues are close together; this takes well under a second).
    Up to :data:`DENSE_RADIUS` unknowns every eigenvalue is computed and both numbers are exact.

    Parameters
    ----------
    S : sparse matrix, shape (n, n)
    steps : int
    failure : float
        Probability, over the random start, that the bound is below the radius.
    seed : int

    Returns
    -------
    (float, float)
        ``(theta, bound)``.

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> n = 2000
    >>> S = -sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])  # -(1D Laplacian)
    >>> theta, bound = spectral_radius_bound(S)
    >>> rho = 2 + 2 * np.cos(np.pi / (n + 1))
    >>> bool(theta <= rho <= bound), bool(bound / rho - 1 < 0.003)
    (True, True)
    """
    from scipy.linalg import eigvalsh_tridiagonal

    if not sp.issparse(S) or S.ndim != 2 or S.shape[0] != S.shape[1]:
        raise ValueError(f"S must be a square sparse matrix, got {type(S).__name__} of shape {getattr(S, 'shape', None)}")
    n = S.shape[0]
    check_int("steps", steps, minimum=1)
    if not 0.0 < failure < 1.0:
        raise ValueError(f"failure must be a probability in (0, 1), got {failure!r}")
    if n == 0:
        return 0.0, 0.0
    if n <= DENSE_RADIUS:
        rho = float(np.abs(np.linalg.eigvalsh(S.toarray())).max())
        return rho, rho
    m = min(int(steps), n)
    S = sp.csr_matrix(S)
    S = sp.csr_matrix((-S.data, S.indices, S.indptr), shape=S.shape)  # -S, positive semi-definite
    q = np.random.default_rng(seed).standard_normal(n)
    q /= math.sqrt(np.einsum("i,i->", q, q))  # einsum, not BLAS: no thread start-up on every short vector
    q_prev = np.zeros(n)
    alpha = np.empty(m)
    beta = np.zeros(m)
    b = 0.0
    for j in range(m):
        w = S @ q
        if b:
            w -= b * q_prev
        a = float(np.einsum("i,i->", q, w))
        w -= a * q
        alpha[j] = a
        b = math.sqrt(float(np.einsum("i,i->", w, w)))
        beta[j] = b
        if not np.isfinite(b):
            raise ValueError("the E -> E operator has non-finite entries; its stability limit cannot be computed")
        if b <= 1e-14 * max(abs(a), 1e-300):  # an invariant subspace: its Ritz values are eigenvalues
            m = j + 1
            break
        w /= b
        q_prev, q = q, w
    theta = float(eigvalsh_tridiagonal(alpha[:m], beta[: m - 1], select="i", select_range=(m - 1, m - 1))[0])
    theta = max(theta, 0.0)
    e = (math.log(1.648 * math.sqrt(n) / failure) / (2 * m - 1)) ** 2
    return theta, (theta / (1.0 - e) if e < 1.0 else float(abs(S).sum(axis=1).max()))


def leapfrog_growth(lam: ArrayLike, dt: float) -> np.ndarray:
    """Per-step amplification ``max |z|`` of leap-frog for ``y'' = lam y`` (``z^2 - (2 + dt^2 lam) z + 1 = 0``).

    1 for real ``lam`` in ``[-4/dt^2, 0]``, above 1 otherwise (complex or
    positive ``lam`` grow whatever ``dt``).

    >>> leapfrog_growth(np.array([-1.0, -5.0, 0.01, -1 + 0.1j]), 1.0).round(4).tolist()
    [1.0, 2.618, 1.1051, 1.0594]
    """
    b = 2.0 + dt * dt * np.asarray(lam, dtype=np.complex128)
    disc = np.sqrt(b * b - 4.0)
    return np.maximum(np.abs(0.5 * (b + disc)), np.abs(0.5 * (b - disc)))
