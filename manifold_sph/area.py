"""Area elements dV (docs/method.md section 3).

- ``"geometric"``: ``|S| / N`` when the surface area is known;
- ``"numerical"``: solve ``sum_j W_ij dV_j = 1`` (sparse, not symmetric); some
  elements may come out negative, and how many is reported;
- ``"shepard"``: ``dV_i = 1 / sum_j W_ij``, always positive.

Mirroring (ghost strips for rectangles) is a neighbourhood matter: ghosts carry
their owner's column, see :class:`manifold_sph.Domain2D`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from . import _jit
from ._sparse import MIN_THREADED_NNZ, RowBlocks, bicgstab_csr
from ._validation import check_positive
from .allocator import release_freed_memory
from .diagnostics import note
from .frames import PairOffsets, offsets_of_rows
from .kernels import Kernel, QuinticSpline
from .neighbors import Neighborhood
from .threads import get_num_threads, in_chunk, pool, run_chunks

__all__ = ["AREA_METHODS", "AreaElements", "area_elements", "check_area_method", "kernel_matrix", "kernel_values"]

AREA_METHODS = ("geometric", "numerical", "shepard")


def kernel_values(nb: Neighborhood, xy: np.ndarray | PairOffsets, kernel: Kernel) -> np.ndarray:
    """Kernel values ``W_ij = W_{h_i}(x_ij)`` (d = 2) of the neighbour pairs, shape (P,), in row chunks on threads.

    ``xy`` is the (P, 2) array of pair offsets or a :class:`manifold_sph.frames.PairOffsets`
    (projected chunk by chunk, never whole).
    """
    return _kernel_values(nb, xy, kernel)[0]


def _kernel_values(nb, xy, kernel, near_columns=None):
    """:func:`kernel_values`, and with ``near_columns`` (the (P,) columns, or None for ``nb.indices``:
    pass ``False`` for neither) also :func:`near_duplicate_pairs` from the same projected offsets
    (one projection pass instead of two): ``(vals, close or None)``."""
    n = nb.n_rows
    vals = np.empty(xy.shape[0])
    a = kernel.alpha(2)
    starts = list(range(0, n, _ROWS))
    compiled = _jit.ENABLED and type(kernel) is QuinticSpline
    near = near_columns is not False
    cols = (nb.indices if near_columns is None else np.asarray(near_columns)) if near else None
    found: list = [None] * len(starts)  # each chunk's near-duplicate pair positions

    def chunk(c):  # rows lo:hi, disjoint slices of ``vals``
        lo = starts[c]
        hi = min(lo + _ROWS, n)
        p0, p1 = nb.indptr[lo], nb.indptr[hi]
        xc = offsets_of_rows(xy, nb.indptr, lo, hi)
        if near:
            found[c] = _near_in_rows(nb, xc, cols, lo, hi, MERGE_TOL)
        if compiled:
            _jit.quintic_values(0, hi - lo, nb.indptr[lo : hi + 1] - p0, xc, nb.h[lo:hi], a, vals[p0:p1])
            return
        h = np.repeat(nb.h[lo:hi], np.diff(nb.indptr[lo : hi + 1]))
        x, y = xc[:, 0], xc[:, 1]
        vals[p0:p1] = kernel.profile(np.sqrt(x * x + y * y) / h) * (a / (h * h))

    run_chunks(chunk, len(starts))
    if not near:
        return vals, None
    return vals, (np.concatenate(found) if found else np.zeros(0, dtype=np.int64))


def _near_in_rows(nb, xc, cols, lo, hi, tol):
    """Positions of the pairs ``i != j`` of rows ``lo:hi`` (offsets ``xc``) closer than ``tol min(h_i, h_j)``.

    Both smoothing lengths: a particle whose support was widened (a stray point far from the
    cloud) has a large ``h_i``, and its neighbours, each other's far apart on their own scale,
    are not near-duplicates of one another through it."""
    p0, p1 = nb.indptr[lo], nb.indptr[hi]
    if _jit.ENABLED:
        close = np.empty(p1 - p0, dtype=np.uint8)
        _jit.near_pairs(0, hi - lo, nb.indptr[lo : hi + 1] - p0, xc, nb.h[lo:hi], cols[p0:p1], lo, tol, close)
        found = np.flatnonzero(close)
    else:
        rows = np.repeat(np.arange(lo, hi), np.diff(nb.indptr[lo : hi + 1]))
        found = np.flatnonzero((np.hypot(xc[:, 0], xc[:, 1]) < tol * nb.h[rows]) & (cols[p0:p1] != rows))
    if found.size:  # few: the column's own scale checked here
        found = found[np.hypot(xc[found, 0], xc[found, 1]) < tol * nb.h[cols[p0 + found]]]
    return p0 + found


def near_duplicate_pairs(
    nb: Neighborhood, xy: np.ndarray | PairOffsets, columns: np.ndarray | None = None, tol: float | None = None
) -> np.ndarray:
    """Positions of the pairs ``i != j`` closer than ``tol min(h_i, h_j)`` (default :data:`MERGE_TOL`), in row chunks."""
    tol = MERGE_TOL if tol is None else check_positive("tol", tol)
    n = nb.n_rows
    cols = nb.indices if columns is None else np.asarray(columns)
    found = []
    for lo in range(0, n, _ROWS):
        hi = min(lo + _ROWS, n)
        found.append(_near_in_rows(nb, offsets_of_rows(xy, nb.indptr, lo, hi), cols, lo, hi, tol))
    return np.concatenate(found) if found else np.zeros(0, dtype=np.int64)


def kernel_matrix(
    nb: Neighborhood,
    xy: np.ndarray | PairOffsets,
    kernel: Kernel,
    columns: np.ndarray | None = None,
    n_cols: int | None = None,
    *,
    _share: bool = False,
    _near: list | None = None,
) -> sp.csr_matrix:
    """Sparse matrix of kernel values ``W_ij = W_{h_i}(x_ij)`` (d = 2) on the neighbour pairs.

    ``columns`` (P,) maps pairs to matrix columns (ghosts to their owners; duplicates are summed).
    ``_near`` (internal): a list that receives :func:`near_duplicate_pairs`, found in the same pass.
    """
    vals, close = _kernel_values(nb, xy, kernel, columns if _near is not None else False)
    if _near is not None:
        _near.append(close)
    n = nb.n_rows
    shape = (n, n if n_cols is None else n_cols)
    if columns is None:  # ``_share``: the matrix may use the neighbourhood's index arrays (internal use)
        return sp.csr_matrix((vals, nb.indices, nb.indptr), shape=shape, copy=not _share)
    return sp.coo_matrix((vals, (nb.rows, columns)), shape=shape).tocsr()


#: Rows per chunk of :func:`kernel_matrix`.
_ROWS = 8192


@dataclass(frozen=True)
class AreaElements:
    """Area elements and what their computation found.

    Attributes
    ----------
    dV : ndarray, shape (N,)
    method : str
    n_negative : int
        Number of negative elements (only the numerical method produces them).
    residual : float
        Max |sum_j W_ij dV_j - 1| (the numerical system's residual; the
        partition-of-unity defect for the other methods).
    n_merged : int
        Particles that were near-duplicates of another (closer than
        :data:`MERGE_TOL` times ``h``): the numerical system was solved with each
        such group merged into one unknown, whose element the group then shares.
    fell_back : bool
        The numerical solve did not converge within its iteration budget and the
        Shepard elements were used instead (a RuntimeWarning says so).
    """

    dV: np.ndarray
    method: str
    n_negative: int
    residual: float
    n_merged: int = 0
    fell_back: bool = False

    @property
    def total(self) -> float:
        """Sum of the elements: an estimate of the area of the domain."""
        return float(self.dV.sum())


def check_area_method(method: str, total_area: float | None = None) -> None:
    """Raise ValueError for an unknown method, or ``"geometric"`` without a positive total area."""
    if method not in AREA_METHODS:
        raise ValueError(f"area must be one of {list(AREA_METHODS)}, got {method!r}")
    if method == "geometric" and (total_area is None or not np.isfinite(total_area) or total_area <= 0):
        raise ValueError(
            f"area='geometric' needs the total surface area (total_area > 0), got {total_area!r}; "
            "use area='numerical' or 'shepard' for clouds of unknown area"
        )


def area_elements(
    method: str,
    nb: Neighborhood,
    xy: np.ndarray | PairOffsets,
    kernel: Kernel,
    *,
    total_area: float | None = None,
    columns: np.ndarray | None = None,
) -> AreaElements:
    """Area element of every particle.

    Parameters
    ----------
    method : {"geometric", "numerical", "shepard"}
    nb : Neighborhood
    xy : ndarray, shape (P, 2), or PairOffsets
        Pair offsets in the tangent planes (or their on-demand projection).
    kernel : Kernel
    total_area : float, optional
        Required by ``"geometric"``.
    columns : ndarray, shape (P,), optional
        Owner column of every pair (ghosts of a mirrored domain).
    """
    n = nb.n_rows
    check_area_method(method, total_area)
    near: list[np.ndarray] = []  # the near-duplicate pairs found in the kernel values' pass ("numerical" only)
    A = kernel_matrix(nb, xy, kernel, columns=columns, n_cols=n, _share=True,  # A never leaves this function
                      _near=near if method == "numerical" else None)
    if method == "geometric":
        assert total_area is not None  # check_area_method refuses "geometric" without it
        dV = np.full(n, float(total_area) / n)
    elif method == "shepard":
        dV = 1.0 / _csr_row_sums(A)
    else:
        return _numerical(A, nb, xy, columns, close=near[0])
    residual = float(np.abs(_product(A, dV) - 1.0).max())
    return AreaElements(dV=dV, method=method, n_negative=int((dV < 0).sum()), residual=residual)


class _Merged:
    """The kernel system of merged near-duplicates without a copy: ``B = A[rep]`` with each column
    ``j`` moved to ``label[j]`` (shape (len(rep), len(rep))), read through the two maps. Its products and
    row sums are those of the copied matrix, bit for bit (same entries, same order in every row)."""

    def __init__(self, A: sp.csr_matrix, rep: np.ndarray, label: np.ndarray) -> None:
        self.A, self.rep, self.label = A, np.asarray(rep, dtype=np.int64), np.asarray(label, dtype=np.int64)
        self.shape = (self.rep.size, self.rep.size)

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        return _product(self.A, x[self.label])[self.rep]

    def row_sums(self) -> np.ndarray:
        return _csr_row_sums(self.A)[self.rep]

    def csr(self) -> sp.csr_matrix:
        """The merged matrix copied (the direct solve and the fallback iteration)."""
        B = self.A[self.rep]
        np.take(self.label.astype(B.indices.dtype), B.indices, out=B.indices)
        B = sp.csr_matrix((B.data, B.indices, B.indptr), shape=self.shape, copy=False)
        B.has_sorted_indices = False
        return B


def _csr_row_sums(A: sp.csr_matrix) -> np.ndarray:
    """``np.asarray(A.sum(axis=1)).ravel()`` (scipy: ``np.add.reduceat`` over the rows), the same numbers,
    in row blocks on threads (scipy's runs on one: 10 ms at 3.5 million entries)."""
    n = A.shape[0]
    indptr = A.indptr
    if A.nnz < MIN_THREADED_NNZ or n == 0 or np.any(indptr[1:] == indptr[:-1]):  # empty rows: scipy's own
        return np.asarray(A.sum(axis=1)).ravel()
    out = np.empty(n, dtype=np.result_type(A.dtype, np.float64))
    starts = list(range(0, n, _SUM_ROWS))

    def chunk(c):
        lo, hi = starts[c], min(starts[c] + _SUM_ROWS, n)
        p0, p1 = int(indptr[lo]), int(indptr[hi])
        out[lo:hi] = np.add.reduceat(A.data[p0:p1], indptr[lo:hi] - p0)

    run_chunks(chunk, len(starts))
    return out


#: Rows per chunk of :func:`_csr_row_sums`.
_SUM_ROWS = 16384


def _product(A, x: np.ndarray) -> np.ndarray:
    """``A @ x`` (a CSR matrix or a merged system), scipy's product on row blocks on threads: the same
    numbers (:class:`manifold_sph._sparse.RowBlocks`)."""
    if isinstance(A, _Merged) or A.nnz < MIN_THREADED_NNZ:
        return A @ x
    return RowBlocks(A) @ x


def _row_sums(A) -> np.ndarray:
    return A.row_sums() if isinstance(A, _Merged) else _csr_row_sums(A)


def _as_csr(A) -> sp.csr_matrix:
    return A.csr() if isinstance(A, _Merged) else A


def _numerical(A: sp.csr_matrix, nb: Neighborhood, xy: np.ndarray | PairOffsets, columns: np.ndarray | None,
               close: np.ndarray | None = None) -> AreaElements:
    """Solve ``A dV = 1``, near-duplicates merged into one unknown; Shepard if the solve fails.
    ``close``: :func:`near_duplicate_pairs` when already found."""
    n = A.shape[0]
    cols = nb.indices if columns is None else np.asarray(columns)
    if close is None:
        close = near_duplicate_pairs(nb, xy, columns)
    n_merged = 0
    if close.size:  # near-duplicates make the system (nearly) singular: one unknown per group
        from scipy.sparse.csgraph import connected_components

        rows = np.searchsorted(nb.indptr, close, side="right") - 1
        G = sp.coo_matrix((np.ones(close.size), (rows, cols[close])), shape=(n, n))
        ncl, label = connected_components(G, directed=False)
        size = np.bincount(label, minlength=ncl)
        rep = np.full(ncl, n)
        np.minimum.at(rep, label, np.arange(n))  # the first particle of each group stands for it
        # the merged system: the representatives' rows, each column moved to its group's unknown (entries
        # of one group in a row are left unsummed: every solver step sums them; a sparse product did
        # the same at 13x the cost of the iteration on a million random points). Not copied: the solver
        # reads A's entries through the row and column maps (a copy would take 12 bytes an entry, 320 MB per
        # million random points, at the build's peak)
        B = _Merged(A, rep, label)
        key = _sweep_key(xy)
        order = None if key is None else np.argsort(key[rep], kind="stable")
        dVc, _, budget = _solve_partition_of_unity(B, order=order)
        del B
        dV = None if dVc is None else dVc[label] / size[label]
        n_merged = n - ncl
        groups = int((size > 1).sum())
        note(
            "merged", f"{n_merged + groups} near-duplicate point(s) in {groups} group(s) share their area elements",
            detail=f"They are closer than {MERGE_TOL:g} h to each other; each group was solved as one point in the "
            "numerical area solve. Remove duplicate points if they are not intended.",
            count=n_merged + groups,
        )
    else:
        key = _sweep_key(xy)
        order = None if key is None else np.argsort(key, kind="stable")
        shepard: dict = {}  # A's entries may be released by the solver (it keeps a copy): not used after this
        dV, residual, budget = _solve_partition_of_unity(A, order=order, shepard=shepard)  # the residual of A itself
        if A.data.size < A.nnz:
            A = None
    if dV is None or not np.all(np.isfinite(dV)):
        fell_back = True
        note(
            "area", "the area elements are the simpler Shepard ones (the numerical area solve did not converge)",
            detail=f"The kernel system sum_j W_ij dV_j = 1 was not solved within {budget} BiCGSTAB iterations ({n} "
            f"particles{', too many for a direct solve' if n > LU_MAX_ROWS else ''}; an irregular cloud) or is "
            "singular. Pass area='shepard' to choose them directly.",
        )
        dV = 1.0 / _csr_row_sums(A) if A is not None else shepard["dV"]
    else:
        fell_back = False
    if A is None:  # released: the solver measured the Shepard elements' residual (a converged one is in hand)
        residual = shepard["residual"] if fell_back else residual
    elif fell_back or close.size:  # merged groups: the residual of the full system
        residual = float(np.abs(_product(A, dV) - 1.0).max())
    release_freed_memory(n)  # the solver's copy of the matrix and its vectors, before the assembly's peak
    return AreaElements(dV=dV, method="numerical", n_negative=int((dV < 0).sum()), residual=residual,
                        n_merged=n_merged, fell_back=fell_back)


#: Near-duplicate particles (closer than this times h) are merged in the numerical area solve.
MERGE_TOL = 1e-2

#: BiCGSTAB iterations of the Shepard-preconditioned area solve (the compiled kernels off, or a
#: non-positive diagonal; :data:`SSOR_MAXITER` otherwise), about the cost of a Shepard build. Measured to
#: 1e-15: Fibonacci sphere (32000) 60, sausage 70, torus (19200) and Poisson-disk sphere (20000) 90,
#: Poisson-disk square (4000) 100. Uniformly random clouds stall near 1e-4 and then fall back to a
#: direct solve (small clouds) or the Shepard elements.
NUMERICAL_MAXITER = 150

#: The area solve gives up when 30 iterations did not cut the smallest residual 10x. Converging
#: clouds gain 10^4 to 10^7 in 30 iterations (60-100 iterations to 1e-15, above); uniformly random
#: ones stall near 1e-4 and now stop there instead of after all 150 iterations.
STALL_WINDOW = 30

#: Above this many particles a failed iterative area solve is not retried with a sparse LU, and
#: ``area='numerical'`` falls back to Shepard instead, so that the build stays within about twice
#: a Shepard build. Measured on uniformly random sphere points (where the iteration stalls near
#: 1e-4 and the exact solution has 25 % negative elements): LU 0.41 s at N = 8000, 1.95 s at
#: 20000, 4.8 s at 32000, ~60 s at 131072, against 0.2-0.5 s for a whole Shepard build.
LU_MAX_ROWS = 10_000


def _solve_partition_of_unity(A: sp.csr_matrix | _Merged, rtol: float = 1e-15, order: np.ndarray | None = None,
                              shepard: dict | None = None) -> tuple[np.ndarray | None, float, int]:
    """Solve ``A dV = 1``: BiCGSTAB started from the Shepard elements, to a relative residual of
    ``rtol``, preconditioned by block SSOR (:func:`bicgstab_ssor`; the Shepard (row-sum) one when
    the compiled kernels are off or a diagonal entry is not positive); sparse LU if the iteration
    does not converge. Returns ``(dV, max |A dV - 1|, iteration budget of the solver used)``, or
    ``(None, inf, budget)``.
    Round-off level (1e-15) keeps the operators
    invariant under rotation, translation and scaling to ~1e-11: at 1e-12 the
    elements' residual, amplified by ill-conditioned boundary systems (cond ~3e4),
    showed as 2e-8 differences (measured, planar ncsph), for ~25 % fewer iterations.

    ``shepard`` (a dict; plain CSR systems of more than :data:`LU_MAX_ROWS` rows only): the
    solver may then release ``A.data`` once its split copy is built (``A`` is unusable after:
    the caller gives it up); the dict receives ``"dV"`` and ``"residual"``, the Shepard elements
    and their ``max |A dV - 1|``, for the fallback."""
    n = A.shape[0]
    ones = np.ones(n)
    rowsum = _row_sums(A)
    release = shepard is not None and not isinstance(A, _Merged) and n > LU_MAX_ROWS
    if shepard is not None:
        shepard["dV"] = 1.0 / rowsum
    budget = SSOR_MAXITER if _jit.ENABLED else NUMERICAL_MAXITER
    if np.all(rowsum > 0):
        dinv = 1.0 / rowsum
        info = -12
        if _jit.ENABLED:  # block SSOR: 3-4x fewer iterations than the Shepard (Jacobi) preconditioner, same cost each
            budget = SSOR_MAXITER
            found: dict = {}
            dV, info = bicgstab_ssor(A, ones, dinv, rtol=rtol, maxiter=SSOR_MAXITER, stall_window=SSOR_STALL_WINDOW,
                                     order=order, _found=found, _release=release)
            if shepard is not None and "x0_residual" in found:  # A's entries released: the Shepard residual measured by the solver
                shepard["residual"] = found["x0_residual"]
        if info == -12:
            budget = NUMERICAL_MAXITER
            found = {}
            dV, info = bicgstab_csr(_as_csr(A), ones, dinv, dinv, rtol=rtol,  # fused, threaded passes
                                    maxiter=NUMERICAL_MAXITER, stall_window=STALL_WINDOW)
        if info == 0 and np.all(np.isfinite(dV)):
            # max |A dV - 1|, from the solver's last true residual when it measured it (the same numbers)
            residual = found["residual"] if "residual" in found else float(np.abs(_product(A, dV) - 1.0).max())
            if residual < 1e-9:
                return dV, residual, budget
    if n > LU_MAX_ROWS:  # a sparse LU of a kernel matrix this large takes minutes and gigabytes
        return None, np.inf, budget
    with np.errstate(all="ignore"):
        try:
            C = sp.csc_matrix(_as_csr(A))
            C.sum_duplicates()  # merged near-duplicates leave repeated entries
            dV = spla.spsolve(C, ones)
        except RuntimeError:  # exactly singular
            return None, np.inf, budget
        return dV, float(np.abs(A @ dV - 1.0).max()), budget


#: Row blocks of the block-SSOR preconditioner: a fixed number (not the thread count, so the
#: result does not depend on it), each thread taking a run of blocks. Blocks cut the couplings
#: between them out of the preconditioner: on a Fibonacci sphere (131072 points) one block
#: needs 12 iterations to 1e-15, two 14, eight 15-17, against 48 with the Shepard (Jacobi) one.
SSOR_BLOCKS = 4

#: Fewest rows per SSOR block (small systems use fewer blocks).
SSOR_MIN_ROWS = 16384

#: Iteration budget and stall window of the SSOR-preconditioned solve. An iteration costs about
#: one Jacobi iteration (each entry read once per operator application), and converging
#: clouds gain 10^2-10^4 per 10 iterations (measured: Fibonacci sphere 10^-11 in 12
#: iterations); uniformly random clouds stall near 1e-4 as with Jacobi and stop after ~13.
SSOR_MAXITER = 60
SSOR_STALL_WINDOW = 10


#: The block-SSOR split stores its columns as int16 offsets from their row when none is farther than
#: this (the matrix's bandwidth in the sweep order: about 10 sqrt(N) on a Fibonacci sphere), else int32.
#: Measured at N = 131072 (Fibonacci, one thread, 16 paired runs): the solve 5 % faster than with int32,
#: and 2 bytes an entry less memory.
SSOR_NARROW_WIDTH = int(np.iinfo(np.int16).max)


def _sweep_key(xy) -> np.ndarray | None:
    """The sweep order of :func:`bicgstab_ssor` as a sort key: the particles' coordinate along the axis
    of the cloud's largest extent; None (their own order) when they are already sorted along an axis
    (Fibonacci spheres, grids) or the pair offsets do not carry the points.

    Measured, iterations to 1e-15 (order given / sorted): Fibonacci sphere of 32000 points 14 / 14
    (sorted along z, its own order; 17 along x), the same points shuffled 28 / 14, Poisson-disk
    sphere (20000) 36 / 28, torus (19200) 35 / 29. Sorting by Morton or lexicographic cell order
    did worse (21-38)."""
    pts = getattr(xy, "points", None)
    if pts is None or pts.ndim != 2 or pts.shape[0] < 2:
        return None
    step = np.diff(pts, axis=0)
    if np.any(np.all(step >= 0, axis=0) | np.all(step <= 0, axis=0)):
        return None
    del step
    axis = int(np.argmax(pts.max(axis=0) - pts.min(axis=0)))
    return pts[:, axis]


def _ssor_bounds(n: int) -> np.ndarray:
    k = int(max(1, min(SSOR_BLOCKS, n // SSOR_MIN_ROWS)))
    return np.linspace(0, n, k + 1).round().astype(np.int64)


def bicgstab_ssor(A: sp.csr_matrix, b: np.ndarray, x0: np.ndarray, rtol: float, maxiter: int,
                  stall_window: int | None = None, order: np.ndarray | None = None,
                  _found: dict | None = None, _release: bool = False) -> tuple[np.ndarray, int]:
    """BiCGSTAB on ``(D + L)^-1 A (D + U)^-1 y = (D + L)^-1 b``, ``x = (D + U)^-1 y``: block-SSOR
    (symmetric Gauss-Seidel) preconditioning applied by Eisenstat's trick, each operator
    application two compiled passes that read every matrix entry once, blocks on threads.

    ``order`` (a permutation of the unknowns, default their own order) is the sweep order of
    the Gauss-Seidel passes and cuts the blocks: a spatially coherent order (:func:`_sweep_key`)
    needs half the iterations of a random one. The preconditioner holds a copy of ``A``'s entries
    split into the two triangles. Stops when the true residual ``|b - A x|_2 < rtol |b|_2`` (checked
    when the preconditioned one gets there), after ``maxiter`` iterations, or when the
    smallest preconditioned residual is not 10x below the one ``stall_window`` iterations
    earlier. Returns ``(x, info)`` as :func:`manifold_sph._sparse.bicgstab_csr`
    (``info = -12``: a diagonal entry is not positive, nothing solved). ``A`` may be a merged
    system (``_Merged``): read through its maps, never copied. ``_found`` (internal) receives
    ``"residual"``, ``max |b - A x|`` of the converged ``x``. Residuals are computed from the split
    copy (the same entries; sums in the sweep order). ``_release`` (internal): once the split is
    built, ``A.data`` is replaced by an empty array (the caller gives up ``A``: its entries are
    not needed twice at the build's peak, 8 bytes an entry); then ``_found`` also receives
    ``"x0_residual"``, ``max |b - A x0|``.
    """
    n = A.shape[0]
    rows_of, cols_of = (A.rep, A.label) if isinstance(A, _Merged) else (None, None)
    A_in = A
    A = A.A if rows_of is not None else A
    indptr = A.indptr
    bounds = _ssor_bounds(n)
    n_blocks = bounds.size - 1
    partial = np.zeros((n_blocks, 2))
    n_threads = min(get_num_threads(), n_blocks) if not in_chunk() else 1
    cuts = [len(g) for g in np.array_split(np.arange(n_blocks), n_threads)]
    edges = np.concatenate([[0], np.cumsum(cuts)])
    workers = pool(n_threads - 1) if n_threads > 1 else None

    def run(kernel: Callable[..., object], *args):  # kernel(g0, g1, bounds, *args, partial) on every block; the sums in block order
        partial[:] = 0.0
        futures = [workers.submit(kernel, edges[k], edges[k + 1], bounds, *args, partial) for k in range(1, n_threads)] if workers else []
        kernel(edges[0], edges[1], bounds, *args, partial)
        for f in futures:
            f.result()
        return partial.sum(axis=0)

    indices = A.indices
    data = np.ascontiguousarray(A.data, dtype=np.float64)
    sweep = np.arange(n, dtype=np.int64) if order is None else np.asarray(order, dtype=np.int64)
    iperm = np.empty(n, dtype=np.int64)
    iperm[sweep] = np.arange(n, dtype=np.int64)
    perm = sweep
    if rows_of is not None:  # A's rows and columns of the merged system, in the sweep order
        perm = rows_of[sweep]
        iperm = iperm[cols_of]
    n_upper = np.empty(n, dtype=np.int64)
    n_rest = np.empty(n, dtype=np.int64)
    diag = np.empty(n)
    if run(_jit.ssor_count, perm, iperm, indptr, indices, data, n_upper, n_rest, diag)[0] > 0:
        return np.array(x0, dtype=np.float64), -12
    # the split's columns are stored as offsets from their row: int16 when the (permuted) matrix is that narrow
    offset_dtype = np.int16 if partial[:, 1].max() <= SSOR_NARROW_WIDTH else np.int32
    ptr_u = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(n_upper, out=ptr_u[1:])
    ptr_r = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(n_rest, out=ptr_r[1:])
    del n_upper, n_rest
    idx_u = np.empty(int(ptr_u[-1]), dtype=offset_dtype)
    dat_u = np.empty(idx_u.size)
    idx_r = np.empty(int(ptr_r[-1]), dtype=offset_dtype)
    dat_r = np.empty(idx_r.size)
    run(_jit.ssor_fill, perm, iperm, indptr, indices, data, ptr_u, idx_u, dat_u, ptr_r, idx_r, dat_r)
    upper = (ptr_u, idx_u, dat_u, diag)
    rest = (ptr_r, idx_r, dat_r, diag)
    del iperm, perm, data, indices, indptr
    if _release and rows_of is None:
        A.data = np.empty(0, dtype=np.float64)  # the split holds every entry now
    del A, A_in
    b = np.ascontiguousarray(b, dtype=np.float64)[sweep]  # the solve runs on the permuted unknowns
    zeros = np.zeros(n)
    t = np.zeros(n)
    w = np.empty(n)

    def unprecondition(y, scatter=True):  # x = (D + U)^-1 y, in the caller's numbering (or the sweep order)
        x = np.empty(n)
        run(_jit.ssor_backward, *upper, 0, y, y, y, 0.0, 0.0, x)
        if not scatter:
            return x
        out = np.empty(n)
        out[sweep] = x
        return out

    def true_residual(xs):  # b - A x, x and the result in the sweep order; and max |b - A x|
        r = np.empty(n)
        run(_jit.ssor_residual, ptr_u, idx_u, dat_u, ptr_r, idx_r, dat_r, diag, b, xs, r)
        return r, float(partial[:, 1].max())

    bnorm = float(np.sqrt(np.einsum("i,i->", b, b)))
    bhat = np.empty(n)
    bhat_norm = float(np.sqrt(run(_jit.ssor_forward, *rest, b, zeros, w, bhat, b)[0]))
    del bhat
    x = np.array(x0, dtype=np.float64)[sweep]
    y = np.empty(n)
    run(_jit.ssor_upper_times, *upper, x, y)  # y0 = (D + U) x0
    r0, r0_max = true_residual(x)
    del x
    if _found is not None and _release:
        _found["x0_residual"] = r0_max
    r = np.empty(n)
    rr = run(_jit.ssor_forward, *rest, r0, zeros, w, r, r0)[0]  # r = (D + L)^-1 (b - A x0)
    del r0
    rtilde = r.copy()
    p = np.zeros(n)
    v = np.zeros(n)
    tv = np.empty(n)
    rho = float(np.einsum("i,i->", rtilde, r))
    target = rtol * bhat_norm
    atol = rtol * bnorm
    tiny = np.finfo(np.float64).eps ** 2
    rho_prev = alpha = omega = beta = 1.0
    best = np.full(max(int(maxiter), 1), np.inf)

    done = {}

    def converged(yv):  # the preconditioned residual is small: is the true one? (x kept when it is)
        nonlocal target
        xs = unprecondition(yv, scatter=False)
        r, r_max = true_residual(xs)
        if float(np.sqrt(np.einsum("i,i->", r, r))) < atol:
            done["x"] = np.empty(n)
            done["x"][sweep] = xs
            if _found is not None:
                _found["residual"] = r_max
            return True
        target *= 0.1  # not yet: go on
        return False

    for it in range(maxiter):
        if np.sqrt(rr) < target and converged(y):
            return done["x"], 0
        best[it] = min(np.sqrt(rr), best[it - 1] if it else np.inf)
        if stall_window and it >= stall_window and best[it] > 0.1 * best[it - stall_window]:
            return unprecondition(y), max(int(maxiter), 1)
        if abs(rho) < tiny:
            return unprecondition(y), -10
        if it > 0:
            if abs(omega) < tiny:
                return unprecondition(y), -11
            beta = (rho / rho_prev) * (alpha / omega)
        run(_jit.ssor_backward, *upper, 1, r, p, v, 0.0 if it == 0 else beta, omega, t)  # p updated, t = (D+U)^-1 p
        rv = run(_jit.ssor_forward, *rest, p, t, w, v, rtilde)[1]  # v = Ahat p
        if rv == 0.0:
            return unprecondition(y), -11
        alpha = rho / rv
        ss = run(_jit.ssor_backward, *upper, 2, r, p, v, alpha, 0.0, t)[0]  # r now holds s; t = (D+U)^-1 s
        if np.sqrt(ss) < target:
            y_half = y + alpha * p
            if converged(y_half):
                return done["x"], 0
            del y_half
        tt, ts = run(_jit.ssor_forward, *rest, r, t, w, tv, r)  # tv = Ahat s
        omega = ts / tt if tt > 0.0 else 0.0
        rho_prev = rho
        rr, rho = run(_jit.bicgstab_step, y, p, r, alpha, omega, r, tv, rtilde)
    return unprecondition(y), max(int(maxiter), 1)
