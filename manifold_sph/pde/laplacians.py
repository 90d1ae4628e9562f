"""Which Laplacian the PDE solvers use, and the limits of the explicit schemes.

``laplacian=`` of every solver in :mod:`manifold_sph.pde`:

- ``"strong"``: the scheme's own Laplacian ``L`` (``Surface.laplacian_matrix(form="strong")``),
  not symmetric;
- ``"stable"``: ``K u = -M Lap_S u`` with the Voronoi stiffness ``K`` (symmetric positive
  semi-definite) and the diagonal mass ``M`` (``Surface.stiffness_matrix()``,
  ``Surface.mass_matrix()``), on any cloud;
- ``"auto"`` (the default): ``"strong"`` when it is both the accurate one on this cloud
  (``Surface.laplacian_form == "strong"``) and shown free of growing modes
  (:func:`strong_form_decays`), otherwise ``"stable"``; ``Solution.laplacian`` says which,
  and ``Surface.report()`` why;
- a sparse matrix, real, used as ``L``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike

from .._validation import check_in, check_int, check_positive
from ..diagnostics import collecting, note
from ..operators import OperatorSet

__all__ = [
    "LAPLACIANS",
    "AUTO_CHECK_MAX",
    "AUTO_MAXITER",
    "strong_form_decays",
    "choose_laplacian",
    "spectral_radius",
    "spectrum_right_edge",
    "explicit_dt_limit",
]

LAPLACIANS = ("auto", "strong", "stable")

#: Above this many particles ``laplacian="auto"`` does not search the strong form's spectrum for growing
#: modes (unless Gershgorin's bound proves it free of them) and uses "stable": on Fibonacci spheres the
#: search converged up to 8,000 points (0.4 s) and did not at 20,000 (2.8 s) or 100,000 (78 s).
AUTO_CHECK_MAX = 20_000

#: ARPACK restarts of the spectrum check behind ``laplacian="auto"``.
AUTO_MAXITER = 50


def check_surface(surface: object) -> None:
    """TypeError unless ``surface`` is a Surface or Domain2D."""
    if not isinstance(surface, OperatorSet):
        raise TypeError(f"surface must be a Surface or Domain2D, got {type(surface).__name__}")


def strong_form_decays(surface: OperatorSet, *, maxiter: int = AUTO_MAXITER) -> bool:
    """Whether every mode of the scheme's (strong-form) Laplacian is shown to decay (no eigenvalue with Re > 0).

    A matrix whose Gershgorin discs all lie in ``Re <= 0`` (non-negative
    off-diagonals dominated by a non-positive diagonal, as the standard scheme
    with Shepard elements gives) decays by that bound alone. Otherwise ARPACK
    looks for the eigenvalues with the largest real parts (``maxiter`` restarts at
    most). Growing modes of SPH Laplacians on irregular clouds are large and
    isolated and are found in a few iterations; the check says True only when the
    right edge converged at 0 (within ``1e-6`` of the Gershgorin bound of the
    spectral radius), and False when a growing mode was found, the iteration did
    not converge, or the cloud has more than :data:`AUTO_CHECK_MAX` particles. The
    result is cached on the surface.

    Examples
    --------
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> strong_form_decays(Surface(shapes.sphere(2000)))     # Fibonacci points
    True
    """
    check_surface(surface)
    maxiter = check_int("maxiter", maxiter, minimum=1)
    return surface.cached(("strong_decays", maxiter), lambda: _strong_form_check(surface, maxiter))[0]


def _strong_form_check(surface, maxiter: int) -> tuple[bool, str]:
    L = surface.laplacian_matrix(form="strong")
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
        ok, reason = False, f"its spectrum is not searched for growing modes above {AUTO_CHECK_MAX:,} points"
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
            ok, reason = False, f"it has growing modes (eigenvalues with positive real part up to {top:.3g})"
        elif converged:
            ok = True
        else:
            ok, reason = False, "its spectrum could not be shown free of growing modes"
    return ok, reason


def choose_laplacian(surface: OperatorSet, laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto") -> str:
    """The Laplacian the solvers use for ``laplacian``: ``"strong"``, ``"stable"`` or ``"matrix"``.

    ``"auto"`` gives ``"strong"`` when it is the accurate form on this cloud
    (``surface.laplacian_form``) and :func:`strong_form_decays`, otherwise ``"stable"``;
    the reason is recorded in ``surface.report()`` (no warning: the stable Laplacian is
    always safe to step).

    Examples
    --------
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> choose_laplacian(Surface(shapes.sphere(2000))), choose_laplacian(Surface(shapes.sphere(2000)), "stable")
    ('strong', 'stable')
    """
    check_surface(surface)
    if laplacian is None:
        laplacian = "auto"
    if not isinstance(laplacian, str):
        return "matrix"
    check_in("laplacian", laplacian, LAPLACIANS)
    if laplacian != "auto":
        return laplacian
    return surface.cached("pde_auto", lambda: _auto(surface))


def _auto(surface) -> str:
    with collecting(surface.report(), warn=False):
        if surface.laplacian_form != "strong":
            note("pde_laplacian", "the PDE solvers use the stable Laplacian", severity="info",
                 detail="The scheme's own Laplacian is not the accurate one on this cloud (see the Laplacian entry).")
            return "stable"
        decays, reason = surface.cached(("strong_decays", AUTO_MAXITER), lambda: _strong_form_check(surface, AUTO_MAXITER))
        if decays:
            note("pde_laplacian", "the PDE solvers use the scheme's own Laplacian", severity="info",
                 detail="It is accurate on this cloud and none of its modes grows.")
            return "strong"
        note("pde_laplacian", "the PDE solvers use the stable Laplacian", severity="info",
             detail=f"The scheme's own Laplacian is accurate here, but {reason}: time steps with it could grow "
             "without bound. Pass laplacian='strong' to use it anyway.")
        return "stable"


@dataclass
class Operator:
    """The Laplacian a solver uses: ``L`` (products), the mass ``m``, and for "stable" also ``K``.

    ``kind`` is ``"strong"``, ``"stable"`` or ``"matrix"``. ``B u_t = -S u`` with
    ``(B, S) = (diag(m), K)`` for the stable Laplacian and ``(I, -L)`` otherwise.
    """

    kind: str
    L: sp.csr_matrix
    m: np.ndarray
    K: sp.csr_matrix | None = None

    @property
    def symmetric(self) -> bool:
        """Whether the steps' system ``B + a S`` is symmetric positive definite (the stable Laplacian)."""
        return self.K is not None

    def stiffness(self) -> sp.csr_matrix:
        """``S``: ``K`` for the stable Laplacian, ``-L`` otherwise."""
        return self.K if self.K is not None else (-self.L).tocsr()

    def weights(self) -> np.ndarray:
        """The diagonal of ``B``: the masses for the stable Laplacian, ones otherwise."""
        return self.m if self.K is not None else np.ones(self.L.shape[0])


