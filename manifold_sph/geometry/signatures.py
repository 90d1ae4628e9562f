"""Spectral shape descriptors from the stable Laplacian's eigenpairs (:meth:`Surface.eigs`).

- Heat kernel signature (Sun, Ovsjanikov and Guibas 2009): ``HKS(x, t) = sum_i exp(-lambda_i t) phi_i(x)^2``.
- Wave kernel signature (Aubry, Schlickewei and Cremers 2011):
  ``WKS(x, e) = sum_i phi_i(x)^2 w_i(e) / sum_i w_i(e)`` with ``w_i(e) = exp(-(e - log lambda_i)^2 / 2 sigma^2)``,
  evaluated relative to the largest weight of each energy, so that any finite energy gives a
  finite signature (far outside the spectrum it tends to the nearest eigenfunction's square).

The eigenpairs are cached on the surface per ``k``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_bool, check_int, check_positive
from .common import check_surface

if TYPE_CHECKING:
    from ..surface import Surface

__all__ = ["heat_kernel_signature", "wave_kernel_signature"]


def _spectrum(surface, k):
    k = check_int("k", k, minimum=2)
    return surface.cached(("eigs", k), lambda: surface.eigs(k))


def heat_kernel_signature(surface: Surface, times: ArrayLike, *, k: int = 100, scale: bool = False) -> np.ndarray:
    """Heat kernel signature ``HKS(x, t) = sum_i exp(-lambda_i t) phi_i(x)^2``, shape (N, T).

    Parameters
    ----------
    surface : Surface
    times : array_like, shape (T,)
        Positive finite diffusion times.
    k : int
        Eigenpairs of :meth:`Surface.eigs` used (the zero one included).
    scale : bool
        Divide each column by its mass-weighted mean (the scale-normalised HKS).
    """
    check_surface(surface)
    t = np.atleast_1d(np.asarray(times, dtype=np.float64))
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t) & (t > 0)):
        raise ValueError(f"times must be a non-empty 1-D array of positive finite values, got {t!r}")
    scale = check_bool("scale", scale)
    lam, V = _spectrum(surface, k)
    H = (V**2) @ np.exp(-np.outer(np.maximum(lam, 0.0), t))
    if scale:
        m = np.asarray(surface.mass_matrix().diagonal())
        H = H / (m @ H / m.sum())
    return H


def wave_kernel_signature(
    surface: Surface,
    energies: ArrayLike | None = None,
    *,
    k: int = 100,
    n_energies: int = 100,
    sigma: float | None = None,
) -> np.ndarray:
    """Wave kernel signature, shape (N, E): ``sum_i phi_i(x)^2 w_i(e) / sum_i w_i(e)`` (module notes).

    Parameters
    ----------
    surface : Surface
    energies : array_like, shape (E,), optional
        Finite log-energies ``e``; by default ``n_energies`` values spread over
        ``[log lambda_1, log lambda_max]`` as in Aubry et al. 2011.
    k : int
        Eigenpairs used (the zero eigenvalue is skipped).
    sigma : float, optional
        Width (default 7 times the spacing of the default energies).

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> s = Surface(shapes.sphere(1000))
    >>> W = wave_kernel_signature(s, [0.0, 1e300], k=20)   # far outside the spectrum: still finite
    >>> W.shape, bool(np.isfinite(W).all())
    ((1000, 2), True)
    """
    check_surface(surface)
    # the arguments are checked before the eigenpairs are computed (bad input fails at once)
    if energies is None:
        n_energies = check_int("n_energies", n_energies, minimum=2)
    else:
        e = np.atleast_1d(np.asarray(energies, dtype=np.float64))
        if e.ndim != 1 or e.size == 0 or not np.all(np.isfinite(e)):
            raise ValueError(f"energies must be a non-empty 1-D array of finite values, got {e!r}")
    if sigma is not None:
        sigma = check_positive("sigma", sigma)
    lam, V = _spectrum(surface, k)
    pos = lam > 1e-10 * max(lam.max(), 1e-300)
    if pos.sum() < 2:
        raise ValueError("wave_kernel_signature needs at least two non-zero eigenvalues; increase k")
    loglam, V = np.log(lam[pos]), V[:, pos]
    if energies is None:
        e = np.linspace(loglam.min(), loglam.max(), n_energies)
    if sigma is None:
        sigma = 7.0 * (loglam.max() - loglam.min()) / max(len(e) - 1, 1) if len(e) > 1 else 1.0
    sigma = check_positive("sigma", sigma)
    D = e[None, :] - loglam[:, None]  # (k, E), never squared: finite for any finite energy
    Dc = D[np.argmin(np.abs(D), axis=0), np.arange(D.shape[1])]  # the nearest eigenvalue's, per energy
    with np.errstate(over="ignore"):
        expo = -((D - Dc) * (D + Dc)) / (2.0 * sigma * sigma)  # <= 0, and 0 at the nearest eigenvalue
    Wgt = np.exp(np.where(np.isfinite(expo), expo, -np.inf))
    return (V**2) @ Wgt / Wgt.sum(axis=0)
