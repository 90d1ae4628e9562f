"""CSPM, the corrective smoothed particle method ([1] sec. 2.4.1; docs/method.md section 4).

First derivatives from the 2x2 system ``M1 g = b1``,
``M1[a, c] = S[x_c W_a]``, ``b1[a] = S[(f_j - f_i) W_a]``; second derivatives
from ``N2 H = b2 - N1 g`` with rows weighted by ``W_xx, W_xy, W_yy``, ``N2``
columns ``x^2/2, xy, y^2/2`` and ``N1`` columns ``x, y``. Exact for linear
functions (gradient).
"""

from __future__ import annotations

import numpy as np

from .base import LocalPairs, Scheme, SchemeWeights, batched_inverse, corrected_weights, quadratic_columns

__all__ = ["CSPM", "first_derivative_weights", "linear_columns", "quadratic_columns"]

#: Selects f_xx + f_yy from H = (f_xx, f_xy, f_yy).
LAPLACE_ROW = np.array([1.0, 0.0, 1.0])


def linear_columns(xy: np.ndarray) -> np.ndarray:
    """(n, K, 2) Taylor columns ``x, y`` of offsets (n, 2, K)."""
    return np.ascontiguousarray(xy.transpose(0, 2, 1))


def first_derivative_weights(
    pairs: LocalPairs, max_condition: float, cols1: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """CSPM weights ``c`` (n, 2, K) on ``f_j - f_i`` for ``(f_x, f_y)``, with ``M1^-1``, condition and failures."""
    rows = pairs.dW * pairs.dV[:, None, :]
    M1 = pairs.moments(rows, linear_columns(pairs.xy) if cols1 is None else cols1)
    M1inv, cond, failed = batched_inverse(M1, max_condition)
    c = np.matmul(M1inv, rows)  # c[i, :, k] = M1^-1 rows[i, :, k]
    return c, M1inv, cond, failed


def second_derivative_weights(
    rows2: np.ndarray, K: np.ndarray, N1: np.ndarray, c: np.ndarray, max_condition: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Laplacian weights (n, K) on ``f_j - f_i`` from ``K H = b2 - N1 g`` (g with weights ``c``)."""
    Kinv, cond, failed = batched_inverse(K, max_condition)
    y = Kinv[:, 0, :] + Kinv[:, 2, :]  # y = K^-T e, e = LAPLACE_ROW
    z = np.matmul(y[:, None, :], N1)  # (N1^T y)^T, (n, 1, 2)
    lap = np.matmul(y[:, None, :], rows2)[:, 0] - np.matmul(z, c)[:, 0]
    return lap, cond, failed


class CSPM(Scheme):
    name = "cspm"
    fallback = "standard"
    min_neighbors = 6

    def weights(self, pairs: LocalPairs, max_condition: float) -> SchemeWeights:
        cols1 = linear_columns(pairs.xy)
        c, _, cond1, failed1 = first_derivative_weights(pairs, max_condition, cols1)
        rows2 = pairs.d2W * pairs.dV[:, None, :]
        N2 = pairs.moments(rows2, quadratic_columns(pairs.xy))
        N1 = pairs.moments(rows2, cols1)
        lap, cond2, failed2 = second_derivative_weights(rows2, N2, N1, c, max_condition)
        return corrected_weights(c, lap, failed1 | failed2, np.maximum(cond1, cond2))
