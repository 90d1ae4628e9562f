"""MSPH, the modified SPH ([1] sec. 2.4.2; docs/method.md section 4).

One 6x6 system per particle: rows weighted by ``W, W_x, W_y, W_xx, W_xy, W_yy``,
columns ``1, x, y, x^2/2, xy, y^2/2``, unknowns ``f, f_x, f_y, f_xx, f_xy, f_yy``,
right-hand side ``S[f_j * row weight]``. Exact for quadratic polynomials.
"""

from __future__ import annotations

import numpy as np

from .base import LocalPairs, Scheme, SchemeWeights, batched_inverse

#: Rows of the unknown vector picking f_x, f_y and f_xx + f_yy.
SELECT = np.array(
    [
        [0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0, 0.0, 1.0],
    ]
)


class MSPH(Scheme):
    name = "msph"
    fallback = "cspm"
    min_neighbors = 6

    def weights(self, pairs: LocalPairs, max_condition: float) -> SchemeWeights:
        rows = np.concatenate([pairs.W[:, None, :], pairs.dW, pairs.d2W], axis=1) * pairs.dV[:, None, :]  # (n, 6, K)
        x, y = pairs.xy[:, 0], pairs.xy[:, 1]
        cols = np.stack([np.ones_like(x), x, y, 0.5 * x * x, x * y, 0.5 * y * y], axis=-1)  # (n, K, 6)
        A = pairs.moments(rows, cols)
        Ainv, cond, failed = batched_inverse(A, max_condition)
        Y = np.matmul(SELECT, Ainv)  # (n, 3, 6): rows of A^-1 picked by SELECT
        w = np.matmul(Y, rows)  # (n, 3, K)
        return SchemeWeights(grad=w[:, :2], lap=w[:, 2], failed=failed, condition=cond)
