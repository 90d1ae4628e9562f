"""CSPM, the corrective smoothed particle method (seed 1, 2.4.1; METHOD.md section 4).

First derivatives from the 2x2 system ``M1 g = b1``,
``M1[a, c] = S[x_c W_a]``, ``b1[a] = S[(f_j - f_i) W_a]``; second derivatives
from ``N2 H = b2 - N1 g`` with rows weighted by ``W_xx, W_xy, W_yy``, ``N2``
columns ``x^2/2, xy, y^2/2`` and ``N1`` columns ``x, y``. Exact for linear
functions (gradient).
"""

from __future__ import annotations

import numpy as np

from .base import LocalPairs, Scheme, SchemeWeights, batched_inverse, corrected_weights

#: Selects f_xx + f_yy from H = (f_xx, f_xy, f_yy).
LAPLACE_ROW = np.array([1.0, 0.0, 1.0])


def quadratic_columns(xy: np.ndarray) -> np.ndarray:
    """(P, 3) Taylor columns ``x^2/2, xy, y^2/2``."""
    x, y = xy[:, 0], xy[:, 1]
    return np.stack([0.5 * x * x, x * y, 0.5 * y * y], axis=1)


def first_derivative_weights(pairs: LocalPairs, max_condition: float):
    """CSPM weights ``c`` (P, 2) on ``f_j - f_i`` for ``(f_x, f_y)``, with ``M1`` data."""
    rows = pairs.dW * pairs.dV[:, None]
    M1 = pairs.moments(rows, pairs.xy)
    M1inv, cond, failed = batched_inverse(M1, max_condition)
    c = np.einsum("pac,pc->pa", M1inv[pairs.row], rows)
    return c, M1inv, cond, failed


def second_derivative_weights(pairs, K, N1, c, max_condition):
    """Laplacian weights on ``f_j - f_i`` from ``K H = b2 - N1 g`` (g with weights ``c``)."""
    Kinv, cond, failed = batched_inverse(K, max_condition)
    y = np.einsum("nca,c->na", Kinv, LAPLACE_ROW)  # y = K^-T e
    z = np.einsum("nra,nr->na", N1, y)  # N1^T y
    rows2 = pairs.d2W * pairs.dV[:, None]
    lap = np.einsum("pa,pa->p", rows2, y[pairs.row]) - np.einsum("pa,pa->p", c, z[pairs.row])
    return lap, cond, failed


class CSPM(Scheme):
    name = "cspm"
    fallback = "standard"
    min_neighbors = 6

    def weights(self, pairs: LocalPairs, max_condition: float) -> SchemeWeights:
        c, _, cond1, failed1 = first_derivative_weights(pairs, max_condition)
        rows2 = pairs.d2W * pairs.dV[:, None]
        N2 = pairs.moments(rows2, quadratic_columns(pairs.xy))
        N1 = pairs.moments(rows2, pairs.xy)
        lap, cond2, failed2 = second_derivative_weights(pairs, N2, N1, c, max_condition)
        return corrected_weights(pairs, c, lap, failed1 | failed2, np.maximum(cond1, cond2))
