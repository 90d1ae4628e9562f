"""Rows taken for the surface: particles whose fitted plane cuts through the cloud.

A fitted plane normally has the nearby points of the surface close to it (heights of
order ``kappa r^2``). Where points lie more than 45 degrees above it AND below it, the fit
saw one row of a cloud sampled along planar curves (the meridian rows of a surface of
revolution, scan lines, a rolled lip a dozen points around) and returned the plane of the
row. The candidate normal is perpendicular to the row (the direction to the nearest
neighbour) and to the nearest steep point on each side (the adjacent rows); it replaces the
fit where it at least halves the smaller steep count.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..threads import get_num_threads
from . import tuning
from .fitting import unit


def steep_counts(pts: np.ndarray, neighbors: np.ndarray, normals: np.ndarray, rows: np.ndarray | None = None) -> tuple[np.ndarray,
                 np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Counts of the neighbours more than 45 degrees above and below the tangent plane of ``normals``.

    ``neighbors``: (R, K) neighbour lists of ``rows`` (all particles when None)."""
    rows = np.arange(pts.shape[0]) if rows is None else rows
    L = pts[neighbors] - pts[rows][:, None, :]
    z = np.einsum("nki,ni->nk", L, normals[rows])
    rho2 = np.einsum("nki,nki->nk", L, L) - z * z
    steep = z * z > tuning.ROW_TAN**2 * np.maximum(rho2, 0.0)
    return (steep & (z > 0)).sum(axis=1), (steep & (z < 0)).sum(axis=1), L, z, steep


def _rows_across(pts, neighbors, normals, rows=None):
    """Step 2b: normals of particles whose tangent plane cuts through the cloud (docs/normals.md).

    A fitted plane through a particle normally has the nearby points of the surface close
    to it (heights of order ``kappa r^2``); points far above AND below it (more than 45
    degrees, at least ``tuning.ROW_STEEP`` on each side among the neighbours) mean the fit saw one
    row of a cloud sampled along planar curves (the meridian rows of a surface of
    revolution, scan lines) and returned the plane of the row. The candidate normal is
    perpendicular to the row (the line to the nearest neighbour) and to the direction to
    the nearest steep point on each side (the adjacent rows); it replaces the fit where it
    at least halves the smaller of the two steep counts. ``neighbors``: (R, K) lists of
    ``rows`` (all particles when None). Returns the normals and the mask of replaced ones.
    """
    N = pts.shape[0]
    rows = np.arange(N) if rows is None else rows
    up, down, L, z, steep = steep_counts(pts, neighbors, normals, rows)
    sel = np.flatnonzero((up >= tuning.ROW_STEEP) & (down >= tuning.ROW_STEEP))
    changed = np.zeros(N, dtype=bool)
    if sel.size == 0:
        return normals, changed
    L, z, steep, nb = L[sel], z[sel], steep[sel], neighbors[sel]
    rows = rows[sel]
    r2 = np.einsum("nki,nki->nk", L, L)
    r = np.arange(rows.size)
    e_up = L[r, np.where(steep & (z > 0), r2, np.inf).argmin(axis=1)]
    e_dn = L[r, np.where(steep & (z < 0), r2, np.inf).argmin(axis=1)]
    t = L[r, np.where(r2 > 0, r2, np.inf).argmin(axis=1)]  # the nearest neighbour: along the row
    c1, c2 = unit(np.cross(t, e_up)), unit(np.cross(t, e_dn))
    cand = unit(c1 + c2 * np.where(np.einsum("ij,ij->i", c1, c2) < 0, -1.0, 1.0)[:, None])
    ok = np.all(np.isfinite(cand), axis=1) & (np.linalg.norm(cand, axis=1) > 0.5)
    trial = normals.copy()
    trial[rows[ok]] = cand[ok]
    cu, cd, *_ = steep_counts(pts, nb, trial, rows)
    before = np.minimum(up[sel], down[sel])
    accept = ok & (np.minimum(cu, cd) <= before // 2)
    out = normals.copy()
    out[rows[accept]] = cand[accept]
    changed[rows[accept]] = True
    return out, changed


def rows_step(pts: np.ndarray, idx: np.ndarray, normals: np.ndarray, w: np.ndarray, tree: cKDTree | None = None) -> tuple[np.ndarray,
              np.ndarray]:
    """Step 2b on every particle with its ``tuning.ROW_K`` nearest, and on the particles whose 10 nearest
    lie on a line (rows denser than that) with their ``tuning.ROW_K_LINE`` nearest."""
    N = pts.shape[0]
    out, across = _rows_across(pts, idx[:, :tuning.ROW_K], normals)
    line = np.flatnonzero(~across & (w[:, 1] < tuning.ROW_LINE * w[:, 2]))
    if line.size and N > tuning.ROW_K:
        tree = cKDTree(pts) if tree is None else tree
        nb = tree.query(pts[line], k=min(tuning.ROW_K_LINE, N), workers=get_num_threads())[1]
        out, more = _rows_across(pts, nb, out, line)
        across |= more
    return out, across
