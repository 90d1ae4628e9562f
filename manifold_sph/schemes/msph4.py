"""Higher-order corrected SPH: ``"msph3"``, ``"msph4"`` and ``"msph5"``.

The corrected family (CSPM, MSPH) matches the Taylor expansion of ``f_j - f_i``
to second order. Carrying the expansion to degree ``q`` in the tangent-plane
coordinates ``(x, y)`` of particle ``i`` (the Monge chart of the projection in
:func:`~manifold_sph.frames.project_pairs`) gives

.. math::

    f_j - f_i = \\sum_{1 \\le a + b \\le q} \\frac{x_j^a y_j^b}{a!\\,b!}\\,
    \\partial_x^a \\partial_y^b f(i) + O(r^{q+1}),

with ``U = (q + 1)(q + 2)/2 - 1`` unknown derivatives (9 for ``q = 3``, 14 for
``q = 4``). As in the finite particle method, the rows of the local system are
this expansion multiplied by the kernel times each monomial and summed over the
neighbours (the moment form):

.. math::

    \\sum_j W_{ij}\\, m_a(x_j)\\, m_c(x_j)\\; D_c f(i)
    = \\sum_j W_{ij}\\, m_a(x_j)\\, (f_j - f_i),

where ``m_c`` are the scaled monomials ``x^a y^b / (a! b!)`` in units of ``h_i``
and ``D_c f`` the matching partial derivatives. The ``U x U`` moment matrix is
symmetric positive semi-definite (it is the normal matrix of a kernel-weighted
polynomial fit); it is equilibrated by its diagonal before the condition test
and the solve, so the test measures the geometry of the neighbourhood, not the
scale of the monomials. Gradient ``(f_x, f_y)`` and Laplacian ``f_xx + f_yy`` come
from the same solve. In the Monge chart the metric is the identity at ``x_i``
with vanishing first derivatives, so ``f_xx + f_yy`` *is* the Laplace-Beltrami
operator at ``i`` and ``f_x u + f_y v`` the surface gradient: no surface fit is
needed when the normals are exact.

Properties
----------
- Exact for polynomials of degree ``q`` in the plane (up to round-off).
- Truncation error ``O(h^q)`` for the gradient and ``O(h^(q-1))`` for the
  Laplacian; on near-uniform clouds the leading odd moments nearly cancel and
  ``msph4``'s Laplacian converges at close to fourth order (measured below).
- Normals: with *estimated* normals, an angle error ``delta`` in the normal
  tilts the chart; the gradient picks up ``O(delta)`` and the Laplacian
  ``O(delta * kappa + delta^2)`` (curvature ``kappa``: the tilted chart's metric
  no longer has vanishing derivatives). So the reachable accuracy is set by the
  normals, not by the scheme. Measured on the unit sphere (Fibonacci points,
  f = cos(xz - sin y)) with PCA normals from the 20 nearest points: rms normal
  error 0.31, 0.21, 0.12 degrees at N = 4032, 8672, 32672 (first order), and
  msph4 errors Laplacian 2.5e-3, 1.5e-3, 9.9e-4, gradient 4.2e-3, 2.6e-3,
  1.7e-3 (msph: 6.6e-3, 3.3e-3, 1.2e-3 and 8.6e-3, 4.3e-3, 1.9e-3), against
  1.0e-5 / 2.0e-7 with exact normals. Fourth order needs normals accurate to
  ``O(h^4)``: exact ones, or normals from a high-order (e.g. quartic) surface fit.

Measured (``python benchmarks/msph4_vs_gmls.py --full``; unit sphere, Fibonacci
points, exact normals, f = cos(xz - sin y), relative L2):

========  ==========  ==========  ==========  ==========
N         msph4 lap   msph4 grad  msph5 lap   msph5 grad
========  ==========  ==========  ==========  ==========
4032      1.03e-5     2.03e-5     1.51e-5     3.7e-7
32672     2.01e-7     3.23e-7     2.26e-7     1.1e-9
131072    1.34e-8     1.79e-8     1.50e-8     2.4e-11
order     3.81        4.03        3.97        5.54
========  ==========  ==========  ==========  ==========

pycompadre's GMLS (order 4, same points) at the same sizes: Laplacian
6.1e-5, 1.4e-6, 1.1e-7 and gradient 6.1e-5, 9.0e-7, 5.5e-8 with its default
weighting (power 2); 2.7e-5, 4.7e-7, 3.6e-8 and 2.9e-5, 4.3e-7, 2.7e-8 with
power 4.

Robustness
----------
A particle fails (and is recomputed with :attr:`~Scheme.fallback`, per particle,
by the assembly) when it has fewer than :attr:`~Scheme.min_neighbors`
neighbours, when its equilibrated moment matrix has a condition number above
``max_condition`` (rank-deficient or nearly collinear neighbourhoods, holes,
sharp edges), or when the matrix is not finite. The chain is
``msph5 -> msph4 -> msph3 -> msph -> cspm -> standard``.

Memory
------
The moment matrices are one batched product of the weighted monomials
(n, U, K) with the monomials over each chunk's padded neighbour slots; the
largest temporaries are these two arrays and the (n, U, U) matrices of the
``n`` rows of a chunk (U = 14 unknowns): about 20 MB for the assembly's
2048-row chunks with 30 neighbours, never a per-pair (P, U, U) array.
"""

