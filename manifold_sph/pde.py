"""PDEs on point-cloud surfaces (docs/method.md section 6): heat, wave, Poisson, Helmholtz-Hodge.

Every solver works with the surface's sparse Laplace-Beltrami matrix ``L``, so
implicit steps and Poisson problems are sparse solves; one factorisation is
reused for all steps.

Which Laplacian (``laplacian=`` of every solver):

- ``"strong"``: the scheme's SPH Laplacian ``L`` (:meth:`Surface.laplacian_matrix`).
  Not symmetric. On near-uniform clouds its spectrum lies in the closed left
  half-plane; on uniformly *random* samples and scans the corrected schemes have
  eigenvalues with large positive real parts (1e5 to 1e8 measured on random
  sphere points), and time stepping with them grows without bound.
- ``"stable"``: the weak form ``K u = -M Lap u`` from tangent-plane Voronoi cells
  (:meth:`Surface.stiffness_matrix`, :meth:`Surface.mass_matrix`,
  :mod:`manifold_sph.voronoi`): ``K`` symmetric positive semi-definite, ``M``
  positive diagonal, on any cloud. Heat steps ``(M + dt K) u' = M u`` conserve
  ``sum(M u)`` and (implicit Euler) obey the maximum principle exactly; the wave
  scheme conserves a discrete energy; on open surfaces the natural (Neumann)
  condition holds.
- ``"auto"`` (the default): ``"strong"`` when :func:`strong_form_is_stable` shows its
  spectrum free of growing modes, otherwise ``"stable"``, said once per surface in a
  RuntimeWarning.
- a sparse matrix: used as ``L``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike

from .exceptions import ManifoldSPHWarning
from .results import Result
from ._sparse import RowBlocks, _dot, bicgstab_csr
from ._validation import as_field, check_in, check_int, check_positive
from .operators import OperatorSet

if TYPE_CHECKING:
    from .surface import Surface

__all__ = [
    "Solution",
    "spectral_radius",
    "spectrum_right_edge",
    "strong_form_is_stable",
    "choose_laplacian",
    "explicit_dt_limit",
    "stabilized_laplacian",
    "heat",
    "wave",
    "wave_energy",
    "poisson",
    "screened_poisson",
    "HodgeDecomposition",
    "helmholtz_hodge",
]

HEAT_METHODS = ("explicit", "implicit", "crank-nicolson")


@dataclass(frozen=True, eq=False, repr=False)
class Solution(Result):
    """What :func:`heat` and :func:`wave` return, whatever the options.

    Attributes
    ----------
    u : ndarray, shape (N,)
        The final state.
    times : ndarray, shape (S,)
        The times of the saved states: ``0, every dt, 2 every dt, ...`` and the
        final time (``[0, steps dt]`` without ``every=``).
    snapshots : ndarray, shape (S, N)
        The saved states, the initial and the final one included.
    laplacian : str
        The Laplacian the steps used: ``"strong"``, ``"stable"`` (what ``"auto"``
        chose) or ``"matrix"`` (one passed in).

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> s = Surface(shapes.sphere(500))
    >>> sol = heat(s, s.points[:, 2], dt=0.01, steps=10, every=5)
    >>> sol.u.shape, sol.snapshots.shape, sol.times.tolist(), sol.laplacian
    ((500,), (3, 500), [0.0, 0.05, 0.1], 'strong')
    """

    u: np.ndarray
    times: np.ndarray
    snapshots: np.ndarray
    laplacian: str


# ----------------------------------------------------------------------------- helpers
LAPLACIANS = ("auto", "strong", "stable")

#: Above this many particles ``laplacian="auto"`` does not run the spectrum check and uses "stable".
AUTO_CHECK_MAX = 200_000

#: ARPACK restarts of the spectrum check behind ``laplacian="auto"``.
AUTO_MAXITER = 50


def _check_surface(surface) -> None:
    if not isinstance(surface, OperatorSet):
        raise TypeError(f"surface must be a Surface or Domain2D, got {type(surface).__name__}")


def strong_form_is_stable(surface: OperatorSet, *, maxiter: int = AUTO_MAXITER) -> bool:
    """Whether the scheme's (strong-form) Laplacian has no growing mode (no eigenvalue with Re > 0).

    A matrix whose Gershgorin discs all lie in ``Re <= 0`` (non-negative
    off-diagonals dominated by a non-positive diagonal, as the standard scheme
    with Shepard elements gives) is stable by that bound alone. Otherwise
    ARPACK looks for the eigenvalues with the largest real parts (``maxiter`` restarts
    at most). Growing modes of SPH Laplacians on irregular clouds are large and
    isolated and are found in a few iterations; the check says True only when the
    right edge converged at 0 (within ``1e-6`` of the Gershgorin bound of the
    spectral radius), and False when a growing mode was found, the iteration did
    not converge, or the cloud has more than :data:`AUTO_CHECK_MAX` particles. The
    result is cached on the surface.

    Examples
    --------
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> strong_form_is_stable(Surface(shapes.sphere(2000)))     # Fibonacci points
    True
    """
    _check_surface(surface)
    maxiter = check_int("maxiter", maxiter, minimum=1)
    return surface.cached(("strong_stable", maxiter), lambda: _strong_form_check(surface, maxiter))[0]


def _strong_form_check(surface, maxiter: int) -> tuple[bool, str]:
    L = surface.laplacian_matrix()
    n = L.shape[0]
    reason = ""
    absL = abs(L.copy())  # abs() of a CSR with unsorted indices sorts them in place: not the shared matrix
    bound = float(absL.sum(axis=1).max())
    diag = L.diagonal()
    if np.all(diag + (np.asarray(absL.sum(axis=1)).ravel() - np.abs(diag)) <= 1e-12 * bound):
        # Gershgorin: every disc lies in Re <= 0 (e.g. the standard scheme with Shepard elements,
        # an M-matrix with zero row sums), a proof without an eigenvalue search
        ok = True
    elif n > AUTO_CHECK_MAX:
        ok, reason = False, f"not checked above {AUTO_CHECK_MAX} particles"
    else:
        v0 = np.random.default_rng(0).standard_normal(n)
        try:
            lam = spla.eigs(L, k=2, which="LR", v0=v0, tol=1e-6, maxiter=maxiter, return_eigenvectors=False)
            converged = True
        except spla.ArpackNoConvergence as exc:
            lam, converged = exc.eigenvalues, False
        except spla.ArpackError:
            lam, converged = np.zeros(0), False
        top = float(np.max(lam.real)) if lam.size else np.nan
        if lam.size and top > 1e-6 * bound:
            ok, reason = False, f"it has eigenvalues with positive real part up to {top:.3g} (growing modes)"
        elif converged:
            ok = True
        else:
            ok, reason = False, "its spectrum could not be shown free of growing modes"
    return ok, reason


def choose_laplacian(surface: OperatorSet, laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto") -> str:
    """The Laplacian the solvers use for ``laplacian``: ``"strong"``, ``"stable"`` or ``"matrix"``.

    ``"auto"`` gives ``"strong"`` when :func:`strong_form_is_stable`, otherwise
    ``"stable"`` with one RuntimeWarning per surface giving the reason.
    """
    _check_surface(surface)
    if laplacian is None:
        laplacian = "auto"
    if not isinstance(laplacian, str):
        return "matrix"
    check_in("laplacian", laplacian, LAPLACIANS)
    if laplacian != "auto":
        return laplacian
    if strong_form_is_stable(surface):
        return "strong"
    first = []
    surface.cached("auto_warned", lambda: first.append(True) or True)  # one warning per surface
    if first:
        reason = surface.cached(("strong_stable", AUTO_MAXITER), lambda: _strong_form_check(surface, AUTO_MAXITER))[1]
        warnings.warn(
            f"laplacian='auto': the {surface.scheme.name!r} scheme's Laplacian is not used for this cloud "
            f"({reason}); using the stable Voronoi Laplacian (laplacian='stable'). Pass laplacian='strong' "
            "to force the scheme's operator",
            ManifoldSPHWarning,
            stacklevel=3,
        )
    return "stable"


@dataclass
class _Operator:
    """The Laplacian a solver uses: ``L`` (products), and for "stable" also ``K`` and the mass ``m``."""

    kind: str
    L: sp.csr_matrix
    m: np.ndarray
    K: sp.csr_matrix | None = None


def _operator(surface, laplacian) -> _Operator:
    kind = choose_laplacian(surface, laplacian)
    n = surface.n_points
    if kind == "stable":
        K = surface.stiffness_matrix()
        m = np.asarray(surface.mass_matrix().diagonal())
        return _Operator("stable", surface.stable_laplacian_matrix(), m, K)
    if kind == "strong":
        return _Operator("strong", surface.laplacian_matrix(), surface.dV)
    if sp.issparse(laplacian) or isinstance(laplacian, np.ndarray):
        L = sp.csr_matrix(laplacian)
    else:
        raise TypeError(f"laplacian must be one of {list(LAPLACIANS)} or a sparse matrix, got {type(laplacian).__name__}")
    if L.shape != (n, n):
        raise ValueError(f"laplacian must have shape ({n}, {n}), got {L.shape}")
    if not np.all(np.isfinite(L.data)):
        raise ValueError("laplacian must have finite entries")
    return _Operator("matrix", L, surface.dV)


def _fixed(fixed, fixed_values, n: int, u0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boolean mask of held particles and their values (default: the initial values)."""
    if fixed is None:
        if fixed_values is not None:
            raise ValueError("fixed_values was given without fixed (the particles to hold)")
        return np.zeros(n, dtype=bool), np.zeros(0)
    arr = np.asarray(fixed)
    if arr.dtype == bool:
        if arr.shape != (n,):
            raise ValueError(f"fixed as a boolean mask must have shape ({n},), got {arr.shape}")
        mask = arr.copy()
    else:
        if arr.size and not np.issubdtype(arr.dtype, np.integer):
            raise TypeError(f"fixed must be integer indices or a boolean mask, got dtype {arr.dtype}")
        idx = arr.astype(np.int64).ravel()
        bad = (idx < 0) | (idx >= n)
        if bad.any():
            raise ValueError(f"fixed indices must lie in [0, {n}), got {idx[bad][:5].tolist()}")
        mask = np.zeros(n, dtype=bool)
        mask[idx] = True
    k = int(mask.sum())
    if fixed_values is None:
        values = u0[mask].copy()
    else:
        values = np.asarray(fixed_values, dtype=np.float64)
        if values.ndim == 0:
            values = np.full(k, float(values))
        if values.shape != (k,):
            raise ValueError(f"fixed_values must be a scalar or have shape ({k},) (one per fixed particle), got {values.shape}")
        if not np.all(np.isfinite(values)):
            raise ValueError("fixed_values must be finite")
    return mask, values


