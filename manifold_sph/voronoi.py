"""Tangent-plane Voronoi cells: a stable Laplace-Beltrami for any cloud (stiffness K, mass M).

The SPH Laplacians of :mod:`manifold_sph.schemes` are consistent but not symmetric,
and on irregular clouds their spectra reach into the right half-plane. The
construction here gives a weak-form Laplacian ``L = -M^-1 K`` that is stable by
construction, whatever the sampling:

1. For particle ``i``, take its neighbours' offsets projected to its tangent
   plane (the same pairs and local coordinates as the SPH operators) and compute
   the Voronoi cell of ``i`` among them, clipped to the convex hull of the
   neighbourhood (so that a particle on an open boundary gets the half-cell on
   the surface's side, as a mesh vertex would).
2. Every cell edge on the bisector with neighbour ``j`` gives the two-point flux
   weight ``w_ij = |edge| / |x_i - x_j|``; the cell's area is ``M_ii``.
3. ``K_ij = -(w_ij + w_ji) / 2`` for ``i != j`` and ``K_ii = -sum_j K_ij``.

On a Delaunay triangulation of the points, ``w_ij`` equals the cotan weight
``(cot a + cot b) / 2``, so this is the cotan finite-element Laplacian with
lumped (Voronoi) mass, without a mesh; each particle sees its own tangent plane,
so it works on raw clouds with estimated normals.

What it guarantees, by construction and for any cloud:

- ``K`` is symmetric with non-positive off-diagonal entries and zero row sums:
  positive semi-definite, ``K @ 1 == 0``, a weighted graph Laplacian (an
  M-matrix form: implicit heat steps obey the discrete maximum principle);
- ``M`` is diagonal with positive entries (cell areas); its sum approximates the
  surface area;
- ``K v = lambda M v`` has real eigenvalues ``>= 0``; implicit heat
  ``(M + dt K) u' = M u`` conserves ``sum(M u)``; on open surfaces it carries the
  natural (Neumann) condition.

It is second-order accurate in the spacing ``h`` for eigenvalues (measured on
uniformly random sphere points: ``benchmarks/spectra.py``), not the higher order
of the corrected SPH schemes on near-uniform clouds.

A cell is exact when every point that could cut it was among the candidates: the
candidates of row ``i`` are all particles within ``radius[i]``, and a cell whose
farthest vertex lies within ``radius[i] / 2`` cannot be cut by any other point.
Rows that fail this test are recomputed with a wider search by the caller.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from . import _jit
from ._validation import _describe, as_points, check_finite, check_int, check_positive

__all__ = ["VoronoiCells", "voronoi_cells", "stiffness_matrix", "DUPLICATE_TOL"]

#: Neighbours closer than this fraction of a cell's size (square root of its area) are
#: near-duplicates: their distance is floored there in the flux weight, so that two
#: points 1e-12 apart couple strongly but finitely.
DUPLICATE_TOL = 1e-3

#: Rows per chunk of the compiled kernel.
_ROWS = 4096

INCOMPLETE, BOUNDARY, DEGENERATE, NEAR_DUPLICATE = 1, 2, 4, 8


@dataclass(frozen=True)
class VoronoiCells:
    """Voronoi cells of every particle in its tangent plane.

    Attributes
    ----------
    weights : ndarray, shape (P,)
        ``|cell edge| / |x_ij|`` for every pair of the neighbourhood (0 if ``j``
        bounds no edge of ``i``'s cell).
    area : ndarray, shape (N,)
        Cell areas (0 for a degenerate cell).
    flags : ndarray, shape (N,), uint8
        Bit 1: the cell may be cut by a particle outside the search; bit 2: it
        touches the neighbourhood's convex hull (an open boundary); bit 4:
        degenerate (collinear or too few neighbours); bit 8: a near-duplicate
        neighbour was met.
    """

    weights: np.ndarray
    area: np.ndarray
    flags: np.ndarray

    def count(self, bit: int) -> int:
        """Number of cells with flag ``bit`` set."""
        return int(np.count_nonzero(self.flags & bit))


def _cells_numpy(indptr, xy, radius, dup_tol, w, area, flags, lo, hi):
    """The compiled kernel run as plain Python (``MANIFOLD_SPH_JIT=0`` or no numba)."""
    fn = getattr(_jit.voronoi_rows, "py_func", _jit.voronoi_rows)
    fn(lo, hi, indptr, xy, radius, dup_tol, w, area, flags)


def voronoi_cells(indptr, xy, radius, *, dup_tol: float = DUPLICATE_TOL) -> VoronoiCells:
    """Voronoi cell of each particle among its neighbours, in its tangent plane.

    Parameters
    ----------
    indptr : ndarray, shape (N + 1,)
        Row offsets of the pairs (CSR layout of a :class:`~manifold_sph.neighbors.Neighborhood`).
    xy : ndarray, shape (P, 2)
        Pair offsets ``x_j - x_i`` in particle ``i``'s tangent plane (the particle
        itself at offset 0).
    radius : ndarray, shape (N,)
        Every particle within this distance of ``i`` is among its pairs.
    dup_tol : float
        See :data:`DUPLICATE_TOL`.

    Returns
    -------
    VoronoiCells

    Examples
    --------
    A square lattice: every interior cell is the unit square, and each of the four
    nearest neighbours bounds an edge of length 1 at distance 1.

    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.arange(-2, 3.0), np.arange(-2, 3.0)), -1).reshape(-1, 2)
    >>> off = g[np.argsort(np.hypot(*g.T), kind="stable")]    # the centre first
    >>> c = voronoi_cells(np.array([0, len(off)]), off, np.array([2.0]))
    >>> float(c.area[0]), sorted(c.weights[c.weights > 0].round(12).tolist()), int(c.flags[0])
    (1.0, [1.0, 1.0, 1.0, 1.0], 0)
    """
    indptr = np.ascontiguousarray(indptr)
    if indptr.ndim != 1 or indptr.size < 1 or not np.issubdtype(indptr.dtype, np.integer):
        raise ValueError(f"indptr must be a 1-D integer array of row offsets (N + 1,), got {_describe(indptr)}")
    xy = as_points("xy", xy, dim=2)
    if indptr[0] != 0 or indptr[-1] != xy.shape[0] or np.any(np.diff(indptr) < 0):
        raise ValueError(
            f"indptr must rise from 0 to the number of pairs {xy.shape[0]}, got {indptr[0]} .. {indptr[-1]}"
            + (" (decreasing somewhere)" if np.any(np.diff(indptr) < 0) else "")
        )
    n = indptr.size - 1
    radius = np.ascontiguousarray(radius, dtype=np.float64)
    if radius.shape != (n,) or np.any(np.isnan(radius)) or np.any(radius <= 0):
        raise ValueError(f"radius must have shape ({n},) with positive values (inf allowed), got {_describe(radius)}")
    dup_tol = check_positive("dup_tol", dup_tol, allow_zero=True)
    w = np.zeros(xy.shape[0])
    area = np.zeros(n)
    flags = np.zeros(n, dtype=np.uint8)
    starts = list(range(0, n, _ROWS))
    if _jit.ENABLED:
        from .threads import run_chunks

        run_chunks(
            lambda c: _jit.voronoi_rows(starts[c], min(starts[c] + _ROWS, n), indptr, xy, radius, float(dup_tol), w, area, flags),
            len(starts),
        )
    else:
        _cells_numpy(indptr, xy, radius, float(dup_tol), w, area, flags, 0, n)
    return VoronoiCells(weights=w, area=area, flags=flags)


def stiffness_matrix(rows, cols, weights, n: int) -> sp.csr_matrix:
    """Symmetric stiffness ``K`` from per-pair flux weights.

    ``K_ij = -(w_ij + w_ji) / 2`` (pairs listed twice are summed), ``K_ii = -sum_j K_ij``.

    Parameters
    ----------
    rows, cols : ndarray, shape (P,)
        Row and column particle of every pair.
    weights : ndarray, shape (P,)
        Non-negative flux weights.
    n : int
        Number of particles.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (N, N)
    """
    rows, cols = np.asarray(rows), np.asarray(cols)
    weights = np.asarray(weights, dtype=np.float64)
    n = check_int("n", n, minimum=1)
    if not (rows.shape == cols.shape == weights.shape and rows.ndim == 1):
        raise ValueError(
            f"rows, cols and weights must be 1-D of one length, got shapes {rows.shape}, {cols.shape}, {weights.shape}"
        )
    if rows.size and (min(rows.min(), cols.min()) < 0 or max(rows.max(), cols.max()) >= n):
        raise ValueError(f"rows and cols must index particles in [0, {n})")
    check_finite("weights", weights)
    if np.any(weights < 0):
        raise ValueError(f"weights must be non-negative (flux weights), got minimum {weights.min():g}")
    keep = (weights != 0) & (rows != cols)
    r, c, w = rows[keep], cols[keep], 0.5 * weights[keep]
    W = sp.coo_matrix((np.concatenate([w, w]), (np.concatenate([r, c]), np.concatenate([c, r]))), shape=(n, n)).tocsr()
    W.sum_duplicates()
    K = sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W
    K = K.tocsr()
    K.sort_indices()
    return K
