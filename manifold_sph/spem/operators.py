"""Cross-set CSPM derivative matrices (docs/method.md sections 4 and 7).

SPEM stores Ez on one particle set and Hx, Hy on other sets; the derivative
of an H component is needed at the E particles and vice versa. The
neighbours of a row particle are therefore searched among the *other* set
(a KD-tree over the column set, queried at the row points), and because the
field is not known at the row particle itself the centre value is either
reconstructed (Shepard) or solved for together with the derivatives.

Three forms of the per-particle system, with ``x = x_j - x_i``,
``W = W_h(x)``, ``W_a = dW/dx_a`` and ``S[g] = sum_j g_j dV_j``:

``"fpm"`` (default)
    The (d+1)x(d+1) system with rows weighted by ``W, W_1, .., W_d`` and
    columns ``1, x_1, .., x_d``, unknowns ``(f_i, f_x, ...)`` ([2] eqs.
    2.30-2.35). It differentiates every linear field exactly on any layout,
    including truncated neighbourhoods at walls.
``"cspm"``
    The full dxd CSPM solve ``M g = b`` with ``M[a,c] = S[x_c W_a]``,
    ``b[a] = S[(f_j - f~_i) W_a]`` and the centre value ``f~_i`` the
    Shepard interpolant ``S[f_j W] / S[W]``.
``"diagonal"``
    The scalar ratios of [2] (eqs. 3.6-3.9), the diagonal of the CSPM
    system: ``f_a = S[(f_j - f~_i) W_a] / S[x_a W_a]``.

On a symmetric neighbourhood all three coincide. Each is linear in the
field, so it is assembled once as a sparse matrix (rows: row set, columns:
column set).

Examples
--------
>>> import numpy as np
>>> e = np.array([[0.0, 0.0]])
>>> g = np.mgrid[-2:3, -2:3].reshape(2, -1).T + 0.5
>>> Dx, Dy = cross_gradient(e, g, h=1.0, kernel="cubic")
>>> float(np.round(Dx @ (3 * g[:, 0] - g[:, 1]), 12)[0]), float(np.round(Dy @ (3 * g[:, 0] - g[:, 1]), 12)[0])
(3.0, -1.0)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from .._validation import as_points, check_in, check_positive
from ..kernels import Kernel, get_kernel

__all__ = ["FORMS", "COUPLINGS", "DEFAULT_COUPLING", "DEFAULT_H_RATIO", "MIMETIC_H_RATIO", "SBP_LAYERS", "cross_pairs",
           "cross_gradient", "sbp_correct", "sbp_pair", "nearest_plane", "mirror_fields",
           "normal_solve", "supernodal_available", "supernodal_cholesky_solve"]

#: Names of the per-particle derivative systems.
FORMS = ("fpm", "cspm", "diagonal")

#: Couplings of the E and H derivative matrices (see :class:`.TMzSolver`).
COUPLINGS = ("sbp", "mimetic", "adjoint", "direct")
#: The default: energy-conserving (stable for every layout, h_ratio and material).
DEFAULT_COUPLING = "sbp"
#: Default smoothing length over spacing (cubic kernel, support 2h = 1.4 dr:
#: the nearest cross neighbours and the next row/column).
DEFAULT_H_RATIO = 0.7
#: Default ``h / dr`` of the "mimetic" coupling (its cubic fits need 10 neighbours or more; 1.2 leaves
#: some Poisson particles with fewer).
MIMETIC_H_RATIO = 1.5

#: Default rings of pairs, around the columns that miss their adjoint
#: conditions, that :func:`sbp_pair` may change (None: the whole operator).
#: Measured: on rectangles (Yee, staggered, jittered) 2 rings and the whole
#: operator give the same phase velocity to 5 digits, with a set-up 5-30x
#: faster; next to the curved wall of the circular cavity 2 rings stall
#: (field error 1.5e-2 / 2.8e-3 / 1.5e-3 / 9.4e-4 at 10 / 20 / 40 / 80
#: spacings per radius, stable dt 0.07 of the CFL step at 80) where the whole
#: operator keeps converging (1.5e-2 / 3.9e-3 / 1.3e-3 / 5.2e-4).
SBP_LAYERS = 2
SBP_REGULARISATION = 1e-12
#: ``normal_solve(method="auto")`` takes the supernodal path from this many unknowns (below, cholespy's simplicial
#: factorisation is faster: cavity at 10 spacings per radius 0.21 s against 0.6 s of set-up; docs/spem.md).
SUPERNODAL_MIN_N = 20_000


def cross_pairs(rows: np.ndarray, cols: np.ndarray, radius: float, *, row_name: str = "rows",
                col_name: str = "cols") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All pairs (i, j) with ``|cols[j] - rows[i]| < radius``.

    Parameters
    ----------
    rows, cols : (N, d) and (M, d) arrays
        Row and column point sets (d = 1 or 2).
    radius : float
        Search radius (the kernel support ``kappa * h``).

    Returns
    -------
    i, j : int arrays
        Pair indices sorted by row, then column.
    x : (P, d) array
        ``cols[j] - rows[i]``.
    """
    radius = check_positive("radius", radius)
    # two trees and one compiled dual-tree pass: no Python list per row (the same pairs, half the time)
    found = cKDTree(rows).sparse_distance_matrix(cKDTree(cols), np.nextafter(radius, 0.0), output_type="ndarray")
    i, j = found["i"].astype(np.int64), found["j"].astype(np.int64)
    del found
    order = np.lexsort((j, i))
    i, j = i[order], j[order]
    return i, j, cols[j] - rows[i]


