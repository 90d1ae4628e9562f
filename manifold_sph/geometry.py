"""Geometry from points: curvature, geodesic distance and spectral descriptors.

Every function takes a :class:`~manifold_sph.Surface` (the methods of the same names
on ``Surface`` call them) and uses only its operators:

- **Curvature.** The shape operator is the tangential gradient of the unit normal
  field, ``W = grad_S n``, written in each particle's tangent frame ``(u, v)`` and
  symmetrised; it is positive on a sphere with outward normals. Its eigenvalues are
  the principal curvatures ``k1 >= k2``, its determinant the Gaussian curvature
  ``K`` and half its trace the mean curvature ``H``. ``H`` also comes from the
  Laplacian of the coordinates, ``Lap_S x = -2 H n``, which needs no derivative of
  the normals. With the jet-fitted normals a ``Surface`` estimates (of the scheme's
  degree) the shape operator is the more accurate, so ``"auto"`` uses it (measured,
  relative L2 error of ``H`` from the normals' gradient / from the Laplacian: torus
  R = 0.8, r = 0.2, Poisson-disk, N = 20,000, bare points, msph 1.4e-3 / 5.3e-3,
  msph4 6.5e-5 / 1.1e-4; uniformly random unit sphere, N = 20,000, bare points, msph
  5.9e-5 / 5.4e-4, msph4 7.6e-7 / 2.8e-5; the torus with noise of 0.05 spacings,
  msph 0.18 / 0.73).
- **Geodesic distance** by the heat method (Crane, Weischedel and Wardetzky 2013):
  a heat step ``(M + t K) u = delta_source`` with the stable Laplacian and
  ``t = 4 h^2`` (``h^2`` the mean Voronoi cell area), the unit field
  ``X = -grad u / |grad u|`` from the scheme's gradient, then the
  Poisson problem ``K phi = -M div X`` (the divergence from the stable Laplacian's own
  fluxes, or the scheme's: :class:`GeodesicSolver`). Particles within ``3 h`` of a source are
  held at their straight-line distance to it (the distance's cone singularity at the
  source otherwise costs first-order accuracy everywhere: 4.4e-3 -> 2.4e-4 at
  N = 40,000 on the unit sphere with msph4). Factorisations are kept for later
  queries. Measured in ``benchmarks/geometry.py``.
- **Spectral descriptors** from :meth:`Surface.eigs`: heat kernel signature
  (Sun, Ovsjanikov and Guibas 2009) and wave kernel signature (Aubry, Schlickewei
  and Cremers 2011).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike
from scipy.sparse.csgraph import connected_components

from ._validation import check_bool, check_in, check_int, check_positive
from .operators import OperatorSet

if TYPE_CHECKING:
    from .surface import Surface

__all__ = [
    "shape_operator",
    "mean_curvature",
    "gaussian_curvature",
    "principal_curvatures",
    "GeodesicSolver",
    "geodesic_distance",
    "heat_kernel_signature",
    "wave_kernel_signature",
    "CURVATURE_METHODS",
    "curvature_method",
]

CURVATURE_METHODS = ("auto", "normals", "laplacian")


def _check_surface(surface):
    if not (isinstance(surface, OperatorSet) and surface.dim == 3):  # a Surface (surface.py imports this module)
        raise TypeError(f"surface must be a Surface, got {type(surface).__name__}")


# ----------------------------------------------------------------------------- curvature
def shape_operator(surface: Surface) -> np.ndarray:
    """Shape operator (Weingarten map) in each particle's tangent frame, shape (N, 2, 2).

    ``W[i] = E_i^T (grad_S n)_i E_i`` symmetrised, with ``E_i = [u_i, v_i]`` (the
    frames :attr:`Surface.u`, :attr:`Surface.v`) and ``(grad_S n)_ab = d n_a / d x_b``
    from :meth:`Surface.gradient_matrix`. Positive definite on a convex surface with
    outward normals. Cached on the surface.
    """
    _check_surface(surface)

    def compute():
        n, N = surface.normals, surface.n_points
        G = surface.gradient_matrix()
        J = np.stack([(G @ n[:, a]).reshape(N, 3) for a in range(3)], axis=1)  # J[i, a, b] = d n_a / d x_b
        E = np.stack([surface.u, surface.v], axis=2)  # (N, 3, 2)
        W = np.einsum("nai,nab,nbj->nij", E, J, E)
        return 0.5 * (W + W.transpose(0, 2, 1))

    return surface.cached("shape_operator", compute)


def curvature_method(surface: Surface, method: str = "auto") -> str:
    """The method :func:`mean_curvature` uses for ``method``: ``"normals"`` or ``"laplacian"``."""
    check_in("method", method, CURVATURE_METHODS)
    return "normals" if method == "auto" else method


def mean_curvature(surface: Surface, method: str = "auto") -> np.ndarray:
    """Mean curvature ``H = (k1 + k2) / 2``, shape (N,): ``1 / r`` on a sphere of radius ``r`` with outward normals.

    Parameters
    ----------
    surface : Surface
    method : {"auto", "normals", "laplacian"}
        ``"normals"``: half the trace of :func:`shape_operator`; ``"laplacian"``:
        ``H = -(Lap_S x) . n / 2`` (no derivative of the normals). ``"auto"`` is
        ``"normals"``, the more accurate of the two with exact normals and with the
        normals a ``Surface`` estimates (jet fits of the scheme's degree; measured in
        the module notes).

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> s = Surface(shapes.sphere(4000, radius=2.0), scheme="msph")
    >>> bool(np.allclose(mean_curvature(s), 0.5, rtol=1e-3))
    True
    """
    _check_surface(surface)
    if curvature_method(surface, method) == "normals":
        W = shape_operator(surface)
        return 0.5 * (W[:, 0, 0] + W[:, 1, 1])
    return surface.cached(("mean_curvature", "laplacian"), lambda: -0.5 * np.einsum(
        "ij,ij->i", surface.laplacian_matrix() @ surface.points, surface.normals))


def gaussian_curvature(surface: Surface) -> np.ndarray:
    """Gaussian curvature ``K = k1 k2``, shape (N,): the determinant of :func:`shape_operator`."""
    W = shape_operator(surface)
    return W[:, 0, 0] * W[:, 1, 1] - W[:, 0, 1] * W[:, 1, 0]


def principal_curvatures(surface: Surface) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Principal curvatures and directions from :func:`shape_operator`.

    Returns
    -------
    k1, k2 : ndarray, shape (N,)
        ``k1 >= k2``, signed like :func:`mean_curvature`.
    d1, d2 : ndarray, shape (N, 3)
        Unit tangent principal directions (each up to sign), ``d1 . d2 = 0``.
        Undefined at umbilic points (``k1 == k2``), where any tangent direction is principal.
    """
    W = shape_operator(surface)
    lam, vec = np.linalg.eigh(W)  # ascending
    E = np.stack([surface.u, surface.v], axis=2)
    d = np.einsum("nai,nij->naj", E, vec)  # (N, 3, 2)
    return lam[:, 1], lam[:, 0], d[:, :, 1], d[:, :, 0]


