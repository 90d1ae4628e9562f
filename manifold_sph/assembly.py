"""Assembly: pair geometry -> scheme weights -> sparse operator matrices.

Particles are processed in chunks of rows: for each chunk the pair data are
put in normalised units (:class:`~manifold_sph.schemes.base.LocalPairs`), the
scheme turns them into per-pair weights, particles whose local systems fail
are recomputed with the scheme's fallback (e.g. ncsph -> cspm -> standard), and
all weights go into one COO -> CSR conversion per operator.

With the quintic spline, cspm, msph, ncsph and msph3/4/5 run as compiled per-row
kernels (:mod:`manifold_sph._jit`), which give the same weights in one pass; the
particles they flag as failed (and those with too few neighbours) are then redone
through the numpy schemes above, down the fallback chain.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from . import _jit
from .frames import PairOffsets, offsets_at, offsets_of_rows
from .kernels import Kernel, QuinticSpline
from .neighbors import Neighborhood
from .schemes import Scheme, get_scheme
from .schemes.base import LocalPairs
from .schemes.cspm import CSPM
from .schemes.msph import MSPH
from .schemes.msph4 import HighOrderCorrected
from .schemes.ncsph import NCSPH
from .threads import run_chunks

__all__ = ["DEFECT_TOL", "Assembled", "ColumnAreas", "assemble", "pair_kernel_data", "quadratic_defect"]

#: Rows per chunk, overriding every scheme's ``chunk_rows`` (and :data:`COMPILED_CHUNK_ROWS`)
#: when set (tests, tuning); ``None``: each scheme's own (chunks bound the per-pair
#: temporaries and keep them in cache).
CHUNK_ROWS: int | None = None

#: Rows per chunk of the compiled schemes (their temporaries are one particle's).
COMPILED_CHUNK_ROWS = 4096


def _compiled_weights(scheme: Scheme, kernel: Kernel):
    """The compiled kernel of :mod:`manifold_sph._jit` computing ``scheme``'s weights, or None.

    Compiled: the quintic spline with cspm, msph, ncsph and msph3/4/5 (not subclasses
    that change the weights); everything else runs the numpy schemes. The result is
    a function ``f(lo, hi, indptr, xy, dV_pairs, h, alpha, max_condition, gx, gy, lp,
    condition, failed)``.
    """
    if not _jit.ENABLED or type(kernel) is not QuinticSpline:
        return None
    table = {CSPM: _jit.cspm_rows, MSPH: _jit.msph_rows, NCSPH: _jit.ncsph_rows}
    if type(scheme) in table:  # exactly these classes: a subclass may change the weights
        return table[type(scheme)]
    if isinstance(scheme, HighOrderCorrected) and type(scheme).weights is HighOrderCorrected.weights:
        exps = scheme.exponents
        px = np.array([a for a, _ in exps], dtype=np.int64)
        py = np.array([b for _, b in exps], dtype=np.int64)
        sel = np.array([exps.index(e) for e in ((1, 0), (0, 1), (2, 0), (0, 2))], dtype=np.int64)
        scale = np.ascontiguousarray(scheme.scale, dtype=np.float64)

        def moment(lo, hi, indptr, xy, dV_pairs, h, alpha, max_condition, gx, gy, lp, condition, failed):
            _jit.moment_rows(lo, hi, indptr, xy, h, alpha, px, py, scale, sel, max_condition, gx, gy, lp, condition, failed)

        return moment
    return None


class Assembled:
    """Operator matrices of one scheme, and what the robustness checks found.

    Attributes
    ----------
    lap : scipy.sparse.csr_matrix, shape (N, M)
        Laplacian weights (M columns: particles).
    dx, dy : scipy.sparse.csr_matrix, shape (N, M)
        Tangent-plane derivative weights, built from ``pair_dx``/``pair_dy`` on first access.
    pair_dx, pair_dy, pair_lap : ndarray, shape (P,)
        The weights per neighbour pair (before duplicate columns are summed).
    condition : ndarray, shape (N,)
        Largest condition number among the local systems of the scheme first tried.
    used_code : ndarray of int8, shape (N,)
        Index into ``used_names`` of the scheme that produced each particle's row.
    used_names : tuple of str
        The scheme first tried, then its fallback chain.
    fallback : dict
        ``{scheme name: indices}`` of particles that fell back *to* that scheme.
    defect : ndarray, shape (N,)
        :func:`quadratic_defect` of every row's Laplacian weights.
    """

    def __init__(
        self,
        pair_dx: np.ndarray | None,
        pair_dy: np.ndarray | None,
        pair_lap: np.ndarray,
        make_csr: Callable[[np.ndarray], sp.csr_matrix],
        condition: np.ndarray,
        used_code: np.ndarray,
        used_names: tuple[str, ...],
        fallback: dict[str, np.ndarray],
        defect: np.ndarray | None = None,
    ) -> None:
        self._pair_dx, self._pair_dy, self.pair_lap = pair_dx, pair_dy, pair_lap
        self.defect = np.zeros(condition.shape) if defect is None else defect
        self._gradient_pass: Callable[[], tuple[np.ndarray, np.ndarray]] | None = None
        self._make_csr = make_csr
        self.condition = condition
        self.used_code = used_code
        self.used_names = used_names
        self.fallback = fallback
        self._matrices: dict[str, sp.csr_matrix] = {}

    def _gradient_weights(self) -> tuple[np.ndarray, np.ndarray]:
        if self._pair_dx is None or self._pair_dy is None:  # assembled for the Laplacian only: the gradient's pass now, once
            assert self._gradient_pass is not None  # set by assemble(gradient=False)
            gx, gy = self._gradient_pass()
            for name, w in (("dx", gx), ("dy", gy)):
                if not np.all(np.isfinite(w)):  # pragma: no cover - guarded by the fallbacks
                    raise FloatingPointError(f"operator {name} has non-finite weights; please report this cloud")
            self._pair_dx, self._pair_dy, self._gradient_pass = gx, gy, None
            return gx, gy
        return self._pair_dx, self._pair_dy

    @property
    def pair_dx(self) -> np.ndarray:
        return self._gradient_weights()[0]

    @property
    def pair_dy(self) -> np.ndarray:
        return self._gradient_weights()[1]

    def _matrix(self, name: str) -> sp.csr_matrix:
        if name not in self._matrices:
            self._matrices[name] = self._make_csr(getattr(self, "pair_" + name))
        return self._matrices[name]

    @property
    def dx(self) -> sp.csr_matrix:
        return self._matrix("dx")

    @property
    def dy(self) -> sp.csr_matrix:
        return self._matrix("dy")

    @property
    def lap(self) -> sp.csr_matrix:
        return self._matrix("lap")

    @property
    def scheme_used(self) -> np.ndarray:
        """(N,) name of the scheme that produced each particle's row."""
        return np.asarray(self.used_names)[self.used_code]


