"""Large sparse linear systems, set up once and solved many times.

The one place the package solves big sparse systems: implicit heat steps on
``M + dt K``, the two solves of the geodesic heat method, Poisson problems and the
shift-invert eigenvalue iterations all call :func:`spd_solver` (or, where the matrix may
not be symmetric positive definite, :func:`linear_solver`).

Two methods for a symmetric positive definite (SPD) matrix ``A``, both set up once:

``"cholesky"``
    A sparse Cholesky factorisation ``P A P^T = L L^T`` (CHOLMOD with a nested-dissection
    ordering, through the ``cholespy`` wheel). Each later solve is two triangular solves:
    tens of milliseconds at 100,000 unknowns. On the stiffness matrices of sampled
    surfaces the factor takes about 1 KB a point (262,144 to 1,048,576 points measured);
    ``docs/solvers.md`` has the measured table.
``"amg"``
    Conjugate gradients preconditioned by one V-cycle of smoothed-aggregation algebraic
    multigrid (``pyamg``), to a relative residual ``rtol``. Memory is linear in ``N``
    (about 0.5 KB a point with the CG vectors); each solve takes 8 to 30 iterations on
    ``M + dt K`` and on a pinned ``K``, independent of ``N``.
``"auto"``
    Cholesky when ``cholespy`` is installed and its estimated factor fits in a quarter of
    the available memory (and ``N <= CHOLESKY_MAX_N``), AMG-CG otherwise.

Both run on the symmetrically scaled matrix ``D^-1/2 A D^-1/2`` (``D`` the diagonal),
which makes them independent of the units of ``A``: a cloud scaled by ``1e-150`` gives
the same iterations and the same relative accuracy as the unit cloud.

:func:`linear_solver` is for a matrix that need not be SPD (a strong-form Laplacian, a
saddle-point system): an SPD matrix goes to :func:`spd_solver`, any other to a sparse LU
(SuperLU), whose fill makes it the slow path beyond about 50,000 unknowns.

Examples
--------
>>> import numpy as np
>>> from manifold_sph import Surface
>>> from manifold_sph.reference import shapes
>>> s = Surface(shapes.sphere(2000))
>>> K, M = s.stiffness_matrix(), s.mass_matrix()
>>> step = spd_solver(M + 1e-3 * K)           # factorise or set up once ...
>>> u = step.solve(M @ np.ones(2000))          # ... and solve many times
>>> bool(np.allclose(u, 1.0))
True
>>> step.method in ("cholesky", "amg"), step.info.residual < 1e-10
(True, True)
"""

from __future__ import annotations

import dataclasses
import os
import time
import warnings
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike

from ._validation import check_bool, check_in, check_int, check_positive
from .results import Result

__all__ = [
    "CHOLESKY_MAX_N",
    "CHOLESKY_BYTES_PER_POINT",
    "NotPositiveDefiniteError",
    "SolveInfo",
    "SolverConvergenceError",
    "SparseSolver",
    "cholesky_available",
    "choose_spd_method",
    "linear_solver",
    "spd_solver",
]

#: ``method="auto"`` uses Cholesky up to this many unknowns (and only if the estimate fits in memory).
CHOLESKY_MAX_N = 4_000_000
#: Bytes a point of a Cholesky factor of a surface stiffness matrix (measured: 0.95 KB at 262,144 points,
#: 0.99 KB at 1,048,576), grown by 15 % per doubling beyond 262,144 points: the estimate that
#: ``method="auto"`` compares with the available memory.
CHOLESKY_BYTES_PER_POINT = 1200
#: Relative difference ``max|A - A^T| / max|A|`` above which a matrix is not symmetric.
SYMMETRY_TOL = 1e-12

SPD_METHODS = ("auto", "cholesky", "amg")
LINEAR_METHODS = ("auto", "cholesky", "amg", "lu")


class NotPositiveDefiniteError(ValueError):
    """The matrix given to :func:`spd_solver` is not symmetric positive definite."""


class SolverConvergenceError(RuntimeError):
    """An iterative solve did not reach its tolerance in its iteration budget."""