def cross_gradient(rows: ArrayLike, cols: ArrayLike, h: float | ArrayLike, *, kernel: str | Kernel | type[Kernel] = "cubic",
                   form: str = "fpm", dV: float | ArrayLike | None = None,
                   row_name: str = "rows", col_name: str = "cols", max_condition: float = 1e10) -> list[sp.csr_matrix]:
    """Sparse first-derivative matrices from the column set to the row set.

    Parameters
    ----------
    rows : (N, d) array
        Points where the derivatives are wanted (d = 1 or 2).
    cols : (M, d) array
        Points carrying the field.
    h : float or (N,) array
        Smoothing length of each row particle.
    kernel : str or Kernel
        Kernel name (``manifold_sph.kernels``); ``"cubic"`` by default.
    form : {"fpm", "cspm", "diagonal"}
        Per-particle system (see the module docstring).
    dV : None, float or (M,) array
        Volume (length, area) of each column particle; uniform if None.
    row_name, col_name : str
        Names used in error messages (e.g. "E particles", "H particles").
    max_condition : float
        Largest accepted condition number of a per-particle system.

    Returns
    -------
    list of d scipy.sparse.csr_matrix of shape (N, M)
        ``D[a] @ f`` approximates ``df/dx_a`` at the row points.

    Raises
    ------
    ValueError
        A row particle has too few (or collinear) neighbours in the column
        set; the message names the set, the count and the first index.
    """
    form = check_in("form", form, FORMS)
    rows = np.asarray(rows, dtype=np.float64)
    cols = np.asarray(cols, dtype=np.float64)
    d = rows.shape[1] if rows.ndim == 2 else 0
    rows = as_points(row_name, rows, dim=(1, 2))
    cols = as_points(col_name, cols, dim=d)
    if len(rows) == 0 or len(cols) == 0:
        empty = row_name if len(rows) == 0 else col_name
        raise ValueError(f"{empty} is empty: need at least one particle in each set")
    k = get_kernel(kernel)
    n = len(rows)
    h_arr = np.broadcast_to(np.asarray(h, dtype=np.float64), (n,)).copy()
    if not np.all(np.isfinite(h_arr) & (h_arr > 0)):
        raise ValueError(f"h must be finite and positive, got min {h_arr.min()!r}")
    if dV is None:
        dV = np.ones(len(cols))
    dV = np.broadcast_to(np.asarray(dV, dtype=np.float64), (len(cols),))
    i, j, x = cross_pairs(rows, cols, k.support * h_arr.max(), row_name=row_name, col_name=col_name)
    hi = h_arr[i]
    r = np.sqrt((x * x).sum(axis=1))
    R = r / hi
    keep = R < k.support
    i, j, x, r, R, hi = i[keep], j[keep], x[keep], r[keep], R[keep], hi[keep]
    count = np.bincount(i, minlength=n)
    need = d + 1 if form == "fpm" else 1
    few = count < need
    if few.any():
        first = int(np.flatnonzero(few)[0])
        raise ValueError(
            f"{int(few.sum())} of {n} {row_name} have fewer than {need} neighbours among the {col_name} "
            f"within kappa*h = {k.support * h_arr[first]:.4g} (first: index {first} at {rows[first].tolist()}, "
            f"{int(count[first])} neighbours); increase h or add {col_name} near it"
        )
    # W (up to the normalisation, which cancels in every form) and grad W
    # with respect to x_j: dW/dx_a = w'(R)/h * x_a / r.
    W = k.w(R) * dV[j]
    G = (k.dw_over_R(R) / hi**2)[:, None] * x * dV[j][:, None]  # w'(R)/R * x / h^2
    if form == "fpm":
        psi = np.concatenate([W[:, None], G], axis=1)  # (P, d+1)
        phi = np.concatenate([np.ones((len(i), 1)), x], axis=1)
        A = _batched_moments(i, psi, phi, n)
        Ainv = _safe_inverse(A, max_condition, row_name, col_name, rows)
        coef = np.einsum("pak,pk->pa", Ainv[i][:, 1:, :], psi)
    else:
        sW = np.bincount(i, weights=W, minlength=n)
        sG = np.stack([np.bincount(i, weights=G[:, a], minlength=n) for a in range(d)], axis=1)
        psi = G - (W / sW[i])[:, None] * sG[i]  # W_a with the Shepard centre removed
        M = _batched_moments(i, G, x, n)
        if form == "cspm":
            Minv = _safe_inverse(M, max_condition, row_name, col_name, rows)
            coef = np.einsum("pak,pk->pa", Minv[i], psi)
        else:
            diag = np.diagonal(M, axis1=1, axis2=2)
            bad = ~(np.abs(diag) > 0)
            if bad.any():
                first = int(np.flatnonzero(bad.any(axis=1))[0])
                raise ValueError(f"{row_name} {first} has a singular diagonal CSPM moment (neighbours collinear)")
            coef = psi / diag[i]
    return [sp.csr_matrix((coef[:, a], (i, j)), shape=(n, len(cols))) for a in range(d)]