class _Recorder:
    """Per-step bookkeeping shared by the time steppers: finiteness, callback, snapshots."""

    def __init__(self, name, u0, dt, steps, every, callback):
        self.name, self.dt, self.steps, self.every, self.callback = name, dt, steps, every, callback
        self.saved, self.times = [u0.copy()], [0.0]

    def __call__(self, step, u):
        if not np.all(np.isfinite(u)):
            raise FloatingPointError(f"{self.name}: the solution stopped being finite at step {step}")
        if self.callback is not None:
            self.callback(step, step * self.dt, u)
        if (self.every and step % self.every == 0) or step == self.steps:
            self.saved.append(u.copy())
            self.times.append(step * self.dt)

    def result(self, u, laplacian):
        return Solution(u, np.array(self.times), np.array(self.saved), laplacian)


def _check_steps(dt, steps, every):
    dt = check_positive("dt", dt)
    steps = check_int("steps", steps, minimum=1)
    if every is not None:
        every = check_int("every", every, minimum=1)
    return dt, steps, every


def spectral_radius(L: sp.spmatrix | sp.sparray | ArrayLike, *, tol: float = 1e-6, seed: int = 0) -> float:
    """Largest eigenvalue modulus of ``L`` (ARPACK; power iteration if it does not converge).

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> round(spectral_radius(sp.diags([-1.0, -4.0, -2.5] * 10)), 6)
    4.0
    """
    L = sp.csr_matrix(L)
    n = L.shape[0]
    v0 = np.random.default_rng(seed).standard_normal(n)
    if n > 3:
        try:
            lam = spla.eigs(L, k=1, which="LM", v0=v0, tol=tol, maxiter=max(1000, 10 * n), return_eigenvectors=False)
            return float(np.abs(lam).max())
        except (spla.ArpackNoConvergence, spla.ArpackError):
            pass
    x = v0 / np.linalg.norm(v0)
    rho = 0.0
    for _ in range(2000):
        y = L @ x
        new = float(np.linalg.norm(y))
        if new == 0.0:
            return 0.0
        x = y / new
        if abs(new - rho) <= tol * new:
            break
        rho = new
    return new


