"""Agreement of a normal with fits on smaller and larger neighbourhoods.

A normal that changes with the neighbourhood size is not determined by the points (thin
parts sampled a few points across, ring-sampled lips, coarse creases). :func:`scale_agreement`
measures it against a plane fitted to the 8 nearest and a quadric fitted to the 20 nearest.
"""

from __future__ import annotations

import numpy as np

from . import tuning
from .fitting import jet_fit, n_coefficients


def scale_agreement(pts: np.ndarray, neighbors: np.ndarray, normals: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
    """``min |n . n'|`` over a plane fitted to the 8 nearest and a quadric to the 20 nearest
    (of every particle, or of ``rows`` only)."""
    rows = np.arange(pts.shape[0]) if rows is None else rows
    agree = np.ones(rows.size)
    for k, degree in zip(tuning.SCALE_K, (1, 2)):
        k = min(k, neighbors.shape[1])
        if k < n_coefficients(degree) + 2:
            continue
        other = jet_fit(pts, neighbors[rows, :k], normals[rows], degree, centers=pts[rows])
        agree = np.minimum(agree, np.abs(np.einsum("ij,ij->i", other, normals[rows])))
    return agree


def noise_level(pts: np.ndarray, neighbors: np.ndarray, distances: np.ndarray, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Noise level and spacing of every particle's region, from degree-2 fits at two scales.

    The mean squared residual of a degree-2 height fit to the ``k`` nearest is about
    ``sigma^2 (1 - 6 / k)`` for noise of standard deviation ``sigma`` along the normal, and
    grows like ``r_k^6`` (third-order terms, ``r_k^2`` proportional to ``k``) where the fit is
    biased by the shape. Fitted at ``k`` and ``2k`` (``tuning.NOISE_K``; residuals averaged over the
    ``tuning.NOISE_REGION`` nearest, medians), the two equations give ``sigma`` apart from the bias:
    a coarse, clean mesh reads near 0 and a scan its noise. The residuals of noise are about
    Gaussian (kurtosis near 3, about 2.7 after the fit); where they fall into two layers (kurtosis
    below ``tuning.NOISE_KURTOSIS``: the two sides of a part about as thin as the spacing, a tube a
    few points around) the residual is the shape, not noise, and the level is scaled down to 0.

    Parameters
    ----------
    pts : ndarray, shape (N, 3)
    neighbors, distances : ndarray, shape (N, K)
        The nearest neighbours (itself first), ``K`` at least ``2 * tuning.NOISE_K`` and
        ``tuning.NOISE_REGION``.
    frame : ndarray, shape (N, 3)
        A first normal per particle (the frame of the height fits).

    Returns
    -------
    sigma : ndarray, shape (N,)
        The noise level (a length).
    spacing : ndarray, shape (N,)
        The regional median distance to the 6 nearest.
    """
    k1 = tuning.NOISE_K
    k2 = 2 * k1
    m = min(tuning.NOISE_REGION, neighbors.shape[1])
    region = neighbors[:, :m]
    r2 = []
    kurt = np.zeros(pts.shape[0])
    for k in (k1, k2):
        res = np.zeros(pts.shape[0])
        jet_fit(pts, neighbors[:, :k], frame, 2, residual=res, kurtosis=kurt if k == k2 else None)
        r2.append(np.median(((res * distances[:, k - 1]) ** 2)[region], axis=1))
    lo, hi = tuning.NOISE_KURTOSIS
    layered = np.clip((np.median(kurt[region], axis=1) - lo) / (hi - lo), 0.0, 1.0)
    p = n_coefficients(2)
    grow = 2.0**3  # (r_2k / r_k)^6 for r^2 proportional to k
    s2 = (grow * r2[0] - r2[1]) / (grow * (1.0 - p / k1) - (1.0 - p / k2))
    spacing = np.median(distances[:, 1:7].mean(axis=1)[region], axis=1)
    return np.sqrt(np.maximum(s2, 0.0)) * layered, spacing


def auto_k(sigma: np.ndarray, spacing: np.ndarray, n_points: int) -> np.ndarray:
    """Neighbours of the fit of every particle from its relative noise ``nu = sigma / spacing``.

    ``k = K0 + A nu^2`` (``tuning.AUTO_K0``, ``tuning.AUTO_K_GAIN``), rounded to the ladder
    ``tuning.AUTO_K_LADDER`` and capped at ``n_points``: the variance of a fitted normal falls like
    ``sigma^2 / (k r_k^2)`` while its bias grows with ``r_k``, so noisier regions take wider fits.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = np.where(spacing > 0, sigma / spacing, 0.0)
    want = tuning.AUTO_K0 + tuning.AUTO_K_GAIN * nu**2
    ladder = np.asarray([k for k in tuning.AUTO_K_LADDER if k <= n_points] or [min(tuning.AUTO_K_LADDER[0], n_points)])
    pos = np.clip(np.searchsorted(ladder, want), 0, ladder.size - 1)
    lower = np.clip(pos - 1, 0, ladder.size - 1)
    pick = np.where(np.abs(ladder[lower] - want) < np.abs(ladder[pos] - want), lower, pos)
    return ladder[pick]