@dataclasses.dataclass(frozen=True, repr=False)
class SolveInfo(Result):
    """What a :class:`SparseSolver` did: its method, set-up and the last solve.

    Attributes
    ----------
    method : str
        ``"cholesky"``, ``"amg"`` or ``"lu"``.
    n : int
        Number of unknowns.
    nnz : int
        Stored entries of the matrix.
    setup_seconds : float
        Wall time of the factorisation or the multigrid set-up.
    solves : int
        Right-hand sides solved so far.
    iterations : int
        CG iterations of the last solve (the largest over its columns); 0 for direct methods.
    residual : float
        Relative residual ``|b - A x| / |b|`` of the last solve (largest over its columns),
        measured on ``A`` itself; NaN before the first solve.
    seconds : float
        Wall time of the last solve.
    """

    method: str
    n: int
    nnz: int
    setup_seconds: float
    solves: int
    iterations: int
    residual: float
    seconds: float


def cholesky_available() -> bool:
    """True when the sparse Cholesky backend (``cholespy``) is importable."""
    try:
        import cholespy  # noqa: F401
    except ImportError:
        return False
    return True


def _as_square_csr(name: str, A: Any) -> sp.csr_matrix:
    if not (sp.issparse(A) or isinstance(A, np.ndarray)):
        raise TypeError(f"{name} must be a scipy sparse matrix or a 2-D ndarray, got {type(A).__name__}")
    if A.ndim != 2 or A.shape[0] != A.shape[1] or A.shape[0] == 0:
        raise ValueError(f"{name} must be a non-empty square matrix, got shape {A.shape}")
    if np.iscomplexobj(A):
        raise TypeError(f"{name} must be real, got dtype {A.dtype}")
    A = sp.csr_matrix(A, dtype=np.float64)
    if not np.all(np.isfinite(A.data)):
        bad = int(np.count_nonzero(~np.isfinite(A.data)))
        raise ValueError(f"{name} must be finite, but it holds {bad} NaN or inf entries")
    A.sum_duplicates()
    A.eliminate_zeros()
    return A


def _asymmetry(A: sp.csr_matrix) -> float:
    scale = abs(A).max() if A.nnz else 0.0
    if scale == 0:
        return 0.0
    return float(abs(A - A.T).max() / scale)


def _estimated_cholesky_bytes(n: int) -> float:
    return CHOLESKY_BYTES_PER_POINT * n * (1.0 + 0.15 * max(0.0, np.log2(max(n, 2) / 262144.0)))


def _available_bytes() -> float:
    try:
        import psutil

        return float(psutil.virtual_memory().available)
    except ImportError:  # pragma: no cover - psutil comes with the test and dask installs
        pages = os.sysconf("SC_AVPHYS_PAGES") if hasattr(os, "sysconf") else 0
        return float(pages * os.sysconf("SC_PAGE_SIZE")) if pages else float("inf")


def choose_spd_method(n: int) -> str:
    """``"cholesky"`` or ``"amg"``: what ``method="auto"`` picks for ``n`` unknowns on this machine now."""
    if cholesky_available() and n <= CHOLESKY_MAX_N and _estimated_cholesky_bytes(n) <= 0.25 * _available_bytes():
        return "cholesky"
    return "amg"