# ----------------------------------------------------------------------------- geodesics
class GeodesicSolver:
    """Geodesic distance by the heat method, with the factorisations kept between queries.

    Parameters
    ----------
    surface : Surface
    t : float, optional
        Heat time (default ``4 h^2``, ``h^2`` the mean Voronoi cell area). Much smaller
        values let ``u`` underflow far from the source, where its gradient's direction
        is then lost; larger ones smooth the direction field. Chosen by measurement:
        against the exact polyhedral geodesics of the test models (homer, cheburashka,
        rocker-arm) ``4 h^2`` gave mean errors of 3.2e-2, 2.9e-2, 2.2e-2 against 5.1e-2,
        5.0e-2, 3.1e-2 with ``h^2``; on random sphere points 2.6e-3 against 8.0e-3
        (N = 40,000).
    source_radius : float
        Particles within ``source_radius * h`` of a source are held at their
        straight-line distance to the nearest source (``h`` the square root of the
        mean cell area).
    divergence : {"weak", "strong"}
        How the right-hand side ``-M div X`` is formed. ``"weak"`` (default): from the
        stable Laplacian's own fluxes, ``sum_j w_ij (X_i + X_j) / 2 . (x_i - x_j)``, so
        that the gradient of a linear function gives that function back; robust on any
        cloud. ``"strong"``: ``M`` times the scheme's divergence: with msph4 on
        near-uniform clouds more accurate (2.4e-4 against 4.2e-4 on the 40,000-point
        Fibonacci sphere), on uniformly random points useless (relative errors of 0.5 to
        50 measured).

    Notes
    -----
    Measured (``benchmarks/geometry.py``), unit sphere, one source, relative L2 error
    against ``arccos(x . x_s)``: Fibonacci points 9.3e-4 / 4.2e-4 at N = 10,000 / 40,000
    (potpourri3d's point-cloud heat method on the same points: 1.5e-2 / 1.3e-2), uniformly
    random points 5.5e-3 / 2.6e-3 (potpourri3d 1.9e-2 / 1.7e-2), with msph; the first
    query takes about as long as potpourri3d's. With msph4 and ``divergence="strong"`` the
    40,000-point Fibonacci sphere reaches 2.4e-4, and 160,000 points 3.4e-4: the error
    stops falling near 2e-4 to 3e-4, where the heat step's direction field is only
    first-order accurate (far from the source ``u`` is tiny). Against the exact
    polyhedral geodesics of the test models (mean relative error, bare points): rocker-arm
    2.2e-2 (potpourri3d 2.8e-2), homer 3.2e-2 (2.2e-2), cheburashka 3.4e-2 (2.1e-2), cow
    0.38 (0.30). Where two sources' fronts meet the distance has a kink, smoothed over
    ``t``: 2.2e-2 with two sources at N = 4000.
    """

    def __init__(
        self, surface: Surface, *, t: float | None = None, source_radius: float = 3.0, divergence: str = "weak"
    ) -> None:
        _check_surface(surface)
        self.surface = surface
        self.divergence = check_in("divergence", divergence, ("weak", "strong"))
        K = surface.stiffness_matrix().tocsr()
        m = np.asarray(surface.mass_matrix().diagonal())
        h2 = float(m.mean())
        self.t = 4.0 * h2 if t is None else check_positive("t", t)
        self.source_radius = check_positive("source_radius", source_radius) * np.sqrt(h2)
        self._K, self._m = K, m
        self._heat = spla.splu((sp.diags(m) + self.t * K).tocsc())
        self._ncomp, self._labels = connected_components(K, directed=False)
        self._poisson_key: bytes | None = None
        W = K.tocoo()
        off = W.row != W.col
        self._pairs = (W.row[off], W.col[off], -W.data[off])  # flux weights w_ij of every pair

    def _sources(self, sources) -> np.ndarray:
        n = self.surface.n_points
        arr = np.atleast_1d(np.asarray(sources))
        if arr.size == 0:
            raise ValueError("sources must hold at least one particle index")
        if not np.issubdtype(arr.dtype, np.integer):
            raise TypeError(f"sources must be integer particle indices, got dtype {arr.dtype}")
        if arr.ndim != 1:
            raise ValueError(f"sources must be an index or a 1-D array of indices, got shape {arr.shape}")
        bad = (arr < 0) | (arr >= n)
        if bad.any():
            raise ValueError(f"sources must lie in [0, {n}), got {arr[bad][:5].tolist()}")
        return np.unique(arr)

    def __call__(self, sources: ArrayLike) -> np.ndarray:
        """Distance from the nearest of ``sources`` (an index or indices), shape (N,).

        Particles in a connected piece of the cloud that holds no source get ``inf``.
        """
        src = self._sources(sources)
        s, P, N = self.surface, self.surface.points, self.surface.n_points
        rhs = np.zeros(N)
        rhs[src] = 1.0
        g = s.gradient(self._heat.solve(rhs))
        norm = np.linalg.norm(g, axis=1)
        X = -g / np.where(norm > 0, norm, 1.0)[:, None]
        if self.divergence == "strong":
            b = -self._m * s.divergence(X)
        else:  # -M div X from the stable Laplacian's fluxes
            i, j, w = self._pairs
            b = np.bincount(i, weights=w * np.einsum("pd,pd->p", 0.5 * (X[i] + X[j]), P[i] - P[j]), minlength=N)
        r = _nearest_source_distance(P, src)
        reached = np.isin(self._labels, self._labels[src])  # pieces of the cloud that hold a source
        near = ((r <= self.source_radius) | np.isin(np.arange(N), src)) & reached
        free = ~near & reached
        key = src.tobytes()
        if self._poisson_key != key:  # the held particles changed: factorise again
            self._poisson = spla.splu(self._K[free][:, free].tocsc()) if free.any() else None
            self._poisson_key = key
        phi = np.full(N, np.inf)
        phi[near] = r[near]
        if free.any():
            phi[free] = self._poisson.solve(b[free] - self._K[free][:, near] @ r[near])
        return phi


