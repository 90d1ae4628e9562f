"""NCSPH ([1] sec. 2.4.3), with the final system [1] omits (docs/method.md section 4).

With ``f_i`` known, the second-order terms are kept in the first-derivative rows:
``M1 g + M2 H = b1``, ``N1 g + N2 H = b2``, i.e.
``(N2 - N1 M1^-1 M2) H = b2 - N1 M1^-1 b1``. We solve the equivalent 5x5 block
system for ``(g, H)`` directly (rows ``W_x, W_y, W_xx, W_xy, W_yy``, columns
``x, y, x^2/2, xy, y^2/2``): the Schur complement loses digits to cancellation
near boundaries, the pivoted 5x5 solve does not. The Laplacian is
``H_xx + H_yy`` from that solve; first derivatives are CSPM's, as [1] says.
Exact for quadratic polynomials (Laplacian) and linear ones (gradient).
"""

from __future__ import annotations

import numpy as np

from .base import LocalPairs, Scheme, SchemeWeights, batched_inverse, corrected_weights
from .cspm import first_derivative_weights

#: Selects H_xx + H_yy from (g_x, g_y, H_xx, H_xy, H_yy).
LAPLACE_ROW = np.array([0.0, 0.0, 1.0, 0.0, 1.0])


class NCSPH(Scheme):
    name = "ncsph"
    fallback = "cspm"
    min_neighbors = 6

    def weights(self, pairs: LocalPairs, max_condition: float) -> SchemeWeights:
        c, _, cond1, failed1 = first_derivative_weights(pairs, max_condition)
        rows = np.concatenate([pairs.dW, pairs.d2W], axis=1) * pairs.dV[:, None, :]  # (n, 5, K)
        x, y = pairs.xy[:, 0], pairs.xy[:, 1]
        cols = np.stack([x, y, 0.5 * x * x, x * y, 0.5 * y * y], axis=-1)  # (n, K, 5)
        A = pairs.moments(rows, cols)
        Ainv, cond2, failed2 = batched_inverse(A, max_condition)
        yv = Ainv[:, 2, :] + Ainv[:, 4, :]  # A^-T e, e = LAPLACE_ROW
        lap = np.matmul(yv[:, None, :], rows)[:, 0]
        return corrected_weights(c, lap, failed1 | failed2, np.maximum(cond1, cond2))
