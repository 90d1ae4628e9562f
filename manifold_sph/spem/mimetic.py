"""Second-order energy-conserving (summation-by-parts) SPEM operators on any layout.

The "mimetic" coupling builds the E -> H gradient ``G`` first, as a corrected
(moving-least-squares) gradient exact for *cubic* fields, and takes the
H -> E operator as its negative adjoint in the volume-weighted inner products,

    D = -V_E^-1 G_free^T V_H          (free E rows, H columns),

so that the pair is skew-adjoint and leap-frog conserves the discrete energy
``sum V_E eps Ez^2 + sum V_H mu H^2`` on every layout, material and support
(the stable step is the computed ``2 / sqrt(rho)``). ``G`` also has
columns at the PEC and driven E particles, which carry data (zero on the
walls), not unknowns: they are free for the gradient's exactness and play no
part in the energy.

Second order needs ``D`` to be consistent as well (the discrete divergence
theorem, the SBP property): for every free E particle ``j`` and both
axes ``a``,

    sum_i G_ij V_i = 0,   sum_i G_ij V_i (x_i - x_j)_a = -V_j,   sum_i G_ij V_i (x_i - x_j)_b = 0,

which make ``D`` exact for linear H fields. Then the E -> E operator
``D mu^-1 G`` is exact for quadratic fields (G exact for quadratics suffices), and its truncation error on
smooth fields has the form ``D (O(dr^2))``: the energy argument gives
second-order convergence of Ez on irregular layouts (a lattice-free
version of the mimetic finite-difference argument).

In the unknowns ``Q = V_H G`` (the flux weights), ``V_H`` and ``V_E`` these
conditions and the gradient's exactness (cubic fields; quadratic on rows
whose cubic fit is singular) are all linear and homogeneous. One sparse
least-squares (normal-equations) solve gives the smallest weighted change of
the kernel estimates ``Q0 = V0_H G0``, ``V0 = 1 / sum_j W_h(x_i - x_j)`` that
meets them exactly (weights: the fit weights for ``Q``, :data:`VOLUME_WEIGHT`
for the relative volume changes). Fitting the volumes first and correcting
``G`` after was tried: the corrections then spread over the whole domain and
grew with resolution (the volumes must take part). Non-positive volumes are
refused (ValueError). The normal equations are symmetric positive definite and are factored without
pivoting in SuperLU's symmetric mode. The solve still dominates the set-up (10-100x a run: the
conditions have a near-null space of smooth multiplier fields that grows with the particle count, see
docs/method.md section 7; ``MimeticOperators.seconds`` gives the parts: at 48 spacings on the jittered
square the factorisation is 41 of 46 s). ``fast=True`` corrects only pairs closer than 2 spacings and keeps
only quadratic exactness of ``G`` (0.7x the conditions, up to 3x faster).

The band along the walls. Where the kernel estimates already meet the conditions (lattices) only the
unknowns within ``band_layers`` rings of the missed conditions are corrected. Next to a curved conductor
seen from outside (PEC and coated cylinders on a lattice) the fast variant's band missed conditions at its
own edge (1.5e-5 at 8 spacings per radius; 4 rings: 1.1e-5). Cause: multiplier fields constant along the
derivative's axis (for d/dx, smooth functions of y alone, with the rows' Taylor coefficients) are nearly
null for every pair whose row and column conditions are both imposed; only pairs with a wall (non-free)
column lift them. The kernel estimates miss conditions up to about 4 spacings from the wall (the dense
wall particles change the kernel volumes and fits within a support), beyond the 2-spacing reach of the
fast variant's corrected pairs, so those components could only be carried along the axis to the far walls:
the whole operator. The band is therefore tried again with the wall closure's pairs (every pair with a
wall column, at any distance within the support) before the whole operator: ``path`` "wall band". PEC /
coated cylinder (``run_scattering``, ``mimetic_fast``, 12 periods; loaded machine) at 8 spacings per radius:
set-up 33 / 44 s -> 4.5 / 4.2 s, error 6.5e-3 / 1.1e-1 -> 8.9e-3 / 1.5e-2; coated at 16: 793 s, 4.8e-3 ->
14 s, 1.1e-2 (3 rings: 7.7e-3 at 16, 2.3e-2 at 8: the coated error moves by 2x with such changes); the PEC
cylinder at 16 meets its conditions in the first band (4.5e-4, 12 s). The operators differ: the band's
correction is local, the whole operator's reaches the far walls (relative change of ``G`` between them
0.12-0.15 on a PEC cylinder at 8 spacings per radius). The default variant (every pair correctable) meets
the conditions in its first band.

Spurious modes. On independently sampled (Poisson) E and H sets the E -> E operator can have eigenvectors
localised on a few particles with eigenvalues among the physical ones (:func:`localised_modes` reports them:
participation number ``1 / sum v^4``). They sit where the free E particles locally outnumber the H
particles (two gradient rows per shared H particle): on the Poisson square at 24 spacings (seed=2) the mode
below the fundamental has 8 E against 3 H particles within 1.5 dr (7 and 7 on average); there ``G`` has a
near-null vector, mostly made by the correction (the kernel-estimate ``G0`` answers that vector about 2.6x
more strongly: Rayleigh quotient 12.95 against 1.96 (pi c)^2).
No setting of the fit or correction weights removed them (measured: ``WEIGHT_POWER`` 0-8, the weight core,
blends of fits, correction-only weight powers 0-8, ``VOLUME_WEIGHT`` 0.01-1, ``WEIGHT_FLOOR`` 1e-4-0.1, the
E rows' own fit as the prior, quadratic-exact columns; steeper correction weights or freer volumes push the
modes up only by giving up accuracy: fundamental error 0.1 % -> 0.3-1.8 % at 24 spacings). The layout
removes them: :func:`manifold_sph.spem.layouts.balanced_poisson_layout` (and ``balanced_disk_layout``) add
H particles where the E particles are locally in excess (:func:`manifold_sph.spem.layouts.balance_h`).

Measured (``benchmarks/spem_mimetic.py``) in docs/method.md section 7.

Examples
--------
>>> from manifold_sph.spem import make_layout
>>> lay = make_layout("poisson", (0.0, 1.0, 0.0, 1.0), 0.1, seed=1)
>>> free = ~lay.e_fixed
>>> ops = mimetic_operators(lay.e, free, [(lay.hy, 0), (lay.hx, 1)], h=0.15, scale=0.1)
>>> (Gx, Dx), (Gy, Dy) = ops.pairs
>>> q = lay.e[:, 0] ** 2 + 3 * lay.e[:, 0] * lay.e[:, 1]          # quadratic Ez
>>> bool(np.allclose(Gx @ q, 2 * lay.hy[:, 0] + 3 * lay.hy[:, 1], atol=1e-6))  # G exact for quadratics
True
>>> u = 2 * lay.hy[:, 0] - lay.hy[:, 1] + 1                         # linear Hy
>>> bool(np.allclose(Dx @ u, 2.0, atol=1e-6))                        # D exact for linear fields
True
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..kernels import Kernel, get_kernel
from .operators import SUPERNODAL_MIN_N, cross_pairs, supernodal_available, supernodal_cholesky_solve

__all__ = ["MimeticOperators", "mimetic_operators", "quadratic_gradient", "kernel_volumes", "LocalisedModes",
           "localised_modes"]

#: Polynomial degree for which the gradient G is exact: 3 (cubic) by default. Measured on the TM22 mode of a
#: Poisson square at 28 spacings (seed=1): the Rayleigh quotient is -2.2 % off with quadratic fits (h = 1.2 dr;
#: G damps short waves) and -0.2 % with cubic fits (h = 1.5 dr); the order of the scheme is 2 either way (D is
#: exact for linear fields only).
GRADIENT_DEGREE = 3
#: Weight of the relative volume changes against the flux-weight changes in the correction (1.0 let one H
#: volume of a Poisson disk fall to 2e-4 of its estimate: a stable step 0.009 of the CFL step; 0.1: 0.17).
VOLUME_WEIGHT = 0.1
#: The fit and correction weights are ``W_h(r) / (r / dr)^WEIGHT_POWER``: steep weights favour the nearest
#: particles (on a lattice the quadratic fit then tends to Yee's two-point difference, the most compact
#: stencil exact for quadratics).
WEIGHT_POWER = 4.0
#: Only the flux weights of pairs closer than this many spacings are corrected (inf: every pair; 1.5 was
#: measured to make the fit infeasible: non-positive volumes on Poisson and jittered layouts; 2.0 with
#: :data:`CORRECTION_DEGREE` 2 is feasible and narrows the coupling of the normal equations).
CORRECTION_RADIUS = np.inf
#: Degree of the exactness the correction keeps in the H rows (3: the cubic rows stay cubic-exact; 2: G
#: ends exact for quadratics only, 6 instead of 10 conditions per row; with :data:`CORRECTION_RADIUS` 2.0
#: the solve is 3-10x faster, see :data:`FAST`).
CORRECTION_DEGREE = 3
#: The faster variant (``fast=True``): ``(CORRECTION_DEGREE, CORRECTION_RADIUS) = (2, 2.0)``.
FAST = (2, 2.0)
#: The fit weights' ``r / dr`` is taken no smaller than this (a particle on top of another would take the whole fit).
WEIGHT_CORE = 0.25
#: Floor of the kernel weights of the gradient correction (relative to the centre value).
WEIGHT_FLOOR = 1e-2
#: The correction touches only the unknowns within this many rings of the conditions the kernel estimates
#: miss (a ring: the unknowns of every condition that shares one with the previous ring); None: all.
BAND_LAYERS: int | None = 2
#: A condition counts as met below this (dimensionless: volumes ~1, spacing 1).
BAND_TOL = 1e-9
#: The band's correction is kept when it meets every condition to this (and keeps the volumes positive); the
#: whole operator is corrected otherwise (its own residual, with the solve's regularisation: 1e-10 to 4e-9).
BAND_ACCEPT = 1e-7
#: :func:`localised_modes`: an eigenvector whose participation number ``1 / sum v^4`` (unit 2-norm) is below
#: this counts as localised (measured on Poisson squares: 1.8-8 for the spurious modes, about 450 for the
#: physical ones at 24 spacings).
LOCALISED_PARTICIPATION = 20.0
#: :func:`localised_modes`: dense eigensolver up to this many free E particles, shift-invert Lanczos above.
DENSE_MODES = 3000


def _band(A: sp.csr_matrix, on: np.ndarray, bad: np.ndarray, layers: int) -> tuple[np.ndarray, np.ndarray]:
    """Correctable unknowns within ``layers`` rings of the ``bad`` conditions, and the conditions they touch."""
    P = A.copy()
    P.data = np.ones_like(P.data)
    P = P[:, on]
    rows = bad.astype(np.float64)
    cols = np.zeros(P.shape[1])
    for _ in range(max(int(layers), 1)):
        cols = (P.T @ rows > 0).astype(np.float64)
        rows = (P @ cols > 0).astype(np.float64)
    cor = np.zeros(len(on), bool)
    cor[np.flatnonzero(on)[cols > 0]] = True
    return cor, np.flatnonzero(rows > 0)


@dataclass
class MimeticOperators:
    """What :func:`mimetic_operators` returns.

    ``pairs[k] = (G, D)`` for each requested ``(H points, axis)``: ``G`` (n_H, n_E) over every E particle,
    ``D`` (n_free, n_H) on the free E particles; ``vol_e`` (n_E,) (set on the free particles, 0 elsewhere),
    ``vol_h`` one (n_H,) array per pair; ``residual`` the largest relative miss of the column conditions
    after the correction; ``correction`` the relative size of the change of ``G`` (Frobenius);
    ``volume_change`` the largest relative change of a volume; ``seconds`` the wall-clock time of the
    set-up's parts ("fit": volumes and gradient fits, "assembly": the conditions, "normal": the normal
    equations, "factor": their factorisation and solve, "total"); ``path`` where the correction was made:
    "band" (along the walls), "wall band" (the band with the wall closure's pairs, see
    :func:`mimetic_operators`) or "whole" (the whole operator).
    """

    pairs: list
    vol_e: np.ndarray
    vol_h: list
    residual: float
    correction: float
    volume_change: float
    path: str = "whole"
    seconds: dict = field(default_factory=dict)


def _pairs(rows: np.ndarray, cols: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~manifold_sph.spem.operators.cross_pairs` (sorted by row, then column), indices only."""
    i, j, _ = cross_pairs(rows, cols, radius)
    return i, j


