"""Weighted local quadric fits (osculating jets), shared by the curvature at a scale and the smoother.

For particle ``i`` with unit normal ``n_i`` and tangent frame ``(u_i, v_i)``, the height
``z = n_i . (x_j - x_i)`` of the points ``x_j`` within ``radius`` is fitted by weighted
least squares as ``z = c0 + c1 y1 + c2 y2 + (c3 y1^2 + 2 c4 y1 y2 + c5 y2^2) / 2`` in the
tangent coordinates ``y = (u_i . (x_j - x_i), v_i . (x_j - x_i))``, with Gaussian weights
``exp(-(2 |x_j - x_i| / radius)^2)`` (times optional per-pair weights). ``c0`` is the
height of the fitted surface above the particle (the smoother moves it there);
``(c1, c2)`` the slope, ``[[c3, c4], [c4, c5]]`` the Hessian of the height function.

Each fit also returns the residual noise (the root of the weighted mean square residual
over the residual degrees of freedom) and the standard deviation of ``(c3 + c5) / 2`` per
unit noise, for confidence intervals. Fits run in chunks of rows on the cloud divided by
its extent, so squared offsets stay in float64's range.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from ..results import Result

__all__ = ["Jets", "field_gradient", "fit_jets", "mean_spacing", "tangent_basis"]

_ROWS = 4096  # particles a chunk


def mean_spacing(points: np.ndarray, tree: cKDTree | None = None) -> float:
    """Mean distance from a particle to its 6 nearest points (over a sample of at most 5,000 particles)."""
    tree = cKDTree(points) if tree is None else tree
    step = max(1, points.shape[0] // 5000)
    d, _ = tree.query(points[::step], k=min(7, points.shape[0]), workers=-1)
    return float(np.mean(d[:, 1:]))


def tangent_basis(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangent vectors ``(u, v)``, each (N, 3), with ``(u, v, n)`` right-handed."""
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(normals, helper)
    u /= np.linalg.norm(u, axis=1)[:, None]
    return u, np.cross(normals, u)


@dataclasses.dataclass(frozen=True, repr=False)
class Jets(Result):
    """Quadric fits of :func:`fit_jets` (in the units of the points given).

    Attributes
    ----------
    coef : ndarray, shape (N, 6)
        ``c0 .. c5`` (module notes).
    noise : ndarray, shape (N,)
        Residual noise (a length: the standard deviation of the heights about the fit).
    mean_sd : ndarray, shape (N,)
        Standard deviation of ``(c3 + c5) / 2`` per unit noise (``mean_sd * noise`` is that of
        the mean curvature; units 1 / length^2).
    """

    coef: np.ndarray
    noise: np.ndarray
    mean_sd: np.ndarray

    def shape_operator(self) -> np.ndarray:
        """Shape operator of the fitted height functions at ``y = 0``, (N, 2, 2), positive on a sphere
        with outward normals: ``-(I + g g^T)^-1 Hess / sqrt(1 + |g|^2)``, symmetrised."""
        c = self.coef
        g = c[:, 1:3]
        hess = np.stack([np.stack([c[:, 3], c[:, 4]], -1), np.stack([c[:, 4], c[:, 5]], -1)], -2)
        first = np.eye(2) + np.einsum("ri,rj->rij", g, g)
        W = -np.linalg.solve(first, hess) / np.sqrt(1.0 + np.einsum("ri,ri->r", g, g))[:, None, None]
        return 0.5 * (W + W.transpose(0, 2, 1))


