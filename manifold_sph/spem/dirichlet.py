"""Kronecker-delta system for Dirichlet values (the thesis [2] sec. 3.1.5; docs/method.md section 7).

SPH shape functions lack the Kronecker-delta property: the field value at a
particle is ``f_i = sum_j W_ij u_j dV_j`` (j over the particle's neighbours,
itself included), not its nodal parameter ``u_i``. Imposing values ``f`` means
solving ``K u = f`` with ``K_ij = W(x_j - x_i) dV_j`` - the
``(A - I) u + b = 0`` of [2] after dividing row i by ``-W_ii dV_i``. ``K`` is
constant while the particles do not move, so it is LU-factorised once and the
factors are reused at every step.

:class:`~manifold_sph.spem.TMzSolver` stores point values (its CSPM
derivatives act on values), so Dirichlet values and hard sources are imposed
directly; this class converts to and from the nodal parameters of the
formulation of [2].

Examples
--------
>>> import numpy as np
>>> x = np.linspace(0.0, 1.0, 41)[:, None]
>>> k = KroneckerSystem(x, h=0.03)
>>> u = k.nodal(np.sin(x[:, 0]))
>>> bool(np.allclose(k.values(u), np.sin(x[:, 0]), atol=1e-12))
True
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from scipy.sparse.linalg import splu
from scipy.spatial import cKDTree

from .._validation import as_field, as_points, check_positive
from ..kernels import Kernel, get_kernel

__all__ = ["KroneckerSystem"]


class KroneckerSystem:
    """``K u = f`` with ``K_ij = W_h(x_j - x_i) dV_j``, factorised once.

    Parameters
    ----------
    points : (N, d) array, d = 1 or 2
    h : float
        Smoothing length.
    kernel : str
        Kernel name (default "cubic").
    dV : None, float or (N,) array
        Particle volumes; the default ``1 / sum_j W_ij`` (Shepard) makes K
        row-stochastic-like and well conditioned.
    """

    def __init__(self, points: ArrayLike, h: float, *, kernel: str | Kernel | type[Kernel] = "cubic",
                 dV: float | ArrayLike | None = None) -> None:
        p = np.asarray(points, dtype=np.float64)
        p = as_points("points", p, dim=(1, 2))
        if len(p) == 0:
            raise ValueError("points is empty: need at least one particle")
        self.h = check_positive("h", h)
        k = get_kernel(kernel)
        d = p.shape[1]
        tree = cKDTree(p)
        D = tree.sparse_distance_matrix(tree, k.support * self.h, output_type="coo_matrix")
        rows = np.r_[D.row, np.arange(len(p))]
        cols = np.r_[D.col, np.arange(len(p))]
        W = k.alpha(d, self.h) * k.w(np.r_[D.data, np.zeros(len(p))] / self.h)
        if dV is None:
            dV = 1.0 / np.bincount(rows, weights=W, minlength=len(p))
        dV = np.broadcast_to(np.asarray(dV, dtype=np.float64), (len(p),))
        self.K = sp.csc_matrix((W * dV[cols], (rows, cols)), shape=(len(p), len(p)))
        self.lu = splu(self.K)
        self.n = len(p)

    def nodal(self, values: ArrayLike) -> np.ndarray:
        """Nodal parameters u with ``K u = values`` (reuses the LU factors)."""
        return self.lu.solve(as_field("values", values, self.n))

    def values(self, nodal: ArrayLike) -> np.ndarray:
        """Point values ``K u`` of nodal parameters u."""
        return self.K @ as_field("nodal", nodal, self.n)
