"""The stable Laplacian's spectrum: eigenpairs of ``K v = lambda M v``.

``K`` is the symmetric positive semi-definite stiffness and ``M`` the diagonal mass of
the stable Laplacian (:mod:`manifold_sph.voronoi`), so the eigenvalues are real and
``>= 0``, one zero per connected piece of the cloud.

One contract for every cloud size:

- ``sigma=None``: the ``k`` smallest eigenpairs; ``sigma=s``: the ``k`` eigenpairs whose
  eigenvalues are nearest ``s``. Both ascending.
- ``component="largest"`` (default): the eigenpairs of the largest connected piece of
  the cloud (connected through ``K``'s fluxes); the particles of the other pieces
  (isolated points, small clusters) are left out, named in ``.excluded``, their rows of
  ``.vectors`` zero, and one warning says how many. ``component=i`` (a particle index):
  the piece that holds particle ``i``; ``component="all"``: the whole cloud, one zero
  eigenvalue per piece (a warning gives their number when there is more than one).
- ``1 <= k <= n - 2`` with ``n`` the particles of the chosen piece.
- Scale-free: the pencil is solved with ``M`` divided by its mean, so a cloud scaled by
  ``c`` gives eigenvalues scaled by exactly ``c^-2`` while they are representable; area
  elements outside ``[MIN_MASS, MAX_MASS]`` (point spacings beyond about 1e-140..1e140,
  eigenvalues beyond float64) are refused with that range.

Methods (``method="auto"`` picks the first that applies):

``"dense"``
    LAPACK ``eigh`` of the dense pencil, for pieces of at most ``DENSE_MAX_N`` particles.
``"shift-invert"``
    Lanczos (ARPACK) on ``(K - sigma M)^-1 M`` with one sparse Cholesky factorisation of
    ``K - sigma M`` (:func:`manifold_sph.solvers.spd_solver`; an LU where ``sigma`` lies
    inside the spectrum). Memory: the factor (about 1 KB a point) and ``2 k + 1`` Lanczos
    vectors (8 bytes each a point): about 1.8 KB a point for ``k = 50``.
``"lobpcg"``
    LOBPCG preconditioned by smoothed-aggregation multigrid on ``K + |sigma| M`` (no
    factorisation: about ``24 (k + 8)`` bytes a point plus the multigrid), where the
    factor does not fit in memory. ``sigma`` inside the spectrum needs shift-invert.

Examples
--------
>>> import numpy as np
>>> from manifold_sph import Surface
>>> from manifold_sph.reference import shapes
>>> s = Surface(shapes.sphere(2000))
>>> ev = stable_eigenpairs(s.stiffness_matrix(), s.mass_matrix().diagonal(), 4)
>>> np.round(ev.values, 1).tolist(), ev.vectors.shape, ev.excluded.size
([0.0, 2.0, 2.0, 2.0], (2000, 4), 0)
>>> lam, V = ev                                   # unpacks as (values, vectors)
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Iterator
from typing import Any, SupportsIndex, overload

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from ._validation import check_in, check_int
from .exceptions import ManifoldSPHWarning
from .results import Result
from .solvers import choose_spd_method, linear_solver, spd_solver

__all__ = ["DENSE_MAX_N", "MAX_MASS", "MIN_MASS", "EIGS_METHODS", "Eigenpairs", "stable_eigenpairs"]

#: Pieces of at most this many particles are solved densely (LAPACK).
DENSE_MAX_N = 1500
#: Mean area elements outside ``[MIN_MASS, MAX_MASS]`` are refused: eigenvalues ~ 1 / area would leave float64.
MIN_MASS = 1e-280
MAX_MASS = 1e280
EIGS_METHODS = ("auto", "dense", "shift-invert", "lobpcg")
#: Iterations of LOBPCG before it stops with a warning.
LOBPCG_MAXITER = 1000


@dataclasses.dataclass(frozen=True, repr=False)
class Eigenpairs(Result):
    """Eigenpairs of ``K v = lambda M v`` (:func:`stable_eigenpairs`, :meth:`Surface.eigs`).

    Behaves as the pair ``(values, vectors)``: ``values, vectors = result``, ``result[0]``.

    Attributes
    ----------
    values : ndarray, shape (k,)
        Ascending eigenvalues (approximating those of ``-Lap_S``).
    vectors : ndarray, shape (N, k)
        M-orthonormal eigenvectors over the whole cloud, zero on :attr:`excluded`.
    excluded : ndarray of int, shape (E,)
        Particles left out (outside the chosen connected piece); empty when none.
    n_components : int
        Connected pieces of the cloud (isolated points count, one each).
    sigma : float or None
        The shift asked for (None: the smallest eigenvalues).
    method : str
        ``"dense"``, ``"shift-invert"`` or ``"lobpcg"``; with ``"+refined"`` after a
        Rayleigh-Ritz refinement.
    """

    values: np.ndarray
    vectors: np.ndarray
    excluded: np.ndarray
    n_components: int
    sigma: float | None
    method: str

    def __iter__(self) -> Iterator[np.ndarray]:
        yield self.values
        yield self.vectors

    def __len__(self) -> int:
        return 2

    @overload
    def __getitem__(self, index: SupportsIndex) -> np.ndarray: ...

    @overload
    def __getitem__(self, index: slice) -> tuple[np.ndarray, ...]: ...

    def __getitem__(self, index: SupportsIndex | slice) -> np.ndarray | tuple[np.ndarray, ...]:
        return (self.values, self.vectors)[index]



def _check_sigma(sigma: Any) -> float | None:
    if sigma is None:
        return None
    if isinstance(sigma, bool) or not isinstance(sigma, (int, float, np.integer, np.floating)):
        raise TypeError(f"sigma must be a real number or None, got {type(sigma).__name__} {sigma!r}")
    if not np.isfinite(sigma):
        raise ValueError(f"sigma must be finite, got {sigma!r}")
    return float(sigma)


def _choose_piece(K: sp.csr_matrix, component: Any) -> tuple[np.ndarray, int, np.ndarray]:
    """``(keep mask, number of pieces, labels)`` for ``component``."""
    n = K.shape[0]
    G = K.copy()
    G.setdiag(0)
    G.eliminate_zeros()
    n_comp, labels = connected_components(G, directed=False)
    if isinstance(component, str):
        check_in("component", component, ("largest", "all"))
        if component == "all" or n_comp == 1:
            return np.ones(n, dtype=bool), n_comp, labels
        sizes = np.bincount(labels, minlength=n_comp)
        return labels == int(np.argmax(sizes)), n_comp, labels
    if isinstance(component, bool) or not isinstance(component, (int, np.integer)):
        raise TypeError(f"component must be 'largest', 'all' or a particle index, got {component!r}")
    if not 0 <= component < n:
        raise ValueError(f"component must be a particle index in [0, {n}), 'largest' or 'all', got {component}")
    return labels == labels[int(component)], n_comp, labels


def _dense(K, m, k, sigma):
    A = K.toarray()
    if sigma is None:
        lam, V = sla.eigh(A, np.diag(m), subset_by_index=[0, k - 1])
    else:
        lam, V = sla.eigh(A, np.diag(m))
        pick = np.sort(np.argsort(np.abs(lam - sigma), kind="stable")[:k])
        lam, V = lam[pick], V[:, pick]
    return lam, V


def _shift_invert(K, m, k, shift):
    n = K.shape[0]
    M = sp.diags(m).tocsc()
    A = (K - shift * sp.diags(m)).tocsr()
    solver = spd_solver(A) if shift < 0 else linear_solver(A, method="lu")  # inside the spectrum: indefinite
    OPinv = spla.LinearOperator((n, n), matvec=lambda x: solver.solve(np.ravel(x)), dtype=np.float64)
    v0 = np.random.default_rng(0).standard_normal(n)
    lam, V = spla.eigsh(K, k=k, M=M, sigma=shift, which="LM", OPinv=OPinv, v0=v0)
    return lam, V


def _lobpcg(K, m, k, shift, tol):
    import pyamg

    n = K.shape[0]
    M = sp.diags(m).tocsr()
    with np.errstate(all="ignore"):
        ml = pyamg.smoothed_aggregation_solver((K + abs(shift) * M).tocsr(), symmetry="hermitian")
    P = ml.aspreconditioner(cycle="V")
    extra = max(8, k // 4)
    X = np.random.default_rng(0).standard_normal((n, k + extra))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lam, V = spla.lobpcg(K, X, B=M, M=P, largest=False, tol=tol, maxiter=LOBPCG_MAXITER)
    if any("Exited" in str(w.message) for w in caught):
        warnings.warn(f"eigs(method='lobpcg'): LOBPCG stopped after {LOBPCG_MAXITER} iterations above the residual "
                      f"tolerance {tol:g}; method='shift-invert' solves to round-off where the factor fits in memory",
                      ManifoldSPHWarning, stacklevel=4)
    order = np.argsort(lam)[:k]
    return lam[order], V[:, order]


def _refine(L, m_full, V, wanted):
    """Rayleigh-Ritz with the strong-form ``L`` in the span of ``V`` (rows on ``keep``): values, M-orthonormal vectors."""
    A = V.T @ (m_full[:, None] * -(L @ V))
    mu, C = np.linalg.eig(A)
    order = np.argsort(mu.real, kind="stable")[:wanted]
    Y = V @ C[:, order]
    # a complex pair's vectors are conjugate: their real parts coincide. Their real and imaginary
    # parts span the same real invariant plane, and keep the Ritz basis of full rank.
    Y = np.where(mu[order].imag < 0, Y.imag, Y.real)
    G = Y.T @ (m_full[:, None] * Y)
    try:
        Lc = np.linalg.cholesky(0.5 * (G + G.T))
    except np.linalg.LinAlgError:  # pragma: no cover - V is M-orthonormal, Y of full rank
        raise RuntimeError("eigs(refine=True): the Ritz vectors are linearly dependent; please report this cloud") from None
    return mu.real[order], np.linalg.solve(Lc, Y.T).T


def stable_eigenpairs(
    K: sp.spmatrix | sp.sparray,
    m: np.ndarray,
    k: int = 50,
    *,
    sigma: float | None = None,
    component: str | int = "largest",
    method: str = "auto",
    laplacian: sp.spmatrix | sp.sparray | None = None,
    tol: float = 1e-10,
) -> Eigenpairs:
    """The ``k`` eigenpairs of ``K v = lambda M v`` smallest, or nearest ``sigma`` (module notes).

    Parameters
    ----------
    K : sparse matrix, shape (N, N)
        Symmetric positive semi-definite stiffness.
    m : ndarray, shape (N,)
        Positive diagonal of the mass matrix.
    k : int
        Eigenpairs wanted, ``1 <= k <= n - 2`` (``n`` the particles of the chosen piece).
    sigma : float, optional
        Return the ``k`` eigenvalues nearest ``sigma`` instead of the smallest.
    component : "largest", "all" or int
        The connected piece to solve on (module notes).
    method : {"auto", "dense", "shift-invert", "lobpcg"}
    laplacian : sparse matrix, shape (N, N), optional
        A strong-form Laplacian ``L``: Rayleigh-Ritz refinement with ``-L`` in the span of
        the first ``k + max(8, k // 4)`` eigenvectors (:meth:`Surface.eigs` ``refine=True``).
    tol : float
        Relative tolerance of LOBPCG (the other methods reach round-off).

    Returns
    -------
    Eigenpairs
    """
    if not sp.issparse(K) or K.ndim != 2 or K.shape[0] != K.shape[1]:
        raise TypeError(f"K must be a square scipy sparse matrix, got {type(K).__name__} of shape {np.shape(K)}")
    n = K.shape[0]
    m = np.asarray(m, dtype=np.float64)
    if m.shape != (n,) or not np.all(np.isfinite(m)) or np.any(m <= 0):
        raise ValueError(f"m must be ({n},) positive finite masses, got shape {m.shape}")
    k = check_int("k", k, minimum=1)
    sigma = _check_sigma(sigma)
    method = check_in("method", method, EIGS_METHODS)
    K = sp.csr_matrix(K, dtype=np.float64)
    keep, n_comp, labels = _choose_piece(K, component)
    nc = int(keep.sum())
    if k > nc - 2:
        where = "" if nc == n else f" in the chosen connected piece ({n - nc} of {n} particles left out)"
        raise ValueError(f"k must be smaller than the number of points minus 1 ({nc - 1}){where}, got {k}")
    excluded = np.flatnonzero(~keep)
    mc = m[keep]
    mbar = float(mc.mean())
    if not MIN_MASS <= mbar <= MAX_MASS:
        raise ValueError(
            f"points: the mean area element is {mbar:.3g} (point spacing about {np.sqrt(mbar):.3g}), outside "
            f"[{MIN_MASS:g}, {MAX_MASS:g}] where eigs works: the eigenvalues (about 1 / area element) would leave "
            "float64. Rescale the points (e.g. divide them by their diameter D) and multiply the eigenvalues by D^-2"
        )
    if excluded.size and component == "largest":  # an explicit piece is the caller's choice: no warning
        isolated = int(np.count_nonzero(np.bincount(labels, minlength=n_comp)[labels[excluded]] == 1))
        warnings.warn(
            f"eigs: {excluded.size} of {n} particles ({isolated} isolated, {n_comp - 1} other connected piece(s)) "
            "lie outside the connected piece solved on: left out (their rows of .vectors are 0; .excluded lists "
            "them; component='all' or a particle index chooses another piece)",
            ManifoldSPHWarning, stacklevel=3,
        )
    elif not excluded.size and n_comp > 1 and sigma is None:
        warnings.warn(
            f"eigs(component='all'): the cloud has {n_comp} connected pieces, so its first {min(n_comp, k)} "
            "eigenvalues are 0 (one constant mode per piece); component='largest' solves on the main piece only",
            ManifoldSPHWarning, stacklevel=3,
        )
    Kc = K[keep][:, keep].tocsr() if excluded.size else K
    w = mc / mbar  # scale-free: M / mean(M)
    s = None if sigma is None else sigma * mbar
    kk = k
    if laplacian is not None:
        kk = min(nc - 2, k + max(8, k // 4))
    if method == "auto":
        if nc <= DENSE_MAX_N:
            method = "dense"
        elif choose_spd_method(nc) == "cholesky" or (s is not None and s > 0):
            method = "shift-invert"
        else:
            method = "lobpcg"
    shift = -1e-2 / nc if s is None else s  # just below the zero eigenvalue, in units of M / mean(M)
    if method == "dense":
        lam, V = _dense(Kc, w, kk, s)
    elif method == "shift-invert":
        lam, V = _shift_invert(Kc, w, kk, shift)
    else:
        if s is not None and s > 0:
            raise ValueError(f"method='lobpcg' finds the smallest eigenvalues only; sigma={sigma} needs "
                             "method='shift-invert' (or 'auto')")
        lam, V = _lobpcg(Kc, w, kk, shift, tol)
    order = np.argsort(lam, kind="stable")
    lam, V = np.maximum(lam[order], 0.0) / mbar, V[:, order]  # K is semi-definite: round-off below 0 is 0
    V = V / np.sqrt(np.einsum("ik,i,ik->k", V, mc, V))
    full = np.zeros((n, V.shape[1])) if excluded.size else V
    if excluded.size:
        full[keep] = V
    if laplacian is not None:
        if not sp.issparse(laplacian) or laplacian.shape != (n, n):
            raise ValueError(f"laplacian must be a sparse ({n}, {n}) matrix, got {np.shape(laplacian)}")
        L = sp.csr_matrix(laplacian)
        if excluded.size:  # the refinement stays on the chosen piece
            L = sp.diags(keep.astype(float)) @ L @ sp.diags(keep.astype(float))
        mfull = np.where(keep, m, 0.0)
        lam, full = _refine(L, mfull, full, k)
        method += "+refined"
    return Eigenpairs(lam, full, excluded.astype(np.int64), int(n_comp), sigma, method)
