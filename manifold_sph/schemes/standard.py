"""Standard SPH ([1] sec. 2.3; docs/method.md section 4): difference gradient and divergence, Taylor Laplacian.

Not consistent on irregular clouds or near boundaries (its error does not vanish
as ``h -> 0`` at fixed neighbour count), but it never fails: it is the last fallback.
"""

from __future__ import annotations

import numpy as np

from .base import LocalPairs, Scheme, SchemeWeights, difference_to_weights


class Standard(Scheme):
    """``grad f_i = sum_j (f_j - f_i) grad_i W dV_j``; ``Lap f_i = 2 sum_j (f_i - f_j) alpha w'/(h r) dV_j``."""

    name = "standard"
    fallback = None
    min_neighbors = 2

    def weights(self, pairs: LocalPairs, max_condition: float) -> SchemeWeights:
        grad = difference_to_weights(pairs.dW * pairs.dV[:, None, :])
        lap = difference_to_weights(-2.0 * pairs.dw_over_r * pairs.dV)
        n = pairs.n
        return SchemeWeights(grad=grad, lap=lap, failed=np.zeros(n, dtype=bool), condition=np.ones(n))
