"""MSPH, the modified SPH (seed 1, 2.4.2; METHOD.md section 4).

One 6x6 system per particle: rows weighted by ``W, W_x, W_y, W_xx, W_xy, W_yy``,
columns ``1, x, y, x^2/2, xy, y^2/2``, unknowns ``f, f_x, f_y, f_xx, f_xy, f_yy``,
right-hand side ``S[f_j * row weight]``. Exact for quadratic polynomials.
"""

from __future__ import annotations

import numpy as np

from .base import LocalPairs, Scheme, SchemeWeights, batched_inverse, quadratic_columns

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
        rows = np.concatenate([pairs.W[..., None], pairs.dW, pairs.d2W], axis=-1) * pairs.dV[..., None]
        cols = np.concatenate([np.ones(pairs.xy.shape[:-1] + (1,)), pairs.xy, quadratic_columns(pairs.xy)], axis=-1)
        A = pairs.moments(rows, cols)
        Ainv, cond, failed = batched_inverse(A, max_condition)
        Y = np.matmul(SELECT, Ainv)  # (n, 3, 6): rows of A^-1 picked by SELECT
        w = np.matmul(rows, Y.transpose(0, 2, 1))  # (n, K, 3)
        return SchemeWeights(grad=w[..., :2].copy(), lap=w[..., 2].copy(), failed=failed, condition=cond)
