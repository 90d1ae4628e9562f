"""Sparse matrix-vector products on both cores.

scipy's CSR product runs on one thread (and releases the GIL), so a matrix
split once into row blocks multiplies on a thread per block. Used for the
operators' ``op(f)``, the area-element solve and explicit time stepping.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp

from .threads import get_num_threads

__all__ = ["RowBlocks"]

#: Below this many stored entries one thread is faster than two.
MIN_THREADED_NNZ = 200_000

_POOL: ThreadPoolExecutor | None = None


def _pool() -> ThreadPoolExecutor:
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=os.cpu_count() or 1, thread_name_prefix="manifold_sph")
    return _POOL


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

    def __init__(self, A, n_blocks: int | None = None):
        A = sp.csr_matrix(A)
        self.shape = A.shape
        self.dtype = A.dtype
        if n_blocks is None:
            n_blocks = get_num_threads() if A.nnz >= MIN_THREADED_NNZ else 1
        n_blocks = max(1, min(int(n_blocks), A.shape[0]))
        # split by stored entries, not rows, so the threads get equal work
        cuts = np.searchsorted(A.indptr, np.linspace(0, A.nnz, n_blocks + 1)[1:-1])
        self.bounds = [0, *[int(c) for c in cuts], A.shape[0]]
        self.blocks = [A[lo:hi] for lo, hi in zip(self.bounds[:-1], self.bounds[1:])]

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        if len(self.blocks) == 1:
            return self.blocks[0] @ x
        if get_num_threads() == 1:  # the blocks were cut for more threads than are now allowed
            return np.concatenate([b @ x for b in self.blocks])
        out = np.empty((self.shape[0],) + x.shape[1:], dtype=np.result_type(self.dtype, x.dtype))

        def job(b):
            out[self.bounds[b] : self.bounds[b + 1]] = self.blocks[b] @ x

        list(_pool().map(job, range(len(self.blocks))))
        return out

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """``A @ x``."""
        return self @ x