def _chain(scheme: Scheme) -> tuple:
    """Names of ``scheme`` and its fallbacks, in order."""
    names = [scheme.name]
    current = scheme
    while current.fallback is not None:
        current = get_scheme(current.fallback)
        names.append(current.name)
    return tuple(names)


def pair_kernel_data(
    kernel: Kernel, x: np.ndarray, y: np.ndarray, h: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Kernel data for padded offsets ``x``, ``y`` (n, K) of rows with smoothing lengths ``h`` (n,).

    Returns normalised ``(xi, W, dW, d2W, dw_over_r)`` as in :class:`LocalPairs` (h = 1 units):
    shapes (n, 2, K), (n, K), (n, 2, K), (n, 3, K), (n, K).
    """
    n, k = x.shape
    xi = np.empty((n, 2, k))
    inv_h = (1.0 / h)[:, None]
    X = np.multiply(x, inv_h, out=xi[:, 0])
    Y = np.multiply(y, inv_h, out=xi[:, 1])
    R = np.sqrt(X * X + Y * Y)
    w, q, t = kernel.radial_terms(R)
    a = kernel.alpha(2)
    q *= a  # alpha w'(R) / R, finite at R = 0
    t *= a
    w *= a
    dW = np.empty((n, 2, k))
    np.multiply(X, q, out=dW[:, 0])  # gradient of W(x_i - x_j) with respect to x_i: -q xi
    np.multiply(Y, q, out=dW[:, 1])
    np.negative(dW, out=dW)
    d2W = np.empty((n, 3, k))
    tx = t * X
    np.multiply(tx, X, out=d2W[:, 0])
    d2W[:, 0] += q
    np.multiply(tx, Y, out=d2W[:, 1])
    np.multiply(t * Y, Y, out=d2W[:, 2])
    d2W[:, 2] += q
    return xi, w, dW, d2W, q


#: A row whose Laplacian weights get the Laplacian of ``x^2/2``, ``xy`` or ``y^2/2`` (in its own
#: tangent-plane coordinates; exact: 1, 0, 1) wrong by more than this is reported as inconsistent.
#: Measured (rows above 3, and the largest defect): cspm on uniformly random sphere points 21 of
#: 5,000 (48), 16 of 20,000 (62; Laplacian error 0.25), 118 of 100,000 (7,090; error 1.5); on
#: variable-density (repelled) points 5 of 20,000 (5.3); none on Poisson-disk spheres (0.57),
#: tori (0.72), the sausage (0.27) or a jittered square's boundary rows (1.36). msph, ncsph and
#: msph3/4/5 are exact on quadratics (1e-13). The standard scheme's rows stay below 1.4 in these
#: cases, but most are moderately wrong on irregular points (median 0.22-0.38 on random spheres, where
#: its Laplacian error is 5.4): it is consistent only on near-uniform clouds (not warned about: it is
#: chosen for its stability, and ``quadratic_defect`` has the values).
DEFECT_TOL = 3.0


def quadratic_defect(xy: np.ndarray, lap: np.ndarray, indptr: np.ndarray) -> np.ndarray:
    """Per row, the largest error of the Laplacian weights ``lap`` (P,) on the quadratics ``x^2/2``,
    ``xy``, ``y^2/2`` of the pair offsets ``xy`` (P, 2) (exact: 1, 0, 1); rows ``indptr`` (n + 1,).

    Dimensionless (weights scale as ``1 / h^2``, offsets as ``h``): a consistency test of any
    scheme's rows that sees what a condition number does not (the CSPM Laplacian on uniformly
    random points: well-conditioned systems, second derivatives built on first derivatives that
    are only first-order accurate there).

    Examples
    --------
    >>> import numpy as np
    >>> xy = np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    >>> quadratic_defect(xy, np.array([-4.0, 1.0, 1.0, 1.0, 1.0]), np.array([0, 5])).tolist()  # 5-point stencil
    [0.0]
    """
    counts = np.diff(indptr)
    out = np.zeros(counts.size)
    full = np.flatnonzero(counts > 0)
    if not full.size:
        return out
    starts = indptr[:-1][full] - indptr[0]
    x, y = xy[:, 0], xy[:, 1]
    for moment, exact in ((0.5 * x * x, 1.0), (x * y, 0.0), (0.5 * y * y, 1.0)):
            out[full] = np.maximum(out[full], np.abs(np.add.reduceat(lap * moment, starts) - exact))
    return out


class ColumnAreas:
    """Area elements looked up per pair (``dV[columns[p]]``) instead of a stored (P,) array."""

    def __init__(self, dV: np.ndarray, columns: np.ndarray) -> None:
        self.dV, self.columns = dV, columns

    def take(self, p0: int, p1: int) -> np.ndarray:
        return self.dV[self.columns[p0:p1]]


def _dv_at(dV_pairs, pos):
    if isinstance(dV_pairs, ColumnAreas):
        return dV_pairs.dV[dV_pairs.columns[pos]]
    return dV_pairs[pos]


def _dv_range(dV_pairs, p0: int, p1: int) -> np.ndarray:
    if isinstance(dV_pairs, ColumnAreas):
        return dV_pairs.take(p0, p1)
    return dV_pairs[p0:p1]


def _local_pairs(rows, nb, xy, dV_pairs, kernel) -> tuple[LocalPairs, np.ndarray]:
    """Padded pair data of ``rows`` (a slice or an index array), and the pair index of every slot
    (0 in unused slots, which get R = support, i.e. a zero kernel, and dV = 0)."""
    starts = nb.indptr[:-1][rows]
    counts = nb.indptr[1:][rows] - starts
    k = int(counts.max())
    slot = np.arange(k)
    valid = slot[None, :] < counts[:, None]
    pos = np.where(valid, starts[:, None] + slot[None, :], 0)
    h = nb.h[rows]
    far = kernel.support * h[:, None]  # outside the support: every kernel factor vanishes
    xp = offsets_at(xy, pos)
    x = np.where(valid, xp[..., 0], far)
    y = np.where(valid, xp[..., 1], 0.0)
    xi, W, dW, d2W, q = pair_kernel_data(kernel, x, y, h)
    xi[:, 0][~valid] = 0.0
    dV = np.where(valid, _dv_at(dV_pairs, pos), 0.0) / (h * h)[:, None]
    return LocalPairs(valid=valid, xy=xi, dV=dV, W=W, dW=dW, d2W=d2W, dw_over_r=q), pos


def _weights_with_fallback(pairs: LocalPairs, scheme: Scheme, max_condition: float):
    """Weights of ``scheme`` with failed particles recomputed down its fallback chain.

    Returns ``grad, lap, condition, used`` with ``used`` (n,) int8 the position
    in the chain (:func:`_chain`) of the scheme each particle got.
    """
    n = pairs.n
    counts = pairs.counts
    res = scheme.weights(pairs, max_condition)
    grad, lap = res.grad, res.lap
    failed = res.failed | (counts < scheme.min_neighbors)
    used = np.zeros(n, dtype=np.int8)
    todo = np.flatnonzero(failed)
    current = scheme
    level = 0
    while todo.size and current.fallback is not None:
        current = get_scheme(current.fallback)
        level += 1
        r = current.weights(pairs.take(todo), max_condition)
        sub_failed = r.failed | (counts[todo] < current.min_neighbors)
        ok = todo[~sub_failed]
        grad[ok] = r.grad[~sub_failed]
        lap[ok] = r.lap[~sub_failed]
        used[ok] = level
        todo = todo[sub_failed]
    return grad, lap, res.condition, used


def assemble(
    nb: Neighborhood,
    xy: np.ndarray | PairOffsets,
    dV_pairs: np.ndarray | ColumnAreas,
    kernel: Kernel,
    scheme: Scheme,
    *,
    columns: np.ndarray | None = None,
    n_cols: int | None = None,
    max_condition: float = 1e8,
    workers: int = -1,
    gradient: bool = True,
) -> Assembled:
    """Build the derivative and Laplacian matrices of ``scheme``.

    Parameters
    ----------
    nb : Neighborhood
    xy : ndarray, shape (P, 2), or PairOffsets
        Pair offsets in the row particle's tangent plane (physical units), or their
        on-demand projection (:class:`manifold_sph.frames.PairOffsets`).
    dV_pairs : ndarray, shape (P,), or ColumnAreas
        Area element of the neighbour of every pair (or looked up per chunk).
    kernel : Kernel
    scheme : Scheme
    columns : ndarray, shape (P,), optional
        Matrix column of every pair (default ``nb.indices``; ghosts map to their owners).
    n_cols : int, optional
        Number of columns (default N).
    max_condition : float
        Local systems above this condition number fall back.
    workers : int
        Threads over row chunks (-1: :func:`manifold_sph.threads.get_num_threads`).
    gradient : bool
        Keep the derivative weights. Without, only the Laplacian's are kept (the local
        systems are the same; 16 bytes a pair less), and ``pair_dx``, ``pair_dy`` are
        computed by a second pass on first access (the same numbers).
    """
    n = nb.n_rows
    n_pairs = xy.shape[0]
    gx = np.empty(n_pairs) if gradient else None
    gy = np.empty(n_pairs) if gradient else None
    lp = np.empty(n_pairs)
    condition = np.empty(n)
    defect = np.empty(n)
    used = np.zeros(n, dtype=np.int8)

    def numpy_rows(rows):  # rows: a slice or indices; their pair slices are disjoint from other calls'
        pairs, pos = _local_pairs(rows, nb, xy, dV_pairs, kernel)
        grad, lap, cond, u = _weights_with_fallback(pairs, scheme, max_condition)
        valid = pairs.valid
        h = nb.h[rows][:, None]
        at = pos[valid]  # row-major: CSR pair order
        if gx is not None and gy is not None:  # gradient=True
            gx[at] = (grad[:, 0] / h)[valid]
            gy[at] = (grad[:, 1] / h)[valid]
        lp[at] = (lap / (h * h))[valid]
        condition[rows] = cond
        used[rows] = u
        x, y = pairs.xy[:, 0], pairs.xy[:, 1]  # units of h, as the weights: the defect is dimensionless
        defect[rows] = np.maximum(np.maximum(np.abs((lap * (0.5 * x * x)).sum(axis=1) - 1.0),
                                             np.abs((lap * (x * y)).sum(axis=1))),
                                  np.abs((lap * (0.5 * y * y)).sum(axis=1) - 1.0))

    compiled = _compiled_weights(scheme, kernel)
    if compiled is None:
        rows_per_chunk = CHUNK_ROWS if CHUNK_ROWS is not None else scheme.chunk_rows
        starts = range(0, n, rows_per_chunk)
        # numpy releases the GIL in the heavy parts
        run_chunks(lambda c: numpy_rows(slice(starts[c], min(starts[c] + rows_per_chunk, n))), len(starts), workers)
    else:
        rows_per_chunk = CHUNK_ROWS if CHUNK_ROWS is not None else COMPILED_CHUNK_ROWS
        failed = np.zeros(n, dtype=bool)
        alpha = kernel.alpha(2)
        starts = range(0, n, rows_per_chunk)

        def chunk(c):  # rows lo:hi on views shifted to start at 0: offsets projected per chunk, never whole
            lo, hi = starts[c], min(starts[c] + rows_per_chunk, n)
            p0, p1 = nb.indptr[lo], nb.indptr[hi]
            # Laplacian only: the derivative weights of the chunk into scratch, dropped
            cx, cy = (gx[p0:p1], gy[p0:p1]) if gx is not None and gy is not None else (np.empty(p1 - p0), np.empty(p1 - p0))
            xc = offsets_of_rows(xy, nb.indptr, lo, hi)
            compiled(0, hi - lo, nb.indptr[lo : hi + 1] - p0, xc, _dv_range(dV_pairs, p0, p1), nb.h[lo:hi], alpha,
                     max_condition, cx, cy, lp[p0:p1], condition[lo:hi], failed[lo:hi])
            defect[lo:hi] = quadratic_defect(xc, lp[p0:p1], nb.indptr[lo : hi + 1] - p0)

        run_chunks(chunk, len(starts), workers)
        # particles the first scheme fails on: the numpy schemes, down the fallback chain
        redo = np.flatnonzero(failed | (nb.counts < scheme.min_neighbors))
        step = CHUNK_ROWS if CHUNK_ROWS is not None else scheme.chunk_rows  # bounded padded arrays, as above
        run_chunks(lambda c: numpy_rows(redo[c * step : (c + 1) * step]), -(-redo.size // step), workers)
    shape = (n, n if n_cols is None else n_cols)
    make_csr = _PairCSR(nb, columns, shape)
    names = _chain(scheme)
    fallback = {names[c]: np.flatnonzero(used == c) for c in range(1, len(names)) if np.any(used == c)}
    out = Assembled(gx, gy, lp, make_csr, condition, used, names, fallback, defect)
    if not gradient:
        out._gradient_pass = _GradientPass(nb, xy, dV_pairs, kernel, scheme, columns, n_cols, max_condition, workers)
    return out


class _PairCSR:
    """Pair weights -> CSR matrix (module level, so that an assembled Surface pickles).

    Without ``columns`` the pairs are already in CSR order, one entry per (row, column), and each
    matrix gets its own copy of the index arrays (in-place scipy methods must not touch the
    neighbourhood); with ``columns`` (ghosts map to their owners) duplicates are summed."""

    def __init__(self, nb: Neighborhood, columns: np.ndarray | None, shape: tuple[int, int]) -> None:
        self.nb, self.columns, self.shape = nb, columns, shape

    def __call__(self, data: np.ndarray) -> sp.csr_matrix:
        if self.columns is None:
            m = sp.csr_matrix((data, self.nb.indices.copy(), self.nb.indptr.copy()), shape=self.shape, copy=False)
            m.has_sorted_indices = False  # neighbours are ordered by distance, not column
            return m
        return sp.coo_matrix((data, (self.nb.rows, self.columns)), shape=self.shape).tocsr()


class _GradientPass:
    """The derivative weights of a Laplacian-only assembly, by a second pass on first use."""

    def __init__(self, nb, xy, dV_pairs, kernel, scheme, columns, n_cols, max_condition, workers) -> None:
        self.args = (nb, xy, dV_pairs, kernel, scheme)
        self.kwargs = dict(columns=columns, n_cols=n_cols, max_condition=max_condition, workers=workers)

    def __call__(self) -> tuple[np.ndarray, np.ndarray]:
        again = assemble(*self.args, gradient=True, **self.kwargs)
        return again.pair_dx, again.pair_dy
