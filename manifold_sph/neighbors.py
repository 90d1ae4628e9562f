"""Neighbourhoods: KD-tree radius search, normal dot-product filter, smoothing lengths.

A neighbourhood is stored CSR-style: the neighbours of particle ``i`` are
``indices[indptr[i]:indptr[i + 1]]``, sorted by distance, the particle itself
first. ``j`` belongs to particle ``i``'s neighbourhood iff
``|p_i - p_j| < support * h_i`` and ``n_i . n_j > normal_threshold``
(docs/method.md section 2.1).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, SupportsFloat, cast, overload

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from . import _jit
from ._validation import as_points, check_int, check_positive
from .allocator import release_freed_memory
from .threads import resolve_workers, run_chunks

__all__ = [
    "Neighborhood",
    "build_tree",
    "find_neighbors",
    "smoothing_length_for_count",
    "adaptive_smoothing_length",
    "LonelyRepair",
    "widen_lonely",
    "check_scale",
    "MAX_EXTENT",
    "H_RANGE",
]


@dataclass(frozen=True)
class Neighborhood:
    """Flat CSR-style neighbour lists.

    Attributes
    ----------
    indptr : ndarray, shape (N + 1,)
        Row offsets into ``indices`` (int32 when the counts allow, else int64).
    indices : ndarray, shape (P,)
        Neighbour index of every pair, the particle itself first in its row
        (same integer type as ``indptr``).
    h : ndarray, shape (N,)
        Smoothing length of each row particle (the support radius is ``support * h``).
    support : float
        Kernel support ``kappa`` in units of ``h``.
    n_filtered : int
        Pairs inside the support that the normal filter removed.
    """

    indptr: np.ndarray
    indices: np.ndarray
    h: np.ndarray
    support: float
    n_filtered: int = 0

    @property
    def n_rows(self) -> int:
        return self.indptr.size - 1

    @property
    def counts(self) -> np.ndarray:
        """(N,) number of neighbours of each particle, itself included."""
        return np.diff(self.indptr)

    @property
    def rows(self) -> np.ndarray:
        """(P,) row particle of every pair."""
        return np.repeat(np.arange(self.n_rows), self.counts)

    def neighbors_of(self, i: int) -> np.ndarray:
        """Indices of the neighbours of particle ``i`` (itself first)."""
        return self.indices[self.indptr[i] : self.indptr[i + 1]]


#: The largest coordinate extent of a cloud: squared distances (the KD-tree's) stay below 1e300.
MAX_EXTENT = 1e150

#: The range of smoothing lengths: areas (``h^2``, down to ``1e-3 h`` squared in the Voronoi cells'
#: tests) and kernel values (``1 / h^2``) stay normal double-precision numbers. The operators scale
#: exactly with the coordinates (measured: the Voronoi ``K`` and ``M / s^2`` equal to 1e-15 from
#: 1e-150 to 1e154), so a cloud outside the range is rescaled by the user, not approximated here.
H_RANGE = (1e-145, 1e145)


def check_scale(points: np.ndarray, h: float | np.ndarray | None = None) -> None:
    """Raise ValueError when the coordinates span more than :data:`MAX_EXTENT` or less than the smallest
    smoothing length, or when ``h`` leaves :data:`H_RANGE`.

    Examples
    --------
    >>> import numpy as np
    >>> check_scale(np.eye(3) * 1e100, 1e99)
    >>> check_scale(np.eye(3) * 1e-140, 1e-146)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: h (smoothing length, about the point spacing) must lie in [1e-145, 1e+145], got 1e-146: areas (h^2) and ...
    """
    pts = np.asarray(points)
    if pts.size:
        with np.errstate(over="ignore"):
            extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
        if 0 < extent < H_RANGE[0]:
            raise ValueError(
                f"points span {extent:.3g} (their largest coordinate extent), less than {H_RANGE[0]:g}: their spacing "
                "would leave double precision; multiply the points by a power of ten (the operators scale exactly: a "
                "Laplacian by 1/s^2 when the points are multiplied by s)"
            )
        if not extent <= MAX_EXTENT:
            raise ValueError(
                f"points span {extent:.3g} (their largest coordinate extent), more than {MAX_EXTENT:g}: squared distances "
                "would overflow; multiply the points by a power of ten (the operators scale exactly: a Laplacian by "
                "1/s^2 when the points are multiplied by s), or remove the far outliers"
            )
    if h is not None:
        hv = np.asarray(h, dtype=np.float64)
        lo, hi = (float(hv.min()), float(hv.max())) if hv.size else (1.0, 1.0)
        if not (H_RANGE[0] <= lo and hi <= H_RANGE[1]):
            got = lo if not H_RANGE[0] <= lo else hi
            raise ValueError(
                f"h (smoothing length, about the point spacing) must lie in [{H_RANGE[0]:g}, {H_RANGE[1]:g}], got "
                f"{got:.3g}: areas (h^2) and kernel values (1/h^2) would leave double precision; multiply the points "
                "by a power of ten (the operators scale exactly: a Laplacian by 1/s^2 when the points are multiplied by s)"
            )


def _knn(tree: cKDTree, query: np.ndarray, k: int, radius: float, workers: int):
    k = min(k, tree.n)
    dist, idx = tree.query(query, k=k, distance_upper_bound=radius, workers=resolve_workers(workers))
    if k == 1:
        dist, idx = dist[:, None], idx[:, None]
    return dist, idx


def build_tree(points: ArrayLike) -> cKDTree:
    """The KD-tree of the neighbour searches: ``cKDTree(points, leafsize=32, balanced_tree=False)``.

    Measured at N = 131072 (Fibonacci sphere, 2 cores): the 31-nearest-neighbour query
    took 0.21 s on scipy's default tree (leaf size 16, balanced) and 0.14 s on this one,
    whose build is also faster (0.019 s against 0.031 s).

    Parameters
    ----------
    points : array_like, shape (N, d), d in 1..3
        Finite coordinates.

    Examples
    --------
    >>> import numpy as np
    >>> int(build_tree(np.eye(3)).query([1.0, 0.0, 0.0])[1])
    0
    """
    return cKDTree(as_points("points", points, dim=(1, 2, 3)), leafsize=32, balanced_tree=False)


#: Above this many points the uniform ``h`` is fitted on an evenly strided subsample.
H_SAMPLE = 10000


def _sample(n: int, size: int) -> np.ndarray:
    """``size`` indices spread evenly over ``range(n)`` (deterministic), or all of them."""
    if n <= size:
        return np.arange(n)
    return np.linspace(0, n - 1, size).round().astype(np.int64)


@overload
def smoothing_length_for_count(
    points: ArrayLike,
    target: float = ...,
    support: float = ...,
    *,
    tree: cKDTree | None = ...,
    workers: int = ...,
    return_knn: Literal[False] = ...,
    sample: int | None = ...,
) -> float: ...


@overload
def smoothing_length_for_count(
    points: ArrayLike,
    target: float = ...,
    support: float = ...,
    *,
    tree: cKDTree | None = ...,
    workers: int = ...,
    return_knn: Literal[True],
    sample: int | None = ...,
) -> tuple[float, tuple[np.ndarray, np.ndarray] | None]: ...


def smoothing_length_for_count(
    points: ArrayLike,
    target: float = 27,
    support: float = 3.0,
    *,
    tree: cKDTree | None = None,
    workers: int = -1,
    return_knn: bool = False,
    sample: int | None = H_SAMPLE,
) -> float | tuple[float, tuple[np.ndarray, np.ndarray] | None]:
    """Uniform ``h`` such that the mean number of particles inside ``support * h`` is ``target``.

    The particle itself is counted (docs/method.md section 2.1).

    Parameters
    ----------
    points : ndarray, shape (N, d)
    target : float
        Mean neighbour count, at least 2 and below N.
    support : float
        Kernel support ``kappa``.
    sample : int or None
        Clouds of more points fit ``h`` on this many of them, evenly strided
        through the array (deterministic): the mean count then matches
        ``target`` to about 0.1 % instead of exactly, at a fraction of the
        cost. ``None`` uses every point. Without a ``tree``, clouds of
        ``GRID_MIN_POINTS`` or more (searched on a grid, so no KD-tree is
        otherwise needed) also count neighbours among every second point only,
        for ``target / 2`` of them: ``h`` within 0.1 % of the full count's
        (measured: Fibonacci and Igea 0.00 %, random sphere -0.08 %, bunny
        +0.03 %) with a tree of half the points and about half the
        nearest neighbours per query.
    return_knn : bool
        Also return the nearest-neighbour query ``(dist, idx)`` of every point
        (``None`` when a subsample was used), which holds every neighbour
        inside the support.

    Returns
    -------
    float, or (float, (dist, idx) or None)

    Examples
    --------
    >>> import numpy as np
    >>> p = np.random.default_rng(0).uniform(size=(2000, 2))
    >>> h = smoothing_length_for_count(p, target=27, support=3.0)
    >>> float(find_neighbors(p, h=h, support=3.0).counts.mean())
    27.0
    """
    pts = np.asarray(points, dtype=np.float64)
    n = pts.shape[0]
    check_scale(pts)
    check_positive("target", target)
    if not 2 <= target < n:
        raise ValueError(f"target (mean neighbour count) must be in [2, {n}) for {n} points, got {target}")
    check_positive("support", support)
    if sample is not None:
        check_int("sample", sample, minimum=1)
    rows = _sample(n, n if sample is None else sample)
    query = pts[rows]
    count = float(target)
    if tree is None and sample is not None and n >= GRID_MIN_POINTS:
        half = pts[::2]
        tree, count = build_tree(half), target * half.shape[0] / n  # the same radius, half the points
    elif tree is None:
        tree = build_tree(pts)
    k = min(int(np.ceil(1.5 * count)) + 4, tree.n)  # doubled below if some particle needs more
    while True:
        dist, idx = _knn(tree, query, k, np.inf, workers)
        flat = dist.ravel()
        m = int(round(count * rows.size))  # the m-th smallest distance closes the mean count
        part = np.partition(flat, [m - 1, m])
        radius = 0.5 * (part[m - 1] + part[m])
        # every particle must have had its full count inside ``radius`` within k
        if k >= tree.n or np.all(dist[:, -1] >= radius):
            h = float(radius / support)
            if not return_knn:
                return h
            return h, ((dist, idx) if rows.size == n and tree.n == n else None)
        k = min(2 * k, tree.n)


def adaptive_smoothing_length(
    points: ArrayLike, k: int = 27, support: float = 3.0, *, tree: cKDTree | None = None, workers: int = -1
) -> np.ndarray:
    """Per-particle ``h_i`` so that exactly ``k`` particles (itself included) lie inside ``support * h_i``.

    The support radius is put midway between the k-th and the (k+1)-th nearest
    distances, for variable-density clouds, and at least at 1.5 times the nearest
    neighbour's distance (so that it lies at ``R <= 2``, inside the kernel's working
    range: where the neighbours form an equidistant ring, as at the pole of a UV
    sphere, the midpoint would put the whole ring at the support's edge, where the
    kernel and its derivatives vanish; such a particle gets more than ``k``).

    Returns
    -------
    ndarray, shape (N,)
    """
    pts = np.asarray(points, dtype=np.float64)
    n = pts.shape[0]
    check_scale(pts)
    check_int("k", k, minimum=2)
    if k >= n:
        raise ValueError(f"k must be smaller than the number of points {n}, got {k}")
    tree = build_tree(pts) if tree is None else tree
    dist, _ = _knn(tree, pts, k + 1, np.inf, workers)
    radius = np.maximum(0.5 * (dist[:, k - 1] + dist[:, k]), 1.5 * dist[:, 1])
    return radius / support


def find_neighbors(
    points: ArrayLike,
    normals: ArrayLike | None = None,
    *,
    h: float | ArrayLike,
    support: float = 3.0,
    normal_threshold: float = 0.0,
    candidates: ArrayLike | None = None,
    candidate_normals: ArrayLike | None = None,
    tree: cKDTree | None = None,
    workers: int = -1,
    knn: tuple[np.ndarray, np.ndarray] | None = None,
) -> Neighborhood:
    """Radius search with the normal dot-product filter.

    Parameters
    ----------
    points : ndarray, shape (N, d)
        Row particles.
    normals : ndarray, shape (N, d), optional
        Unit normals; when given, pairs with ``n_i . n_j <= normal_threshold`` are dropped.
    h : float or ndarray, shape (N,)
        Smoothing length (uniform or per row particle).
    support : float
        Kernel support ``kappa``: neighbours satisfy ``|p_i - p_j| < support * h_i``.
    normal_threshold : float
        In [-1, 1). 0 keeps neighbours whose normals make less than 90 degrees.
    candidates : ndarray, shape (M, d), optional
        Points searched (default: ``points``). The first N candidates must be
        ``points`` themselves (extra rows are ghosts, e.g. for mirroring).
    candidate_normals : ndarray, shape (M, d), optional
        Normals of the candidates (default: ``normals``).
    knn : (dist, idx), optional
        A nearest-neighbour query of ``points`` among the candidates, sorted by
        distance, that already holds every neighbour inside the support (as
        returned by :func:`smoothing_length_for_count`); saves a second query.

    Returns
    -------
    Neighborhood

    Examples
    --------
    >>> import numpy as np
    >>> x = np.linspace(0, 1, 11)[:, None] * np.ones((1, 2))
    >>> nb = find_neighbors(x, h=0.05, support=3.0)
    >>> nb.neighbors_of(0).tolist(), int(nb.counts[5])
    ([0, 1], 3)
    """
    pts = np.asarray(points, dtype=np.float64)
    n = pts.shape[0]
    cand = pts if candidates is None else np.asarray(candidates, dtype=np.float64)
    cnorm = normals if candidate_normals is None else candidate_normals
    if np.ndim(h) == 0:
        hv = np.full(n, check_positive("h", float(cast(SupportsFloat, h))))  # a number or a 0-d array
    else:
        hv = np.asarray(h, dtype=np.float64)
        if hv.shape != (n,):
            raise ValueError(f"h must be a scalar or have shape ({n},), got shape {hv.shape}")
        if not np.all(np.isfinite(hv) & (hv > 0)):
            raise ValueError("h must be finite and positive everywhere")
    if not -1.0 <= normal_threshold < 1.0:
        raise ValueError(f"normal_threshold must lie in [-1, 1), got {normal_threshold}")
    check_scale(cand, hv)
    radii = support * hv
    nr = None if normals is None else np.asarray(normals, dtype=np.float64)
    cn = None if normals is None else np.asarray(cnorm, dtype=np.float64)
    # int32 indices when they fit: scipy's sparse matrices then take them without conversion
    index_dtype = np.int32 if cand.shape[0] < 2**31 - 1 else np.int64
    usable_knn = knn is not None and np.all(knn[0][:, -1] >= radii)
    if candidates is None and not usable_knn:
        found = _grid_search(pts, nr, radii, float(normal_threshold), workers, index_dtype)
        if found is not None:
            indptr, indices, n_filtered = found
            return Neighborhood(indptr=indptr, indices=indices, h=hv, support=float(support), n_filtered=n_filtered)
    tree = build_tree(cand) if tree is None else tree
    counts = np.empty(n, dtype=np.int64)
    n_filtered = np.zeros(n, dtype=np.int64)
    if usable_knn:
        blocks = [(0, n, knn)]
    else:  # row blocks: the (rows, k) query arrays of one block at a time, not of the whole cloud
        blocks = [(lo, min(lo + _QUERY_ROWS, n), None) for lo in range(0, n, _QUERY_ROWS)]
    parts = []
    for lo, hi, given in blocks:
        groups = [(None,) + tuple(given)] if given is not None else _radius_knn(tree, pts[lo:hi], radii[lo:hi], workers)
        pieces = []
        for rows, dist, idx in groups:  # the first: every row; the others: rows asked again, wider
            at = slice(lo, hi) if rows is None else lo + rows
            c = np.empty(hi - lo if rows is None else rows.size, dtype=np.int64)
            f = np.zeros_like(c)
            flat = _filter_block(dist, idx, radii[at], None if nr is None else nr[at], cn, normal_threshold, c, f,
                                 index_dtype, workers)
            pieces.append((rows, c, f, flat))
        del groups, dist, idx
        parts.append(_merge_groups(pieces, hi - lo, counts[lo:hi], n_filtered[lo:hi], index_dtype))
        del pieces
    indices = parts[0] if len(parts) == 1 else np.concatenate(parts) if parts else np.zeros(0, dtype=index_dtype)
    del parts
    if indices.size >= 2**31 - 1:  # more pairs than int32 offsets hold: both arrays int64
        index_dtype = np.int64
        indices = indices.astype(np.int64)
    indptr = np.zeros(n + 1, dtype=index_dtype)
    np.cumsum(counts, out=indptr[1:])
    return Neighborhood(indptr=indptr, indices=indices, h=hv, support=float(support), n_filtered=int(n_filtered.sum()))


#: Rows per chunk of the neighbour filter.
_FILTER_ROWS = 8192

#: The grid (cell list) search of :func:`_grid_search` replaces the KD-tree query from this many
#: points (below, the KD-tree's is as fast and the smoothing length's k-NN query is often reused).
GRID_MIN_POINTS = 20_000

#: ... when the largest support radius is at most this many times the smallest (the cells are
#: sized by the largest).
GRID_MAX_RADIUS_RATIO = 1.5

#: ... and no column of cells holds more than this many points (its sort is quadratic): clouds
#: filling a volume rather than a surface keep the KD-tree.
GRID_MAX_COLUMN = 4096

#: Sorted positions per chunk (thread task) of the grid search.
_GRID_ROWS = 8192


def _grid_search(pts, nr, radii, normal_threshold, workers, index_dtype):
    """Radius search and normal filter on a grid of cells (compiled), or None where it does not apply.

    Cells of the largest support radius ``r``; the points are sorted into columns of cells along the
    two axes of the cloud's largest extent, each column sorted along the third axis, and every point
    scans the 3 x 3 columns around its own within ``r`` along the third axis. Distances are computed
    as scipy's KD-tree computes them (``sqrt((dx^2 + dy^2) + dz^2)``, then ``< radius``), so the
    neighbour sets are the KD-tree search's; each row is sorted by distance (the particle itself
    first, ties by index). Measured on a 131,072-point Fibonacci sphere: the same ``indptr`` and
    ``indices`` arrays as the KD-tree search.
    """
    n = pts.shape[0]
    if not _jit.ENABLED or n < GRID_MIN_POINTS or pts.ndim != 2 or pts.shape[1] != 3:
        return None
    rmax, rmin = float(radii.max()), float(radii.min())
    if not (np.isfinite(rmax) and rmin > 0 and rmax <= GRID_MAX_RADIUS_RATIO * rmin):
        return None
    lo = pts.min(axis=0)
    extent = pts.max(axis=0) - lo
    axes = np.argsort(-extent, kind="stable")  # the two largest extents make the columns
    ax_a, ax_b, ax_z = (int(x) for x in axes)
    cell = rmax * (1.0 + 1e-9)  # a neighbour is at most one cell away along every axis, rounding included
    n_a = int(extent[ax_a] // cell) + 1
    n_b = int(extent[ax_b] // cell) + 1
    if n_a * n_b > 4 * n + 1024:  # far-flung outliers: too many empty columns
        return None
    pts = np.ascontiguousarray(pts, dtype=np.float64)
    colptr = np.empty(n_a * n_b + 1, dtype=np.int64)
    order = np.empty(n, dtype=np.int64)
    if _jit.grid_sort(pts, lo, cell, ax_a, ax_b, ax_z, n_a, n_b, GRID_MAX_COLUMN, colptr, order) > GRID_MAX_COLUMN:
        return None
    # the columns' sorts along the third axis and the gather, in chunks on threads (the counting sort
    # above is the only serial pass)
    ncols = n_a * n_b
    col_cuts = np.searchsorted(colptr, np.arange(0, n, _GRID_ROWS), side="right") - 1  # ~_GRID_ROWS points a chunk
    col_cuts = np.unique(np.concatenate([[0], col_cuts, [ncols]]))
    run_chunks(lambda c: _jit.grid_sort_columns(int(col_cuts[c]), int(col_cuts[c + 1]), pts, ax_z, colptr, order),
               col_cuts.size - 1, workers)
    use = nr is not None
    # the sorted copies (points, normals, third coordinate, column coordinates) in a dict that the
    # closures read and that is cleared once the rows are found: the memory goes before the scatter
    buf = {"ps": np.empty((n, 3)), "ns": np.empty((n, 3)) if use else np.zeros((1, 3)), "zs": np.empty(n),
           "ca": np.empty(n, dtype=np.int64), "cb": np.empty(n, dtype=np.int64)}
    nr_c = np.ascontiguousarray(nr) if use else buf["ns"]
    starts = list(range(0, n, _GRID_ROWS))
    run_chunks(lambda c: _jit.grid_gather(starts[c], min(starts[c] + _GRID_ROWS, n), order, pts, nr_c, use, lo, cell,
                                          ax_a, ax_b, ax_z, n_a, n_b, buf["ps"], buf["ns"], buf["zs"], buf["ca"], buf["cb"]),
               len(starts), workers)
    counts = np.empty(n, dtype=np.int64)
    n_filtered = np.zeros(n, dtype=np.int64)
    found: list = [None] * len(starts)  # each chunk's buffers from the compiled search, cleared after the scatter
    like = np.zeros(0, dtype=index_dtype if n < 2**31 - 1 else np.int64)  # the chunks' buffers: column indices

    def search(c: int) -> None:  # one pass: each chunk's neighbours in its own buffer, in sorted order
        s0, s1 = starts[c], min(starts[c] + _GRID_ROWS, n)
        found[c] = _jit.grid_rows(s0, s1, order, buf["ps"], buf["ns"], buf["zs"], buf["ca"], buf["cb"], n_a, n_b, colptr,
                                  cell, radii, normal_threshold, use, 32, counts, n_filtered, like)

    run_chunks(search, len(starts), workers)
    buf.clear()
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    if indptr[-1] >= 2**31 - 1:
        index_dtype = np.int64
    indices = np.empty(int(indptr[-1]), dtype=index_dtype)
    run_chunks(lambda c: _jit.grid_scatter(starts[c], min(starts[c] + _GRID_ROWS, n), order, found[c][0], found[c][1],
                                           indptr, indices), len(starts), workers)
    found.clear()
    release_freed_memory(n)
    return indptr.astype(index_dtype), indices, int(n_filtered.sum())

#: Rows per block of the neighbour query: its (rows, k) distance and index arrays are the largest
#: temporaries of a build (16 bytes a slot: 690 MB for a million points queried whole at k = 43).
_QUERY_ROWS = 65536


def _filter_block(dist, idx, radii, nr, cn, normal_threshold, counts, n_filtered, index_dtype, workers):
    """Radius mask and normal filter of one block of rows (arrays of the block, ``cn`` of all
    candidates); fills ``counts`` and ``n_filtered`` (views) and returns the block's columns."""
    n = dist.shape[0]
    starts = list(range(0, n, _FILTER_ROWS))
    if _jit.ENABLED:  # compiled: a mask pass, then the columns written in place
        keep = np.empty(dist.shape, dtype=np.uint8)
        use = nr is not None
        nr_, cn_ = (nr, cn) if use else (np.zeros((1, 3)), np.zeros((1, 3)))
        run_chunks(
            lambda c: _jit.filter_count(
                starts[c], min(starts[c] + _FILTER_ROWS, n), dist, idx, radii, nr_, cn_, float(normal_threshold),
                use, keep, counts, n_filtered,
            ),
            len(starts),
            workers,
        )
        indptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        out = np.empty(int(indptr[-1]), dtype=index_dtype)
        run_chunks(
            lambda c: _jit.filter_fill(starts[c], min(starts[c] + _FILTER_ROWS, n), idx, keep, indptr, out),
            len(starts),
            workers,
        )
        return out
    parts: list = [None] * len(starts)  # each chunk's columns

    def chunk(c):  # radius mask and normal filter of rows lo:hi; disjoint outputs
        lo = starts[c]
        hi = min(lo + _FILTER_ROWS, n)
        mask = dist[lo:hi] < radii[lo:hi, None]
        if nr is not None:
            safe = np.where(mask, idx[lo:hi], 0)
            keep = np.einsum("nd,nkd->nk", nr[lo:hi], cn[safe]) > normal_threshold
            n_filtered[lo:hi] = (mask & ~keep).sum(axis=1)
            mask &= keep
        counts[lo:hi] = mask.sum(axis=1)
        parts[c] = idx[lo:hi][mask].astype(index_dtype, copy=False)

    run_chunks(chunk, len(starts), workers)
    return np.concatenate(parts) if parts else np.zeros(0, dtype=index_dtype)


