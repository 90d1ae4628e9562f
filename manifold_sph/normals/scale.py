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
