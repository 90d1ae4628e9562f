"""The scheme interface: local 2D pair data in, per-pair weights out.

Every scheme works on a chunk of particles in *normalised* units: offsets and
kernel derivatives are expressed with ``h_i = 1`` (offsets divided by ``h_i``,
area elements by ``h_i^2``). The assembly rescales first derivatives by
``1 / h_i`` and second derivatives by ``1 / h_i^2``. This keeps the local
systems dimensionless, so one condition-number threshold fits every ``h``.

A scheme returns weights ``w`` such that, for the row particle ``i``,
``d f / d x (i) = sum_p w_grad[p, 0] f[col[p]]`` over the pairs ``p`` of row ``i``
(the particle itself included), likewise for ``d/dy`` and the Laplacian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LocalPairs", "SchemeWeights", "Scheme", "batched_inverse", "difference_to_weights"]


@dataclass
class LocalPairs:
    """Pair data of a chunk of ``n`` row particles, in units of ``h_i``.

    Attributes
    ----------
    indptr : ndarray, shape (n + 1,)
        Chunk-local row offsets.
    row : ndarray, shape (P,)
        Chunk-local row of each pair.
    is_self : ndarray, shape (P,)
        True for the pair (i, i).
    xy : ndarray, shape (P, 2)
        Offsets ``x_j - x_i`` in the tangent plane of ``i``, divided by ``h_i``.
    dV : ndarray, shape (P,)
        Area element of ``j`` divided by ``h_i^2``.
    W : ndarray, shape (P,)
        Kernel ``W(x_i - x_j)`` with ``h = 1`` in ``d = 2``.
    dW : ndarray, shape (P, 2)
        Its gradient with respect to ``x_i``.
    d2W : ndarray, shape (P, 3)
        Its second derivatives ``(W_xx, W_xy, W_yy)``.
    dw_over_r : ndarray, shape (P,)
        ``alpha_2 w'(R) / R`` (the Taylor Laplacian's factor), finite at ``R = 0``.
    """

    indptr: np.ndarray
    row: np.ndarray
    is_self: np.ndarray
    xy: np.ndarray
    dV: np.ndarray
    W: np.ndarray
    dW: np.ndarray
    d2W: np.ndarray
    dw_over_r: np.ndarray

    @property
    def n(self) -> int:
        return self.indptr.size - 1

    def row_sum(self, values: np.ndarray) -> np.ndarray:
        """Sum per-pair values (P, ...) over each row -> (n, ...)."""
        return np.add.reduceat(values, self.indptr[:-1], axis=0)

    def _padding(self):
        """Positions of each row's pairs in an (n, K) grid (K the largest count) and its mask."""
        if getattr(self, "_pad", None) is None:
            counts = np.diff(self.indptr)
            k = int(counts.max()) if counts.size else 0
            slot = np.arange(k)
            valid = slot[None, :] < counts[:, None]
            pos = np.where(valid, self.indptr[:-1, None] + slot[None, :], 0)
            self._pad = (pos, valid)
        return self._pad

    def moments(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Per-particle moment matrices ``M[i, a, c] = sum_j rows[p, a] cols[p, c]``.

        ``rows`` (P, A) and ``cols`` (P, C) -> (n, A, C), as one batched matrix
        product over rows padded to the largest neighbour count.
        """
        pos, valid = self._padding()
        r = np.where(valid[:, :, None], rows[pos], 0.0)  # (n, K, A)
        c = cols[pos]  # (n, K, C); padded slots meet zero rows
        return np.matmul(r.transpose(0, 2, 1), c)


@dataclass
class SchemeWeights:
    """Per-pair weights of one scheme on a chunk, and the particles it failed on.

    Attributes
    ----------
    grad : ndarray, shape (P, 2)
        Weights of ``(d/dx, d/dy)`` on ``f_j``.
    lap : ndarray, shape (P,)
        Weights of the Laplacian on ``f_j``.
    failed : ndarray, shape (n,)
        Particles whose local system was singular or ill-conditioned; their
        weights are zero and the assembly recomputes them with the fallback.
    condition : ndarray, shape (n,)
        Largest 2-norm condition number of the local systems of each particle
        (1 for schemes without systems).
    """

    grad: np.ndarray
    lap: np.ndarray
    failed: np.ndarray
    condition: np.ndarray


class Scheme:
    """Base class. Subclasses set ``name``, ``fallback``, ``min_neighbors`` and implement ``weights``."""

    #: Registry name.
    name: str = ""
    #: Scheme used for particles this one fails on (None: never fails).
    fallback: str | None = None
    #: Fewest particles in a neighbourhood (itself included) the scheme needs.
    min_neighbors: int = 2
    #: Mean neighbour count used when the caller gives none (27: the seeds' choice for
    #: second-order schemes with the quintic spline).
    default_neighbors: int = 27
    #: Whether the weights depend on the area elements dV.
    uses_area: bool = True

    def weights(self, pairs: LocalPairs, max_condition: float) -> SchemeWeights:  # pragma: no cover - interface
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<scheme {self.name!r}>"


def batched_inverse(A: np.ndarray, max_condition: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Invert a stack of small matrices, flagging the ill-conditioned ones.

    Parameters
    ----------
    A : ndarray, shape (n, k, k)
    max_condition : float
        Matrices whose 1-norm condition number ``|A|_1 |A^-1|_1`` exceeds this
        (or is not finite) fail.

    Returns
    -------
    inv : ndarray, shape (n, k, k)
        Inverses, zero where the matrix failed.
    cond : ndarray, shape (n,)
    failed : ndarray of bool, shape (n,)
    """
    n, k, _ = A.shape
    if n == 0:
        return np.zeros_like(A), np.zeros(0), np.zeros(0, dtype=bool)
    finite = np.all(np.isfinite(A), axis=(1, 2))
    A = np.where(finite[:, None, None], A, np.eye(k))
    try:
        with np.errstate(all="ignore"):
            inv = np.linalg.inv(A)
    except np.linalg.LinAlgError:  # an exactly singular matrix: invert one by one
        inv = np.full_like(A, np.nan)
        for i in np.flatnonzero(finite):  # rare path; n is one chunk
            try:
                inv[i] = np.linalg.inv(A[i])
            except np.linalg.LinAlgError:
                pass
    with np.errstate(all="ignore"):
        cond = np.abs(A).sum(axis=1).max(axis=1) * np.abs(inv).sum(axis=1).max(axis=1)
    cond = np.where(finite & np.isfinite(cond), cond, np.inf)
    failed = ~(cond <= max_condition)
    inv[failed] = 0.0
    return inv, cond, failed


def difference_to_weights(pairs: LocalPairs, c: np.ndarray) -> np.ndarray:
    """Turn weights on ``f_j - f_i`` into weights on ``f_j`` (the self pair takes minus the row sum).

    ``c`` has shape (P,) or (P, m); returns the same shape.
    """
    w = np.where(pairs.is_self.reshape((-1,) + (1,) * (c.ndim - 1)), 0.0, c)
    sums = np.add.reduceat(w, pairs.indptr[:-1], axis=0)
    w[pairs.is_self] -= sums  # exactly one self pair per row, in row order
    return w


def corrected_weights(pairs: LocalPairs, grad_c: np.ndarray, lap_c: np.ndarray, failed: np.ndarray, condition) -> SchemeWeights:
    """Weights of a corrected scheme from its weights on ``f_j - f_i``; failed particles get zeros."""
    grad = difference_to_weights(pairs, grad_c)
    lap = difference_to_weights(pairs, lap_c)
    grad[failed[pairs.row]] = 0.0
    lap[failed[pairs.row]] = 0.0
    return SchemeWeights(grad=grad, lap=lap, failed=failed, condition=condition)