def _nearest_source_distance(P, src):
    from scipy.spatial import cKDTree

    return cKDTree(P[src]).query(P)[0]


def geodesic_distance(surface: Surface, sources: ArrayLike, **options: Any) -> np.ndarray:
    """Geodesic distance from ``sources`` (an index or indices), shape (N,); see :class:`GeodesicSolver`.

    The solver (and its factorisations) is cached on the surface for the default options.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> c = shapes.sphere(4000)
    >>> d = geodesic_distance(Surface(c, scheme="msph4"), 0)
    >>> exact = np.arccos(np.clip(c.points @ c.points[0], -1, 1))
    >>> bool(np.linalg.norm(d - exact) / np.linalg.norm(exact) < 2e-3)
    True
    """
    _check_surface(surface)
    if options:
        return GeodesicSolver(surface, **options)(sources)
    return surface.cached("geodesic_solver", lambda: GeodesicSolver(surface))(sources)


# ----------------------------------------------------------------------------- descriptors
def _spectrum(surface, k):
    k = check_int("k", k, minimum=2)
    return surface.cached(("eigs", k), lambda: surface.eigs(k))


def heat_kernel_signature(surface: Surface, times: ArrayLike, *, k: int = 100, scale: bool = False) -> np.ndarray:
    """Heat kernel signature ``HKS(x, t) = sum_i exp(-lambda_i t) phi_i(x)^2``, shape (N, T).

    Parameters
    ----------
    surface : Surface
    times : array_like, shape (T,)
        Positive diffusion times.
    k : int
        Eigenpairs of :meth:`Surface.eigs` used (the zero one included).
    scale : bool
        Divide each column by its mass-weighted mean (the scale-normalised HKS).
    """
    _check_surface(surface)
    t = np.atleast_1d(np.asarray(times, dtype=np.float64))
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t) & (t > 0)):
        raise ValueError(f"times must be a non-empty 1-D array of positive finite values, got {t!r}")
    scale = check_bool("scale", scale)
    lam, V = _spectrum(surface, k)
    H = (V**2) @ np.exp(-np.outer(np.maximum(lam, 0.0), t))
    if scale:
        m = np.asarray(surface.mass_matrix().diagonal())
        H = H / (m @ H / m.sum())
    return H