def _batched_moments(i, psi, phi, n):
    """``A[i, a, c] = sum_p psi[p, a] phi[p, c]`` over the pairs of row i."""
    ka, kc = psi.shape[1], phi.shape[1]
    A = np.empty((n, ka, kc))
    for a in range(ka):
        for c in range(kc):
            A[:, a, c] = np.bincount(i, weights=psi[:, a] * phi[:, c], minlength=n)
    return A


def _safe_inverse(A, max_condition, row_name, col_name, rows):
    cond = np.linalg.cond(A)
    bad = ~(cond < max_condition)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{int(bad.sum())} {row_name} have a singular or ill-conditioned derivative system "
            f"(condition {cond[first]:.3g} > {max_condition:.3g}; first: index {first} at {rows[first].tolist()}): "
            f"their {col_name} neighbours are too few or collinear"
        )
    return np.linalg.inv(A)


def sbp_correct(D: sp.spmatrix | sp.sparray, rows: np.ndarray, cols: np.ndarray, axis: int,
                vol_rows: ArrayLike, vol_cols: ArrayLike,
                col_mask: np.ndarray | None = None, scale: float = 1.0) -> sp.csr_matrix:
    """Smallest change of ``D`` (same sparsity) that makes its negative adjoint consistent too.

    ``D`` (rows x cols) approximates ``d/dx_axis`` from the column set to the
    row set and is exact for linear fields (row conditions, kept). The
    returned ``D + Delta`` also satisfies, for every column j in
    ``col_mask``, the column conditions that make
    ``G = -V_cols^-1 D^T V_rows`` exact for linear fields at j:

        sum_i D_ij V_i = 0,  sum_i D_ij V_i (x_i - x_j)_axis = -V_j,
        sum_i D_ij V_i (x_i - x_j)_other = 0.

    Then the pair (D, G) is skew-adjoint in the V inner products (the
    leap-frog scheme conserves a discrete energy: stable on irregular
    layouts) and both operators are first-order consistent away from the
    excluded columns. Minimum-norm correction by a sparse normal-equations
    solve. ``scale`` (the spacing) makes the system dimensionless.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> e = rng.random((150, 2)); h = rng.random((160, 2))
    >>> D = cross_gradient(e, h, 0.15)[0]
    >>> Vr, Vc = np.full(150, 1 / 150), np.full(160, 1 / 160)
    >>> inner = np.all((h > 0.3) & (h < 0.7), axis=1)
    >>> Dc = sbp_correct(D, e, h, 0, Vr, Vc, inner, scale=0.08)
    >>> G = -(Dc.T @ sp.diags(Vr)) / Vc[:, None]
    >>> bool(np.allclose((G @ e[:, 0])[inner], 1.0)), bool(np.allclose(Dc @ h[:, 0], 1.0))
    (True, True)
    """
    from scipy.sparse.linalg import spsolve

    D = sp.csr_matrix(D)
    D.sort_indices()
    n_r, n_c = D.shape
    i = np.repeat(np.arange(n_r), np.diff(D.indptr))
    j = D.indices
    x = (cols[j] - rows[i]) / scale  # (P, 2), x_j - x_i in spacings
    vr = np.asarray(vol_rows, dtype=np.float64)
    vc = np.asarray(vol_cols, dtype=np.float64)
    vmean = vr.mean()
    vr, vc = vr / vmean, vc / vmean
    d = D.data * scale
    P = len(d)
    other = 1 - axis
    # row constraints: sum_j Delta_ij {1, x, y} = 0
    blocks_r, blocks_c, blocks_v, rhs = [], [], [], []
    for k, phi in enumerate((np.ones(P), x[:, 0], x[:, 1])):
        blocks_r.append(3 * i + k)
        blocks_c.append(np.arange(P))
        blocks_v.append(phi)
    m_rows = 3 * n_r
    rhs.append(np.zeros(m_rows))
    cm = np.ones(n_c, bool) if col_mask is None else np.asarray(col_mask, bool)
    cidx = -np.ones(n_c, dtype=np.int64)
    cidx[cm] = np.arange(int(cm.sum()))
    sel = cm[j]
    q = np.flatnonzero(sel)
    jj = cidx[j[q]]
    y = -x[q]  # x_i - x_j
    psi = (np.ones(len(q)), y[:, axis], y[:, other])
    n_cc = int(cm.sum())
    for k in range(3):
        blocks_r.append(m_rows + 3 * jj + k)
        blocks_c.append(q)
        blocks_v.append(vr[i[q]] * psi[k])
    A = sp.csr_matrix((np.concatenate(blocks_v), (np.concatenate(blocks_r), np.concatenate(blocks_c))),
                      shape=(m_rows + 3 * n_cc, P))
    target = np.zeros(3 * n_cc)
    target[0::3] = 0.0
    target[1::3] = -vc[cm]
    r = np.concatenate([np.zeros(m_rows), target]) - A @ d
    r[:m_rows] = 0.0  # D already meets its row conditions (up to round-off)
    AAt = (A @ A.T).tocsc()
    AAt = AAt + sp.identity(AAt.shape[0], format="csc") * (1e-12 * AAt.diagonal().max())
    lam = spsolve(AAt, r)
    delta = A.T @ lam
    out = sp.csr_matrix(((d + delta) / scale, D.indices.copy(), D.indptr.copy()), shape=D.shape)
    return out