from __future__ import annotations

from math import factorial

import numpy as np

from .base import LocalPairs, Scheme, SchemeWeights, batched_inverse, corrected_weights

__all__ = ["MSPH3", "MSPH4", "MSPH5", "HighOrderCorrected", "taylor_exponents"]


def taylor_exponents(degree: int) -> list[tuple[int, int]]:
    """Exponents ``(a, b)`` of the monomials ``x^a y^b`` with ``1 <= a + b <= degree``.

    Ordered by total degree, then by decreasing power of ``x``.

    Examples
    --------
    >>> taylor_exponents(2)
    [(1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]
    >>> len(taylor_exponents(4))
    14
    """
    return [(d - b, b) for d in range(1, degree + 1) for b in range(d + 1)]


def _powers(v: np.ndarray, top: int) -> list[np.ndarray]:
    out = [np.ones_like(v)]
    for _ in range(top):
        out.append(out[-1] * v)
    return out


class HighOrderCorrected(Scheme):
    """Corrected SPH in moment form with Taylor terms up to degree :attr:`degree`.

    Subclasses set ``degree`` (and the registry attributes). See the module
    docstring for the system.
    """

    uses_area = False  # the moment rows carry no area elements

    #: Highest total degree of the Taylor terms.
    degree: int = 4

    def __init__(self) -> None:
        exps = taylor_exponents(self.degree)
        self.exponents = exps
        self.n_unknowns = len(exps)
        self.scale = np.array([1.0 / (factorial(a) * factorial(b)) for a, b in exps])
        # Selectors: f_x, f_y and f_xx + f_yy in the unknown vector.
        sel = np.zeros((3, len(exps)))
        sel[0, exps.index((1, 0))] = 1.0
        sel[1, exps.index((0, 1))] = 1.0
        sel[2, exps.index((2, 0))] = 1.0
        sel[2, exps.index((0, 2))] = 1.0
        self.select = sel

    def monomials(self, xy: np.ndarray) -> np.ndarray:
        """(n, U, K) scaled monomials ``x^a y^b / (a! b!)`` of padded offsets (n, 2, K)."""
        px = _powers(xy[:, 0], self.degree)
        py = _powers(xy[:, 1], self.degree)
        n, _, k = xy.shape
        m = np.empty((n, self.n_unknowns, k))
        for a, (pa, qa) in enumerate(self.exponents):
            np.multiply(px[pa], py[qa], out=m[:, a])
            m[:, a] *= self.scale[a]
        return m

    def weights(self, pairs: LocalPairs, max_condition: float) -> SchemeWeights:
        m = self.monomials(pairs.xy)
        mw = m * pairs.W[:, None, :]  # (n, U, K), zero in unused slots
        A = pairs.moments(mw, np.ascontiguousarray(m.transpose(0, 2, 1)))  # (n, U, U) = sum_j W_ij m_a m_c
        # Equilibrate (Jacobi): As = D A D with D = diag(A)^(-1/2).
        diag = np.einsum("nkk->nk", A)
        finite = np.all(np.isfinite(A), axis=(1, 2)) & np.all(diag > 0, axis=1)
        d = np.where(finite[:, None], 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0)), 0.0)
        As = np.where(finite[:, None, None], A * d[:, :, None] * d[:, None, :], 0.0)
        As[~finite] = np.nan  # batched_inverse fails these
        # 1-norm condition number of the equilibrated matrix, from its inverse
        Asinv, cond, failed = batched_inverse(As, max_condition)
        # Y = S A^-1 = S D As^-1 D (rows of A^-1 picked by S); zero for failed particles
        Y = np.matmul(self.select, d[:, :, None] * Asinv * d[:, None, :])  # (n, 3, U)
        # weights on f_j - f_i: c[i, s, k] = sum_a Y[i, s, a] W_ik m_a(x_ik)
        c = np.matmul(Y, mw)  # (n, 3, K)
        return corrected_weights(c[:, :2], c[:, 2], failed, cond)


