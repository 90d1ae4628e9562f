"""The scheme interface: local 2D pair data in, per-pair weights out.

Every scheme works on a chunk of ``n`` particles in *normalised* units: offsets
and kernel derivatives are expressed with ``h_i = 1`` (offsets divided by
``h_i``, area elements by ``h_i^2``). The assembly rescales first derivatives
by ``1 / h_i`` and second derivatives by ``1 / h_i^2``. This keeps the local
systems dimensionless, so one condition-number threshold fits every ``h``.

Pair data are *padded* and *component-major*: particle ``i``'s neighbours
occupy slots ``0 .. counts[i] - 1`` of an ``(n, K)`` grid (``K`` the largest
count in the chunk), the particle itself in slot 0, and vector quantities are
``(n, components, K)``. Every kernel quantity and area element is zero in the
unused slots, so moment sums are batched matrix products
``(n, A, K) @ (n, K, C)`` of contiguous operands with no gathers, the weights
``M^-1 rows`` are ``(n, A, A) @ (n, A, K)``, and a subset of particles is a
slice of the first axis.

A scheme returns weights ``w`` such that, for the particle ``i``,
``d f / d x (i) = sum_k w_grad[i, 0, k] f[neighbour k of i]`` over its slots
(itself included), likewise for ``d/dy`` and the Laplacian; unused slots carry
zero weight.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "LocalPairs",
    "SchemeWeights",
    "Scheme",
    "batched_inverse",
    "difference_to_weights",
    "corrected_weights",
    "quadratic_columns",
]


@dataclass
class LocalPairs:
    """Pair data of a chunk of ``n`` particles, in units of ``h_i``, padded to ``K`` slots.

    Attributes
    ----------
    valid : ndarray of bool, shape (n, K)
        True for the slots holding a neighbour; slot 0 is the particle itself.
    xy : ndarray, shape (n, 2, K)
        Offsets ``x_j - x_i`` in the tangent plane of ``i``, divided by ``h_i`` (0 in unused slots).
    dV : ndarray, shape (n, K)
        Area element of ``j`` divided by ``h_i^2`` (0 in unused slots).
    W : ndarray, shape (n, K)
        Kernel ``W(x_i - x_j)`` with ``h = 1`` in ``d = 2``.
    dW : ndarray, shape (n, 2, K)
        Its gradient with respect to ``x_i``.
    d2W : ndarray, shape (n, 3, K)
        Its second derivatives ``(W_xx, W_xy, W_yy)``.
    dw_over_r : ndarray, shape (n, K)
        ``alpha_2 w'(R) / R`` (the Taylor Laplacian's factor), finite at ``R = 0``.
    """

    valid: np.ndarray
    xy: np.ndarray
    dV: np.ndarray
    W: np.ndarray
    dW: np.ndarray
    d2W: np.ndarray
    dw_over_r: np.ndarray

    @property
    def n(self) -> int:
        return self.valid.shape[0]

    @property
    def counts(self) -> np.ndarray:
        """(n,) number of neighbours of each particle, itself included."""
        return self.valid.sum(axis=1)

    def take(self, rows: np.ndarray) -> "LocalPairs":
        """The pair data of a subset of the particles (indices into the chunk)."""
        return LocalPairs(**{name: getattr(self, name)[rows] for name in self.__dataclass_fields__})

    @staticmethod
    def moments(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Per-particle moment matrices ``M[i, a, c] = sum_k rows[i, a, k] cols[i, k, c]``.

        ``rows`` (n, A, K), zero in unused slots, and ``cols`` (n, K, C) -> (n, A, C):
        one batched product (fastest with both operands contiguous).
        """
        return np.matmul(rows, cols)

    @classmethod
    def from_flat(
        cls,
        indptr: ArrayLike,
        xy: ArrayLike,
        dV: ArrayLike,
        W: ArrayLike,
        dW: ArrayLike,
        d2W: ArrayLike,
        dw_over_r: ArrayLike,
    ) -> "LocalPairs":
        """Pad flat CSR-ordered pair arrays (P, ...) with row offsets ``indptr`` (n + 1,).

        Each row's first pair must be the particle itself. Mainly for tests and
        hand-built neighbourhoods; the assembly pads its chunks directly.
        """
        indptr = np.asarray(indptr)
        counts = np.diff(indptr)
        k = int(counts.max()) if counts.size else 0
        valid = np.arange(k)[None, :] < counts[:, None]
        pos = np.where(valid, indptr[:-1, None] + np.arange(k)[None, :], 0)

        def pad(a):  # (P, ...) -> (n, ..., K)
            a = np.asarray(a, dtype=np.float64)
            out = np.where(valid.reshape(valid.shape + (1,) * (a.ndim - 1)), a[pos], 0.0)
            return np.ascontiguousarray(np.moveaxis(out, 1, -1))

        return cls(valid=valid, xy=pad(xy), dV=pad(dV), W=pad(W), dW=pad(dW), d2W=pad(d2W), dw_over_r=pad(dw_over_r))


