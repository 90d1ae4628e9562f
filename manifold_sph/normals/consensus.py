"""Undetermined directions chosen among candidate fits by agreement with the neighbours.

Where a normal disagrees with the fits on other neighbourhood sizes, candidate directions come
from jet and PCA fits on several neighbourhoods; each such particle takes the candidate that
best agrees with its neighbours' normals reflected in the bisector planes (the normal a circle
through both points predicts; right across a thin tube or sheet).
"""

from __future__ import annotations

import numpy as np

from . import tuning
from .fitting import jet_fit, n_coefficients, pca_rows, unit
from .scale import scale_agreement


def _reflected(pts, rows, nbrs, m):
    """Normals ``m`` (R, K, 3) at ``pts[nbrs]`` reflected in the bisector planes of ``p_i p_j``:
    the normals predicted at ``pts[rows]`` (the reflection rule of step 3)."""
    e = unit(pts[nbrs] - pts[rows][:, None, :])
    return m - 2.0 * np.einsum("rkj,rkj->rk", m, e)[..., None] * e


def consensus_normals(pts: np.ndarray, neighbors: np.ndarray, normals: np.ndarray, fixed: np.ndarray | None = None,
                      pole: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Undetermined directions chosen among candidates by agreement with the neighbours (step 7).

    Where the normal disagrees with the plane of the 8 nearest or the quadric of the
    20 nearest by more than ``tuning.CONSENSUS_DEGREES``, candidate directions come from jet
    fits and PCA on several neighbourhoods (``tuning.CONSENSUS_CANDIDATES``) and the current
    normal; each such particle takes the candidate that maximises the distance-weighted
    sum of ``|c . R_ij n_j|`` over its neighbours (``R_ij n_j``: the neighbour's normal
    reflected in the bisector plane, the normal a circle through both points predicts
    at ``p_i``; right across a thin tube or sheet), plus ``tuning.CONSENSUS_PRIOR`` for the
    current normal. A few rounds of iterated conditional modes, all undetermined
    particles at once; the signs then follow the reflection-rule vote of the neighbours.
    Returns the normals and the scale agreement before (None when not run).
    """
    if neighbors.shape[1] < max(k for k, _ in tuning.CONSENSUS_CANDIDATES):
        return normals, None
    agree = scale_agreement(pts, neighbors, normals)
    undetermined = agree < np.cos(np.radians(tuning.CONSENSUS_DEGREES))
    if fixed is not None:
        undetermined &= ~fixed
    rows = np.flatnonzero(undetermined)
    if rows.size == 0:
        return normals, agree
    base = normals[rows]
    cands = []
    for k, degree in tuning.CONSENSUS_CANDIDATES:
        if degree == 0:
            cands.append(pca_rows(pts, neighbors[rows, :k]))
        else:
            cands.append(jet_fit(pts, neighbors[rows, :k], base, degree, centers=pts[rows]))
    if pole is not None:  # poles=True: the Voronoi pole line, and fits in its frame (docs/normals.md, step 9)
        e = unit(pole[rows])
        e = np.where(np.einsum("ij,ij->i", e, e)[:, None] > 0.5, e, base)  # no pole (a duplicate): its own normal
        cands.append(e)
        for kp, dp in tuning.POLE_FITS:
            kp = min(kp, neighbors.shape[1])
            nbp = neighbors[rows, :kp]
            L = pts[nbp] - pts[rows][:, None, :]
            z = np.einsum("rkj,rj->rk", L, e)
            # only the neighbours less than 45 degrees off the pole's tangent plane (not across a thin part)
            wp = (2.0 * z * z <= np.einsum("rkj,rkj->rk", L, L)).astype(np.float64)
            few = wp.sum(axis=1) < n_coefficients(dp) + 2
            cands.append(np.where(few[:, None], e, jet_fit(pts, nbp, e, dp, weights=wp, centers=pts[rows])))
    cands.append(base)
    C = np.stack(cands, axis=1)  # (R, c, 3)
    prior = np.zeros(C.shape[:2])
    prior[:, -1] = tuning.CONSENSUS_PRIOR
    nb = neighbors[rows, 1:tuning.CONSENSUS_K]
    d = np.linalg.norm(pts[nb] - pts[rows][:, None, :], axis=2)
    dmax = d.max(axis=1, keepdims=True)
    w = np.where(undetermined[nb], 0.5, 1.0) * np.exp(-(d / np.where(dmax > 0, dmax, 1.0)) ** 2)
    w = w / np.maximum(w.sum(axis=1, keepdims=True), 1e-300)
    n = normals.copy()
    choice = np.full(rows.size, -1)
    for _ in range(tuning.CONSENSUS_ROUNDS):
        pred = _reflected(pts, rows, nb, n[nb])
        score = np.einsum("rck,rk->rc", np.abs(np.einsum("rcj,rkj->rck", C, pred)), w) + prior
        new = score.argmax(axis=1)
        if np.array_equal(new, choice):
            break
        choice = new
        c = C[np.arange(rows.size), choice]
        n[rows] = c * np.where(np.einsum("ij,ij->i", c, base) < 0, -1.0, 1.0)[:, None]
    # signs: the reflection-rule vote of the neighbours
    vote = np.einsum("rkj,rj->r", _reflected(pts, rows, nb, n[nb]) * w[..., None], n[rows])
    n[rows] *= np.where(vote < 0, -1.0, 1.0)[:, None]
    return n, agree