def operator_for(surface: OperatorSet, laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None) -> Operator:
    """The :class:`Operator` for ``laplacian`` (a name or a matrix), validated."""
    kind = choose_laplacian(surface, laplacian)
    n = surface.n_points
    if kind == "stable":
        K = surface.stiffness_matrix()
        m = np.asarray(surface.mass_matrix().diagonal())
        return Operator("stable", surface.stable_laplacian_matrix(), m, K)
    if kind == "strong":
        return Operator("strong", surface.laplacian_matrix(form="strong"), surface.dV)
    if laplacian is None or isinstance(laplacian, str) or not (sp.issparse(laplacian) or isinstance(laplacian, np.ndarray)):
        raise TypeError(f"laplacian must be one of {list(LAPLACIANS)} or a sparse matrix, got {type(laplacian).__name__}")
    if np.iscomplexobj(laplacian):
        raise TypeError(
            f"laplacian must be a real matrix, got dtype {laplacian.dtype}: the solvers step real fields "
            "(for a complex operator, step its real and imaginary parts as a real system of twice the size)"
        )
    if laplacian.dtype == object or not (np.issubdtype(laplacian.dtype, np.number) or laplacian.dtype == bool):
        raise TypeError(f"laplacian must be a real numeric matrix, got dtype {laplacian.dtype}")
    L = sp.csr_matrix(laplacian, dtype=np.float64)
    if L.shape != (n, n):
        raise ValueError(f"laplacian must have shape ({n}, {n}), got {L.shape}")
    if not np.all(np.isfinite(L.data)):
        raise ValueError("laplacian must have finite entries")
    return Operator("matrix", L, surface.dV)


