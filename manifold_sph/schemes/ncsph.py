"""NCSPH (seed 1, 2.4.3), with the final system the seed omits (METHOD.md section 4).

With ``f_i`` known, the second-order terms are kept in the first-derivative rows:
``M1 g + M2 H = b1``, ``N1 g + N2 H = b2``, so
``(N2 - N1 M1^-1 M2) H = b2 - N1 M1^-1 b1``. First derivatives are CSPM's.
"""

from __future__ import annotations

import numpy as np

from .base import LocalPairs, Scheme, SchemeWeights, difference_to_weights
from .cspm import first_derivative_weights, quadratic_columns, second_derivative_weights


class NCSPH(Scheme):
    name = "ncsph"
    fallback = "cspm"
    min_neighbors = 6

    def weights(self, pairs: LocalPairs, max_condition: float) -> SchemeWeights:
        c, M1inv, cond1, failed1 = first_derivative_weights(pairs, max_condition)
        rows1 = pairs.dW * pairs.dV[:, None]
        rows2 = pairs.d2W * pairs.dV[:, None]
        quad = quadratic_columns(pairs.xy)
        M2 = pairs.moments(rows1, quad)
        N1 = pairs.moments(rows2, pairs.xy)
        N2 = pairs.moments(rows2, quad)
        K = N2 - N1 @ M1inv @ M2
        lap, cond2, failed2 = second_derivative_weights(pairs, K, N1, c, max_condition)
        failed = failed1 | failed2
        grad = difference_to_weights(pairs, c)
        lap = difference_to_weights(pairs, lap)
        grad[failed[pairs.row]] = 0.0
        lap[failed[pairs.row]] = 0.0
        return SchemeWeights(grad=grad, lap=lap, failed=failed, condition=np.maximum(cond1, cond2))
