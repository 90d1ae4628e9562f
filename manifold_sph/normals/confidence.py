"""Per-particle confidence terms of the estimated normals.

The confidence returned by :func:`~manifold_sph.normals.estimate_normals` is the product of a
shape term (:func:`~manifold_sph.normals.fitting.shape_confidence`: ``1 - lambda_0 / lambda_1``
of the local covariance), an orientation term (the jump of the winding number across the
particle), a scale term (:func:`scale_confidence`: agreement with fits on other neighbourhood
sizes) and a thickness term (:func:`thin_confidence`: below 1 on the two sides of a part
thinner than the spacing).
"""

from __future__ import annotations

import numpy as np

from . import tuning
from .scale import scale_agreement


def scale_confidence(pts: np.ndarray, neighbors: np.ndarray, normals: np.ndarray, before: np.ndarray | None = None) -> np.ndarray:
    """1 where ``normals`` agree within 10 degrees with fits on smaller and larger neighbourhoods, 0 beyond 30.

    ``before``: the agreement before the consensus of step 7 (a normal chosen there stays
    as doubtful as the one it replaced: the points did not determine it)."""
    if before is None:
        agree = scale_agreement(pts, neighbors, normals)
    else:  # only the particles step 7 reconsidered can have changed: refit those alone
        rows = np.flatnonzero(before < np.cos(np.radians(tuning.CONSENSUS_DEGREES)))
        agree = before.copy()
        agree[rows] = np.minimum(before[rows], scale_agreement(pts, neighbors, normals, rows))
    lo, hi = tuning.SCALE_COS
    return np.clip((agree - lo) / (hi - lo), 0.0, 1.0)


def thin_confidence(pts: np.ndarray, neighbors: np.ndarray, distances: np.ndarray, normals: np.ndarray, noise: float = 0.0) -> np.ndarray:
    """``min(1, t / s)``: ``t`` the height above or below the tangent plane of the nearest point
    lying steeply across it (more than 45 degrees off the plane, and higher than
    ``tuning.THIN_NOISE * noise`` times the distance to the farthest neighbour, ``noise`` the cloud's
    median relative jet-fit residual), ``s`` the local spacing (median distance to the 6
    nearest). Below 1 on the two sides of a part or a gap thinner than the spacing, which
    neither the winding number nor propagation resolves (docs/normals.md)."""
    L = pts[neighbors[:, 1:]] - pts[:, None, :]
    zs = np.einsum("nkj,nj->nk", L, normals)
    z = np.abs(zs)
    lateral2 = np.maximum(np.einsum("nkj,nkj->nk", L, L) - z * z, 0.0)
    steep = z * z > lateral2
    s = np.median(distances[:, 1 : min(7, distances.shape[1])], axis=1)
    # noise guard: only points across by more than tuning.THIN_NOISE times the cloud's noise level
    # (``noise``: the median relative residual of the jet fits, times the fit radius)
    t = np.where(steep & (z > tuning.THIN_NOISE * noise * distances[:, -1:]), z, np.inf).min(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(s > 0, np.clip(t / np.where(s > 0, s, 1.0), 0.0, 1.0), 1.0)
