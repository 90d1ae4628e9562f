"""Voronoi poles of a point cloud (Amenta & Bern 1999): a normal line from the 3D Delaunay.

The pole of a sample is the farthest vertex of its Voronoi cell (the circumcentre of
the incident Delaunay tetrahedron farthest from it); for a sample on the convex hull,
whose cell is unbounded, the pole lies at infinity along the mean outward normal of the
incident hull facets. The second pole is the farthest vertex of the cell on the other
side (negative projection on the first pole vector). For a surface sampled densely
enough (Amenta & Bern's epsilon-sampling, epsilon well below 1) the vectors from the
sample to its poles lie close to the normal line, one inside and one outside, whatever
the k nearest neighbours are: they come from the empty balls touching the sample.
:func:`pole_signs` checks the signs with the winding number at both poles.
Cost: one qhull Delaunay triangulation.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import Delaunay

from . import tuning
from .fitting import point_array, unit
from .winding import winding_numbers

__all__ = ["pole_signs", "voronoi_poles"]


def _circumcentres(pts, tets):
    """Circumcentres of the tetrahedra and a mask of the non-degenerate ones."""
    a = pts[tets[:, 0]]
    B = pts[tets[:, 1:]] - a[:, None, :]
    rhs = 0.5 * np.einsum("mki,mki->mk", B, B)
    det = np.linalg.det(B)
    scale = np.einsum("mki,mki->m", B, B) ** 1.5
    ok = np.abs(det) > 1e-10 * scale
    c = np.linalg.solve(np.where(ok[:, None, None], B, np.eye(3)), np.where(ok[:, None], rhs, 0.0)[..., None])[..., 0]
    return a + c, ok


def voronoi_poles(points: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pole vectors of every sample: from the sample to the farthest vertex of its Voronoi cell.

    Parameters
    ----------
    points : array_like (N, 3), or anything point-like (a PointCloud, Surface, path, ...)
        At least 5 points, not all in one plane.

    Returns
    -------
    pole : ndarray, shape (N, 3)
        The vector from each sample to its pole (for samples on the convex hull the
        mean outward normal of the incident hull facets, scaled to 1e6 times the cloud's
        diameter: the pole at infinity). Zero for a sample that is a vertex of no
        non-degenerate tetrahedron (an exact duplicate of another sample).
    radius : ndarray, shape (N,)
        The distance to the pole (``inf`` on the hull, 0 where ``pole`` is zero).
    second : ndarray, shape (N, 3)
        The vector to the second pole: the farthest vertex of the cell with a negative
        projection on ``pole`` (zero where there is none).

    Raises
    ------
    ValueError
        On a bad ``points`` array, fewer than 5 points, or points that span no volume.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph.reference import shapes
    >>> c = shapes.sphere(500)
    >>> pole, r, second = voronoi_poles(c.points)
    >>> u = pole / np.linalg.norm(pole, axis=1)[:, None]
    >>> bool(np.abs(np.einsum("ij,ij->i", u, c.normals)).min() > 0.99)
    True
    """
    pts = point_array(points)
    N = pts.shape[0]
    if N < 5:
        raise ValueError(f"points must hold at least 5 points for Voronoi poles, got {N}")
    centre = pts.mean(axis=0)
    if np.linalg.matrix_rank(pts - centre, tol=1e-12 * max(np.ptp(pts, axis=0).max(), 1e-300)) < 3:
        raise ValueError("points must span a volume (not all in one plane) for Voronoi poles")
    try:
        tri = Delaunay(pts - centre)
    except Exception as exc:  # qhull: degenerate input (e.g. nearly planar after all)
        raise ValueError(f"points admit no 3D Delaunay triangulation for Voronoi poles: {exc}") from exc
    tets = tri.simplices
    C, ok = _circumcentres(pts, tets)
    t = np.repeat(np.arange(tets.shape[0]), 4)[np.repeat(ok, 4)]
    u = tets[ok].ravel()
    d = np.linalg.norm(C[t] - pts[u], axis=1)
    order = np.lexsort((d, u))
    last = order[np.r_[u[order][1:] != u[order][:-1], True]]
    pole = np.zeros_like(pts)
    radius = np.zeros(N)
    pole[u[last]] = C[t[last]] - pts[u[last]]
    radius[u[last]] = d[last]
    # samples on the convex hull: the pole at infinity along the mean outward facet normal
    hull = tri.convex_hull
    hn = np.cross(pts[hull[:, 1]] - pts[hull[:, 0]], pts[hull[:, 2]] - pts[hull[:, 0]])
    hn *= np.where(np.einsum("ij,ij->i", hn, pts[hull[:, 0]] - centre) < 0, -1.0, 1.0)[:, None]
    hn /= np.maximum(np.linalg.norm(hn, axis=1), 1e-300)[:, None]
    H = np.zeros_like(pts)
    for a in range(3):
        np.add.at(H, hull[:, a], hn)
    on = np.linalg.norm(H, axis=1) > 0
    diameter = float(np.ptp(pts, axis=0).max())
    pole[on] = H[on] / np.linalg.norm(H[on], axis=1)[:, None] * 1e6 * diameter
    radius[on] = np.inf
    # the second pole: the farthest vertex on the other side of the sample (negative projection)
    proj = np.einsum("ij,ij->i", C[t] - pts[u], pole[u])
    d2 = np.where(proj < 0, d, -1.0)
    order = np.lexsort((d2, u))
    last = order[np.r_[u[order][1:] != u[order][:-1], True]]
    last = last[d2[last] > 0]
    second = np.zeros_like(pts)
    second[u[last]] = C[t[last]] - pts[u[last]]
    return pole, radius, second



def pole_signs(pts: np.ndarray, nrm: np.ndarray, distances: np.ndarray, poles: tuple[np.ndarray, np.ndarray,
               np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Signs from the winding number at the two Voronoi poles of every particle (``poles=True``, step 9).

    ``poles``: ``(pole, radius, second)`` of :func:`voronoi_poles`. The
    winding number ``w`` of the oriented cloud is evaluated at both poles (0 at a pole at infinity);
    where the two differ by more than ``tuning.POLE_JUMP`` and the poles lie on opposite sides of the
    particle (``-u_1 . u_2 > tuning.POLE_ANTI``), the pole with the smaller ``w`` is outside, and a normal
    pointing away from it (``n . u_out < 0``) is flipped. Returns the normals and the flipped mask.
    """
    N = pts.shape[0]
    pole, radius, second = poles
    ka = min(8, distances.shape[1])
    r = distances[:, ka - 1]
    r = np.where(r > 0, r, np.median(r[r > 0]) if np.any(r > 0) else 1.0)
    area = np.pi * r**2 / max(ka - 0.5, 1.0)
    hull = ~np.isfinite(radius)
    has2 = np.einsum("ij,ij->i", second, second) > 0
    q = np.vstack([pts + np.where(hull[:, None], 0.0, pole), pts + second])
    W = winding_numbers(q, pts, nrm, area, 0.2 * np.sqrt(area), np.zeros(N, dtype=np.int64), 1)[:, 0]
    w1, w2 = np.where(hull, 0.0, W[:N]), W[N:]
    out = np.where((w1 < w2)[:, None], pole, second)
    anti = -np.einsum("ij,ij->i", unit(pole), unit(second))
    flip = has2 & (np.abs(w1 - w2) > tuning.POLE_JUMP) & (anti > tuning.POLE_ANTI) & (np.einsum("ij,ij->i", out, nrm) < 0)
    return np.where(flip[:, None], -nrm, nrm), flip