def spectrum_right_edge(L: sp.spmatrix | sp.sparray | ArrayLike, k: int = 6, *, seed: int = 0) -> np.ndarray:
    """The ``k`` eigenvalues of ``L`` with the largest real parts (growing modes have Re > 0).

    Uses ARPACK; returns them sorted by decreasing real part.
    """
    L = sp.csr_matrix(L)
    v0 = np.random.default_rng(seed).standard_normal(L.shape[0])
    try:
        lam = spla.eigs(L, k=k, which="LR", v0=v0, tol=1e-8, maxiter=20 * L.shape[0], return_eigenvectors=False)
    except spla.ArpackNoConvergence as exc:  # keep what converged
        lam = exc.eigenvalues
    return lam[np.argsort(-lam.real)]


def _rho(surface, op: _Operator) -> float:
    """Spectral radius of the operator's ``L`` (cached per surface for "strong" and "stable" only:
    a matrix passed in is measured every time, never keyed by its ``id``)."""
    if op.kind != "matrix":
        return surface.cached(("rho", op.kind), lambda: _rho_of(op))
    return _rho_of(op)


def _rho_of(op: _Operator) -> float:
    if op.kind == "stable":  # M^-1 K is similar to the symmetric M^-1/2 K M^-1/2: Lanczos
        d = 1.0 / np.sqrt(op.m)
        S = (sp.diags(d) @ op.K @ sp.diags(d)).tocsr()
        n = S.shape[0]
        if n <= 3:
            rho = float(np.abs(np.linalg.eigvalsh(S.toarray())).max())
        else:
            v0 = np.random.default_rng(0).standard_normal(n)
            try:
                rho = float(spla.eigsh(S, k=1, which="LA", v0=v0, tol=1e-6, return_eigenvectors=False)[0])
            except spla.ArpackNoConvergence:
                rho = float(abs(S).sum(axis=1).max())  # Gershgorin: an upper bound
    else:
        rho = spectral_radius(op.L)
    return rho


