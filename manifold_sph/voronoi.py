"""Tangent-plane Voronoi cells: a stable Laplace-Beltrami for any cloud (stiffness K, mass M).

The SPH Laplacians of :mod:`manifold_sph.schemes` are consistent but not symmetric,
and on irregular clouds their spectra reach into the right half-plane. The
construction here gives a weak-form Laplacian ``L = -M^-1 K`` that is stable by
construction, whatever the sampling:

1. For particle ``i``, take its neighbours' offsets projected to its tangent
   plane (the same pairs and local coordinates as the SPH operators) and compute
   the Voronoi cell of ``i`` among them, clipped to the convex hull of the
   neighbourhood (so that a particle on an open boundary gets the half-cell on
   the surface's side, as a mesh vertex would). On surfaces each neighbour cuts
   with the section of its bisector in space by the tangent plane (its height
   ``n_i . (x_j - x_i)`` above a tolerated slope moves the planar bisector out:
   :func:`lift_offsets`), so points of another sheet across a gap do not cut.
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

The cells are computed by the compiled kernel :func:`manifold_sph._jit.voronoi_rows`, or
by its numpy twin (gift-wrapped hulls and Sutherland-Hodgman clipping on all rows of a
chunk at once) when the compiled kernels are off; ``tests/test_jit.py`` compares them.

A cell is exact when every point that could cut it was among the candidates: the
candidates of row ``i`` are all particles within ``radius[i]``, and a cell whose
farthest vertex lies within ``radius[i] / 2`` cannot be cut by any other point
(with heights, within ``0.964 radius[i] / 2``: :func:`_lift_reach`).
Rows that fail this test are recomputed with a wider search by the caller.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from . import _jit
from ._validation import as_points, check_finite, check_int, check_positive, describe
from .threads import run_chunks

__all__ = ["VoronoiCells", "voronoi_cells", "lift_offsets", "roughness", "stiffness_matrix", "DUPLICATE_TOL"]

#: Neighbours closer than this fraction of a cell's size (square root of its area) are
#: near-duplicates: their distance is floored there in the flux weight, so that two
#: points 1e-12 apart couple strongly but finitely.
DUPLICATE_TOL = 1e-3

#: Rows per chunk (the numpy twin pads a chunk to its largest neighbourhood: ~1.6 kB per row).
_ROWS = 4096

#: Tangent-plane slope ``|z| / |t|`` of a neighbour tolerated as the same sheet (curvature and the
#: normal's error): only the height above ``LIFT_SLOPE * |t|`` moves a bisector (:func:`lift_offsets`).
LIFT_SLOPE = 0.2

#: Heights within this many times a particle's :func:`roughness` are tolerated too (noise).
ROUGHNESS_FACTOR = 3.0

INCOMPLETE, BOUNDARY, DEGENERATE, NEAR_DUPLICATE = 1, 2, 4, 8


#: Rows per block of :func:`roughness` and of :func:`voronoi_cells` with heights: their temporary pair
#: arrays (a dozen of 8 bytes a pair) scale with the block, not the cloud.
LIFT_BLOCK_ROWS = 131072


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


def _hull_numpy(X, Y, valid):
    """Convex hulls (counter-clockwise) of each row's valid points, by gift wrapping on all rows at once.

    Returns ``(HX, HY, size)``: (n, K) vertex coordinates and (n,) hull sizes (0 when degenerate).
    """
    n, K = X.shape
    rows = np.arange(n)
    big = np.inf
    # start: the lowest point (smallest y, then smallest x), which is on the hull
    key_y = np.where(valid, Y, big)
    ymin = key_y.min(axis=1)
    start = np.argmin(np.where(valid & (Y == ymin[:, None]), X, big), axis=1)
    HX, HY = np.zeros((n, K)), np.zeros((n, K))
    size = np.zeros(n, dtype=np.int64)
    cur = start.copy()
    active = valid.sum(axis=1) >= 3
    for step in range(K):
        HX[rows[active], step] = X[active, cur[active]]
        HY[rows[active], step] = Y[active, cur[active]]
        size[active] += 1
        # next: the point q such that every other point is left of cur -> q (the most clockwise one)
        px, py = X[rows, cur][:, None], Y[rows, cur][:, None]
        dx, dy = X - px, Y - py
        d2 = dx * dx + dy * dy
        usable = valid & (d2 > 0)
        nxt = np.argmax(usable, axis=1)  # any usable candidate, improved below
        for j in range(K):  # keep the candidate that has every other one on its left (ties: the farthest)
            cx, cy = X[rows, nxt] - px[:, 0], Y[rows, nxt] - py[:, 0]
            cross = cx * dy[:, j] - cy * dx[:, j]
            better = usable[:, j] & ((cross < 0) | ((cross == 0) & (d2[:, j] > cx * cx + cy * cy)))
            nxt = np.where(better, j, nxt)
        cur = nxt
        active &= cur != start
        if not active.any():
            break
    return HX, HY, size


def _clip_numpy(PX, PY, lab, cnt, nx, ny, c, j, use):
    """Clip every row's polygon (``cnt`` vertices, edge labels ``lab``) by ``x . (nx, ny) <= c``, labelling
    new edges ``j``; rows where ``use`` is False are left unchanged. Sutherland-Hodgman on all rows at once."""
    n, V = PX.shape
    idx = np.arange(V)
    live = idx[None, :] < cnt[:, None]
    nxt = np.where(idx[None, :] + 1 < cnt[:, None], idx[None, :] + 1, 0)
    rows = np.arange(n)[:, None]
    AX, AY, BX, BY = PX, PY, PX[rows, nxt], PY[rows, nxt]
    sa = AX * nx[:, None] + AY * ny[:, None] - c[:, None]
    sb = BX * nx[:, None] + BY * ny[:, None] - c[:, None]
    with np.errstate(all="ignore"):  # edges that do not cross: t is unused there
        t = sa / (sa - sb)
        IX, IY = AX + t * (BX - AX), AY + t * (BY - AY)
    # each edge emits up to two points: (the start if inside, the crossing if the edge crosses)
    emit_a = live & (sa <= 0)
    emit_i = live & (((sa <= 0) & (sb > 0)) | ((sa > 0) & (sb <= 0)))
    OX = np.stack([AX, IX], axis=2).reshape(n, 2 * V)
    OY = np.stack([AY, IY], axis=2).reshape(n, 2 * V)
    OL = np.stack([lab, np.where(sa <= 0, j, lab)], axis=2).reshape(n, 2 * V)
    keep = np.stack([emit_a, emit_i], axis=2).reshape(n, 2 * V)
    order = np.argsort(~keep, axis=1, kind="stable")
    new_cnt = keep.sum(axis=1)
    OX, OY, OL = (np.take_along_axis(a, order, axis=1) for a in (OX, OY, OL))
    dead = np.arange(2 * V)[None, :] >= new_cnt[:, None]  # slots past the polygon: no stale inf or NaN
    OX, OY, OL = np.where(dead, 0.0, OX), np.where(dead, 0.0, OY), np.where(dead, -1, OL)
    u = use & (cnt >= 3)
    out_x = np.where(u[:, None], OX[:, :V * 2], np.pad(PX, ((0, 0), (0, V))))
    out_y = np.where(u[:, None], OY[:, :V * 2], np.pad(PY, ((0, 0), (0, V))))
    out_l = np.where(u[:, None], OL[:, :V * 2], np.pad(lab, ((0, 0), (0, V)), constant_values=-1))
    return out_x, out_y, out_l, np.where(u, new_cnt, cnt)


def _cells_numpy(lo, hi, indptr, xy, radius, dup_tol, w, area, flags):
    """numpy twin of :func:`manifold_sph._jit.voronoi_rows` (``MANIFOLD_SPH_JIT=0`` or no numba):
    the same cells, all rows at once (padded to the largest neighbourhood)."""
    counts = np.diff(indptr[lo : hi + 1])
    n, K = hi - lo, int(counts.max()) if hi > lo else 0
    if n == 0 or K == 0:
        return
    rows = np.arange(n)
    slot = np.arange(K)
    valid = slot[None, :] < counts[:, None]
    pair = np.where(valid, indptr[lo:hi][:, None] + slot[None, :], 0)
    X, Y = np.where(valid, xy[pair, 0], 0.0), np.where(valid, xy[pair, 1], 0.0)
    HX, HY, hsize = _hull_numpy(X, Y, valid)
    hx1, hy1 = np.roll(HX, -1, axis=1), np.roll(HY, -1, axis=1)
    hx1[rows, np.maximum(hsize - 1, 0)] = HX[:, 0]
    hy1[rows, np.maximum(hsize - 1, 0)] = HY[:, 0]
    a2 = np.where(slot[None, :] < hsize[:, None], HX * hy1 - hx1 * HY, 0.0).sum(axis=1)
    scale2 = np.where(valid, X * X + Y * Y, 0.0).max(axis=1)
    ok = (hsize >= 3) & (a2 > 1e-12 * scale2)
    V = 2 * K + 8
    PX = np.zeros((n, V))
    PY = np.zeros((n, V))
    PX[:, :K], PY[:, :K] = HX, HY
    lab = np.full((n, V), -1, dtype=np.int64)
    cnt = np.where(ok, hsize, 0)
    for j in range(K):
        d2 = X[:, j] ** 2 + Y[:, j] ** 2
        use = valid[:, j] & (d2 > 0) & ok & (cnt >= 3)
        d = np.sqrt(np.where(use, d2, 1.0))
        PX, PY, lab, cnt = _clip_numpy(PX, PY, lab, cnt, X[:, j] / d, Y[:, j] / d, 0.5 * d, j, use)
        PX, PY, lab = PX[:, :V], PY[:, :V], lab[:, :V]
    idx = np.arange(V)
    live = idx[None, :] < cnt[:, None]
    nxt = np.where(idx[None, :] + 1 < cnt[:, None], idx[None, :] + 1, 0)
    BX, BY = PX[rows[:, None], nxt], PY[rows[:, None], nxt]
    A = np.where(cnt >= 3, 0.5 * np.where(live, PX * BY - BX * PY, 0.0).sum(axis=1), 0.0)
    A = np.where(ok, A, 0.0)
    rmax2 = np.where(live, PX * PX + PY * PY, 0.0).max(axis=1)
    good = A > 0
    fl = np.where(good, 0, 4).astype(np.uint8)
    edge = live & good[:, None]
    hull_edge = edge & (lab < 0)
    fl[hull_edge.any(axis=1)] |= 3
    L = np.hypot(BX - PX, BY - PY)
    has = edge & (lab >= 0)
    jl = np.where(has, lab, 0)
    dj = np.sqrt(X[rows[:, None], jl] ** 2 + Y[rows[:, None], jl] ** 2)
    floor = dup_tol * np.sqrt(np.where(good, A, 0.0))[:, None]
    near = has & (dj < floor)
    fl[near.any(axis=1)] |= 8
    contrib = np.where(has, L / np.where(near, floor, np.where(has, dj, 1.0)), 0.0)
    wrow = np.zeros((n, K))
    np.add.at(wrow, (np.broadcast_to(rows[:, None], jl.shape)[has], jl[has]), contrib[has])
    fl[good & (4.0 * rmax2 > radius[lo:hi] ** 2)] |= 1
    w[pair[valid]] = wrow[valid]
    area[lo:hi] = np.where(good, A, 0.0)
    flags[lo:hi] = fl


def voronoi_cells(
    indptr: ArrayLike, xy: ArrayLike, radius: ArrayLike, *, height: ArrayLike | None = None,
    height_tol: ArrayLike | None = None, dup_tol: float = DUPLICATE_TOL
) -> VoronoiCells:
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
    height : ndarray, shape (P,), optional
        Offset of each pair along particle ``i``'s normal, ``n_i . (x_j - x_i)``. When
        given, neighbour ``j`` cuts the cell with its bisector *in space* (the plane
        of points equidistant from ``x_i`` and ``x_j``) intersected with ``i``'s tangent
        plane, and ``w_ij`` divides by the distance in space: the cell is the section of
        the 3D Voronoi cell by the tangent plane. See :func:`lift_offsets`.
    height_tol : ndarray, shape (N,), optional
        Heights tolerated in each row (noise; :func:`roughness`): only the height above
        ``height_tol + LIFT_SLOPE * |t|`` moves a bisector.
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
        raise ValueError(f"indptr must be a 1-D integer array of row offsets (N + 1,), got {describe(indptr)}")
    xy = as_points("xy", xy, dim=2)
    if indptr[0] != 0 or indptr[-1] != xy.shape[0] or np.any(np.diff(indptr) < 0):
        raise ValueError(
            f"indptr must rise from 0 to the number of pairs {xy.shape[0]}, got {indptr[0]} .. {indptr[-1]}"
            + (" (decreasing somewhere)" if np.any(np.diff(indptr) < 0) else "")
        )
    n = indptr.size - 1
    radius = np.ascontiguousarray(radius, dtype=np.float64)
    if radius.shape != (n,) or np.any(np.isnan(radius)) or np.any(radius <= 0):
        raise ValueError(f"radius must have shape ({n},) with positive values (inf allowed), got {describe(radius)}")
    dup_tol = check_positive("dup_tol", dup_tol, allow_zero=True)
    if height is not None:
        height = np.ascontiguousarray(height, dtype=np.float64)
        if height.shape != (xy.shape[0],):
            raise ValueError(f"height must have shape ({xy.shape[0]},) (one offset a pair), got {describe(height)}")
        check_finite("height", height)
        if height_tol is not None:
            height_tol = np.ascontiguousarray(height_tol, dtype=np.float64)
            if height_tol.shape != (n,) or np.any(~(height_tol >= 0)):
                raise ValueError(f"height_tol must have shape ({n},) with values >= 0, got {describe(height_tol)}")
        if n > LIFT_BLOCK_ROWS:  # rows are independent: the lift's pair arrays block by block, a fraction of the memory
            blocks = []
            for a in range(0, n, LIFT_BLOCK_ROWS):
                b = min(a + LIFT_BLOCK_ROWS, n)
                p0, p1 = int(indptr[a]), int(indptr[b])
                blocks.append(voronoi_cells(indptr[a : b + 1] - p0, xy[p0:p1], radius[a:b], dup_tol=dup_tol,
                                            height=height[p0:p1], height_tol=None if height_tol is None else height_tol[a:b]))
            return VoronoiCells(weights=np.concatenate([c.weights for c in blocks]),
                                area=np.concatenate([c.area for c in blocks]), flags=np.concatenate([c.flags for c in blocks]))
        xy, scale, keep = lift_offsets(xy, height, LIFT_SLOPE, tol=0.0 if height_tol is None else np.repeat(height_tol, np.diff(indptr)))
        # bisector beyond the search radius: it can cut only cells already flagged incomplete
        far = np.flatnonzero(scale > 1.0)  # only lifted offsets can have left the search radius
        row = np.searchsorted(indptr, far, side="right") - 1
        keep[far[np.einsum("pk,pk->p", xy[far], xy[far]) > 4.0 * radius[row] ** 2]] = False
        # a point beyond radius in space may have its lifted offset as near as _lift_reach() * (radius - tol)
        radius = _lift_reach(LIFT_SLOPE) * (radius if height_tol is None else np.maximum(radius - height_tol, 1e-9 * radius))
        if not keep.all():  # on i's normal line (the bisector is parallel to the tangent plane) or far
            kept = np.concatenate([[0], np.cumsum(keep)])[indptr]
            cells = voronoi_cells(kept, xy[keep], radius, dup_tol=dup_tol)
            w = np.zeros(keep.size)
            w[keep] = cells.weights * scale[keep]
            return VoronoiCells(weights=w, area=cells.area, flags=cells.flags)
        cells = voronoi_cells(indptr, xy, radius, dup_tol=dup_tol)
        return VoronoiCells(weights=cells.weights * scale, area=cells.area, flags=cells.flags)
    w = np.zeros(xy.shape[0])
    area = np.zeros(n)
    flags = np.zeros(n, dtype=np.uint8)
    starts = list(range(0, n, _ROWS))
    kernel = _jit.voronoi_rows if _jit.ENABLED else _cells_numpy
    run_chunks(
        lambda c: kernel(starts[c], min(starts[c] + _ROWS, n), indptr, xy, radius, float(dup_tol), w, area, flags),
        len(starts),
    )
    return VoronoiCells(weights=w, area=area, flags=flags)


def roughness(indptr: np.ndarray, xy: np.ndarray, height: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Tolerated height of each row's neighbours: :data:`ROUGHNESS_FACTOR` times the local noise.

    The noise of row ``i`` is the weighted mean ``|z - q(t)|`` of its neighbours' heights
    about the quadric ``q(t) = a t_x^2 + b t_x t_y + c t_y^2`` fitted to them (weighted least
    squares), with Gaussian weights ``exp(-(3 |x_j - x_i| / radius_i)^2)`` (about the nearest
    ring): curvature is fitted away, noise is not, and a point of another sheet two spacings
    away weighs little. There is no linear term, so a normal tilted by more than the
    tolerated slope also counts as rough and its row keeps the projected cell.

    Parameters
    ----------
    indptr : ndarray, shape (N + 1,)
        Row offsets of the pairs (CSR).
    xy, height : ndarray, shape (P, 2) and (P,)
        Tangent-plane offsets and heights along the row's normal.
    radius : ndarray, shape (N,)
        Neighbourhood radius of every particle.

    Returns
    -------
    ndarray, shape (N,)
    """
    n = radius.shape[0]
    if n > LIFT_BLOCK_ROWS:  # rows are independent: the fit's pair arrays block by block
        parts = []
        for a in range(0, n, LIFT_BLOCK_ROWS):
            b = min(a + LIFT_BLOCK_ROWS, n)
            p0, p1 = int(indptr[a]), int(indptr[b])
            parts.append(roughness(indptr[a : b + 1] - p0, xy[p0:p1], height[p0:p1], radius[a:b]))
        return np.concatenate(parts)
    counts = np.diff(indptr)
    out = np.zeros(n)
    if xy.shape[0] == 0:
        return out
    full = np.flatnonzero(counts > 0)
    starts = indptr[:-1][full]

    def rowsum(v):  # sums over each non-empty row's pairs
        r = np.zeros(n)
        r[full] = np.add.reduceat(v, starts)
        return r

    # in units of each row's radius: the fit's sums of t^4 stay finite and normal at any scale (1e100
    # coordinates overflowed them)
    r = np.repeat(np.where(np.isfinite(radius) & (radius > 0), radius, 1.0), counts)
    tx, ty, height = xy[:, 0] / r, xy[:, 1] / r, height / r
    d2 = tx * tx + ty * ty + height * height
    w = np.exp(-9.0 * d2)
    w[d2 == 0] = 0.0
    phi = (tx * tx, tx * ty, ty * ty)
    A, b = np.empty((n, 3, 3)), np.empty((n, 3))
    for a in range(3):
        wp = w * phi[a]
        b[:, a] = rowsum(wp * height)
        for c in range(a, 3):
            A[:, a, c] = A[:, c, a] = rowsum(wp * phi[c])
    A += (1e-9 * np.trace(A, axis1=1, axis2=2) + 1e-300)[:, None, None] * np.eye(3)  # rows with < 3 pairs
    q = np.repeat(np.linalg.solve(A, b[:, :, None])[:, :, 0], counts, axis=0)
    e = np.abs(height - (q[:, 0] * phi[0] + q[:, 1] * phi[1] + q[:, 2] * phi[2]))
    sw = rowsum(w)
    scale = np.where(np.isfinite(radius) & (radius > 0), radius, 1.0)
    return ROUGHNESS_FACTOR * scale * (rowsum(w * e) / np.where(sw > 0, sw, 1.0))