def fit_jets(
    points: np.ndarray,
    normals: np.ndarray,
    radius: float,
    *,
    u: np.ndarray | None = None,
    v: np.ndarray | None = None,
    spacing: float | None = None,
    robust: int = 0,
) -> Jets:
    """Weighted quadric fit at every particle (module notes).

    Parameters
    ----------
    points, normals : ndarray, shape (N, 3)
    radius : float
        Fit radius (same units as ``points``).
    u, v : ndarray, shape (N, 3), optional
        Tangent frames (default :func:`tangent_basis`).
    spacing : float, optional
        Mean spacing, for the number of nearest points searched (default from the bounding box).
    robust : int
        Reweighting passes: each multiplies the weights by ``1 / (1 + (res / (2 s))^2)`` (Cauchy),
        ``res`` the residuals of the previous fit and ``s`` their weighted RMS, so that a fit
        across a sharp edge settles on one side.
    """
    n = points.shape[0]
    lo, hi = points.min(axis=0), points.max(axis=0)
    L = float(np.max(hi - lo))
    P = (points - (lo + 0.5 * (hi - lo))) / L
    r = radius / L
    if u is None or v is None:
        u, v = tangent_basis(normals)
    tree = cKDTree(P)
    spacing_n = mean_spacing(P, tree) if spacing is None else spacing / L
    k = int(min(n, max(12, np.ceil(1.2 * np.pi * r * r / (0.9 * spacing_n**2)))))
    coef = np.zeros((n, 6))
    noise = np.zeros(n)
    var = np.zeros(n)
    e_mean = np.array([0.0, 0.0, 0.0, 0.5, 0.0, 0.5]) / (r * r)
    scale = np.array([1.0, 1.0 / r, 1.0 / r, 1.0 / r**2, 1.0 / r**2, 1.0 / r**2])
    for lo_ in range(0, n, _ROWS):
        rows = np.arange(lo_, min(n, lo_ + _ROWS))
        dist, idx = tree.query(P[rows], k=k, workers=-1)
        if k == 1:
            dist, idx = dist[:, None], idx[:, None]
        off = P[idx] - P[rows][:, None, :]
        y1 = np.einsum("rkd,rd->rk", off, u[rows]) / r
        y2 = np.einsum("rkd,rd->rk", off, v[rows]) / r
        z = np.einsum("rkd,rd->rk", off, normals[rows])
        w = np.exp(-((2.0 * dist / r) ** 2)) * (dist <= r)
        A = np.stack([np.ones_like(y1), y1, y2, 0.5 * y1 * y1, y1 * y2, 0.5 * y2 * y2], axis=-1)
        for it in range(robust + 1):
            AtW = A * w[..., None]
            G = np.einsum("rki,rkj->rij", AtW, A)
            G += (1e-10 * np.trace(G, axis1=1, axis2=2))[:, None, None] * np.eye(6)
            Ginv = np.linalg.inv(G)
            c = np.einsum("rij,rj->ri", Ginv, np.einsum("rki,rk->ri", AtW, z))
            res = z - np.einsum("rki,ri->rk", A, c)
            sw = np.maximum(w.sum(axis=1), 1e-300)
            if it < robust:
                s = np.sqrt(np.einsum("rk,rk->r", w, res * res) / sw) + 1e-12 * r
                w = w / (1.0 + (res / (2.0 * s[:, None])) ** 2)
        coef[rows] = c * scale
        dof = np.maximum(sw - np.einsum("rk,rk->r", w, w) / sw * 6.0, 1.0)
        noise[rows] = np.einsum("rk,rk->r", w, res * res) / dof
        Ge = Ginv @ (e_mean * r * r)  # in the scaled columns
        var[rows] = np.einsum("rk,rk->r", np.einsum("rki,ri->rk", A, Ge) ** 2, w * w) / r**4
    coef[:, 0] *= L
    coef[:, 3:] /= L
    return Jets(coef=coef, noise=np.sqrt(noise) * L, mean_sd=np.sqrt(var) / L / L)  # each factor in float64's range


def field_gradient(
    points: np.ndarray, u: np.ndarray, v: np.ndarray, f: np.ndarray, *, neighbors: int = 24, tree: cKDTree | None = None
) -> np.ndarray:
    """Tangential gradient of a scalar field from quadric fits over each particle's ``neighbors`` nearest points.

    ``f(x_j) - f(x_i)`` is fitted by least squares as ``g . y + y^T A y / 2`` in the tangent
    coordinates ``y`` of particle ``i`` (frame ``(u, v)``), with weights ``exp(-(|x_j - x_i| / d_k)^2)``
    (``d_k`` the distance to the farthest of them). Returns the gradients in ambient coordinates,
    shape (N, 3). Particles whose value is not finite are left out of the fits.
    """
    n = points.shape[0]
    tree = cKDTree(points) if tree is None else tree
    k = min(int(neighbors), n)
    good = np.isfinite(f)
    out = np.zeros((n, 3))
    for lo in range(0, n, _ROWS):
        rows = np.arange(lo, min(n, lo + _ROWS))
        dist, idx = tree.query(points[rows], k=k, workers=-1)
        off = points[idx] - points[rows][:, None, :]
        reach = np.maximum(dist[:, -1:], 1e-300)
        y1 = np.einsum("rkd,rd->rk", off, u[rows]) / reach
        y2 = np.einsum("rkd,rd->rk", off, v[rows]) / reach
        df = np.where(good[idx], f[idx] - np.where(good[rows], f[rows], 0.0)[:, None], 0.0)
        w = np.exp(-((dist / reach) ** 2)) * good[idx]
        A = np.stack([y1, y2, 0.5 * y1 * y1, y1 * y2, 0.5 * y2 * y2], axis=-1)
        AtW = A * w[..., None]
        G = np.einsum("rki,rkj->rij", AtW, A)
        G += (1e-10 * np.trace(G, axis1=1, axis2=2) + 1e-300)[:, None, None] * np.eye(5)
        c = np.linalg.solve(G, np.einsum("rki,rk->ri", AtW, df)[..., None])[..., 0]
        out[rows] = (c[:, :1] * u[rows] + c[:, 1:2] * v[rows]) / reach
    return out