def wave_kernel_signature(
    surface: Surface,
    energies: ArrayLike | None = None,
    *,
    k: int = 100,
    n_energies: int = 100,
    sigma: float | None = None,
) -> np.ndarray:
    """Wave kernel signature, shape (N, E): ``sum_i phi_i(x)^2 exp(-(e - log lambda_i)^2 / 2 sigma^2)``, normalised.

    Parameters
    ----------
    surface : Surface
    energies : array_like, shape (E,), optional
        Log-energies ``e``; by default ``n_energies`` values spread over
        ``[log lambda_1, log lambda_max]`` as in Aubry et al. 2011.
    k : int
        Eigenpairs used (the zero eigenvalue is skipped).
    sigma : float, optional
        Width (default 7 times the spacing of the default energies).
    """
    _check_surface(surface)
    # the arguments are checked before the eigenpairs are computed (bad input fails at once)
    if energies is None:
        n_energies = check_int("n_energies", n_energies, minimum=2)
    else:
        e = np.atleast_1d(np.asarray(energies, dtype=np.float64))
        if e.ndim != 1 or e.size == 0 or not np.all(np.isfinite(e)):
            raise ValueError(f"energies must be a non-empty 1-D array of finite values, got {e!r}")
    if sigma is not None:
        sigma = check_positive("sigma", sigma)
    lam, V = _spectrum(surface, k)
    pos = lam > 1e-10 * max(lam.max(), 1e-300)
    if pos.sum() < 2:
        raise ValueError("wave_kernel_signature needs at least two non-zero eigenvalues; increase k")
    loglam, V = np.log(lam[pos]), V[:, pos]
    if energies is None:
        e = np.linspace(loglam.min(), loglam.max(), n_energies)
    if sigma is None:
        sigma = 7.0 * (loglam.max() - loglam.min()) / max(len(e) - 1, 1) if len(e) > 1 else 1.0
    sigma = check_positive("sigma", sigma)
    Wgt = np.exp(-((e[None, :] - loglam[:, None]) ** 2) / (2 * sigma**2))  # (k, E)
    return (V**2) @ Wgt / Wgt.sum(axis=0)