class MSPH3(HighOrderCorrected):
    """Third-degree corrected SPH (9 unknowns), exact for cubic polynomials.

    The gradient is third order (close to fourth on near-uniform clouds); the
    Laplacian is only second order (the degree-4 terms do not cancel), so this
    scheme is mainly the first fallback of ``msph4``. Default neighbours 24: the
    fewest that kept Poisson-disk spheres and tori (N = 8000) free of fallbacks
    (16 left about 0.5 % of the particles to ``msph``).
    """

    name = "msph3"
    chunk_rows = 1024  # assembly at N = 131072, 2 cores: 0.52 s with 2048 rows, 0.50 s with 1024
    fallback = "msph"
    degree = 3
    min_neighbors = 10
    default_neighbors = 24


class MSPH4(HighOrderCorrected):
    """Fourth-degree corrected SPH (14 unknowns), exact for quartic polynomials.

    Default neighbours 30 (mean count inside the quintic spline's support 3h).
    The 14x14 moment matrix needs at least 14 neighbours besides the particle,
    and the kernel weighs its outer ring little. Measured trade-off (unit sphere
    and torus, ``benchmarks/msph4_vs_gmls.py --neighbours``): on Fibonacci
    spheres the errors are flat from 22 to 30 neighbours and grow beyond
    (x2.3 at 45, x4 at 60, x8 at 80: the error constant grows with the support);
    on Poisson-disk clouds 24 neighbours leave ~0.2 % of the particles to the
    fallback, 28-30 none (a rare one on tori). 30 is the smallest count that is
    robust on irregular clouds.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(2012)
    >>> s = Surface(cloud, scheme="msph4")
    >>> x = cloud.points
    >>> f = x[:, 0] * x[:, 1] * x[:, 2]           # Lap_S(xyz) = -12 xyz on the unit sphere
    >>> err = np.linalg.norm(s.laplacian(f) + 12 * f) / np.linalg.norm(12 * f)
    >>> bool(err < 1e-4)                          # msph: 8.7e-3
    True
    """

    name = "msph4"
    chunk_rows = 512  # assembly at N = 131072, 2 cores: 0.99 s with 2048 rows, 0.85 s with 512
    fallback = "msph3"
    degree = 4
    min_neighbors = 15
    default_neighbors = 30


class MSPH5(HighOrderCorrected):
    """Fifth-degree corrected SPH (20 unknowns), exact for quintic polynomials.

    Not asked for by the issue, but the same solve carried one degree further:
    the gradient gains one to two orders of magnitude over ``msph4`` and the
    Laplacian becomes genuinely fourth order on irregular clouds (on near-uniform
    ones ``msph4``'s Laplacian already is, by cancellation). Default neighbours
    40: the fewest that keep Poisson-disk spheres and tori free of fallbacks
    (36 leaves a few); each extra neighbour widens the support and raises the
    Laplacian's error constant.
    """

    name = "msph5"
    chunk_rows = 256  # assembly at N = 131072, 2 cores: 1.93 s with 2048 rows, 1.57 s with 256
    fallback = "msph4"
    degree = 5
    min_neighbors = 21
    default_neighbors = 40