def _lift_reach(slope: float) -> float:
    """Smallest ``|lifted offset|`` of a point at distance 1 in space (:func:`lift_offsets`), slightly under.

    With ``u = |z| / |t|`` it is ``(1 + (u - slope)^2) / sqrt(1 + u^2)`` for ``u >= slope`` (and
    ``1 / sqrt(1 + u^2)`` below), minimised on a fine grid; 0.965 for ``slope = 0.2``.
    """
    u = slope + np.linspace(0.0, 4.0, 40001)
    return 0.999 * float(np.min((1.0 + (u - slope) ** 2) / np.sqrt(1.0 + u * u)))


def lift_offsets(
    xy: np.ndarray, height: np.ndarray, slope: float = LIFT_SLOPE, tol: np.ndarray | float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Planar offsets whose bisectors are the tangent-plane sections of the bisectors in space.

    The points equidistant from ``x_i`` and ``x_j = x_i + t + z n_i`` (``t`` in the tangent
    plane) cut the tangent plane in the line ``p . t / |t| = (|t|^2 + z^2) / (2 |t|)``: the
    planar bisector of the offset ``t (|t|^2 + z^2) / |t|^2``. Only the part of ``|z|``
    above ``tol + slope * |t|`` is counted, so that a neighbour on the same sheet (``|z| / |t|``
    about ``|t| kappa / 2`` plus the normal's error) keeps its projected offset, while a
    point on another sheet across a gap (``|z|`` comparable to ``|t|``) moves out of the
    cell's reach.

    Parameters
    ----------
    xy : ndarray, shape (P, 2)
        Offsets ``t`` projected to the row particle's tangent plane.
    height : ndarray, shape (P,)
        Offsets ``z`` along the row particle's normal.
    slope : float
        See :data:`LIFT_SLOPE`.
    tol : float or ndarray, shape (P,)
        Height tolerated on top of ``slope * |t|`` (noise: :func:`roughness`).

    Returns
    -------
    lifted : ndarray, shape (P, 2)
    scale : ndarray, shape (P,)
        ``|lifted| / sqrt(|t|^2 + z_eff^2)``: the planar weight ``|edge| / |lifted|`` times
        ``scale`` is ``|edge|`` over the lifted distance.
    keep : ndarray of bool, shape (P,)
        False for points on ``i``'s normal line (``|t|`` below 1e-9 of ``|z|``), whose
        bisector never meets the tangent plane.

    Examples
    --------
    >>> import numpy as np
    >>> lifted, scale, keep = lift_offsets(np.array([[1.0, 0.0], [1.0, 0.0]]), np.array([0.1, 1.2]))
    >>> lifted.round(3).tolist(), keep.tolist()        # 0.1 < 0.2 * 1: unchanged; 1.2 -> 1 + 1.0**2
    ([[1.0, 0.0], [2.0, 0.0]], [True, True])
    """
    scale = np.ones(xy.shape[0])
    keep = np.ones(xy.shape[0], dtype=bool)
    t2 = xy[:, 0] * xy[:, 0] + xy[:, 1] * xy[:, 1]
    tol = np.broadcast_to(np.asarray(tol, dtype=np.float64), height.shape)
    up = np.flatnonzero(np.abs(height) - tol > slope * np.sqrt(t2))  # the only pairs that move
    if up.size == 0:
        return xy, scale, keep
    t2u = t2[up]
    z = np.abs(height[up]) - tol[up] - slope * np.sqrt(t2u)
    on_axis = t2u <= 1e-18 * z * z
    keep[up[on_axis]] = False
    factor = np.where(on_axis, 1.0, (t2u + z * z) / np.where(on_axis, 1.0, t2u))
    xy = xy.copy()
    xy[up] *= factor[:, None]
    scale[up] = np.sqrt(factor)
    return xy, scale, keep


def stiffness_matrix(rows: ArrayLike, cols: ArrayLike, weights: ArrayLike, n: int) -> sp.csr_matrix:
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