class SparseSolver:
    """A linear system ``A x = b`` set up once (factorised, or multigrid built) and solved on demand.

    Made by :func:`spd_solver` or :func:`linear_solver`; call :meth:`solve` (or the object).

    Attributes
    ----------
    method : str
        ``"cholesky"``, ``"amg"`` or ``"lu"``.
    n : int
        Number of unknowns.
    rtol : float
        Relative residual the iterative method solves to.
    """

    def __init__(self, A: sp.csr_matrix, method: str, *, rtol: float, maxiter: int | None, progress: bool,
                 lu_fallback: bool = False) -> None:
        self.n = A.shape[0]
        self._lu_fallback = lu_fallback
        self.method = method
        self.rtol = rtol
        self.maxiter = maxiter
        self.progress = progress
        self._A = A
        self._nnz = int(A.nnz)
        self._solves = 0
        self._last = (0, float("nan"), 0.0)
        t0 = time.perf_counter()
        if method == "lu":
            self._set_lu()
        else:
            d = A.diagonal()
            bad = np.flatnonzero(~(d > 0))
            if bad.size:
                raise NotPositiveDefiniteError(
                    f"A is not positive definite: {bad.size} diagonal entr{'y' if bad.size == 1 else 'ies'} "
                    f"<= 0 (first at row {int(bad[0])}: {d[bad[0]]:g}); a stiffness matrix K is only semi-definite: "
                    "solve with M + dt K, pin some values, or use linear_solver for an indefinite matrix"
                )
            self._scale = 1.0 / np.sqrt(d)
            S = sp.diags(self._scale) @ A @ sp.diags(self._scale)
            S = sp.csr_matrix(S)
            S.sort_indices()
            if method == "cholesky":
                self._factor = _cholesky(S)
            else:
                import pyamg

                with np.errstate(all="ignore"):
                    self._amg = pyamg.smoothed_aggregation_solver(S, symmetry="hermitian", max_coarse=500)
                self._S = S
        self._setup = time.perf_counter() - t0

    def _set_lu(self) -> None:
        self.method = "lu"
        self._scale = np.ones(self.n)
        try:
            self._lu = spla.splu(self._A.tocsc())
        except RuntimeError as exc:  # SuperLU: "Factor is exactly singular"
            raise ValueError(f"A is singular (the LU factorisation stopped: {exc})") from exc

    # ------------------------------------------------------------------ info
    @property
    def info(self) -> SolveInfo:
        """A :class:`SolveInfo`: method, set-up time, and the last solve's iterations and residual."""
        its, res, secs = self._last
        return SolveInfo(self.method, self.n, self._nnz, self._setup, self._solves, its, res, secs)

    def __repr__(self) -> str:
        return f"SparseSolver(method={self.method!r}, n={self.n}, nnz={self._nnz})"

    # ----------------------------------------------------------------- solve
    def __call__(self, b: ArrayLike, x0: ArrayLike | None = None) -> np.ndarray:
        return self.solve(b, x0)

    def solve(self, b: ArrayLike, x0: ArrayLike | None = None) -> np.ndarray:
        """Solve ``A x = b``.

        Parameters
        ----------
        b : array_like, shape (N,) or (N, m)
            Right-hand side(s); ``m`` columns are solved together.
        x0 : array_like, shape like ``b``, optional
            Starting guess of the iterative method (ignored by the direct ones).

        Returns
        -------
        ndarray, shape like ``b``

        Raises
        ------
        SolverConvergenceError
            CG did not reach ``rtol`` in ``maxiter`` iterations.
        """
        b = np.asarray(b)
        if np.iscomplexobj(b):
            raise TypeError(f"b must be real, got dtype {b.dtype}")
        if b.ndim not in (1, 2) or b.shape[0] != self.n:
            raise ValueError(f"b must have shape ({self.n},) or ({self.n}, m), got {b.shape}")
        b = b.astype(np.float64, copy=False)
        if not np.all(np.isfinite(b)):
            raise ValueError(f"b must be finite, but it holds {int(np.count_nonzero(~np.isfinite(b)))} NaN or inf values")
        if x0 is not None:
            x0 = np.asarray(x0, dtype=np.float64)
            if x0.shape != b.shape:
                raise ValueError(f"x0 must have the shape of b {b.shape}, got {x0.shape}")
        try:
            return self._solve(b, x0)
        except SolverConvergenceError:
            if not self._lu_fallback:
                raise
            self._set_lu()  # linear_solver: a symmetric matrix that CG could not solve is indefinite
            return self._solve(b, x0)

    def _solve(self, b: np.ndarray, x0: np.ndarray | None) -> np.ndarray:
        t0 = time.perf_counter()
        cols = b.reshape(self.n, -1)
        guess = None if x0 is None else x0.reshape(self.n, -1)
        if self.method == "lu":
            x = self._lu.solve(np.ascontiguousarray(cols))
            its = 0
        else:
            s = self._scale[:, None]
            y_rhs = np.ascontiguousarray(s * cols)
            if self.method == "cholesky":
                y = np.zeros_like(y_rhs)
                self._factor.solve(y_rhs, y)
                its = 0
            else:
                y = np.empty_like(y_rhs)
                its = 0
                for j in range(y.shape[1]):
                    g = None if guess is None else guess[:, j] / self._scale
                    y[:, j], it = self._cg(y_rhs[:, j], g)
                    its = max(its, it)
            x = s * y
        if not np.all(np.isfinite(x)):
            raise FloatingPointError(
                f"the {self.method} solve overflowed (entries of b up to {np.abs(b).max():g}); rescale b or A"
            )
        res = self._residual(cols, x)
        self._solves += cols.shape[1]
        self._last = (its, res, time.perf_counter() - t0)
        return x.reshape(b.shape)

    def _residual(self, b: np.ndarray, x: np.ndarray) -> float:
        r = b - self._A @ x
        nb = np.linalg.norm(b, axis=0)
        nr = np.linalg.norm(r, axis=0)
        rel = np.where(nb > 0, nr / np.where(nb > 0, nb, 1.0), nr)
        return float(rel.max()) if rel.size else 0.0

    def _cg(self, b: np.ndarray, x0: np.ndarray | None) -> tuple[np.ndarray, int]:
        if not np.any(b):
            return np.zeros_like(b), 0
        maxiter = self.maxiter if self.maxiter is not None else max(200, int(20 * np.log2(self.n + 2)))
        residuals: list[float] = []
        bar = None
        callback = None
        if self.progress:
            from tqdm.auto import tqdm

            bar = tqdm(total=maxiter, desc=f"AMG-CG, {self.n} unknowns", unit="it", leave=False)
            callback = lambda _x: bar.update(1)  # noqa: E731
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                y = self._amg.solve(b, x0=x0, tol=self.rtol, maxiter=maxiter, accel="cg", residuals=residuals,
                                    callback=callback)
        finally:
            if bar is not None:
                bar.close()
        its = max(len(residuals) - 1, 0)
        nb = np.linalg.norm(b)
        rel = np.linalg.norm(b - self._S @ y) / nb
        if any("ndefinite" in str(w.message) for w in caught):
            raise SolverConvergenceError(
                f"CG met a direction of negative curvature after {its} iterations (relative residual {rel:.3g}): "
                "A is not positive definite; use linear_solver for an indefinite matrix"
            )
        if not np.isfinite(rel) or rel > 10 * self.rtol:
            raise SolverConvergenceError(
                f"AMG-preconditioned CG stopped at relative residual {rel:.3g} after {its} iterations "
                f"(rtol={self.rtol:g}, maxiter={maxiter}); A may not be positive definite, or pass a larger "
                "maxiter, or method='cholesky'"
            )
        return y, its


