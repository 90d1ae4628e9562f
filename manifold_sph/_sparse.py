"""Sparse matrix-vector products on both cores.

scipy's CSR product runs on one thread (and releases the GIL), so a matrix
split once into row blocks multiplies on a thread per block. Used for the
operators' ``op(f)``, the area-element solve and explicit time stepping.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from .threads import get_num_threads, in_chunk, pool

__all__ = ["RowBlocks", "bicgstab_csr"]

#: Below this many stored entries one thread is faster than two (measured, 2 cores: 0.15 against
#: 0.24 ms at 270,000 entries, 0.60 against 0.50 ms at 1,080,000).
MIN_THREADED_NNZ = 600_000



def _nnz_bounds(A: sp.csr_matrix, n_blocks: int) -> list[int]:
    """Row bounds ``[0, ..., N]`` cutting ``A`` into ``n_blocks`` blocks of about equal stored entries."""
    cuts = np.searchsorted(A.indptr, np.linspace(0, A.nnz, n_blocks + 1)[1:-1])
    return [0, *[int(min(c, A.shape[0])) for c in cuts], A.shape[0]]


def _row_block(A: sp.csr_matrix, lo: int, hi: int) -> sp.csr_matrix:
    """Rows ``lo:hi`` of ``A`` sharing its data and index arrays (``A[lo:hi]`` copies them:
    0.5 s for a million rows)."""
    p0, p1 = int(A.indptr[lo]), int(A.indptr[hi])
    block = sp.csr_matrix(
        (A.data[p0:p1], A.indices[p0:p1], A.indptr[lo : hi + 1] - A.indptr[lo]), shape=(hi - lo, A.shape[1]), copy=False
    )
    block.has_sorted_indices = A.has_sorted_indices
    return block


class RowBlocks:
    """A CSR matrix split into row blocks, one per core, for threaded ``A @ x``.

    Parameters
    ----------
    A : scipy.sparse matrix, shape (N, M)
    n_blocks : int, optional
        Default: the number of cores (1 for matrices under ``MIN_THREADED_NNZ`` entries).

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> A = sp.random(500, 500, density=0.05, random_state=0, format="csr")
    >>> x = np.arange(500.0)
    >>> bool(np.allclose(RowBlocks(A, n_blocks=2) @ x, A @ x))
    True
    """

    def __init__(self, A: sp.spmatrix | sp.sparray | np.ndarray, n_blocks: int | None = None) -> None:
        A = sp.csr_matrix(A)
        self.shape = A.shape
        self.dtype = A.dtype
        if n_blocks is None:
            n_blocks = get_num_threads() if A.nnz >= MIN_THREADED_NNZ else 1
        n_blocks = max(1, min(int(n_blocks), A.shape[0]))
        self.bounds = _nnz_bounds(A, n_blocks)  # by stored entries, not rows: the threads get equal work
        self.blocks = [_row_block(A, lo, hi) for lo, hi in zip(self.bounds[:-1], self.bounds[1:])]

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        if len(self.blocks) == 1:
            return self.blocks[0] @ x
        if get_num_threads() == 1 or in_chunk():  # cut for more threads than are now allowed, or nested
            return np.concatenate([b @ x for b in self.blocks])
        out = np.empty((self.shape[0],) + x.shape[1:], dtype=np.result_type(self.dtype, x.dtype))

        def job(b):
            out[self.bounds[b] : self.bounds[b + 1]] = self.blocks[b] @ x

        futures = [pool(len(self.blocks) - 1).submit(job, b) for b in range(1, len(self.blocks))]
        job(0)  # the calling thread takes the first block
        for f in futures:
            f.result()
        return out

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """``A @ x``."""
        return self @ x


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    # einsum, not BLAS: OpenBLAS's threads spin for milliseconds after a threaded
    # ddot/dnrm2 and take a core from the row-block products that follow (measured:
    # a 1e6-row product 19 ms -> 34 ms after an np.dot)
    return float(np.einsum("i,i->", a, b))


def _scipy_bicgstab(A: sp.csr_matrix, b: np.ndarray, dinv: np.ndarray, x0: np.ndarray, rtol: float, maxiter: int):
    """scipy's BiCGSTAB with the preconditioner ``diag(dinv)`` and products on row blocks (threads):
    the fallback of :func:`bicgstab_csr` when the compiled kernels are off."""
    import scipy.sparse.linalg as spla

    blocks = RowBlocks(A)
    op = spla.LinearOperator(A.shape, matvec=lambda v: blocks @ np.ravel(v), dtype=np.float64)
    M = spla.LinearOperator(A.shape, matvec=lambda v: dinv * np.ravel(v), dtype=np.float64)
    x, info = spla.bicgstab(op, b, x0=np.array(x0, dtype=np.float64), rtol=rtol, atol=0.0, maxiter=max(int(maxiter), 1), M=M)
    return x, int(info)


#: Blocks of rows of the compiled BiCGSTAB: fixed by the matrix (not by the thread count), so
#: the inner products add the same partial sums in the same order on any number of threads.
_SOLVE_BLOCK_NNZ = 65536
_SOLVE_MAX_BLOCKS = 64


def _solve_blocks(A: sp.csr_matrix) -> np.ndarray:
    """Row bounds of about equal stored entries (at most ``_SOLVE_MAX_BLOCKS`` blocks)."""
    n_blocks = int(min(_SOLVE_MAX_BLOCKS, max(1, A.nnz // _SOLVE_BLOCK_NNZ)))
    return np.unique(_nnz_bounds(A, n_blocks)).astype(np.int64)


def bicgstab_csr(A: sp.csr_matrix, b: np.ndarray, dinv: np.ndarray, x0: np.ndarray, rtol: float, maxiter: int,
                 stall_window: int | None = None) -> tuple[np.ndarray, int]:
    """BiCGSTAB for ``A x = b`` with the preconditioner ``diag(dinv)``, each step one fused compiled pass on threads.

    scipy's iteration (right preconditioning by ``diag(dinv)``, stop when
    ``|r|_2 < rtol |b|_2``, scipy's breakdown tests); every vector update is fused
    with the matrix product or the inner products that follow it, so a step reads
    each vector once or twice instead of a dozen times. Falls back to
    ``scipy.sparse.linalg.bicgstab`` (products on row blocks) when the compiled kernels are off.

    Parameters
    ----------
    A : scipy.sparse.csr_matrix, shape (N, N)
    b, dinv, x0 : ndarray, shape (N,)
    rtol : float
    maxiter : int
    stall_window : int, optional
        Give up early (``info = maxiter``, not converged) when the smallest residual
        so far is not 10x below the smallest one ``stall_window`` iterations earlier:
        a stalled iteration (uniformly random clouds in the area solve) stops there
        instead of running to ``maxiter``.

    Returns
    -------
    x : ndarray, shape (N,)
    info : int
        0 converged; ``max(maxiter, 1)`` not converged; -10 or -11 a breakdown.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> A = (sp.diags([4.0, 5.0, 6.0]) + sp.eye(3, k=1)).tocsr()
    >>> x, info = bicgstab_csr(A, np.ones(3), 1.0 / A.diagonal(), np.zeros(3), 1e-14, 50)
    >>> info, bool(np.allclose(A @ x, 1.0))
    (0, True)
    """
    from . import _jit

    if not _jit.ENABLED:
        return _scipy_bicgstab(sp.csr_matrix(A), b, dinv, x0, rtol, maxiter)
    A = sp.csr_matrix(A)
    n = A.shape[0]
    indptr, indices = A.indptr, A.indices
    data = np.ascontiguousarray(A.data, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    dinv = np.ascontiguousarray(dinv, dtype=np.float64)
    x = np.array(x0, dtype=np.float64)
    bounds = _solve_blocks(A)
    n_blocks = bounds.size - 1
    partial = np.zeros((n_blocks, 2))
    n_threads = min(get_num_threads(), n_blocks) if A.nnz >= MIN_THREADED_NNZ and not in_chunk() else 1
    cuts = [len(g) for g in np.array_split(np.arange(n_blocks), n_threads)]
    edges = np.concatenate([[0], np.cumsum(cuts)])  # thread k takes blocks edges[k]:edges[k + 1]
    workers = pool(n_threads - 1) if n_threads > 1 else None

    def run(kernel: Callable[..., object], *args):  # kernel(g0, g1, bounds, *args, partial) on every block; the sums in block order
        futures = [workers.submit(kernel, edges[k], edges[k + 1], bounds, *args, partial) for k in range(1, n_threads)] if workers else []
        kernel(edges[0], edges[1], bounds, *args, partial)
        for f in futures:
            f.result()
        return partial.sum(axis=0)

    r = np.empty(n)
    run(_jit.csr_matvec_dot, indptr, indices, data, x, r, b)
    np.subtract(b, r, out=r)
    rtilde = r.copy()
    p = np.empty(n)
    v = np.zeros(n)
    t = np.empty(n)
    phat = np.empty(n)
    shat = np.empty(n)
    atol = rtol * np.sqrt(float(np.einsum("i,i->", b, b)))
    tiny = np.finfo(np.float64).eps ** 2
    rr = float(np.einsum("i,i->", r, r))
    rho = float(np.einsum("i,i->", rtilde, r))
    rho_prev = alpha = omega = beta = 1.0
    best = np.full(max(int(maxiter), 1), np.inf)  # smallest residual norm up to each iteration
    for it in range(maxiter):
        if np.sqrt(rr) < atol:
            return x, 0
        best[it] = min(np.sqrt(rr), best[it - 1] if it else np.inf)
        if stall_window and it >= stall_window and best[it] > 0.1 * best[it - stall_window]:
            return x, max(int(maxiter), 1)  # stalled: reported as not converged
        if abs(rho) < tiny:
            return x, -10
        if it > 0:
            if abs(omega) < tiny:
                return x, -11
            beta = (rho / rho_prev) * (alpha / omega)
        run(_jit.bicgstab_direction, r, p, v, dinv, phat, beta, omega, it == 0)
        rv = run(_jit.csr_matvec_dot, indptr, indices, data, phat, v, rtilde)[0]
        if rv == 0.0:
            return x, -11
        alpha = rho / rv
        ss = run(_jit.bicgstab_half, r, v, alpha, dinv, shat)[0]  # r now holds s
        if np.sqrt(ss) < atol:
            x += alpha * phat
            return x, 0
        tt, ts = run(_jit.csr_matvec_dots2, indptr, indices, data, shat, t, r)
        omega = ts / tt if tt > 0.0 else 0.0
        rho_prev = rho
        rr, rho = run(_jit.bicgstab_step, x, phat, shat, alpha, omega, r, t, rtilde)
    return x, max(int(maxiter), 1)  # > 0: not converged (also for maxiter = 0)