@dataclass
class SchemeWeights:
    """Per-pair weights of one scheme on a chunk, and the particles it failed on.

    Attributes
    ----------
    grad : ndarray, shape (n, 2, K)
        Weights of ``(d/dx, d/dy)`` on ``f_j``.
    lap : ndarray, shape (n, K)
        Weights of the Laplacian on ``f_j``.
    failed : ndarray, shape (n,)
        Particles whose local system was singular or ill-conditioned; their
        weights are zero and the assembly recomputes them with the fallback.
    condition : ndarray, shape (n,)
        Largest 1-norm condition number of the local systems of each particle
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
    #: Mean neighbour count used when the caller gives none (27: the choice of [1] and [2] for
    #: second-order schemes with the quintic spline).
    default_neighbors: int = 27
    #: Whether the weights depend on the area elements dV.
    uses_area: bool = True
    #: Particles per assembly chunk: a chunk's pair arrays should stay in cache. Measured
    #: at N = 131072 on 2 cores: 2048 for the second-order schemes; fewer for the
    #: larger systems of msph3/4/5 (``benchmarks/perf.py``).
    chunk_rows: int = 2048

    def weights(self, pairs: LocalPairs, max_condition: float) -> SchemeWeights:  # pragma: no cover - interface
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<scheme {self.name!r}>"


def _small_inverse(A: np.ndarray) -> np.ndarray:
    """Closed-form inverses of a stack of 2x2 or 3x3 matrices (adjugate over determinant)."""
    if A.shape[-1] == 2:
        a, b, c, d = A[:, 0, 0], A[:, 0, 1], A[:, 1, 0], A[:, 1, 1]
        det = a * d - b * c
        inv = np.stack([d, -b, -c, a], axis=1).reshape(-1, 2, 2)
    else:
        a, b, c = A[:, 0, 0], A[:, 0, 1], A[:, 0, 2]
        d, e, f = A[:, 1, 0], A[:, 1, 1], A[:, 1, 2]
        g, h, k = A[:, 2, 0], A[:, 2, 1], A[:, 2, 2]
        c0, c1, c2 = e * k - f * h, f * g - d * k, d * h - e * g
        det = a * c0 + b * c1 + c * c2
        inv = np.stack(
            [c0, c * h - b * k, b * f - c * e, c1, a * k - c * g, c * d - a * f, c2, b * g - a * h, a * e - b * d], axis=1
        ).reshape(-1, 3, 3)
    with np.errstate(all="ignore"):
        return inv / det[:, None, None]


def _norm1(A: np.ndarray) -> np.ndarray:
    """1-norms (largest absolute column sum) of a stack (n, k, k), summing rows one by one (fast for small k)."""
    s = np.abs(A[:, 0, :])
    for i in range(1, A.shape[1]):
        s += np.abs(A[:, i, :])
    return s.max(axis=1)


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

    Examples
    --------
    >>> A = np.array([[[2.0, 0.0], [0.0, 4.0]], [[1.0, 1.0], [1.0, 1.0]]])
    >>> inv, cond, failed = batched_inverse(A, 1e8)
    >>> (inv[0] + 0.0).tolist(), cond.tolist(), failed.tolist()   # + 0.0 turns -0.0 into 0.0
    ([[0.5, 0.0], [0.0, 0.25]], [2.0, inf], [False, True])
    """
    n, k, _ = A.shape
    if n == 0:
        return np.zeros_like(A), np.zeros(0), np.zeros(0, dtype=bool)
    finite = np.all(np.isfinite(A), axis=(1, 2))
    A = np.where(finite[:, None, None], A, np.eye(k))
    if k <= 3:
        inv = _small_inverse(A) if k > 1 else 1.0 / A
    else:
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
        cond = _norm1(A) * _norm1(inv)
    cond = np.where(finite & np.isfinite(cond), cond, np.inf)
    failed = ~(cond <= max_condition)
    inv[failed] = 0.0
    return inv, cond, failed


def quadratic_columns(xy: np.ndarray) -> np.ndarray:
    """(n, K, 3) Taylor columns ``x^2/2, xy, y^2/2`` of offsets (n, 2, K)."""
    x, y = xy[:, 0], xy[:, 1]
    return np.stack([0.5 * x * x, x * y, 0.5 * y * y], axis=-1)


def difference_to_weights(c: np.ndarray) -> np.ndarray:
    """Turn weights on ``f_j - f_i`` into weights on ``f_j``: slot 0 (the particle itself) takes minus the row sum.

    ``c`` has shape (n, K) or (n, m, K), zero in unused slots; returns a new array of the same shape.
    """
    w = c.copy()
    w[..., 0] = -c[..., 1:].sum(axis=-1)
    return w


def corrected_weights(grad_c: np.ndarray, lap_c: np.ndarray, failed: np.ndarray, condition: np.ndarray) -> SchemeWeights:
    """Weights of a corrected scheme from its weights on ``f_j - f_i``; failed particles get zeros."""
    grad = difference_to_weights(grad_c)
    lap = difference_to_weights(lap_c)
    grad[failed] = 0.0
    lap[failed] = 0.0
    return SchemeWeights(grad=grad, lap=lap, failed=failed, condition=condition)
