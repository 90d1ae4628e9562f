"""Signs from visibility (``orient="visible"``): hidden point removal from viewpoints around the cloud.

On a closed surface the outward normal faces every viewpoint that sees its particle
(Katz, Tal & Basri 2007: one convex hull of the spherically flipped cloud per viewpoint).
"""

from __future__ import annotations

import numpy as np

from . import tuning
from .fitting import unit


def _fibonacci_directions(m):
    i = np.arange(m) + 0.5
    z = 1.0 - 2.0 * i / m
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (1.0 + 5.0**0.5) * i
    return np.c_[r * np.cos(phi), r * np.sin(phi), z]


def _visibility(pts, views=None, gamma=None):
    """Sum of the unit directions towards the viewpoints that see each particle, and their count.

    Hidden point removal (Katz, Tal & Basri 2007) from ``views`` viewpoints on a sphere of
    three bounding radii around the centroid: the cloud seen from ``C`` is flipped
    spherically, ``p -> p + 2 (R - |p|) p / |p|`` (``p`` relative to ``C``, ``R`` ``10**gamma``
    times the largest ``|p|``), and the particles on the convex hull of the flipped cloud and
    ``C`` are the visible ones. One hull per viewpoint (a loop over viewpoints only).
    """
    from scipy.spatial import ConvexHull, QhullError

    views = tuning.VIS_VIEWS if views is None else views
    gamma = tuning.VIS_GAMMA if gamma is None else gamma
    N = pts.shape[0]
    acc = np.zeros((N, 3))
    count = np.zeros(N, dtype=np.int64)
    centre = pts.mean(axis=0)
    radius = float(np.linalg.norm(pts - centre, axis=1).max())
    if radius <= 0:
        return acc, count
    for v in _fibonacci_directions(views):
        q = pts - (centre + 3.0 * radius * v)
        nq = np.linalg.norm(q, axis=1)
        R = float(nq.max()) * 10.0**gamma
        flipped = q + (2.0 * (R - nq) / nq)[:, None] * q
        try:
            hull = ConvexHull(np.vstack([flipped, np.zeros((1, 3))]))
        except (QhullError, ValueError):  # degenerate views see nothing
            continue
        seen = hull.vertices[hull.vertices < N]
        acc[seen] -= q[seen] / nq[seen, None]
        count[seen] += 1
    return acc, count


def visible_signs(pts: np.ndarray, nrm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """orient="visible": flip the normals that face away from the viewpoints that see them.

    For a closed surface, a particle seen from a viewpoint ``C`` has its outward normal on
    the side of ``C``. Where at least ``tuning.VIS_MIN_VIEWS`` viewpoints see a particle and its
    normal makes a cosine below ``-tuning.VIS_COS`` with the mean direction towards them, it is
    flipped. Returns the normals and the mask of flipped ones.
    """
    acc, count = _visibility(pts)
    mean_dir = unit(acc)
    flip = (count >= tuning.VIS_MIN_VIEWS) & (np.einsum("ij,ij->i", mean_dir, nrm) < -tuning.VIS_COS)
    return np.where(flip[:, None], -nrm, nrm), flip