def _monomials(z: np.ndarray, degree: int) -> np.ndarray:
    zx, zy = z[:, 0], z[:, 1]
    out = [np.ones(len(z)), zx, zy]
    if degree >= 2:
        out += [zx * zx, zx * zy, zy * zy]
    if degree >= 3:
        out += [zx**3, zx * zx * zy, zx * zy * zy, zy**3]
    return np.stack(out, axis=1)


#: Pairs per chunk of the gradient's coefficient gather (bounded scratch memory).
_PAIR_CHUNK = 65536


def _n_monomials(degree: int) -> int:
    return (degree + 1) * (degree + 2) // 2


def kernel_volumes(points: np.ndarray, h: float, kernel: str | Kernel | type[Kernel] = "cubic") -> np.ndarray:
    """``1 / sum_j W_h(x_i - x_j)`` over the particle's own set (the SPH volume estimate, 2D)."""
    k = get_kernel(kernel)
    i, j = _pairs(points, points, k.support * h)
    R = np.linalg.norm(points[j] - points[i], axis=1) / h
    s = np.bincount(i, weights=k.w(R), minlength=len(points)) * k.alpha(2) / h**2
    return 1.0 / s


def quadratic_gradient(rows: np.ndarray, cols: np.ndarray, h: float, *, kernel: str | Kernel | type[Kernel] = "cubic",
                       scale: float = 1.0, degree: int = 2, max_condition: float = 1e12,
                       row_name: str = "H particles", col_name: str = "E particles"
                       ) -> tuple[sp.csr_matrix, sp.csr_matrix, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Moving-least-squares gradient from ``cols`` to ``rows``, exact for polynomials of ``degree`` (2 or 3).

    With ``degree=3`` the rows whose cubic fit is singular or ill-conditioned (e.g. particles on a straight
    wall, with three rows of neighbours) fall back to the quadratic fit; a row whose quadratic fit is
    singular too is refused (ValueError).

    Returns ``(Gx, Gy, i, j, w, deg)``: the two csr matrices (rows x cols), the pair lists and fit weights in
    their storage order, and the degree of each row's fit.
    """
    k = get_kernel(kernel)
    i, j = _pairs(rows, cols, k.support * h)
    z = (cols[j] - rows[i]) / scale
    R = np.linalg.norm(z, axis=1) * (scale / h)
    w = k.w(R) / np.maximum(np.linalg.norm(z, axis=1), WEIGHT_CORE) ** WEIGHT_POWER
    n = len(rows)
    count = np.bincount(i, minlength=n)
    few = count < 6
    if few.any():
        first = int(np.flatnonzero(few)[0])
        raise ValueError(
            f"{int(few.sum())} of {n} {row_name} have fewer than 6 neighbours among the {col_name} within kappa*h = "
            f"{k.support * h:.4g} (first: index {first} at {rows[first].tolist()}, {int(count[first])}); the "
            f"second-order (mimetic) coupling needs a wider support: increase h_ratio (1.5 or more)"
        )
    deg = np.full(n, degree)
    coef = np.zeros((len(i), 2))
    for d in sorted({degree, 2}, reverse=True):
        todo = deg == d
        if not todo.any():
            continue
        m = _n_monomials(d)
        sel = todo[i]
        ii, P, ww = i[sel], _monomials(z[sel], d), w[sel]
        A = np.zeros((n, m, m))
        for a in range(m):
            for c in range(a, m):
                A[:, a, c] = A[:, c, a] = np.bincount(ii, weights=ww * P[:, a] * P[:, c], minlength=n)
        A[~todo] = np.eye(m)
        ev = np.abs(np.linalg.eigvalsh(A))  # A symmetric: its singular values (the 2-norm condition, not an SVD)
        with np.errstate(divide="ignore", invalid="ignore"):
            cond = ev.max(axis=1) / ev.min(axis=1)
        bad = ~(cond < max_condition) | (count < m)
        if bad.any() and d == 3:
            deg[bad & todo] = 2  # refit these rows with quadratics
            sel &= ~bad[i]
            ii, P, ww = i[sel], _monomials(z[sel], d), w[sel]
            A[bad] = np.eye(m)
        elif bad.any():
            first = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"{int(bad.sum())} {row_name} have a singular or ill-conditioned quadratic fit (condition "
                f"{cond[first]:.3g}; first: index {first} at {rows[first].tolist()}): their {col_name} neighbours "
                f"are too few or collinear; increase h_ratio"
            )
        B = np.ascontiguousarray(np.linalg.inv(A)[:, 1:3, :])  # the two gradient rows of each inverse
        del A
        out = np.empty((ii.size, 2))
        for lo in range(0, ii.size, _PAIR_CHUNK):  # gathered per chunk: B[ii] whole is 16 m bytes a pair
            hi = min(lo + _PAIR_CHUNK, ii.size)
            out[lo:hi] = np.einsum("pak,pk->pa", B[ii[lo:hi]], P[lo:hi])
        coef[sel] = out * ww[:, None] / scale
    shape = (n, len(cols))
    Gx = sp.csr_matrix((coef[:, 0], (i, j)), shape=shape)
    Gy = sp.csr_matrix((coef[:, 1], (i, j)), shape=shape)
    return Gx, Gy, i, j, w, deg


def mimetic_operators(e: np.ndarray, free: np.ndarray, h_sets: list[tuple[np.ndarray, int]], h: float, *,
                      kernel: str | Kernel | type[Kernel] = "cubic",
                      scale: float = 1.0, vol_e0: np.ndarray | None = None, vol_h0: list[np.ndarray] | None = None,
                      fit_volumes: bool = True, degree: int | None = None, fast: bool = False,
                      band_layers: int | None | str = "auto") -> MimeticOperators:
    """The skew-adjoint, second-order pairs ``(G, D)`` for each ``(H points, axis)`` in ``h_sets``.

    Parameters
    ----------
    e : (n_E, 2) array
        Every E particle (free, PEC and driven).
    free : (n_E,) bool array
        The E particles that are unknowns (rows of ``D``, energy carriers).
    h_sets : list of (points, axis)
        ``(Hy, 0)`` for d/dx and ``(Hx, 1)`` for d/dy; the same array may appear twice (shared H set).
    h : float
        Smoothing length (support ``kappa h``); about ``1.2 dr`` or more with the cubic kernel.
    scale : float
        The spacing (makes the systems dimensionless).
    vol_e0, vol_h0 : arrays, optional
        Volume priors (default: the kernel estimates).
    fit_volumes : bool
        Step 1 (volume least squares); without it the priors are used as they are.
    fast : bool
        Correct only pairs closer than 2 spacings and keep only quadratic exactness of ``G`` (:data:`FAST`;
        default: :data:`CORRECTION_DEGREE`, :data:`CORRECTION_RADIUS`, cubic-exact ``G``).
    band_layers : int, None or "auto"
        Correct only the unknowns within this many rings of the conditions the kernel estimates miss
        (:func:`_band`): on lattices with walls, a band along the walls instead of the whole domain. When
        the band's correction misses a condition by more than :data:`BAND_ACCEPT` or a volume turns
        non-positive, the band is tried again with every pair that has a wall (non-free) column correctable
        (``fast``: the wall closure beyond 2 spacings; curved conductors seen from outside), and then the
        whole operator is corrected (the band is the whole operator when it covers everything: irregular
        layouts). None: always the whole operator; "auto": :data:`BAND_LAYERS`.
    """
    c_degree, c_radius = FAST if fast else (CORRECTION_DEGREE, CORRECTION_RADIUS)
    if not (band_layers is None or band_layers == "auto"
            or (isinstance(band_layers, (int, np.integer)) and not isinstance(band_layers, bool) and band_layers >= 1)):
        raise ValueError(f"band_layers must be a positive int, None (the whole operator) or 'auto', got {band_layers!r}")
    degree = GRADIENT_DEGREE if degree is None else degree
    if degree not in (2, 3):
        raise ValueError(f"degree must be 2 or 3, got {degree!r}")
    e = np.asarray(e, dtype=np.float64)
    free = np.asarray(free, dtype=bool)
    n_e = len(e)
    fidx = np.flatnonzero(free)
    n_f = len(fidx)
    where = -np.ones(n_e, dtype=np.int64)
    where[fidx] = np.arange(n_f)
    # distinct H sets (a shared set keeps one volume vector)
    sets, set_of = [], []
    for pts, _axis in h_sets:
        for s_idx, q in enumerate(sets):
            if q is pts:
                set_of.append(s_idx)
                break
        else:
            sets.append(pts)
            set_of.append(len(sets) - 1)
    t_start = time.perf_counter()
    seconds = {"fit": 0.0, "assembly": 0.0, "normal": 0.0, "factor": 0.0}
    ve0 = (kernel_volumes(e, h, kernel) if vol_e0 is None else np.asarray(vol_e0, float)) / scale**2
    vh0 = [(kernel_volumes(p, h, kernel) if vol_h0 is None else np.asarray(vol_h0[k], float)) / scale**2
           for k, p in enumerate(sets)]
    grads, degs = [], []
    for pts, axis in h_sets:
        Gx, Gy, i, j, w, deg = quadratic_gradient(pts, e, h, kernel=kernel, scale=scale, degree=degree)
        G = Gx if axis == 0 else Gy
        grads.append((G.data * scale, i, j, w))
        degs.append(deg)  # dimensionless, aligned with (i, j)
    offs_h = np.cumsum([0] + [len(v) for v in vh0])
    seconds["fit"] = time.perf_counter() - t_start
    # Unknowns: the flux weights Q = V_H G of every pair (linear in everything), then V_H of each
    # distinct set and V_E of the free particles. Constraints (all homogeneous, linear):
    #   rows    sum_j Q_ij p(x_j - x_i) - V_i dp/dx_a(0) = 0   (6 quadratic monomials per H row)
    #   columns sum_i Q_ij {1, y_a, y_b} + V_j {0, 1, 0} = 0   (3 per free E column, y = x_i - x_j)
    n_q = [len(g) for g, *_ in grads]
    offs_q = np.cumsum([0] + n_q)
    o_vh = int(offs_q[-1])
    o_ve = o_vh + int(offs_h[-1])
    n_u = o_ve + n_f
    R_, C_, V_ = [], [], []
    n_con = 0
    q0 = []
    for k, ((g, i, j, w), (pts, axis)) in enumerate(zip(grads, h_sets)):
        n_h = len(pts)
        other = 1 - axis
        z = (e[j] - pts[i]) / scale  # x_j - x_i
        vcol = o_vh + offs_h[set_of[k]]
        Mr = _monomials(z, degree)
        m_row = np.array([_n_monomials(d) for d in (0, 1, 2, 3)])[np.minimum(degs[k], c_degree)]
        row_off = n_con + np.r_[0, np.cumsum(m_row)[:-1]]
        for c in range(Mr.shape[1]):
            use = np.flatnonzero(c < m_row[i])
            R_.append(row_off[i[use]] + c)
            C_.append(offs_q[k] + use)
            V_.append(Mr[use, c])
        # - V_i d/dx_axis of the monomial at 0: monomial 1 + axis is x_axis (derivative 1)
        R_.append(row_off + 1 + axis)
        C_.append(vcol + np.arange(n_h))
        V_.append(-np.ones(n_h))
        n_con += int(m_row.sum())
        sel = np.flatnonzero(free[j])
        jj = where[j[sel]]
        y = -z[sel]
        for c, val in enumerate((np.ones(len(sel)), y[:, axis], y[:, other])):
            R_.append(n_con + 3 * jj + c)
            C_.append(offs_q[k] + sel)
            V_.append(val)
        R_.append(n_con + 3 * np.arange(n_f) + 1)
        C_.append(o_ve + np.arange(n_f))
        V_.append(np.ones(n_f))
        n_con += 3 * n_f
        q0.append(g * vh0[set_of[k]][i])
    A = sp.csr_matrix((np.concatenate(V_), (np.concatenate(R_), np.concatenate(C_))), shape=(n_con, n_u))
    u0 = np.concatenate(q0 + list(vh0) + [ve0[fidx]])
    wq = np.concatenate([np.maximum(w, WEIGHT_FLOOR * w.max()) * vh0[set_of[k]][i]
                         for k, (g, i, j, w) in enumerate(grads)])
    wv = VOLUME_WEIGHT * np.concatenate(list(vh0) + [ve0[fidx]]) ** 2
    wt = np.r_[wq, wv] if fit_volumes else np.r_[wq, 1e-14 * wv]
    near = np.concatenate([np.linalg.norm(e[j] - h_sets[k][0][i], axis=1) < c_radius * scale
                           for k, (g, i, j, w) in enumerate(grads)])
    on = np.r_[near, np.ones(n_u - o_vh, bool)]
    # the wall closure: the pairs with a wall (non-free) column, at any distance (a second band attempt)
    wall = np.r_[np.concatenate([~free[j] for g, i, j, w in grads]), np.zeros(n_u - o_vh, bool)]
    layers = BAND_LAYERS if band_layers == "auto" else band_layers
    seconds["assembly"] = time.perf_counter() - t_start - seconds["fit"]
    u, delta, after, path = _correct(A, u0, wt, on, o_vh, layers, wall, seconds)
    ve = u[o_ve:]
    vh = [u[o_vh + offs_h[s]: o_vh + offs_h[s + 1]] for s in range(len(sets))]
    v_all = np.r_[np.concatenate(vh), ve]
    if not np.all(v_all > 0):
        raise ValueError(f"the mimetic volume fit gave {int((v_all <= 0).sum())} non-positive volumes: the "
                         f"neighbourhoods are too small for the second-order conditions; increase h_ratio or use "
                         f"coupling='sbp'")
    volume_change = float(np.abs(v_all / np.r_[np.concatenate(vh0), ve0[fidx]] - 1).max())
    worst = float(np.abs(after).max())
    corr = float(np.linalg.norm(delta[:o_vh]) / np.linalg.norm(u0[:o_vh]))
    pairs = []
    for k, ((g, i, j, w), (pts, axis)) in enumerate(zip(grads, h_sets)):
        vhk = vh[set_of[k]]
        Q = sp.csr_matrix((u[offs_q[k]: offs_q[k + 1]], (i, j)), shape=(len(pts), n_e))
        G = (sp.diags(1.0 / (vhk * scale)) @ Q).tocsr()
        D = (-(sp.diags(1.0 / (ve * scale)) @ Q[:, fidx].T)).tocsr()
        pairs.append((G, D))
    vol_e = np.zeros(n_e)
    vol_e[fidx] = ve * scale**2
    seconds["total"] = time.perf_counter() - t_start
    return MimeticOperators(pairs, vol_e, [vh[s] * scale**2 for s in set_of], worst, corr, volume_change, path,
                            seconds)


def _solve_spd(K: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
    """``K^-1 rhs`` for the symmetric positive definite normal equations (SuperLU, no pivoting, symmetric mode)."""
    K = K.tocsc()
    K = K + sp.identity(K.shape[0], format="csc") * (1e-13 * K.diagonal().max())
    if K.shape[0] >= SUPERNODAL_MIN_N and supernodal_available():  # CHOLMOD supernodal where installed (docs/spem.md)
        try:
            return supernodal_cholesky_solve(K, rhs)
        except ArithmeticError:
            pass
    # K is symmetric positive definite: no pivoting, symmetric ordering (half the fill of a general LU)
    return splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}).solve(rhs)


def _correct(A: sp.csr_matrix, u0: np.ndarray, wt: np.ndarray, on: np.ndarray, o_vh: int,
             layers: int | None, wall: np.ndarray | None = None, seconds: dict | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """The smallest ``wt^-1``-weighted change of ``u0`` among the unknowns ``on`` with ``A u = 0``.

    Returns ``(u, delta, A u, path)``, ``path`` one of "band", "wall band", "whole". With ``layers`` the
    change is sought in a band first (:func:`_band`); when the band's misses a condition by more than
    :data:`BAND_ACCEPT` or a volume (``u[o_vh:]``) turns non-positive, in the band of the unknowns
    ``on | wall`` (the wall closure's pairs, when ``wall`` adds any), and then on the whole operator
    (``on``). ``seconds`` (optional) accumulates the time of the normal equations ("normal") and of their
    factorisation and solve ("factor").
    """
    n_u = len(u0)
    res = -(A @ u0)

    seconds = {} if seconds is None else seconds

    def solve(cor, rows, name):
        t0 = time.perf_counter()
        Ab = A[rows][:, cor] if rows is not None else A[:, cor]
        AW = Ab @ sp.diags(wt[cor])
        K = AW @ Ab.T
        t1 = time.perf_counter()
        lam = _solve_spd(K, res[rows] if rows is not None else res)
        seconds["normal"] = seconds.get("normal", 0.0) + t1 - t0
        seconds["factor"] = seconds.get("factor", 0.0) + time.perf_counter() - t1
        delta = np.zeros(n_u)
        delta[cor] = AW.T @ lam
        u = u0 + delta
        return u, delta, A @ u, name

    if layers is not None:  # correct only the unknowns within `layers` rings of the unmet conditions
        bad = np.abs(res) > BAND_TOL
        tries = [(on, "band")] + ([(on | wall, "wall band")] if wall is not None and (wall & ~on).any() else [])
        for use, name in tries:
            cor, rows = _band(A, use, bad, layers)
            if cor.sum() == use.sum():  # irregular layouts: the band is everything, the whole operator
                break
            out = solve(cor, rows, name)
            if np.abs(out[2]).max() < BAND_ACCEPT and np.all(out[0][o_vh:] > 0):
                return out
    return solve(on, None, "whole")  # the whole operator


@dataclass
class LocalisedModes:
    """What :func:`localised_modes` returns (the ``k`` lowest modes, ascending).

    ``eigenvalues`` (k,): eigenvalues of ``-E''/E`` (units 1 / length^2 with ``eps = mu = 1``: ``k^2`` of the
    mode; over ``pi^2`` for the unit square's 2, 5, 5, 8, ...); ``participation`` (k,): ``1 / sum v^4`` of
    each unit eigenvector of the symmetric form (about 1 for a mode on one particle, of the order of the
    particle count for a physical one); ``localised`` (k,) bool: ``participation < threshold``;
    ``vectors`` (n_free, k): the eigenvectors of the symmetric form ``V_E^(1/2) L V_E^(-1/2)`` (rows: the
    free E particles in index order); ``particles`` (k,): the free E particle (index into ``e``) carrying
    the largest amplitude of each mode.
    """

    eigenvalues: np.ndarray
    participation: np.ndarray
    localised: np.ndarray
    vectors: np.ndarray
    particles: np.ndarray

    @property
    def lowest_localised(self) -> float:
        """The lowest localised eigenvalue among the ``k`` (inf when none is)."""
        return float(self.eigenvalues[self.localised].min(initial=np.inf))


def localised_modes(ops: MimeticOperators, free: np.ndarray, k: int = 16, *,
                    threshold: float = LOCALISED_PARTICIPATION) -> LocalisedModes:
    """The ``k`` lowest modes of the E -> E operator of :func:`mimetic_operators` and how localised they are.

    The lossless operator (``eps = mu = 1``) is ``L = sum_a D_a G_a`` on the free E particles; its
    symmetric form ``S = V_E^(1/2) (-L) V_E^(-1/2)`` is positive semi-definite. On irregular layouts some
    eigenvectors may concentrate on one to a few particles (participation number ``1 / sum v^4`` far below
    that of the physical modes); when their eigenvalues fall among the physical ones they are spurious
    modes: they conserve energy and smooth data hardly excite them, but a broadband source does.

    Parameters
    ----------
    ops : MimeticOperators
        The operators (both axes, e.g. ``[(hy, 0), (hx, 1)]``).
    free : (n_E,) bool array
        The free E particles passed to :func:`mimetic_operators`.
    k : int
        How many of the lowest modes (dense eigensolver up to :data:`DENSE_MODES` free particles,
        shift-invert Lanczos above).
    threshold : float
        Participation number below which a mode counts as localised (:data:`LOCALISED_PARTICIPATION`).

    Returns
    -------
    LocalisedModes

    Examples
    --------
    >>> from manifold_sph.spem import make_layout
    >>> lay = make_layout("jittered", (0.0, 1.0, 0.0, 1.0), 0.1, seed=1)
    >>> ops = mimetic_operators(lay.e, ~lay.e_fixed, [(lay.hy, 0), (lay.hx, 1)], h=0.15, scale=0.1)
    >>> m = localised_modes(ops, ~lay.e_fixed, k=4)
    >>> np.round(m.eigenvalues / np.pi**2, 1).tolist(), bool(m.localised.any())
    ([1.9, 4.9, 4.9, 7.5], False)
    """
    from scipy.sparse.linalg import eigsh

    if not isinstance(ops, MimeticOperators):
        raise TypeError(f"ops must be MimeticOperators, got {type(ops).__name__}")
    free = np.asarray(free)
    if free.dtype != bool or free.shape != ops.vol_e.shape:
        raise ValueError(f"free must be a bool array of shape {ops.vol_e.shape}, got {free.dtype} {free.shape}")
    fidx = np.flatnonzero(free)
    n_f = len(fidx)
    if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)) or not 1 <= k < n_f:
        raise ValueError(f"k must be an int in [1, {n_f - 1}] (free E particles - 1), got {k!r}")
    if not (np.isfinite(threshold) and threshold > 0):
        raise ValueError(f"threshold must be positive and finite, got {threshold!r}")
    for G, D in ops.pairs:
        if D.shape != (n_f, G.shape[0]):
            raise ValueError(f"free selects {n_f} E particles but the operators' D has {D.shape[0]} rows")
    v = ops.vol_e[fidx]
    A = sum(-(D @ G[:, fidx]) for G, D in ops.pairs)
    S = sp.diags(v**0.5) @ A @ sp.diags(v**-0.5)
    S = (0.5 * (S + S.T)).tocsc()
    if n_f <= DENSE_MODES:
        ev, V = np.linalg.eigh(S.toarray())
        ev, V = ev[:k], V[:, :k]
    else:  # shift-invert about a small negative shift (S is semi-definite)
        shift = -1e-3 * float(abs(S).sum(axis=1).max()) / n_f
        ev, V = eigsh(S, k=int(k), sigma=shift, which="LM")
        order = np.argsort(ev)
        ev, V = ev[order], V[:, order]
    part = 1.0 / np.sum(V**4, axis=0)
    return LocalisedModes(ev, part, part < threshold, V, fidx[np.argmax(np.abs(V), axis=0)])