# ------------------------------------------------------------------ spectra and explicit limits
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
    rho = new = 0.0
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


def operator_radius(surface: OperatorSet, op: Operator) -> float:
    """Spectral radius of the operator's ``L`` (cached per surface for "strong" and "stable" only:
    a matrix passed in is measured every time, never keyed by its ``id``)."""
    if op.kind != "matrix":
        return surface.cached(("rho", op.kind), lambda: _rho_of(op))
    return _rho_of(op)


def _rho_of(op: Operator) -> float:
    if op.kind == "stable":  # M^-1 K is similar to the symmetric M^-1/2 K M^-1/2: Lanczos
        d = 1.0 / np.sqrt(op.m)
        S = (sp.diags(d) @ op.K @ sp.diags(d)).tocsr()
        n = S.shape[0]
        if n <= 3:
            return float(np.abs(np.linalg.eigvalsh(S.toarray())).max())
        v0 = np.random.default_rng(0).standard_normal(n)
        try:
            return float(spla.eigsh(S, k=1, which="LA", v0=v0, tol=1e-6, return_eigenvectors=False)[0])
        except spla.ArpackNoConvergence:
            return float(abs(S).sum(axis=1).max())  # Gershgorin: an upper bound
    return spectral_radius(op.L)


def dt_limit(surface: OperatorSet, op: Operator, speed: float, equation: str) -> float:
    """The explicit scheme's stability limit: ``2 / (speed rho)`` (heat) or ``2 / (speed sqrt(rho))`` (wave)."""
    rho = operator_radius(surface, op)
    if rho == 0:
        return np.inf
    return 2.0 / (speed * rho) if equation == "heat" else 2.0 / (speed * np.sqrt(rho))


def explicit_dt_limit(surface: OperatorSet, *, equation: str = "heat", diffusivity: float = 1.0, c: float = 1.0,
                      laplacian: str | sp.spmatrix | sp.sparray | np.ndarray | None = "auto") -> float:
    """Largest stable time step of the explicit schemes, from the spectral radius ``rho`` of ``L``.

    Heat (forward Euler): ``2 / (diffusivity rho)``. Wave (centred): ``2 / (c sqrt(rho))``.
    Exact for eigenvalues on the negative real axis (always the case with
    ``laplacian="stable"``); complex eigenvalues near the imaginary axis are not
    covered (use an implicit method). ``laplacian`` as in :func:`manifold_sph.pde.heat`.

    Examples
    --------
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> s = Surface(shapes.sphere(1000), area="shepard")
    >>> heat_dt, wave_dt = explicit_dt_limit(s, diffusivity=2.0), explicit_dt_limit(s, equation="wave", c=2.0)
    >>> bool(0 < heat_dt < wave_dt)
    True
    """
    check_surface(surface)
    check_in("equation", equation, ("heat", "wave"))
    if equation == "heat":
        speed = check_positive("diffusivity", diffusivity)
    else:
        speed = check_positive("c", c)
    return dt_limit(surface, operator_for(surface, laplacian), speed, equation)


def fixed_particles(fixed: ArrayLike | None, fixed_values: float | ArrayLike | None, n: int,
                    u0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
        if np.iscomplexobj(fixed_values):
            raise TypeError(f"fixed_values must be real, got dtype {np.asarray(fixed_values).dtype}")
        values = np.asarray(fixed_values, dtype=np.float64)
        if values.ndim == 0:
            values = np.full(k, float(values))
        if values.shape != (k,):
            raise ValueError(f"fixed_values must be a scalar or have shape ({k},) (one per fixed particle), got {values.shape}")
        if not np.all(np.isfinite(values)):
            raise ValueError("fixed_values must be finite")
    return mask, values