def _cholesky(S: sp.csr_matrix):
    try:
        import cholespy
    except ImportError as exc:  # pragma: no cover - cholespy is a dependency
        raise ImportError(
            "method='cholesky' needs the cholespy package (pip install cholespy); method='amg' needs none"
        ) from exc
    n = S.shape[0]
    lower = sp.tril(S, format="csr")
    lower.sort_indices()
    if lower.nnz >= 2**31:
        raise ValueError(f"A has {lower.nnz} entries in its lower triangle; Cholesky takes fewer than 2**31: method='amg'")
    try:
        return cholespy.CholeskySolverD(
            n, lower.indptr.astype(np.int32), lower.indices.astype(np.int32), np.ascontiguousarray(lower.data),
            cholespy.MatrixType.CSR,
        )
    except ValueError as exc:  # "Matrix is not positive definite!"
        raise NotPositiveDefiniteError(
            f"A is not positive definite (the Cholesky factorisation stopped: {exc}); a stiffness matrix K is "
            "only semi-definite: solve with M + dt K or pin some values; use linear_solver for an indefinite matrix"
        ) from exc


def _check_common(rtol: float, maxiter: int | None, progress: bool) -> tuple[float, int | None, bool]:
    rtol = check_positive("rtol", rtol)
    if rtol >= 1:
        raise ValueError(f"rtol must be below 1, got {rtol:g}")
    if maxiter is not None:
        maxiter = check_int("maxiter", maxiter, minimum=1)
    return rtol, maxiter, check_bool("progress", progress)