def _radius_knn(tree: cKDTree, pts: np.ndarray, radii: np.ndarray, workers: int) -> list:
    """Nearest-neighbour queries holding every candidate within ``radii`` of each point.

    Returns a list of ``(rows, dist, idx)``: first ``(None, dist, idx)`` for every point, then, for
    rows whose query came back full (more neighbours inside their radius than asked for), the
    same rows asked again with twice as many, ``rows`` their indices (these replace the first
    group's rows). The number asked of everyone comes from a small strided subsample: its
    largest count, not counting the 1 % of the subsample that is fuller still (dense clumps,
    widened supports), plus 10 %, at least 2 more; each later group's arrays are as wide as its
    largest count, so that a few wide rows (a stray point whose support reaches the whole
    cloud) never widen every row's arrays. Measured at N = 131072 with 30 neighbours: a probe
    margin of 2 left 8 full rows, and widening every row to their doubled query made the search
    0.62 s instead of 0.15 s.
    """
    n, m = pts.shape[0], tree.n
    rmax = float(radii.max())
    probe = _sample(n, 2000)
    k = min(64, m)
    while True:
        d, _ = _knn(tree, pts[probe], k, rmax, workers)
        cnt = (d < radii[probe, None]).sum(axis=1)
        packed = cnt >= k
        if k >= m or packed.mean() <= 0.01:  # the few packed rows are asked again below
            break
        k = min(2 * k, m)
    top = int(cnt[~packed].max()) if not packed.all() else k
    k = min(m, top + max(2, -(-top // 10)))
    dist, idx = _knn(tree, pts, k, rmax, workers)
    groups = [(None, dist, idx)]
    full = np.flatnonzero(dist[:, -1] < radii)
    while full.size and k < m:
        k = min(2 * k, m)
        d2, i2 = _knn(tree, pts[full], k, float(radii[full].max()), workers)
        done = ~(d2[:, -1] < radii[full]) | (k >= m)
        if done.any():
            width = min(k, int((d2[done] < radii[full[done], None]).sum(axis=1).max()) + 1)
            groups.append((full[done], d2[done, :width], i2[done, :width]))
        full = full[~done]
    return groups


def _merge_groups(pieces, n, counts, n_filtered, index_dtype):
    """The columns of ``n`` rows from the filtered groups of :func:`_radius_knn` (a later group's rows
    replace the first's); fills ``counts`` and ``n_filtered`` (views of the block)."""
    if len(pieces) == 1:
        _, c, f, flat = pieces[0]
        counts[:], n_filtered[:] = c, f
        return flat
    owner = np.zeros(n, dtype=np.int64)
    counts[:], n_filtered[:] = pieces[0][1], pieces[0][2]
    for g, (rows, c, f, _) in enumerate(pieces[1:], 1):
        owner[rows] = g
        counts[rows], n_filtered[rows] = c, f
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    out = np.empty(int(indptr[-1]), dtype=index_dtype)
    for g, (rows, c, _, flat) in enumerate(pieces):
        r = np.arange(n) if rows is None else rows
        mine = owner[r] == g
        cm = c[mine]
        ends = np.cumsum(cm)
        within = np.arange(int(ends[-1]) if cm.size else 0) - np.repeat(ends - cm, cm)
        out[np.repeat(indptr[r[mine]], cm) + within] = flat[np.repeat(mine, c)]
    return out

#: Rounds of :func:`widen_lonely` (each repairs the rows left lonely by the previous one's flips).
LONELY_ROUNDS = 6

#: A widened particle whose smoothing length ends above this many times the median is reported as a stray.
STRAY_FACTOR = 10.0

#: :func:`widen_lonely` replaces the normal of a particle short of neighbours when it makes more
#: than 60 degrees (either sign) with the mean normal of the largest agreeing group of its nearest
#: points: a normal across the surface, not a wrong orientation (an edge's normal, between two faces
#: at a right angle, makes 45 degrees with either; a cube corner's 55).
REPAIR_COS = 0.5


@dataclass(frozen=True)
class LonelyRepair:
    """What :func:`widen_lonely` repaired.

    Attributes
    ----------
    neighborhood : Neighborhood
        The neighbourhood after the repairs.
    normals : ndarray, shape (N, 3)
        The normals after the repairs (the input array itself when none changed).
    h : ndarray, shape (N,)
        Smoothing lengths, widened where a particle had too few neighbours.
    widened : ndarray of int
        Particles whose smoothing length was widened.
    flipped : ndarray of int
        Particles whose normal disagreed with its nearest points' and agreed once flipped.
    repaired : ndarray of int
        Particles whose normal lay across the surface of its nearest points or agreed with too
        few of them either way (a stray point, a noisy fit): given the mean normal of the largest
        group of mutually agreeing normals among them.
    unfiltered : ndarray of int
        Particles that even then had fewer than ``need`` normal-compatible neighbours: their row
        holds their ``target`` nearest points without the normal filter.
    strays : ndarray of int
        Widened particles whose smoothing length ended more than :data:`STRAY_FACTOR` times the
        median: points far from the cloud, whose area elements (of the scale of their support)
        dominate sums and integrals over it.
    need, target : int
        The fewest neighbours a row must have, and the count a widened row reaches.
    normal_threshold : float
    """

    neighborhood: Neighborhood
    normals: np.ndarray
    h: np.ndarray
    widened: np.ndarray
    flipped: np.ndarray
    repaired: np.ndarray
    unfiltered: np.ndarray
    strays: np.ndarray
    need: int
    target: int
    normal_threshold: float

    def entries(self) -> list[tuple[str, str, str, np.ndarray]]:
        """``(key, summary, detail, indices)`` for each kind of repair made, in user terms: what a
        build report (:mod:`manifold_sph.diagnostics`) lists."""
        t, out = self.normal_threshold, []
        if self.flipped.size:
            out.append(("flipped", f"{self.flipped.size} normal(s) pointed against all their neighbours' and were flipped",
                        f"Each disagreed with every nearby point's normal (n_i . n_j <= normal_threshold = {t:g}) and "
                        "agrees once flipped: a wrongly oriented normal. Check the orientation of the normals given, or "
                        "give none to have them estimated.", self.flipped))
        if self.repaired.size:
            out.append(("repaired", f"{self.repaired.size} normal(s) lay across the surface of their nearest points "
                        f"(first indices {self.repaired[:8].tolist()}) and were replaced by their neighbours' consensus",
                        f"They agreed with too few of their nearest points either way (n_i . n_j > {t:g}): noisy fits or "
                        "stray points. Each was replaced by the mean normal of the largest group of agreeing normals "
                        "among its nearest points.", self.repaired))
        if self.widened.size:
            out.append(("widened", f"{self.widened.size} isolated or sparse point(s) got wider supports (reaching "
                        f"{self.target} neighbours)",
                        f"They had fewer than {self.need} neighbours inside the kernel support (stray points, or sparse "
                        "parts of the cloud); their smoothing length was widened, so their operators are smoother and "
                        "less accurate there. Remove stray points, or sample those parts more densely.", self.widened))
        if self.strays.size:
            out.append(("strays", f"{self.strays.size} point(s) lie far from the cloud (first indices "
                        f"{self.strays[:8].tolist()})",
                        f"Their supports grew to more than {STRAY_FACTOR:g} times the median smoothing length, so their "
                        "area elements, of their supports' size, dominate sums and integrals over the cloud. Remove them "
                        "(manifold_sph.scans.cleaning.remove_outliers).", self.strays))
        if self.unfiltered.size:
            out.append(("unfiltered", f"{self.unfiltered.size} point(s) found no neighbours whose normals agree with "
                        "theirs and use their nearest points without the normal filter",
                        f"Fewer than {self.need} points anywhere in the cloud have normals agreeing with theirs "
                        f"(n_i . n_j > {t:g}); their rows hold their {self.target} nearest points.", self.unfiltered))
        return out


def _agreeing_group_normals(nrm: np.ndarray, idx: np.ndarray, threshold: float) -> np.ndarray:
    """For each row of candidate indices ``idx`` (R, m), the normalised sum of the largest group of
    normals agreeing (``n_a . n_b > threshold``) with one of them, then of those agreeing with that
    mean (the group centred), shape (R, 3)."""
    G = nrm[idx]  # (R, m, 3)
    agree = np.einsum("rad,rbd->rab", G, G) > threshold
    best = np.argmax(agree.sum(axis=2), axis=1)
    group = agree[np.arange(idx.shape[0]), best]  # (R, m): the members of the largest group
    s = np.einsum("rm,rmd->rd", group.astype(np.float64), G)
    s /= np.linalg.norm(s, axis=1)[:, None]  # the best candidate agrees with itself: s != 0
    again = np.einsum("rmd,rd->rm", G, s) > threshold  # once more, about the group's mean (centred)
    t = np.einsum("rm,rmd->rd", again.astype(np.float64), G)
    norm = np.linalg.norm(t, axis=1)
    return np.where((norm > 0)[:, None], t / np.where(norm > 0, norm, 1.0)[:, None], s)


def widen_lonely(
    nb: Neighborhood,
    points: np.ndarray,
    normals: np.ndarray,
    h: float | np.ndarray,
    *,
    need: int,
    target: int,
    normal_threshold: float = 0.0,
    tree: cKDTree | None = None,
    workers: int = -1,
) -> LonelyRepair:
    """Give every particle at least ``need`` normal-compatible neighbours, repairing the normals in the way.

    A particle with fewer than ``need`` neighbours (itself included) inside its support is an
    isolated point, part of a sparse region, or a particle whose normal disagrees with its
    neighbours' (a wrong orientation, or a normal across the surface from a noisy fit). Such a
    particle is never a reason to refuse the cloud; in rounds, each on the particles still short:

    1. a normal across the surface, more than 60 degrees (:data:`REPAIR_COS`, either sign) from
       the mean normal of the largest group of mutually agreeing normals (``n_a . n_b >
       normal_threshold``) among its ``target - 1`` nearest points, is replaced by that mean;
    2. a normal whose opposite agrees with more of those nearest points than it does is flipped
       (repeated while flips change the votes: wrong normals side by side are flipped together);
       one that still agrees with fewer than ``need - 1`` of them (a strict threshold) is replaced
       as in 1;
    3. its smoothing length is widened until the support holds ``target`` compatible neighbours (or
       every compatible point of the cloud, the search doubling up to all of them);

    then the neighbourhood is searched again, with the new normals, since a flip may have taken a
    neighbour from another particle. Rows still short after :data:`LONELY_ROUNDS` rounds hold their
    ``target`` nearest points without the normal filter (reported in ``unfiltered``).

    Parameters
    ----------
    nb : Neighborhood
        The neighbourhood found with ``normals`` and ``h``.
    points, normals : ndarray, shape (N, 3)
    h : float or ndarray, shape (N,)
    need : int
        Fewest neighbours of a row, itself included (the scheme's minimum; at least 2).
    target : int
        Neighbours a widened row reaches.
    normal_threshold : float
    tree : cKDTree, optional
        The KD-tree of ``points``.

    Returns
    -------
    LonelyRepair

    Examples
    --------
    A sphere with one normal turned into the tangent plane: replaced, not refused.

    >>> import numpy as np
    >>> from manifold_sph.reference import shapes
    >>> c = shapes.sphere(400)
    >>> n = c.normals.copy(); n[7] = np.cross(n[7], [0.0, 0.0, 1.0]); n[7] /= np.linalg.norm(n[7])
    >>> h = smoothing_length_for_count(c.points, 27, 3.0)
    >>> nb = find_neighbors(c.points, n, h=h, support=3.0, normal_threshold=0.9)
    >>> fix = widen_lonely(nb, c.points, n, h, need=6, target=27, normal_threshold=0.9)
    >>> fix.repaired.tolist(), bool(fix.normals[7] @ c.normals[7] > 0.98), int(fix.neighborhood.counts.min()) >= 6
    ([7], True, True)
    """
    need = check_int("need", need, minimum=2)
    target = check_int("target", target, minimum=need)
    pts = np.asarray(points, dtype=np.float64)
    n = pts.shape[0]
    target = min(target, n - 1)
    nrm = normals
    hv = np.array(np.broadcast_to(np.asarray(h, dtype=np.float64), (n,)))
    support = nb.support
    none = np.zeros(0, dtype=np.int64)
    widened, flipped, repaired = [none], [none], [none]
    lonely = np.flatnonzero(nb.counts < need)
    if lonely.size:
        tree = build_tree(pts) if tree is None else tree
    changed = 2  # the lists start with one empty array each
    for _ in range(LONELY_ROUNDS):
        if not lonely.size:
            break
        if nrm is normals:
            nrm = np.array(normals, dtype=np.float64)
        k = min(n, 4 * target)
        dist, idx = _knn(tree, pts[lonely], k, np.inf, workers)

        def dots_of(rows, cand, nrm=nrm, lonely=lonely):  # nrm changes in place: the current normals
            d = np.einsum("rkd,rd->rk", nrm[cand], nrm[lonely[rows]])
            d[:, 0] = np.inf  # the particle itself
            return d

        everyone = np.arange(lonely.size)
        m = min(target, k) - 1  # the nearest points that vote (itself excluded)
        group = _agreeing_group_normals(nrm, idx[:, 1 : m + 1], normal_threshold)
        across = np.flatnonzero(np.abs(np.einsum("rd,rd->r", group, nrm[lonely])) < REPAIR_COS)
        if across.size:
            nrm[lonely[across]] = group[across]
            repaired.append(lonely[across])
        for _flip in range(8):  # flips of neighbours change each other's votes: until none changes
            dots = dots_of(everyone, idx)
            near = dots[:, 1 : m + 1]
            flip = (-near > normal_threshold).sum(axis=1) > (near > normal_threshold).sum(axis=1)
            if not flip.any():
                break
            nrm[lonely[flip]] *= -1.0
            flipped.append(lonely[flip])
        dots = dots_of(everyone, idx)
        bad = np.flatnonzero((dots[:, 1 : m + 1] > normal_threshold).sum(axis=1) < need - 1)
        if bad.size:  # too few agree either way (a strict normal_threshold)
            nrm[lonely[bad]] = _agreeing_group_normals(nrm, idx[bad, 1 : m + 1], normal_threshold)
            repaired.append(lonely[bad])
            dots[bad] = dots_of(bad, idx[bad])
        ok = dots > normal_threshold
        reach = np.empty(lonely.size)
        total = ok.sum(axis=1)
        enough = np.minimum(target, total)  # ``target`` counting itself, or all compatible ones
        full = total >= target
        rank = np.cumsum(ok, axis=1)
        reach[full] = dist[full, np.argmax(rank[full] >= enough[full, None], axis=1)]
        short = np.flatnonzero(~full)
        kk = k
        while short.size and kk < n:  # too few compatible points among the k nearest: search wider
            kk = min(2 * kk, n)
            d2, i2 = _knn(tree, pts[lonely[short]], kk, np.inf, workers)
            ok2 = dots_of(short, i2) > normal_threshold
            tot2 = ok2.sum(axis=1)
            done = (tot2 >= target) | (kk >= n)
            en2 = np.minimum(target, tot2)
            at = np.argmax(np.cumsum(ok2, axis=1) >= en2[:, None], axis=1)
            reach[short[done]] = d2[done, at[done]]
            short = short[~done]
        reach[short] = dist[short, np.argmax(rank[short] >= enough[short, None], axis=1)]  # k == n from the start
        hv[lonely] = np.maximum(hv[lonely], 1.0001 * reach / support)
        widened.append(lonely)
        if len(flipped) + len(repaired) > changed:  # normals changed: other rows' normal filter too
            changed = len(flipped) + len(repaired)
            nb = find_neighbors(pts, nrm, h=hv, support=support, normal_threshold=normal_threshold, tree=tree,
                                workers=workers)
        else:  # only the widened rows change: search them alone (a full search with widened h takes the
            # slower KD-tree path everywhere: a 100k-point random slab with 2 lonely points 5.0 s instead of 1.0 s)
            nb = _splice_rows(nb, lonely, pts, nrm, hv, normal_threshold, tree, workers)
        lonely = np.flatnonzero(nb.counts < need)
    unfiltered = lonely
    if unfiltered.size:
        nb = _unfiltered_rows(nb, pts, hv, unfiltered, target, tree, workers)
    uniq = [np.unique(np.concatenate(a)) for a in (widened, flipped, repaired)]
    # a normal flipped an even number of times is back where it was
    if uniq[1].size:
        uniq[1] = uniq[1][np.einsum("rd,rd->r", nrm[uniq[1]], np.asarray(normals)[uniq[1]]) < 0]
        uniq[1] = np.setdiff1d(uniq[1], uniq[2])
    strays = uniq[0][hv[uniq[0]] > STRAY_FACTOR * np.median(hv)] if uniq[0].size else uniq[0]
    return LonelyRepair(nb, nrm, hv, uniq[0], uniq[1], uniq[2], unfiltered, strays, need, target,
                        float(normal_threshold))


def _splice_rows(nb, rows, pts, nrm, hv, normal_threshold, tree, workers):
    """``nb`` with the neighbour lists of ``rows`` searched again with the smoothing lengths ``hv``.

    The same arrays as a search of every row with ``hv`` (each row's list depends only on its own
    support and the normals; rows keep the search's order, the particle first).
    """
    def search(h):
        return find_neighbors(pts[rows], nrm[rows], h=h, support=nb.support, normal_threshold=normal_threshold,
                              candidates=pts, candidate_normals=nrm, tree=tree, workers=workers)

    new, old = search(hv[rows]), search(nb.h[rows])
    counts = nb.counts.copy()
    counts[rows] = new.counts
    indptr = np.zeros(counts.size + 1, dtype=nb.indptr.dtype)
    np.cumsum(counts, out=indptr[1:])
    indices = np.empty(int(indptr[-1]), dtype=nb.indices.dtype)
    keep = np.ones(counts.size, dtype=bool)
    keep[rows] = False
    r = nb.rows
    mask = keep[r]
    pos = np.flatnonzero(mask)
    indices[indptr[r[mask]] + (pos - nb.indptr[r[mask]])] = nb.indices[mask]
    owner = np.repeat(np.arange(rows.size), new.counts)
    indices[indptr[rows[owner]] + (np.arange(new.indices.size) - new.indptr[owner])] = new.indices
    return Neighborhood(indptr=indptr, indices=indices, h=hv, support=nb.support,
                        n_filtered=nb.n_filtered - old.n_filtered + new.n_filtered)


def _unfiltered_rows(nb, pts, hv, rows, target, tree, workers):
    """``nb`` with the rows ``rows`` replaced by their ``target`` nearest points (no normal filter);
    ``hv`` (changed in place) reaches them."""
    n = pts.shape[0]
    dist, idx = _knn(tree, pts[rows], min(target, n), np.inf, workers)
    hv[rows] = np.maximum(hv[rows], 1.0001 * dist[:, -1] / nb.support)
    counts = nb.counts.copy()
    counts[rows] = idx.shape[1]
    keep = np.ones(nb.indices.size, dtype=bool)
    mark = np.zeros(n, dtype=bool)
    mark[rows] = True
    keep[np.repeat(mark, nb.counts)] = False
    index_dtype = nb.indices.dtype
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    indices = np.empty(int(indptr[-1]), dtype=index_dtype)
    rest = np.ones(indices.size, dtype=bool)
    pos = (indptr[rows][:, None] + np.arange(idx.shape[1])[None, :]).ravel()
    rest[pos] = False
    indices[pos] = idx.ravel()
    indices[rest] = nb.indices[keep]
    return Neighborhood(indptr=indptr.astype(nb.indptr.dtype), indices=indices, h=hv, support=nb.support,
                        n_filtered=nb.n_filtered)