def nearest_plane(points: np.ndarray, planes: Sequence[float], reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Which points lie within ``reach`` of a mirror plane ``x = m`` (bool (n,)), and each point's nearest plane."""
    n = len(points)
    if not len(planes) or reach <= 0:
        return np.zeros(n, dtype=bool), np.zeros(n)
    pl = np.asarray(planes, dtype=np.float64)
    dist = np.abs(np.asarray(points)[:, [0]] - pl[None, :])
    return dist.min(axis=1) < reach, pl[dist.argmin(axis=1)]


def mirror_fields(z: np.ndarray, x_at: np.ndarray, near: np.ndarray, plane: np.ndarray, odd: bool, axis: int,
                  scale: float, near_owner: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """The three linear test fields of each owner particle at the pairs' other points, and their exact derivatives.

    ``z`` (P, 2): the other point minus the owner, in spacings; ``x_at`` (P,): the other point's x; ``near``,
    ``plane`` (P,): the owner lies within reach of a mirror plane ``x = plane``; ``near_owner`` (n,) the same per
    owner. An owner away from every plane is tested on ``1``, the offset along ``axis`` and the other offset
    (derivatives 0, 1, 0). Next to a plane, the field tested must meet the mirror conditions, its continuation
    across the plane being what the folded rows see: an even field on ``1`` and ``y`` (derivatives 0 and
    ``axis == 1``), an odd one on ``x - m`` (derivative ``axis == 0``); unused slots are zero.
    """
    za, zo = z[:, axis], z[:, 1 - axis]
    der = np.zeros((len(near_owner), 3))
    der[:, 1] = 1.0
    if not near_owner.any():
        return [np.ones(len(z)), za, zo], der
    far = ~near
    if odd:
        fields = [np.where(near, (x_at - plane) / scale, 1.0), za * far, zo * far]
        der[near_owner] = (float(axis == 0), 0.0, 0.0)
    else:
        fields = [np.ones(len(z)), np.where(near, z[:, 1], za), zo * far]
        der[near_owner] = (0.0, float(axis == 1), 0.0)
    return fields, der


def supernodal_available() -> bool:
    """True when ``cvxopt`` (CHOLMOD's supernodal Cholesky on an optimised BLAS) is importable."""
    try:
        import cvxopt.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


def supernodal_cholesky_solve(AAt: sp.spmatrix, rhs: np.ndarray) -> np.ndarray:
    """Solve ``AAt x = rhs`` (symmetric positive definite) by CHOLMOD's supernodal Cholesky through ``cvxopt``.

    The same factorisation as :func:`manifold_sph.solvers.spd_solver` (CHOLMOD, a fill-reducing ordering, the
    lower triangle), with its dense supernode updates on the optimised BLAS that the ``cvxopt`` wheel carries.
    Raises ``ArithmeticError`` when a pivot is not positive and ``ImportError`` without ``cvxopt``.
    """
    import cvxopt
    import cvxopt.cholmod as cholmod

    lower = sp.tril(AAt, format="coo")
    M = cvxopt.spmatrix(cvxopt.matrix(np.ascontiguousarray(lower.data, dtype=np.float64)),
                        cvxopt.matrix(lower.row.astype(np.int64)), cvxopt.matrix(lower.col.astype(np.int64)),
                        size=AAt.shape)
    saved = dict(cholmod.options)
    cholmod.options.update({"supernodal": 2, "postorder": True})
    try:
        factor = cholmod.symbolic(M, uplo="L")
        cholmod.numeric(M, factor)
        out = cvxopt.matrix(np.ascontiguousarray(rhs, dtype=np.float64))
        cholmod.solve(factor, out)
    finally:
        cholmod.options.clear()
        cholmod.options.update(saved)
    return np.array(out).ravel()


def normal_solve(AAt: sp.spmatrix, rhs: np.ndarray, *, method: str = "auto") -> np.ndarray:
    """Solve the regularised normal equations ``A A^T lam = rhs`` of a correction (symmetric positive definite).

    ``method``: ``"supernodal"`` (CHOLMOD's supernodal Cholesky on an optimised BLAS through ``cvxopt``,
    :func:`supernodal_cholesky_solve`), ``"cholesky"`` (:func:`manifold_sph.solvers.spd_solver`: CHOLMOD through
    ``cholespy``, whose wheel carries the reference BLAS), ``"lu"`` (SuperLU), or ``"auto"``: the first of these
    that is installed (the supernodal one from :data:`SUPERNODAL_MIN_N` unknowns), SuperLU also when a
    factorisation meets a non-positive pivot. All factorise the same
    matrix: their solutions differ by round-off, amplified by the near-null multiplier fields of the
    correction (docs/spem.md, "Set-up of the sbp correction", has the measured differences and times).
    """
    from scipy.sparse.linalg import spsolve

    from ..solvers import NotPositiveDefiniteError, cholesky_available, spd_solver

    method = check_in("method", method, ("auto", "supernodal", "cholesky", "lu"))
    if method == "supernodal" or (method == "auto" and AAt.shape[0] >= SUPERNODAL_MIN_N and supernodal_available()):
        try:
            return supernodal_cholesky_solve(AAt, rhs)
        except ArithmeticError:
            if method == "supernodal":
                raise
    if method in ("auto", "cholesky") and (method == "cholesky" or cholesky_available()):
        try:
            return spd_solver(AAt, method="cholesky").solve(rhs)
        except NotPositiveDefiniteError:
            if method == "cholesky":
                raise
    return spsolve(sp.csc_matrix(AAt), rhs)


def sbp_pair(D: sp.spmatrix | sp.sparray, rows: np.ndarray, cols: np.ndarray, axis: int,
             vol_rows: ArrayLike, vol_cols: ArrayLike,
             B: sp.spmatrix | sp.sparray | None = None, wall: np.ndarray | None = None, scale: float = 1.0,
             degree: int = 1, layers: int | None = SBP_LAYERS, planes: Sequence[float] = (), odd_rows: bool = False,
             odd_cols: bool = False, reach: float = 0.0) -> tuple[sp.csr_matrix, sp.csr_matrix | None]:
    """Energy-conserving pair with a boundary closure: corrected ``D`` and the wall weights ``B``.

    ``D`` (rows x cols) approximates ``d/dx_axis`` from the column set (H)
    to the row set (the E particles that are updated or driven), exact for
    linear fields. The column set's operator is

        G = -V_cols^-1 D^T V_rows  (on the row particles)  +  B  (on the wall particles),

    where the wall particles (PEC, Ez = 0) only carry the boundary closure
    ``B`` (cols x walls): it multiplies zero fields, so ``(D, G)`` is
    skew-adjoint in the V inner products on the unknowns (leap-frog then
    conserves a discrete energy) whatever ``B`` is. The returned
    ``D + Delta`` and ``B + Delta_B`` are the minimum-norm changes (same
    sparsity) that keep every row of ``D`` exact for linear fields and make
    every row of ``G`` exact for linear fields too (walls included), so
    both operators are first-order consistent everywhere.

    With mirror ``planes`` (the derivative matrices of :mod:`.mirror`, whose
    rows next to a plane see the columns' mirror images folded back), a row or
    column within ``reach`` of a plane is fitted on the linear fields that
    meet the mirror conditions instead (:func:`mirror_fields`: ``1`` and
    ``y`` for an even field, ``x - m`` for an odd one): a folded row is exact
    on those and not on plain ``x`` (nor ``1`` and ``y`` for an odd field), so
    demanding plain linear exactness there would pull the pair away from the
    fold and stiffen it.

    Parameters
    ----------
    D : sparse (n_r, n_c)
    rows, cols : (n_r, 2), (n_c, 2) arrays
    axis : int
        0 for d/dx, 1 for d/dy.
    vol_rows, vol_cols : arrays
        Positive particle volumes (the energy weights).
    B : sparse (n_c, n_w), optional
        Initial wall weights of the column set's rows (e.g. their direct
        CSPM weights at the wall particles); none if omitted.
    wall : (n_w, 2) array, optional
        Wall particle positions (with ``B``).
    scale : float
        The spacing (makes the system dimensionless).
    degree : {1, 2}
        Exactness of both operators: linear fields (1) or quadratic fields
        (2, experimental: needs ``h_ratio`` >= 1.3 with the cubic kernel;
        measured phase error of the TM22 mode of a PEC square at 14 / 28
        particles per wavelength: jittered -0.30 % / +0.15 %, but set-up
        61 s at 40 x 40, and on Poisson layouts the conditions cannot all
        be met: +128 % / +90 %, unusable).

    layers : int or None
        Rings of pairs around the columns that miss their conditions that
        may change (None: the whole operator, a larger sparse solve; see
        :data:`SBP_LAYERS`).
    planes : sequence of float
        x values of mirror planes (none by default); ``degree`` 1 only.
    odd_rows, odd_cols : bool
        The row (column) set's field is odd about the planes (else even).
    reach : float
        Rows and columns closer than this to a plane take the mirror
        conditions (the kernel support ``kappa h``: a farther particle's
        support holds no image).

    Returns
    -------
    D_corrected : csr (n_r, n_c)
    B_corrected : csr (n_c, n_w) or None

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> e = 0.05 + 0.9 * rng.random((150, 2)); h = rng.random((160, 2))
    >>> D = cross_gradient(e, h, 0.15)[0]
    >>> Vr, Vc = np.full(150, 1 / 150), np.full(160, 1 / 160)
    >>> t = np.linspace(0, 1, 40, endpoint=False)
    >>> wall = np.vstack([np.c_[t, 0 * t], np.c_[1 + 0 * t, t], np.c_[1 - t, 1 + 0 * t], np.c_[0 * t, 1 - t]])
    >>> B = cross_gradient(h, np.vstack([e, wall]), 0.15)[0][:, 150:]
    >>> Dc, Bc = sbp_pair(D, e, h, 0, Vr, Vc, B, wall, scale=0.08)
    >>> G = -(Dc.T @ sp.diags(Vr)) / Vc[:, None]
    >>> bool(np.allclose(G @ e[:, 0] + Bc @ wall[:, 0], 1.0)), bool(np.allclose(Dc @ h[:, 0], 1.0))
    (True, True)
    """

    D = sp.csr_matrix(D, dtype=np.float64)
    D.sort_indices()
    n_r, n_c = D.shape
    i = np.repeat(np.arange(n_r), np.diff(D.indptr))
    j = D.indices
    x = (cols[j] - rows[i]) / scale  # x_j - x_i in spacings
    vr = np.asarray(vol_rows, dtype=np.float64)
    vc = np.asarray(vol_cols, dtype=np.float64)
    vmean = vr.mean()
    vr, vc = vr / vmean, vc / vmean
    other = 1 - axis
    P = len(j)
    if B is not None:
        B = sp.csr_matrix(B, dtype=np.float64)
        B.sort_indices()
        jb = np.repeat(np.arange(n_c), np.diff(B.indptr))
        wb = B.indices
        yb = (np.asarray(wall, dtype=np.float64)[wb] - cols[jb]) / scale  # x_wall - x_j
        b = B.data * scale
    else:
        jb = wb = np.zeros(0, dtype=np.int64)
        yb = np.zeros((0, 2))
        b = np.zeros(0)
    Pb = len(b)
    # unknowns u = [Delta (P), Delta_B (Pb)]; constraints: m monomials per row particle and per column particle
    y = -x  # x_i - x_j

    def monomials(z):  # (P, 2) offsets in the axis/other frame -> list of m arrays
        za, zo = z[:, axis], z[:, other]
        out = [np.ones(len(z)), za, zo]
        if degree == 2:
            out += [za * za, za * zo, zo * zo]
        return out

    m = 3 if degree == 1 else 6
    nk = m * (n_r + n_c)
    wall_xy = np.asarray(wall, dtype=np.float64) if B is not None else np.zeros((0, 2))
    # each row (column) particle within ``reach`` of a mirror plane is tested on the linear fields that meet
    # the mirror conditions of the column (row) field instead of 1, x and y (:func:`mirror_fields`)
    if not np.all(np.isfinite(np.asarray(planes, dtype=np.float64))) or not (np.isfinite(reach) and reach >= 0):
        raise ValueError(f"sbp_pair: planes must be finite x values and reach a finite length >= 0, got planes="
                         f"{list(planes)!r}, reach={reach!r}")
    near_r, plane_r = nearest_plane(rows, planes, reach)
    near_c, plane_c = nearest_plane(cols, planes, reach)
    if degree == 2 and (near_r.any() or near_c.any()):
        raise ValueError("sbp_pair: degree=2 is not available with mirror planes (degree 1 only)")
    if degree == 1:
        r_val, r_der = mirror_fields(x, cols[j, 0], near_r[i], plane_r[i], odd_cols, axis, scale, near_r)
        c_fields, c_der = mirror_fields(y, rows[i, 0], near_c[j], plane_c[j], odd_rows, axis, scale, near_c)
        cb_fields, _ = mirror_fields(yb, wall_xy[wb, 0], near_c[jb], plane_c[jb], odd_rows, axis, scale, near_c)
    else:
        r_val, c_fields, cb_fields = monomials(x), monomials(y), monomials(yb)
        r_der = np.zeros((n_r, m))
        r_der[:, 1] = 1.0  # d/dx_axis of x_axis
        c_der = np.zeros((n_c, m))
        c_der[:, 1] = 1.0
    r_idx = [m * i + k for k in range(m)]
    c_val = [vr[i] * f for f in c_fields]
    c_idx = [m * n_r + m * j + k for k in range(m)]
    cb_val = [-vc[jb] * f for f in cb_fields]
    cb_idx = [m * n_r + m * jb + k for k in range(m)]
    A = sp.csr_matrix(
        (np.concatenate(r_val + c_val + cb_val),
         (np.concatenate(r_idx + c_idx + cb_idx),
          np.concatenate([np.tile(np.arange(P), 2 * m), np.tile(P + np.arange(Pb), m)]))),
        shape=(nk, P + Pb))
    target = np.concatenate([r_der.ravel(), (-vc[:, None] * c_der).ravel()])
    u0 = np.r_[D.data * scale, b]
    r = target - A @ u0
    if degree == 1:
        r[: m * n_r] = 0.0  # D already meets its row conditions (up to round-off)
    # Only the columns that miss their conditions (next to walls, everywhere on
    # irregular layouts) and ``layers`` rings of pairs around them are changed.
    bad_c = np.abs(r[m * n_r :].reshape(n_c, m)).max(axis=1) > 1e-10
    bad_c |= np.bincount(j, weights=(np.abs(r[: m * n_r]).reshape(n_r, m).max(axis=1) > 1e-10)[i], minlength=n_c) > 0
    delta = np.zeros(P + Pb)
    if bad_c.any():
        col_on = bad_c if layers is not None else np.ones(n_c, bool)
        for _ in range(layers or 0):
            row_on = np.bincount(i, weights=col_on[j], minlength=n_r) > 0
            col_on = np.bincount(j, weights=row_on[i], minlength=n_c) > 0
        row_on = np.bincount(i, weights=col_on[j], minlength=n_r) > 0
        u_on = np.r_[row_on[i] & col_on[j], col_on[jb]]
        c_on = np.r_[np.repeat(row_on, m), np.repeat(col_on, m)]
        As = A if u_on.all() and c_on.all() else A[c_on][:, u_on]
        AAt = (As @ As.T).tocsc()
        AAt = AAt + sp.identity(AAt.shape[0], format="csc") * (SBP_REGULARISATION * AAt.diagonal().max())
        delta[u_on] = As.T @ normal_solve(AAt, r[c_on])
    Dc = sp.csr_matrix(((D.data * scale + delta[:P]) / scale, D.indices.copy(), D.indptr.copy()), shape=D.shape)
    Bc = None if B is None else sp.csr_matrix(((b + delta[P:]) / scale, B.indices.copy(), B.indptr.copy()),
                                              shape=B.shape)
    return Dc, Bc
