"""Poisson and screened Poisson problems on a point cloud.

With the stable Laplacian the systems are symmetric: ``K u = -M f`` with one value pinned
on each connected piece (positive definite) and ``(M + alpha K) u = M f``, both solved by
:func:`manifold_sph.solvers.spd_solver` (sparse Cholesky, or CG with multigrid). The strong
form is not symmetric: a bordered system, one zero-mean constraint per piece, by sparse LU.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike
from scipy.sparse.csgraph import connected_components

from .._validation import as_field, check_in, check_positive
from ..operators import OperatorSet
from ..solvers import spd_solver
from .laplacians import Operator, check_surface, fixed_particles, operator_for

__all__ = ["poisson", "screened_poisson"]

SOLVERS = ("auto", "direct", "iterative")
_SPD_METHOD = {"auto": "auto", "direct": "cholesky", "iterative": "amg"}


def _has_boundary(surface) -> bool:
    """A planar domain without mirroring, or a surface whose Voronoi cells found an open boundary."""
    from ..domain import Domain2D

    if isinstance(surface, Domain2D):
        return not surface.mirror
    return surface.stable_report["boundary"] > 0


def _components(A: sp.csr_matrix) -> tuple[int, np.ndarray]:
    return connected_components(A, directed=True, connection="weak")


def poisson(surface: OperatorSet, rhs: ArrayLike, *, dirichlet: tuple[ArrayLike, ArrayLike] | None = None,
            tol: float = 1e-3, laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto",
            solver: str = "auto") -> np.ndarray:
    """Solve ``Lap_S u = rhs``.

    Without ``dirichlet`` the solution is defined up to a constant on each connected
    piece of the cloud: the one with zero mean (``sum m u = 0``) on every piece is
    returned, and ``rhs`` must have zero mean on every piece,
    ``|sum m rhs| <= tol * sum m |rhs|``, otherwise a ValueError quotes the worst
    piece (within the tolerance, the mean is removed). ``m`` is the operator's mass (the
    Voronoi cell areas for the stable Laplacian, the area elements ``dV`` for the strong
    form). With ``dirichlet=(indices, values)`` the given particles are held at the values.

    On a surface with an open boundary (or a planar domain), the stable Laplacian
    solves the Neumann problem (zero normal derivative, its natural condition); the
    strong form has no boundary condition of its own there and needs ``dirichlet``.

    Parameters
    ----------
    surface : Surface or Domain2D
    rhs : array_like, shape (N,)
    dirichlet : (array_like of int, array_like of float), optional
    tol : float
        Relative tolerance on the mean of ``rhs``.
    laplacian : {"auto", "strong", "stable"} or sparse matrix
        See :func:`~manifold_sph.pde.heat`.
    solver : {"auto", "direct", "iterative"}
        Stable Laplacian: sparse Cholesky ("direct"), CG with multigrid ("iterative"), or
        Cholesky where it fits in memory ("auto"). Other Laplacians: sparse LU.

    Returns
    -------
    ndarray, shape (N,)

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(2000)
    >>> x = cloud.points
    >>> u = poisson(Surface(cloud), -12 * x.prod(axis=1))     # Lap_S(xyz) = -12 xyz
    >>> bool(np.linalg.norm(u - x.prod(axis=1)) / np.linalg.norm(x.prod(axis=1)) < 0.02)
    True
    """
    check_surface(surface)
    f = as_field("rhs", rhs, surface.n_points)
    tol = check_positive("tol", tol)
    check_in("solver", solver, SOLVERS)
    op = operator_for(surface, laplacian)
    return poisson_solve(surface, op, f[:, None], dirichlet=dirichlet, tol=tol, solver=solver)[:, 0]


def poisson_solve(surface: OperatorSet, op: Operator, F: np.ndarray, *,
                  dirichlet: tuple[ArrayLike, ArrayLike] | None = None, tol: float = 1e-3,
                  solver: str = "auto") -> np.ndarray:
    """:func:`poisson` for the columns of ``F`` (N, m) with one set-up of the solver."""
    n = surface.n_points
    stable = op.kind == "stable"
    # -S u = B f: (S, B) = (K, M) for the stable Laplacian, (-L, I) otherwise
    S = op.stiffness()
    BF = op.m[:, None] * F if stable else F.copy()
    if dirichlet is not None:
        return _dirichlet(op, S, BF, dirichlet, n, solver)
    if op.kind == "strong" and _has_boundary(surface):
        raise ValueError(
            "poisson with the strong-form Laplacian on a cloud with an open boundary needs a boundary condition: "
            "pass dirichlet=(indices, values), or laplacian='stable' for the Neumann problem"
        )
    m = op.m
    pattern = S.copy()  # not the surface's own matrix
    pattern.eliminate_zeros()
    ncomp, labels = _components(pattern)
    for j in range(F.shape[1]):
        _check_mean(m, F[:, j], labels, ncomp, tol, stable)
    if stable:
        return _pinned(S, BF, m, labels, ncomp, solver)
    # bordered system [[S / s, C], [C^T m / area, 0]] [u, lam] = [-B rhs / s, 0], one constraint per piece;
    # S / s and the areas' weights are of order 1 whatever the cloud's units (S carries 1 / length^2,
    # m length^2: unscaled, LU left a residual above 1e-6 on a unit sphere scaled by 1e3 or 1e-100)
    s = float(np.max(np.abs(S.data))) if S.nnz else 1.0
    area = np.bincount(labels, weights=m, minlength=ncomp)
    C = sp.csr_matrix((np.ones(n), (np.arange(n), labels)), shape=(n, ncomp))
    Cm = sp.csr_matrix((m / area[labels], (labels, np.arange(n))), shape=(ncomp, n))
    A = sp.bmat([[S / s, C], [Cm, None]], format="csc")
    BF = BF / s
    rhs_full = np.vstack([-BF, np.zeros((ncomp, F.shape[1]))])
    with np.errstate(all="ignore"):
        try:
            sol = spla.splu(A).solve(rhs_full)
        except RuntimeError:  # SuperLU: "Factor is exactly singular"
            sol = np.full_like(rhs_full, np.nan)
    U = sol[:n]
    if not np.all(np.isfinite(U)):
        raise ValueError(
            "poisson: the Laplacian is singular beyond one constant per connected piece (its scheme's operator "
            "may have spurious null modes on this cloud); try laplacian='stable'"
        )
    resid = np.linalg.norm(A @ sol - rhs_full) / max(np.linalg.norm(BF), 1e-300)
    if resid > 1e-6:
        raise ValueError(
            f"poisson: the solve did not converge (relative residual {resid:.2e}): the {op.kind} Laplacian is "
            "(nearly) singular on this cloud; try laplacian='stable'"
        )
    return U


def _check_mean(m, f, labels, ncomp, tol, stable):
    mean = np.bincount(labels, weights=m * f, minlength=ncomp)
    scale = np.bincount(labels, weights=np.abs(m * f), minlength=ncomp)
    rel = np.abs(mean) / np.maximum(scale, 1e-300)
    bad = np.flatnonzero(np.abs(mean) > tol * np.maximum(scale, 1e-300))
    if bad.size:
        worst = bad[np.argmax(rel[bad])]
        mn = "m" if stable else "dV"  # the stable Laplacian's cell areas, or the area elements
        where = " over the cloud" if ncomp == 1 else f" on {bad.size} of the cloud's {ncomp} connected pieces (worst: piece {worst})"
        raise ValueError(
            f"rhs must have zero mean{where}, but sum({mn} * rhs) = {mean[worst]:.4g} ({rel[worst]:.2e} of sum({mn} * |rhs|), "
            f"tolerance {tol:g}); subtract its mean" + (" on each piece" if ncomp > 1 else "")
        )


def _pinned(K: sp.csr_matrix, BF: np.ndarray, m: np.ndarray, labels: np.ndarray, ncomp: int, solver: str) -> np.ndarray:
    """``K u = -B f`` with zero mean on each piece: one particle pinned per piece (``K`` without its
    row and column is positive definite), the right-hand side's mean removed first (what the
    tolerance allowed), then the mean of ``u`` on each piece."""
    n = K.shape[0]
    area = np.bincount(labels, weights=m, minlength=ncomp)
    b = -BF
    b -= m[:, None] * (np.stack([np.bincount(labels, weights=col, minlength=ncomp) for col in b.T], axis=1) / area[:, None])[labels]
    pin = np.full(ncomp, n)
    np.minimum.at(pin, labels, np.arange(n))  # the first particle of each piece
    free = np.ones(n, dtype=bool)
    free[pin] = False
    U = np.zeros_like(b)
    if free.any():
        Kf = K[free][:, free]
        U[free] = spd_solver(Kf, method=_SPD_METHOD[solver]).solve(b[free])
    mean = np.stack([np.bincount(labels, weights=m * col, minlength=ncomp) for col in U.T], axis=1) / area[:, None]
    return U - mean[labels]


def _dirichlet(op: Operator, S, BF, dirichlet, n: int, solver: str) -> np.ndarray:
    try:
        idx, vals = dirichlet
    except (TypeError, ValueError):
        raise TypeError("dirichlet must be a pair (indices, values)") from None
    try:
        mask, values = fixed_particles(np.asarray(idx), vals, n, np.zeros(n))
    except (TypeError, ValueError) as exc:  # its messages name heat's fixed= / fixed_values=
        raise type(exc)(f"dirichlet=(indices, values): {exc}") from None
    if not mask.any():
        raise ValueError("dirichlet needs at least one particle")
    free = ~mask
    U = np.zeros_like(BF)
    U[mask] = values[:, None]
    Sf = S[free]
    Sff = Sf[:, free].tocsr()
    Sff.eliminate_zeros()
    ncomp, labels = _components(Sff)
    touched = np.zeros(ncomp, dtype=bool)
    coupled = np.asarray(abs(Sf[:, mask]).sum(axis=1)).ravel() > 0
    touched[labels[coupled]] = True
    if not touched.all():
        raise ValueError(
            f"poisson: {int((~touched).sum())} connected piece(s) of the cloud hold no Dirichlet particle and "
            "touch none, so their solution is not unique; add held particles there"
        )
    rhs = -BF[free] - (Sf[:, mask] @ values)[:, None]
    if op.kind == "stable":  # K restricted to the free particles, each piece touching a held one: SPD
        U[free] = spd_solver(Sff, method=_SPD_METHOD[solver]).solve(rhs)
    else:
        with np.errstate(all="ignore"):
            try:
                U[free] = spla.splu(Sff.tocsc()).solve(rhs)
            except RuntimeError:  # SuperLU: "Factor is exactly singular"
                U[free] = np.nan
    if not np.all(np.isfinite(U)):
        raise ValueError("poisson: the Dirichlet problem is singular for these held particles")
    return U


def screened_poisson(surface: OperatorSet, rhs: ArrayLike, alpha: float, *,
                     laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto",
                     solver: str = "auto") -> np.ndarray:
    """Solve ``u - alpha Lap_S u = rhs`` (alpha > 0), a well-posed smoothing problem.

    With the stable Laplacian: ``(M + alpha K) u = M rhs``, symmetric positive definite
    (``solver`` as in :func:`poisson`); otherwise ``(I - alpha L) u = rhs`` by sparse LU.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(2000)
    >>> z = cloud.points[:, 2]                      # (1 + 2 alpha) u = rhs for Y_1
    >>> u = screened_poisson(Surface(cloud), 3 * z, alpha=1.0)
    >>> bool(np.allclose(u, z, atol=5e-3))
    True
    """
    check_surface(surface)
    n = surface.n_points
    f = as_field("rhs", rhs, n)
    alpha = check_positive("alpha", alpha)
    check_in("solver", solver, SOLVERS)
    op = operator_for(surface, laplacian)
    if op.kind == "stable":
        return spd_solver(sp.diags(op.m) + alpha * op.stiffness(), method=_SPD_METHOD[solver]).solve(op.m * f)
    return spla.spsolve((sp.identity(n, format="csc") - alpha * op.L).tocsc(), f)