def spd_solver(
    A: sp.spmatrix | sp.sparray | np.ndarray,
    *,
    method: str = "auto",
    rtol: float = 1e-10,
    maxiter: int | None = None,
    progress: bool = False,
) -> SparseSolver:
    """Set up the solve of ``A x = b`` for a symmetric positive definite ``A``.

    Parameters
    ----------
    A : sparse matrix or ndarray, shape (N, N)
        Symmetric (to ``SYMMETRY_TOL`` relative) and positive definite, finite.
    method : {"auto", "cholesky", "amg"}
        Sparse Cholesky (factorised here), or CG with a smoothed-aggregation multigrid
        preconditioner (set up here); ``"auto"`` chooses Cholesky where it fits in memory
        (module notes).
    rtol : float
        Relative residual ``|b - A x| / |b|`` that CG reaches (a direct solve reaches
        round-off, about ``1e-15 cond(A)``).
    maxiter : int, optional
        CG iterations per right-hand side (default ``max(200, 20 log2 N)``).
    progress : bool
        Show a progress bar during CG iterations.

    Returns
    -------
    SparseSolver
        ``.solve(b)``; ``.method``; ``.info`` (iterations, residual, timings).

    Raises
    ------
    NotPositiveDefiniteError
        ``A`` is not symmetric, has a diagonal entry ``<= 0``, or its factorisation
        meets a non-positive pivot.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> A = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(100, 100))
    >>> x = spd_solver(A, method="amg").solve(np.ones(100))
    >>> bool(np.allclose(A @ x, 1.0))
    True
    """
    method = check_in("method", method, SPD_METHODS)
    rtol, maxiter, progress = _check_common(rtol, maxiter, progress)
    A = _as_square_csr("A", A)
    asym = _asymmetry(A)
    if asym > SYMMETRY_TOL:
        raise NotPositiveDefiniteError(
            f"A must be symmetric, but max|A - A^T| / max|A| = {asym:.3g} (tolerance {SYMMETRY_TOL:g}); "
            "use linear_solver for a non-symmetric matrix"
        )
    if asym > 0:
        A = ((A + A.T) * 0.5).tocsr()
    if method == "auto":
        method = choose_spd_method(A.shape[0])
    return SparseSolver(A, method, rtol=rtol, maxiter=maxiter, progress=progress)


def linear_solver(
    A: sp.spmatrix | sp.sparray | np.ndarray,
    *,
    method: str = "auto",
    rtol: float = 1e-10,
    maxiter: int | None = None,
    progress: bool = False,
) -> SparseSolver:
    """Set up the solve of ``A x = b`` for any square non-singular ``A``.

    An SPD matrix takes the path of :func:`spd_solver`; a non-symmetric or indefinite
    one a sparse LU (SuperLU), the general fallback: its fill grows fast with ``N``.

    Parameters
    ----------
    A : sparse matrix or ndarray, shape (N, N)
    method : {"auto", "cholesky", "amg", "lu"}
        ``"auto"``: :func:`spd_solver`'s choice when ``A`` is symmetric with a positive
        diagonal and its Cholesky factorisation succeeds (or multigrid is chosen), LU
        otherwise. The others as in :func:`spd_solver`, and ``"lu"`` always.
    rtol, maxiter, progress
        As in :func:`spd_solver`.

    Returns
    -------
    SparseSolver

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> A = sp.diags([-1.0, 2.0, -0.5], [-1, 0, 1], shape=(50, 50))   # not symmetric
    >>> s = linear_solver(A)
    >>> s.method, bool(np.allclose(A @ s.solve(np.ones(50)), 1.0))
    ('lu', True)
    """
    method = check_in("method", method, LINEAR_METHODS)
    rtol, maxiter, progress = _check_common(rtol, maxiter, progress)
    A = _as_square_csr("A", A)
    if method in ("cholesky", "amg"):
        return spd_solver(A, method=method, rtol=rtol, maxiter=maxiter, progress=progress)
    asym = _asymmetry(A)
    if method == "auto" and asym <= SYMMETRY_TOL and np.all(A.diagonal() > 0):
        if asym > 0:
            A = ((A + A.T) * 0.5).tocsr()
        try:  # CG that stalls (an indefinite matrix) hands over to LU at the first solve
            return SparseSolver(A, choose_spd_method(A.shape[0]), rtol=rtol, maxiter=maxiter, progress=progress,
                                lu_fallback=True)
        except NotPositiveDefiniteError:
            pass  # symmetric indefinite: LU below
    return SparseSolver(A, "lu", rtol=rtol, maxiter=maxiter, progress=progress)