def explicit_dt_limit(surface: OperatorSet, *, equation: str = "heat", diffusivity: float = 1.0, c: float = 1.0,
                      laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto") -> float:
    """Largest stable time step of the explicit schemes, from the spectral radius ``rho`` of ``L``.

    Heat (forward Euler): ``2 / (diffusivity rho)``. Wave (centred): ``2 / (c sqrt(rho))``.
    Exact for eigenvalues on the negative real axis (always the case with
    ``laplacian="stable"``); complex eigenvalues near the imaginary axis are not
    covered (use an implicit method). ``laplacian`` as in :func:`heat`.

    Examples
    --------
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> s = Surface(shapes.sphere(1000), area="shepard")
    >>> heat_dt, wave_dt = explicit_dt_limit(s, diffusivity=2.0), explicit_dt_limit(s, equation="wave", c=2.0)
    >>> bool(0 < heat_dt < wave_dt)
    True
    """
    check_in("equation", equation, ("heat", "wave"))
    if equation == "heat":
        speed = check_positive("diffusivity", diffusivity)
    else:
        speed = check_positive("c", c)
    return _dt_limit(surface, _operator(surface, laplacian), speed, equation)


def _dt_limit(surface, op: _Operator, k: float, equation: str) -> float:
    rho = _rho(surface, op)
    if rho == 0:
        return np.inf
    return 2.0 / (k * rho) if equation == "heat" else 2.0 / (k * np.sqrt(rho))


def stabilized_laplacian(surface: OperatorSet, method: str = "taylor") -> sp.csr_matrix:
    """``surface.stabilized_laplacian(method)``: see :meth:`manifold_sph.operators.OperatorSet.stabilized_laplacian`."""
    if not isinstance(surface, OperatorSet):
        raise TypeError(f"surface must be a Surface or Domain2D, got {type(surface).__name__}")
    return surface.stabilized_laplacian(method)


# ----------------------------------------------------------------------------- heat
def heat(
    surface: OperatorSet,
    u0: ArrayLike,
    dt: float,
    steps: int,
    diffusivity: float = 1.0,
    *,
    method: str = "implicit",
    fixed: ArrayLike | None = None,
    fixed_values: float | ArrayLike | None = None,
    every: int | None = None,
    callback: Callable | None = None,
    laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto",
    solver: str = "auto",
) -> Solution:
    """Heat equation ``u_t = diffusivity Lap_S u``.

    Parameters
    ----------
    surface : Surface or Domain2D
    u0 : array_like, shape (N,)
        Initial temperature.
    dt : float
        Time step (> 0). The explicit method refuses a ``dt`` above its stability
        limit :func:`explicit_dt_limit`, quoting the limit.
    steps : int
    diffusivity : float
        The diffusivity ``k`` of ``u_t = k Lap_S u`` (> 0).
    method : {"implicit", "crank-nicolson", "explicit"}
        Backward Euler, Crank-Nicolson (one sparse LU reused for all steps) or the
        forward Euler of [1] (docs/method.md section 6).
    fixed : array_like of int or bool mask, optional
        Particles held at ``fixed_values`` (default: their initial values), e.g. a
        heat source at the north pole.
    fixed_values : float or array_like, shape (n_fixed,), optional
    every : int, optional
        Also save the state every ``every`` steps (the initial and the final state
        are always saved).
    callback : callable, optional
        ``callback(step, t, u)`` after every step.
    laplacian : {"auto", "strong", "stable"} or sparse matrix
        Which Laplace-Beltrami (module notes). With ``"stable"`` the steps are
        ``(M + theta dt k K) u' = (M - (1 - theta) dt k K) u``: without ``fixed``
        particles ``sum(M u)`` is conserved to round-off, and implicit Euler keeps
        ``u`` within the range of the initial values (discrete maximum principle;
        Crank-Nicolson does so only for small ``dt``).
    solver : {"auto", "direct", "iterative"}
        Implicit steps: one sparse LU reused for all steps ("direct"), or
        Jacobi-preconditioned BiCGSTAB on both cores, started from the current
        state, to 1e-10 relative residual, with algebraic multigrid (pyamg, set up
        once) and then LU as fallbacks for stiff steps ("iterative"; LU fill-in
        makes the direct solve slow beyond ~50,000 particles). "auto" picks
        "direct" up to 50,000 particles.

    Returns
    -------
    Solution
        ``.u`` the final state (N,), ``.snapshots`` (S, N) saved at ``.times`` (S,),
        ``.laplacian`` the Laplacian used.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(2000)
    >>> z = cloud.points[:, 2]                      # a degree-1 harmonic: decays as exp(-2 k t)
    >>> u = heat(Surface(cloud), z, dt=0.01, steps=10, method="crank-nicolson").u
    >>> bool(np.allclose(u, np.exp(-0.2) * z, atol=2e-3))
    True
    """
    _check_surface(surface)
    n = surface.n_points
    u = as_field("u0", u0, n).copy()
    dt, steps, every = _check_steps(dt, steps, every)
    k = check_positive("diffusivity", diffusivity)
    check_in("method", method, HEAT_METHODS)
    check_in("solver", solver, ("auto", "direct", "iterative"))
    op = _operator(surface, laplacian)
    L = op.L
    mask, values = _fixed(fixed, fixed_values, n, u)
    u[mask] = values
    free = ~mask
    a = k * dt
    if method == "explicit":
        limit = _dt_limit(surface, op, k, "heat")
        if dt > limit:
            raise ValueError(
                f"dt = {dt:g} is above the explicit heat stability limit {limit:.4g} "
                f"(2 / (diffusivity * spectral radius)); use a smaller dt or method='implicit'"
            )
        theta = 0.0
    else:
        theta = 1.0 if method == "implicit" else 0.5
    solve = None
    # B u_t = -S u: (B, S) = (I, -L) for a strong-form L, (M, K) for the stable Laplacian
    B = op.m if op.kind == "stable" else np.ones(n)
    S = op.K if op.kind == "stable" else -L
    if theta > 0:
        Sf = S[free]
        A = (sp.diags(B[free]) + theta * a * Sf[:, free]).tocsr()
        solve = _implicit_solver(A, solver)
        rhs_fixed = theta * a * (Sf[:, mask] @ values) if mask.any() else 0.0
    record = _Recorder("heat", u, dt, steps, every, callback)
    Lb = RowBlocks(L if theta == 0 else S)  # threaded products
    for step in range(1, steps + 1):
        if theta == 0:
            u = u + a * (Lb @ u)
        else:
            new = u.copy()
            rhs = B * u - (1 - theta) * a * (Lb @ u) if theta < 1 else B * u
            new[free] = solve(rhs[free] - rhs_fixed, u[free])
            u = new
        u[mask] = values
        record(step, u)
    return record.result(u, op.kind)


#: Jacobi-BiCGSTAB iterations tried before multigrid is set up.
JACOBI_MAXITER = 500


def _implicit_solver(A: sp.csr_matrix, solver: str) -> Callable:
    """``solve(rhs, guess)`` for the implicit step matrix ``A``, factorised or iterative.

    The iterative path is Jacobi-preconditioned BiCGSTAB on both cores (row-block
    products, BLAS-free inner products), started from the current state, to 1e-10
    relative residual. Measured at N = 131072 (cspm, one solve): 0.10 / 0.31 / 0.66
    / 1.21 s for dt = 0.001 / 0.01 / 0.1 / 1, against 0.35 / 0.63 / 1.20 / 2.46 s
    for pyamg's Ruge-Stuben multigrid (not counting its set-up, 0.7-0.9 s): the
    corrected Laplacians are not M-matrices, and multigrid gains little on them.
    If Jacobi-BiCGSTAB does not converge in :data:`JACOBI_MAXITER` iterations,
    multigrid (set up once, BiCGSTAB-accelerated) takes over; if that fails too, a
    sparse LU, kept for the later steps.
    """
    n = A.shape[0]
    if solver == "direct" or (solver == "auto" and n <= 50000):
        lu = spla.splu(A.tocsc())
        return lambda rhs, guess: lu.solve(rhs)
    state = {"jacobi": True}
    blocks = RowBlocks(A)
    dinv = 1.0 / A.diagonal()

    def good(x, rhs):  # BLAS-free norms (see _sparse._dot)
        r = blocks @ x - rhs
        return np.all(np.isfinite(x)) and np.sqrt(_dot(r, r)) <= 1e-9 * max(np.sqrt(_dot(rhs, rhs)), 1e-300)

    def solve(rhs, guess):
        if "lu" in state:
            return state["lu"].solve(rhs)
        if state["jacobi"]:
            x, info = bicgstab_csr(A, rhs, dinv, guess, rtol=1e-10, maxiter=JACOBI_MAXITER)
            if info == 0 and good(x, rhs):
                return x
            state["jacobi"] = False  # too stiff for Jacobi: multigrid from now on
        if "amg" not in state:
            try:
                import pyamg

                with np.errstate(all="ignore"):
                    state["amg"] = pyamg.ruge_stuben_solver(A)
            except Exception:  # noqa: BLE001 - any set-up failure just skips multigrid
                state["amg"] = None
        if state["amg"] is not None:
            with np.errstate(all="ignore"):
                x = state["amg"].solve(rhs, x0=guess, tol=1e-10, accel="bicgstab", maxiter=200)
            if good(x, rhs):
                return x
            state["amg"] = None
        state["lu"] = spla.splu(A.tocsc())
        return state["lu"].solve(rhs)

    return solve


# ----------------------------------------------------------------------------- wave
def wave(
    surface: OperatorSet,
    u0: ArrayLike,
    dt: float,
    steps: int,
    c: float = 1.0,
    *,
    v0: ArrayLike | None = None,
    fixed: ArrayLike | None = None,
    fixed_values: float | ArrayLike | None = None,
    every: int | None = None,
    callback: Callable | None = None,
    laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto",
) -> Solution:
    """Wave equation ``u_tt = c^2 Lap_S u`` with the centred scheme.

    ``u^{n+1} = 2 u^n - u^{n-1} + c^2 dt^2 L u^n`` (docs/method.md section 6; eq. 3.20
    of [1] as printed is not consistent), started with
    ``u^1 = u^0 + dt v0 + c^2 dt^2 L u^0 / 2``. The scheme is explicit: a ``dt``
    above ``2 / (c sqrt(rho(L)))`` is refused with the limit in the message.

    With ``laplacian="stable"`` (``L = -M^-1 K``) this is the leap-frog scheme of
    ``M u_tt = -c^2 K u``, which conserves the discrete energy of :func:`wave_energy`
    to round-off (without ``fixed`` particles).

    Parameters and return value as for :func:`heat` (``c`` the wave speed, ``v0``
    the initial velocity, default zero).

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(2000)
    >>> z = cloud.points[:, 2]                      # Y_1: u = cos(sqrt(2) t) z
    >>> u = wave(Surface(cloud), z, dt=0.01, steps=100).u
    >>> bool(np.allclose(u, np.cos(np.sqrt(2.0)) * z, atol=1e-2))
    True
    """
    _check_surface(surface)
    n = surface.n_points
    u = as_field("u0", u0, n).copy()
    v = np.zeros(n) if v0 is None else as_field("v0", v0, n)
    dt, steps, every = _check_steps(dt, steps, every)
    c = check_positive("c", c)
    op = _operator(surface, laplacian)
    L = op.L
    limit = _dt_limit(surface, op, c, "wave")
    if dt > limit:
        raise ValueError(
            f"dt = {dt:g} is above the centred wave scheme's stability limit {limit:.4g} "
            f"(2 / (c * sqrt(spectral radius)))"
        )
    mask, values = _fixed(fixed, fixed_values, n, u)
    u[mask] = values
    b = (c * dt) ** 2
    prev = u
    u = prev + dt * v + 0.5 * b * (L @ prev)
    u[mask] = values
    record = _Recorder("wave", prev, dt, steps, every, callback)
    Lb = RowBlocks(L)  # threaded products
    for step in range(1, steps + 1):
        if step > 1:
            prev, u = u, 2 * u - prev + b * (Lb @ u)
            u[mask] = values
        record(step, u)
    return record.result(u, op.kind)


def wave_energy(surface: OperatorSet, u_prev: ArrayLike, u_next: ArrayLike, dt: float, c: float = 1.0,
                laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto") -> float:
    """Discrete energy of the centred scheme between two successive states.

    ``E = 1/2 |(u^{n+1} - u^n)/dt|_M^2 - c^2/2 (u^{n+1})^T M L u^n``, with ``M`` the
    stable Laplacian's mass (``laplacian="stable"``: then ``-M L = K`` and ``E`` is
    exactly conserved) or ``diag(dV)`` (strong form: ``E`` is conserved when ``M L``
    is symmetric, so its drift measures the non-symmetry of the SPH Laplacian).
    """
    _check_surface(surface)
    n = surface.n_points
    u_prev = as_field("u_prev", u_prev, n)
    u_next = as_field("u_next", u_next, n)
    dt = check_positive("dt", dt)
    c = check_positive("c", c)
    op = _operator(surface, laplacian)
    L, dV = op.L, op.m
    vel = (u_next - u_prev) / dt
    return float(0.5 * np.sum(dV * vel**2) - 0.5 * c**2 * np.dot(u_next * dV, L @ u_prev))


# ----------------------------------------------------------------------------- Poisson
def _has_boundary(surface) -> bool:
    """A planar domain without mirroring, or a surface whose Voronoi cells found an open boundary."""
    from .domain import Domain2D

    if isinstance(surface, Domain2D):
        return not surface.mirror
    return surface.stable_report["boundary"] > 0


def _components(A: sp.csr_matrix) -> tuple[int, np.ndarray]:
    from scipy.sparse.csgraph import connected_components

    return connected_components(A, directed=True, connection="weak")


def poisson(surface: OperatorSet, rhs: ArrayLike, *, dirichlet: tuple[ArrayLike, ArrayLike] | None = None,
            tol: float = 1e-3,
            laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto") -> np.ndarray:
    """Solve ``Lap_S u = rhs``.

    Without ``dirichlet`` the solution is defined up to a constant on each connected
    piece of the cloud: the one with zero mean (``sum m u = 0``) on every piece is
    returned, and ``rhs`` must have zero mean on every piece,
    ``|sum m rhs| <= tol * sum m |rhs|``, otherwise a ValueError quotes the worst
    piece. ``m`` is the operator's mass (the Voronoi cell areas for the stable
    Laplacian, the area elements ``dV`` for the strong form). With
    ``dirichlet=(indices, values)`` the given particles are held at the values.

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
        See :func:`heat`.

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
    _check_surface(surface)
    n = surface.n_points
    f = as_field("rhs", rhs, n)
    tol = check_positive("tol", tol)
    op = _operator(surface, laplacian)
    # -S u = B rhs: (S, B) = (K, M) for the stable Laplacian, (-L, I) otherwise
    stable = op.kind == "stable"
    S = op.K if stable else -op.L
    Bf = op.m * f if stable else f
    if dirichlet is not None:
        try:
            idx, vals = dirichlet
        except (TypeError, ValueError):
            raise TypeError("dirichlet must be a pair (indices, values)") from None
        mask, values = _fixed(np.asarray(idx), vals, n, np.zeros(n))
        if not mask.any():
            raise ValueError("dirichlet needs at least one particle")
        free = ~mask
        u = np.zeros(n)
        u[mask] = values
        Sf = S[free]
        ncomp, labels = _components(Sf[:, free])
        touched = np.zeros(ncomp, dtype=bool)
        coupled = np.asarray(abs(Sf[:, mask]).sum(axis=1)).ravel() > 0
        touched[labels[coupled]] = True
        if not touched.all():
            raise ValueError(
                f"poisson: {int((~touched).sum())} connected piece(s) of the cloud hold no Dirichlet particle and "
                "touch none, so their solution is not unique; add held particles there"
            )
        with np.errstate(all="ignore"):
            u[free] = spla.spsolve(Sf[:, free].tocsc(), -Bf[free] - Sf[:, mask] @ values)
        if not np.all(np.isfinite(u)):
            raise ValueError("poisson: the Dirichlet problem is singular for these held particles")
        return u
    if op.kind == "strong" and _has_boundary(surface):
        raise ValueError(
            "poisson with the strong-form Laplacian on a cloud with an open boundary needs a boundary condition: "
            "pass dirichlet=(indices, values), or laplacian='stable' for the Neumann problem"
        )
    m = op.m
    ncomp, labels = _components(S)
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
    # bordered system [[S, C], [C^T m, 0]] [u, lam] = [-B rhs, 0], one constraint per piece
    C = sp.csr_matrix((np.ones(n), (np.arange(n), labels)), shape=(n, ncomp))
    Cm = sp.csr_matrix((m, (labels, np.arange(n))), shape=(ncomp, n))
    A = sp.bmat([[S, C], [Cm, None]], format="csc")
    with np.errstate(all="ignore"):
        sol = spla.spsolve(A, np.append(-Bf, np.zeros(ncomp)))
    u = sol[:n]
    if not np.all(np.isfinite(u)):
        raise ValueError(
            "poisson: the Laplacian is singular beyond one constant per connected piece (its scheme's operator "
            "may have spurious null modes on this cloud); try laplacian='stable'"
        )
    rhs_full = np.append(-Bf, np.zeros(ncomp))
    resid = np.linalg.norm(A @ sol - rhs_full) / max(np.linalg.norm(Bf), 1e-300)
    if resid > 1e-6:
        raise ValueError(
            f"poisson: the solve did not converge (relative residual {resid:.2e}): the {op.kind} Laplacian is "
            "(nearly) singular on this cloud; try laplacian='stable'"
        )
    return u


def screened_poisson(surface: OperatorSet, rhs: ArrayLike, alpha: float, *,
                     laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto") -> np.ndarray:
    """Solve ``u - alpha Lap_S u = rhs`` (alpha > 0), a well-posed smoothing problem.

    With the stable Laplacian: ``(M + alpha K) u = M rhs`` (symmetric positive definite).

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
    _check_surface(surface)
    n = surface.n_points
    f = as_field("rhs", rhs, n)
    alpha = check_positive("alpha", alpha)
    op = _operator(surface, laplacian)
    if op.kind == "stable":
        return spla.spsolve((sp.diags(op.m) + alpha * op.K).tocsc(), op.m * f)
    return spla.spsolve((sp.identity(n, format="csc") - alpha * op.L).tocsc(), f)


# ----------------------------------------------------------------------------- Hodge
@dataclass
class HodgeDecomposition:
    """``F = gradient + cogradient + harmonic`` with ``gradient = grad phi`` and
    ``cogradient = n x grad psi`` (all (N, 3)); ``phi``, ``psi`` zero-mean (N,)."""

    gradient: np.ndarray
    cogradient: np.ndarray
    harmonic: np.ndarray
    phi: np.ndarray
    psi: np.ndarray


def helmholtz_hodge(surface: Surface, F: ArrayLike) -> HodgeDecomposition:
    """Helmholtz-Hodge decomposition of a tangent field on a closed surface.

    ``Lap phi = div F`` and ``Lap psi = -div(n x F)`` are solved with :func:`poisson`;
    the harmonic part is what remains (zero on a sphere; on a torus it holds the
    two harmonic fields).

    Parameters
    ----------
    surface : Surface
    F : array_like, shape (N, 3)
        Its normal part is discarded.

    Returns
    -------
    HodgeDecomposition
    """
    from .surface import Surface

    if not isinstance(surface, Surface):
        raise TypeError(f"surface must be a Surface (a closed point-cloud surface), got {type(surface).__name__}")
    n = surface.normals
    F = as_field("F", F, surface.n_points, 3)
    F = F - np.einsum("ij,ij->i", F, n)[:, None] * n

    op = _operator(surface, "auto")

    def zero_mean(g):
        return g - np.dot(op.m, g) / op.m.sum()

    phi = poisson(surface, zero_mean(surface.divergence(F)), laplacian=op.kind)
    psi = poisson(surface, zero_mean(-surface.divergence(np.cross(n, F))), laplacian=op.kind)
    grad = surface.gradient(phi)
    cograd = np.cross(n, surface.gradient(psi))
    return HodgeDecomposition(gradient=grad, cogradient=cograd, harmonic=F - grad - cograd, phi=phi, psi=psi)
