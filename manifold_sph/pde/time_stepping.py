"""Heat and wave equations on a point cloud, in units of the cloud (docs/pde.md).

How long to run is said relative to the cloud, so that one call means the same on a
cloud 0.25 across and on one 658 across:

- ``reach=``: how far the solution travels, as a fraction of the cloud's diameter
  (:func:`cloud_diameter`): for heat, the standard deviation ``sqrt(2 a t)`` (diffusivity a) of the heat
  kernel (``reach=0.1``: a hot spot spreads over a tenth of the object; ``reach=1``:
  nearly flat); for waves, the distance ``c t`` a front travels (``reach=1``: across
  the object);
- ``t_end=``: the final time, in the cloud's own units;
- ``dt=`` and ``steps=``: both given, absolute, as they are.

With ``reach=`` or ``t_end=``, ``dt`` is chosen when not given: implicit heat steps
diffuse about one spacing each (``dt = spacing^2 / k``, the spacing
``sqrt(area / N)``), between :data:`MIN_STEPS` and :data:`MAX_STEPS` steps; the explicit
schemes take :data:`EXPLICIT_SAFETY` of their stability limit. A ``dt`` given with a
duration is lowered so that whole steps end exactly at ``t_end``.

Implicit steps with the stable Laplacian solve ``(M + theta dt k K) u' = rhs``, symmetric
positive definite: one sparse Cholesky factorisation (or one multigrid set-up for CG)
for all steps (:func:`manifold_sph.solvers.spd_solver`). The strong form is not
symmetric: one sparse LU up to 50,000 particles, Jacobi-preconditioned BiCGSTAB above.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike

from .._sparse import RowBlocks, bicgstab_csr
from .._validation import as_field, check_bool, check_in, check_int, check_positive
from ..operators import OperatorSet
from ..results import Result
from ..solvers import NotPositiveDefiniteError, spd_solver
from .laplacians import Operator, check_surface, dt_limit, fixed_particles, operator_for

__all__ = [
    "Solution",
    "cloud_diameter",
    "cloud_spacing",
    "time_steps",
    "heat",
    "wave",
    "wave_energy",
    "HEAT_METHODS",
    "MIN_STEPS",
    "MAX_STEPS",
    "EXPLICIT_SAFETY",
]

HEAT_METHODS = ("implicit", "crank-nicolson", "explicit")
SOLVERS = ("auto", "direct", "iterative")

#: Fewest and most implicit steps chosen when ``dt`` is not given (about one spacing of diffusion a step
#: in between). 200 backward-Euler steps leave 0.25 % of error in a mode that decays by e over the run.
MIN_STEPS = 10
MAX_STEPS = 200

#: Share of the stability limit the explicit schemes step at when ``dt`` is not given (forward Euler at
#: half its limit damps the fastest mode in one step instead of flipping it).
EXPLICIT_SAFETY = 0.5

#: Explicit runs longer than this many steps are refused before they start (use an implicit method).
MAX_EXPLICIT_STEPS = 5_000_000

#: Above this many particles ``solver="auto"`` solves non-symmetric implicit steps iteratively.
LU_MAX_N = 50_000

#: Jacobi-BiCGSTAB iterations tried before multigrid is set up (non-symmetric steps).
JACOBI_MAXITER = 500


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
    dt : float
        The time step used.
    solver : str
        How the steps were solved: ``"explicit"``, ``"cholesky"``, ``"amg"`` (CG with
        multigrid), ``"lu"`` or ``"bicgstab"``.

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
    dt: float = math.nan
    solver: str = ""


# ----------------------------------------------------------------------------- units of the cloud
def cloud_diameter(surface: OperatorSet) -> float:
    """The cloud's diameter: twice the largest distance of a point from the centroid.

    Exact for a sphere and a segment, within a factor 1.16 of the largest distance between
    two points in the plane and in space; invariant under rotation and translation,
    proportional to scale. The length that ``reach=`` of :func:`heat` and :func:`wave` is a
    fraction of.

    Examples
    --------
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> round(cloud_diameter(Surface(shapes.sphere(500))), 3)
    2.0
    """
    check_surface(surface)
    x = np.asarray(surface.points, dtype=np.float64)
    return float(2.0 * np.sqrt(((x - x.mean(axis=0)) ** 2).sum(axis=1).max()))


def cloud_spacing(surface: OperatorSet, laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto") -> float:
    """The mean spacing ``sqrt(area / N)``, the area from the Laplacian's mass (cell areas or area elements).

    Examples
    --------
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> round(cloud_spacing(Surface(shapes.sphere(4000)), "stable") / (4 * 3.14159 / 4000) ** 0.5, 2)
    1.0
    """
    check_surface(surface)
    return _spacing(surface, operator_for(surface, laplacian))


def _spacing(surface, op: Operator) -> float:
    area = float(np.sum(op.m))
    if not (np.isfinite(area) and area > 0):  # area elements of an irregular cloud: the stable cells'
        area = float(np.sum(surface.mass_matrix().diagonal()))
    return math.sqrt(area / surface.n_points)


def _duration(surface, op: Operator, *, equation: str, method: str, speed: float, reach, t_end, dt, steps):
    """``(dt, steps)`` from the duration keywords (module notes)."""
    if reach is not None and t_end is not None:
        raise ValueError(f"give the duration as reach= or as t_end=, not both (got reach={reach!r}, t_end={t_end!r})")
    if dt is not None:
        dt = check_positive("dt", dt)
    if steps is not None:
        steps = check_int("steps", steps, minimum=1)
    if reach is None and t_end is None:
        if dt is None or steps is None:
            given = ", ".join(f"{k}={v!r}" for k, v in (("dt", dt), ("steps", steps)) if v is not None) or "none"
            raise ValueError(
                f"{equation} needs a duration: reach= (how far the solution travels, as a fraction of the cloud's "
                f"diameter, e.g. reach=0.1), t_end= (the final time), or both dt= and steps= (got {given})"
            )
        return dt, steps
    if dt is not None and steps is not None:
        raise ValueError(
            f"dt={dt!r} and steps={steps!r} fix the duration already: with reach= or t_end= give one of them or neither"
        )
    if reach is not None:
        reach = check_positive("reach", reach)
        length = reach * cloud_diameter(surface)
        t_end = length**2 / (2.0 * speed) if equation == "heat" else length / speed
    else:
        t_end = check_positive("t_end", t_end)
    if steps is not None:
        return t_end / steps, steps
    if dt is not None:
        steps = max(1, math.ceil(t_end / dt * (1 - 1e-12)))
    elif equation == "heat" and method != "explicit":
        own = _spacing(surface, op) ** 2 / speed
        steps = min(max(math.ceil(t_end / own * (1 - 1e-12)), MIN_STEPS), MAX_STEPS)
    else:
        limit = dt_limit(surface, op, speed, equation)
        steps = max(1, math.ceil(t_end / (EXPLICIT_SAFETY * limit) * (1 - 1e-12))) if np.isfinite(limit) else MIN_STEPS
    if steps > MAX_EXPLICIT_STEPS:
        raise ValueError(
            f"{equation}: t_end = {t_end:.4g} takes {steps:,} explicit steps (dt at most {t_end / steps:.3g}); "
            "shorten the run" + (", or use method='implicit'" if equation == "heat" else "")
        )
    return t_end / steps, steps


def time_steps(
    surface: OperatorSet,
    *,
    equation: str = "heat",
    reach: float | None = None,
    t_end: float | None = None,
    dt: float | None = None,
    steps: int | None = None,
    diffusivity: float = 1.0,
    c: float = 1.0,
    method: str = "implicit",
    laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto",
) -> tuple[float, int]:
    """``(dt, steps)`` that :func:`heat` or :func:`wave` takes for these arguments, without stepping.

    For planning a run: how many steps, how many snapshots (``every=``), how long.

    Examples
    --------
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> s = Surface(shapes.sphere(2000))
    >>> dt, steps = time_steps(s, reach=0.1)     # t_end = (0.1 * 2)^2 / 2 = 0.02, at least MIN_STEPS
    >>> steps, round(dt * steps, 6)
    (10, 0.02)
    """
    check_surface(surface)
    check_in("equation", equation, ("heat", "wave"))
    if equation == "heat":
        speed = check_positive("diffusivity", diffusivity)
        check_in("method", method, HEAT_METHODS)
    else:
        speed, method = check_positive("c", c), "explicit"
    op = operator_for(surface, laplacian)
    return _duration(surface, op, equation=equation, method=method, speed=speed, reach=reach, t_end=t_end, dt=dt,
                     steps=steps)


# ----------------------------------------------------------------------------- bookkeeping
class _Recorder:
    """Per-step bookkeeping shared by the time steppers: finiteness, callback, snapshots, progress."""

    def __init__(self, name, u0, dt, steps, every, callback, progress):
        self.name, self.dt, self.steps, self.every, self.callback = name, dt, steps, every, callback
        self.saved, self.times = [u0.copy()], [0.0]
        self.bar = None
        if progress:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=steps, desc=name, unit="step", leave=False)

    def __call__(self, step, u):
        if not np.all(np.isfinite(u)):
            self.close()
            raise FloatingPointError(f"{self.name}: the solution stopped being finite at step {step}")
        if self.callback is not None:
            self.callback(step, step * self.dt, u)
        if (self.every and step % self.every == 0) or step == self.steps:
            self.saved.append(u.copy())
            self.times.append(step * self.dt)
        if self.bar is not None:
            self.bar.update()

    def close(self):
        if self.bar is not None:
            self.bar.close()
            self.bar = None

    def result(self, u, laplacian, solver):
        self.close()
        return Solution(u, np.array(self.times), np.array(self.saved), laplacian, float(self.dt), solver)


def _check_options(every, callback, progress):
    if every is not None:
        every = check_int("every", every, minimum=1)
    if callback is not None and not callable(callback):
        raise TypeError(f"callback must be a callable callback(step, t, u) or None, got {type(callback).__name__} {callback!r}")
    return every, check_bool("progress", progress)


# ----------------------------------------------------------------------------- heat
def heat(
    surface: OperatorSet,
    u0: ArrayLike,
    *,
    reach: float | None = None,
    t_end: float | None = None,
    dt: float | None = None,
    steps: int | None = None,
    diffusivity: float = 1.0,
    method: str = "implicit",
    fixed: ArrayLike | None = None,
    fixed_values: float | ArrayLike | None = None,
    every: int | None = None,
    callback: Callable | None = None,
    progress: bool = False,
    laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto",
    solver: str = "auto",
) -> Solution:
    """Heat equation ``u_t = diffusivity Lap_S u``.

    Parameters
    ----------
    surface : Surface or Domain2D
    u0 : array_like, shape (N,)
        Initial temperature.
    reach : float, optional
        How far heat spreads, as a fraction of the cloud's diameter: runs until the heat
        kernel's standard deviation ``sqrt(2 diffusivity t)`` is ``reach`` times
        :func:`cloud_diameter` (0.1: a hot spot spreads over a tenth of the object; 1:
        nearly flat). Or give ``t_end``, or ``dt`` and ``steps``.
    t_end : float, optional
        Final time, in the cloud's units.
    dt : float, optional
        Time step (> 0). Chosen from the spacing when not given (module notes). The
        explicit method refuses a ``dt`` above its stability limit
        (:func:`~manifold_sph.pde.explicit_dt_limit`), quoting the limit.
    steps : int, optional
    diffusivity : float
        ``k`` of ``u_t = k Lap_S u`` (> 0).
    method : {"implicit", "crank-nicolson", "explicit"}
        Backward Euler, Crank-Nicolson (one system set up for all steps) or the
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
    progress : bool
        Show a progress bar (tqdm) over the steps.
    laplacian : {"auto", "strong", "stable"} or sparse matrix
        Which Laplace-Beltrami (:func:`~manifold_sph.pde.choose_laplacian`). With
        ``"stable"`` the steps are ``(M + theta dt k K) u' = (M - (1 - theta) dt k K) u``:
        without ``fixed`` particles ``sum(M u)`` is conserved to round-off, and implicit
        Euler keeps ``u`` within the range of the initial values (discrete maximum
        principle; Crank-Nicolson does so only for small ``dt``).
    solver : {"auto", "direct", "iterative"}
        Implicit steps. The stable Laplacian's systems are symmetric positive definite:
        "direct" is one sparse Cholesky factorisation, "iterative" CG with multigrid set
        up once, "auto" Cholesky where it fits in memory
        (:func:`manifold_sph.solvers.spd_solver`). Other Laplacians: "direct" one sparse
        LU, "iterative" Jacobi-preconditioned BiCGSTAB (multigrid, then LU, if it stalls),
        "auto" LU up to 50,000 particles.

    Returns
    -------
    Solution
        ``.u`` the final state (N,), ``.snapshots`` (S, N) saved at ``.times`` (S,),
        ``.laplacian`` the Laplacian used, ``.dt``, ``.solver``.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(2000)
    >>> z = cloud.points[:, 2]                      # a degree-1 harmonic: decays as exp(-2 t) (diffusivity 1)
    >>> sol = heat(Surface(cloud), z, t_end=0.1, method="crank-nicolson")
    >>> bool(np.allclose(sol.u, np.exp(-0.2) * z, atol=2e-3)), float(sol.times[-1])
    (True, 0.1)
    >>> sol = heat(Surface(cloud), z, reach=0.1)     # sqrt(2 t) = 0.1 * diameter: t = 0.02
    >>> round(float(sol.times[-1]), 6)
    0.02
    """
    check_surface(surface)
    n = surface.n_points
    u = as_field("u0", u0, n).copy()
    k = check_positive("diffusivity", diffusivity)
    check_in("method", method, HEAT_METHODS)
    check_in("solver", solver, SOLVERS)
    every, progress = _check_options(every, callback, progress)
    op = operator_for(surface, laplacian)
    dt, steps = _duration(surface, op, equation="heat", method=method, speed=k, reach=reach, t_end=t_end, dt=dt,
                          steps=steps)
    mask, values = fixed_particles(fixed, fixed_values, n, u)
    u[mask] = values
    free = ~mask
    a = k * dt
    if method == "explicit":
        limit = dt_limit(surface, op, k, "heat")
        if dt > limit:
            raise ValueError(
                f"dt = {dt:g} is above the explicit heat stability limit {limit:.4g} "
                f"(2 / (diffusivity * spectral radius)); use a smaller dt or method='implicit'"
            )
        theta = 0.0
    else:
        theta = 1.0 if method == "implicit" else 0.5
    B = op.weights()
    S = op.stiffness()  # B u_t = -S u
    name = "explicit"
    if theta > 0:
        Sf = S[free]
        A = (sp.diags(B[free]) + theta * a * Sf[:, free]).tocsr()
        solve, name = _step_solver(A, solver, op.symmetric)
        rhs_fixed = theta * a * (Sf[:, mask] @ values) if mask.any() else 0.0
    record = _Recorder("heat", u, dt, steps, every, callback, progress)
    Lb = RowBlocks(op.L if theta == 0 else S)  # threaded products
    try:
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
    finally:
        record.close()
    return record.result(u, op.kind, name)


def _step_solver(A: sp.csr_matrix, solver: str, spd: bool) -> tuple[Callable, str]:
    """``(solve(rhs, guess), name)`` for the implicit step matrix ``A``, set up once.

    ``spd``: ``A`` comes from the stable Laplacian (symmetric positive definite):
    :func:`~manifold_sph.solvers.spd_solver`. Otherwise a non-symmetric one; a user's
    symmetric matrix that makes ``A`` positive definite takes the SPD path too.
    """
    method = {"auto": "auto", "direct": "cholesky", "iterative": "amg"}[solver]
    if spd or _maybe_spd(A):
        try:
            s = spd_solver(A, method=method)
            return s.solve, s.method
        except NotPositiveDefiniteError:
            if spd:
                raise
    return _nonsymmetric_solver(A, solver)


def _maybe_spd(A: sp.csr_matrix) -> bool:
    if not np.all(A.diagonal() > 0):
        return False
    scale = abs(A).max()
    return bool(scale > 0 and abs(A - A.T).max() <= 1e-12 * scale)


def _nonsymmetric_solver(A: sp.csr_matrix, solver: str) -> tuple[Callable, str]:
    """Sparse LU, or Jacobi-preconditioned BiCGSTAB on both cores with multigrid and LU as fallbacks.

    BiCGSTAB starts from the current state and stops at 1e-10 relative residual. If it does
    not converge in :data:`JACOBI_MAXITER` iterations, Ruge-Stuben multigrid (set up once,
    BiCGSTAB-accelerated) takes over; if that fails too, a sparse LU, kept for the later steps.
    """
    n = A.shape[0]
    if solver == "direct" or (solver == "auto" and n <= LU_MAX_N):
        lu = spla.splu(A.tocsc())
        return (lambda rhs, guess: lu.solve(rhs)), "lu"
    state: dict = {"jacobi": True}
    blocks = RowBlocks(A)
    dinv = 1.0 / A.diagonal()

    def norm(v):  # einsum, not BLAS: OpenBLAS's spinning threads would slow the row-block products
        return math.sqrt(float(np.einsum("i,i->", v, v)))

    def good(x, rhs):
        return np.all(np.isfinite(x)) and norm(blocks @ x - rhs) <= 1e-9 * max(norm(rhs), 1e-300)

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

    return solve, "bicgstab"


# ----------------------------------------------------------------------------- wave
def wave(
    surface: OperatorSet,
    u0: ArrayLike,
    *,
    reach: float | None = None,
    t_end: float | None = None,
    dt: float | None = None,
    steps: int | None = None,
    c: float = 1.0,
    v0: ArrayLike | None = None,
    fixed: ArrayLike | None = None,
    fixed_values: float | ArrayLike | None = None,
    every: int | None = None,
    callback: Callable | None = None,
    progress: bool = False,
    laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto",
) -> Solution:
    """Wave equation ``u_tt = c^2 Lap_S u`` with the centred scheme.

    ``u^{n+1} = 2 u^n - u^{n-1} + c^2 dt^2 L u^n`` (docs/method.md section 6), started
    with ``u^1 = u^0 + dt v0 + c^2 dt^2 L u^0 / 2``. The scheme is explicit: a ``dt``
    above ``2 / (c sqrt(rho(L)))`` is refused with the limit in the message; without
    ``dt`` it steps at :data:`EXPLICIT_SAFETY` of it.

    With ``laplacian="stable"`` (``L = -M^-1 K``) this is the leap-frog scheme of
    ``M u_tt = -c^2 K u``, which conserves the discrete energy of :func:`wave_energy`
    to round-off (without ``fixed`` particles).

    Parameters and return value as for :func:`heat`; ``reach`` is the distance ``c t``
    a front travels as a fraction of the cloud's diameter (1: across the object), ``c``
    the wave speed, ``v0`` the initial velocity (default zero).

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
    check_surface(surface)
    n = surface.n_points
    u = as_field("u0", u0, n).copy()
    v = np.zeros(n) if v0 is None else as_field("v0", v0, n)
    c = check_positive("c", c)
    every, progress = _check_options(every, callback, progress)
    op = operator_for(surface, laplacian)
    dt, steps = _duration(surface, op, equation="wave", method="explicit", speed=c, reach=reach, t_end=t_end, dt=dt,
                          steps=steps)
    L = op.L
    limit = dt_limit(surface, op, c, "wave")
    if dt > limit:
        raise ValueError(
            f"dt = {dt:g} is above the centred wave scheme's stability limit {limit:.4g} "
            f"(2 / (c * sqrt(spectral radius)))"
        )
    mask, values = fixed_particles(fixed, fixed_values, n, u)
    u[mask] = values
    b = (c * dt) ** 2
    prev = u
    u = prev + dt * v + 0.5 * b * (L @ prev)
    u[mask] = values
    record = _Recorder("wave", prev, dt, steps, every, callback, progress)
    Lb = RowBlocks(L)  # threaded products
    try:
        for step in range(1, steps + 1):
            if step > 1:
                prev, u = u, 2 * u - prev + b * (Lb @ u)
                u[mask] = values
            record(step, u)
    finally:
        record.close()
    return record.result(u, op.kind, "explicit")


def wave_energy(surface: OperatorSet, u_prev: ArrayLike, u_next: ArrayLike, dt: float, *, c: float = 1.0,
                laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto") -> float:
    """Discrete energy of the centred scheme between two successive states.

    ``E = 1/2 |(u^{n+1} - u^n)/dt|_M^2 - c^2/2 (u^{n+1})^T M L u^n``, with ``M`` the
    stable Laplacian's mass (``laplacian="stable"``: then ``-M L = K`` and ``E`` is
    exactly conserved) or ``diag(dV)`` (strong form: ``E`` is conserved when ``M L``
    is symmetric, so its drift measures the non-symmetry of the SPH Laplacian).
    """
    check_surface(surface)
    n = surface.n_points
    u_prev = as_field("u_prev", u_prev, n)
    u_next = as_field("u_next", u_next, n)
    dt = check_positive("dt", dt)
    c = check_positive("c", c)
    op = operator_for(surface, laplacian)
    L, dV = op.L, op.m
    vel = (u_next - u_prev) / dt
    return float(0.5 * np.sum(dV * vel**2) - 0.5 * c**2 * np.dot(u_next * dV, L @ u_prev))
