"""Geodesic distance on a point cloud: :class:`GeodesicSolver` and :func:`geodesic_distance`.

Two methods, one interface (from one particle or a set, to every particle or a few,
all pairs of a moderate set):

``"wavefront"`` (default)
    Propagation over the cloud's local Delaunay triangles
    (:mod:`manifold_sph.geometry.wavefront`): exact across developable strips, the kink
    where fronts meet exact, never below the straight line; on curved surfaces the fronts
    carry their geodesic curvature (second order on a sphere of Fibonacci points). Needs only
    the points (and takes a Surface's normals when given one).
``"heat"``
    The heat method (Crane, Weischedel and Wardetzky 2013) on a Surface's stable Laplacian:
    a heat step ``(M + t K) u = delta``, the unit field ``X = -grad u / |grad u|``, a Poisson
    solve ``K phi = -M div X`` with the particles near the sources held at their straight-line
    distance. Smooth (differentiable) distances, rounded where fronts meet.

Measured in ``benchmarks/geometry.py`` and ``docs/geometry.md``.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Any, overload

import numpy as np
from numpy.typing import ArrayLike
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .._validation import check_in, check_int, check_positive
from ..exceptions import ManifoldSPHWarning
from ..frames import unit_rows
from .common import (
    SCALE_RANGE,
    WAVEFRONT_SCALE_RANGE,
    as_cloud_points,
    check_scale,
    is_surface,
)
from .wavefront import local_triangles, propagate

if TYPE_CHECKING:
    from ..surface import Surface

__all__ = ["CLEAN_READING", "DENOISE_NOISE", "GEODESIC_METHODS", "PAIRWISE_MAX_BYTES", "GeodesicSolver", "geodesic_distance"]

GEODESIC_METHODS = ("wavefront", "heat")
#: Largest all-pairs matrix :meth:`GeodesicSolver.pairwise` builds (bytes of float64).
PAIRWISE_MAX_BYTES = 2 << 30
#: ``denoise="auto"``: the wavefront runs over the smoothed cloud when its noise level
#: (:attr:`GeodesicSolver.noise`, in spacings) is above this. Gaussian noise of ``s`` spacings per coordinate
#: reads about ``0.9 s``; clean test models read 0.00-0.09 (the cow 0.05, the beetle 0.09).
DENOISE_NOISE = 0.07
#: Below this reading of the 16-point quadrics' residuals (:meth:`LocalTriangles.noise`, an upper bound of the
#: noise) a cloud is clean without the two-scale estimate.
CLEAN_READING = 0.05


def straight_line(P: np.ndarray, src: np.ndarray) -> np.ndarray:
    """Distance in space from every point of ``P`` (N, 3) to the nearest of the points ``P[src]``, shape (N,)."""
    if src.size <= 16:  # a few sources: direct (a KD-tree's set-up and threads cost more at small N)
        r = np.full(P.shape[0], np.inf)
        for i in src:
            np.minimum(r, np.sqrt(np.einsum("nd,nd->n", P - P[i], P - P[i])), out=r)
        return r
    return cKDTree(P[src]).query(P, workers=-1 if P.shape[0] > 100_000 else 1)[0]


def check_denoise(denoise: bool | str) -> bool | str:
    """``denoise`` checked: ``"auto"``, True or False (numpy booleans as bool); ValueError otherwise."""
    if isinstance(denoise, (bool, np.bool_)):
        return bool(denoise)
    if isinstance(denoise, str) and denoise == "auto":
        return denoise
    raise ValueError(f"denoise must be True, False or 'auto', got {denoise!r}")


def _noise_level(tri) -> float:
    """The cloud's noise in spacings from degree-2 fits at two scales (:func:`manifold_sph.normals.scale.noise_level`:
    the shape's bias grows like the fit radius cubed, noise does not), the median over the particles."""
    from ..normals import tuning
    from ..normals.scale import noise_level

    P = tri.points
    k = max(tuning.NOISE_REGION, 2 * tuning.NOISE_K)
    dist, idx = cKDTree(P).query(P, k=k, workers=-1 if P.shape[0] > 50_000 else 1)
    sigma, spacing = noise_level(P, idx, dist, tri.normals)
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = np.where(spacing > 0, sigma / spacing, 0.0)
    return float(np.median(nu))


class _Wavefront:
    """The wavefront engine: local triangles built once, one sweep a query."""

    def __init__(self, points, normals, neighbors, denoise):
        check_scale(points, "geodesic distance (method='wavefront')", WAVEFRONT_SCALE_RANGE)
        self.tri = local_triangles(points, normals, neighbors=neighbors)
        self.noise = self.tri.noise()
        if self.noise > CLEAN_READING and points.shape[0] >= 32:  # noise or a coarse cloud's misfit: told apart
            self.noise = _noise_level(self.tri)
        self.denoised = denoise is True or (denoise == "auto" and self.noise > DENOISE_NOISE)
        self._chord = None
        if self.denoised:
            # the noise's zigzag lengthens every path by about its slope squared: the distances are measured
            # over the cloud smoothed onto its local quadrics, the straight-line bound over the input points
            from ..pointcloud import PointCloud
            from .smoothing import smooth

            raw = self.tri
            den = smooth(PointCloud(points, normals) if normals is not None else points)
            self.tri = local_triangles(den.points, den.normals, neighbors=neighbors)
            self._chord = (raw.points, raw.scale)
        self._inc = self.tri.incidence()
        self._adj = self.tri.adjacency()
        self._gauss = self.tri.resolved_gauss()
        self._rescue = self.tri.rescuable()
        n = points.shape[0]
        import scipy.sparse as sp

        e = self.tri.edges
        A = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
        self.n_components, self.labels = connected_components(A, directed=False)

    def distance(self, src, offsets, targets):
        P = self.tri.points
        d = propagate(P, self._inc, self._adj, src, offsets / self.tri.scale, targets, gauss=self._gauss,
                      rescue=self._rescue)
        d *= self.tri.scale
        if not offsets.any():  # never below the straight line to the nearest source (unreached: inf stays inf)
            Q, scale = (P, self.tri.scale) if self._chord is None else self._chord
            np.maximum(d, straight_line(Q, src) * scale, out=d)
        return d


class _Heat:
    """The heat-method engine on a Surface: the heat step factorised once, a Poisson factor per source set."""

    def __init__(self, surface, t, source_radius, divergence):
        from ..solvers import cholesky_available, spd_solver

        check_scale(surface.points, "geodesic distance (method='heat')", SCALE_RANGE)
        self.s = surface
        self.divergence = divergence
        K = surface.stiffness_matrix().tocsr()
        m = np.asarray(surface.mass_matrix().diagonal(), dtype=np.float64)
        self.h2 = float(m.mean())  # work in units of the mean cell: scale-free
        self.m = m / self.h2
        self.t = 4.0 * self.h2 if t is None else check_positive("t", t)
        import scipy.sparse as sp

        # A direct (Cholesky) solve keeps the heat step's far field accurate to its last digits (an M-matrix:
        # no cancellation); CG stops at a relative residual, below which u is noise (measured, 16,000-point
        # sphere: relative error 7.0e-4 with Cholesky, 0.13 with AMG-CG at rtol 1e-10).
        A = (sp.diags(self.m) + (self.t / self.h2) * K).tocsr()
        self._heat = spd_solver(A, method="cholesky" if cholesky_available() else "auto")
        self.K = K
        self.radius = check_positive("source_radius", source_radius) * np.sqrt(self.h2)
        self.n_components, self.labels = connected_components(K, directed=False)
        W = K.tocoo()
        off = W.row != W.col
        self._pairs = (W.row[off], W.col[off], -W.data[off])
        self._poisson_key: bytes | None = None
        self._poisson: Any = None  # spd_solver of the free particles' block, for the sources in _poisson_key

    def distance(self, src, offsets, targets):
        s, N = self.s, self.s.n_points
        rhs = np.zeros(N)
        rhs[src] = 1.0 / self.m[src]  # a unit of heat at each source, whatever its cell's size
        u = self._heat.solve(rhs)
        reached_u = np.isin(self.labels, self.labels[src])
        lost = reached_u & ~(u > 1e-300 * u.max())
        if lost.any():
            warnings.warn(
                f"geodesic heat method: the heat step's solution is below the solver's accuracy or float64's range at "
                f"{int(lost.sum())} particle(s) (too far from the sources for t = {self.t:.3g}, or an iterative solve): "
                "their distances are unreliable; use method='wavefront' (or a larger t)",
                ManifoldSPHWarning,
                stacklevel=3,
            )
        return self.integrate(-unit_rows(s.gradient(u)), src)

    def integrate(self, X, src, held=None, radius=None):
        """The Poisson step: ``K phi = -M div X`` for the unit field ``X`` (N, 3), particles near ``src`` held
        (within ``radius``, default ``self.radius``, at ``held``, default their straight-line distance)."""
        from ..solvers import spd_solver

        s, P, N = self.s, self.s.points, self.s.n_points
        if self.divergence == "strong":
            b = -(self.m * self.h2) * s.divergence(X)
        else:  # -M div X from the stable Laplacian's fluxes
            i, j, w = self._pairs
            b = np.bincount(i, weights=w * np.einsum("pd,pd->p", 0.5 * (X[i] + X[j]), P[i] - P[j]), minlength=N)
        r = straight_line(P, src)
        radius = self.radius if radius is None else radius
        reached = np.isin(self.labels, self.labels[src])
        near = ((r <= radius) | np.isin(np.arange(N), src)) & reached
        free = ~near & reached
        key = src.tobytes() + np.float64(radius).tobytes()
        if self._poisson_key != key:  # the held particles changed: set up again
            self._poisson = spd_solver(self.K[free][:, free].tocsr()) if free.any() else None
            self._poisson_key = key
        if held is not None and not np.all(np.isfinite(held[near]) & (held[near] >= 0)):
            raise ValueError("near must be finite and non-negative at the particles it holds (within radius of the sources)")
        phi = np.full(N, np.inf)
        phi[near] = r[near] if held is None else held[near]
        if self._poisson is not None:  # built above exactly when some particles are free
            phi[free] = self._poisson.solve(b[free] - self.K[free][:, near] @ phi[near])
        return np.maximum(phi, r)


class GeodesicSolver:
    """Geodesic distances on a point cloud, with what every query shares built once.

    Parameters
    ----------
    cloud : Surface, PointCloud or array_like of shape (N, 3)
        The cloud. ``method="heat"`` needs a :class:`~manifold_sph.Surface` (bare points
        are given one with the default options); ``"wavefront"`` uses only the points and,
        if present, the normals.
    method : {"wavefront", "heat"}
        See the module notes. ``"wavefront"``: accurate on coarse, thin and sharp models and
        exact where fronts meet; ``"heat"``: smooth distances from the stable Laplacian.
    neighbors : int
        ``"wavefront"``: nearest points among which each particle's Delaunay fan is
        computed (16; at least 4).
    t : float, optional
        ``"heat"``: heat time (default ``4 h^2``, ``h^2`` the mean Voronoi cell area).
    source_radius : float
        ``"heat"``: particles within ``source_radius * h`` of a source are held at their
        straight-line distance to it (the cone at the source otherwise costs first-order
        accuracy everywhere).
    divergence : {"weak", "strong"}
        ``"heat"``: ``-M div X`` from the stable Laplacian's fluxes (robust on any cloud),
        or ``M`` times the scheme's divergence (more accurate with msph4 on near-uniform
        clouds, useless on random ones).
    denoise : {"auto", True, False}
        ``"wavefront"``: measure the distances over the cloud smoothed onto its local quadrics
        (:func:`~manifold_sph.geometry.smooth` with its defaults). On noisy points every path
        zigzags through the noise and runs long (about 3 % at 0.3 spacings of noise on a sphere);
        smoothed first, 20 times less there. ``"auto"`` (default) smooths when the cloud's
        :attr:`noise` is above :data:`DENOISE_NOISE` spacings, which clean clouds stay below
        (smoothing a clean coarse model only moves its points off its surface). The straight-line
        bound stays that of the input points. ``True`` with ``method="heat"`` is refused.

    Attributes
    ----------
    n_points : int
    method : str
    unreached : ndarray of int
        Particles the last query did not reach (pieces of the cloud that hold no source):
        their distance is ``inf``, and the query warns with their count.
    boundary : ndarray of int
        ``"wavefront"``: particles on an open boundary (their Delaunay fan is open); pass
        them as sources for the distance from the boundary.
    n_components : int
        Connected pieces of the cloud (as the method sees them).
    noise : float
        ``"wavefront"``: the cloud's noise level in spacings (NaN for ``"heat"``): the median over the
        particles of the noise read from quadric fits at two scales, which tells noise from a coarse
        cloud's misfit (as the normal estimation does); where the quadrics fitted to each particle's
        16 nearest points leave less than :data:`CLEAN_READING` spacings, that residual (an upper bound).
    denoised : bool
        Whether the distances are measured over the smoothed cloud (``denoise``).

    Notes
    -----
    Measured (``python benchmarks/geometry.py``): against libigl's exact polyhedral
    geodesics on the vertices of the test models, mean relative error 2 to 10 times
    below potpourri3d's point-cloud heat method; on the unit sphere of Fibonacci points
    second order in the spacing. ``docs/geometry.md`` has the tables.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph.reference import shapes
    >>> c = shapes.sphere(4000)
    >>> solver = GeodesicSolver(c)
    >>> d = solver.distance(0)                                # to every particle
    >>> exact = np.arccos(np.clip(c.points @ c.points[0], -1, 1))
    >>> bool(np.linalg.norm(d - exact) / np.linalg.norm(exact) < 6e-3)    # measured 4.5e-3
    True
    >>> round(float(solver.distance(0, to=1234)), 3) == round(float(d[1234]), 3)   # point to point
    True
    >>> solver.pairwise([0, 10, 20]).shape                      # all pairs of a set
    (3, 3)
    >>> noisy = c.points + 0.02 * np.random.default_rng(0).standard_normal((4000, 3))
    >>> GeodesicSolver(noisy).denoised      # 0.36 spacings of noise: measured over the smoothed cloud
    True
    """

    def __init__(
        self,
        cloud: Surface | ArrayLike,
        *,
        method: str = "wavefront",
        neighbors: int = 16,
        t: float | None = None,
        source_radius: float = 3.0,
        divergence: str = "weak",
        denoise: bool | str = "auto",
    ) -> None:
        self.method = check_in("method", method, GEODESIC_METHODS)
        denoise = check_denoise(denoise)
        if denoise is True and self.method != "wavefront":
            raise ValueError("denoise=True is supported by method='wavefront' only (smooth the cloud first for "
                             "the heat method: manifold_sph.geometry.smooth)")
        check_in("divergence", divergence, ("weak", "strong"))
        neighbors = check_int("neighbors", neighbors, minimum=4)
        if t is not None:
            check_positive("t", t)
        check_positive("source_radius", source_radius)
        if self.method == "heat":
            if not is_surface(cloud):
                from ..surface import Surface

                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", ManifoldSPHWarning)
                    cloud = Surface(cloud)
            self._engine: Any = _Heat(cloud, t, source_radius, divergence)
            self.n_points = cloud.n_points
            self.boundary = np.zeros(0, dtype=np.int64)
            self.denoised, self.noise = False, float("nan")
        else:
            points, normals = as_cloud_points(cloud)
            if points.shape[0] < 3:
                raise ValueError(f"cloud must hold at least 3 points, got {points.shape[0]}")
            self._engine = _Wavefront(points, normals, neighbors, denoise if points.shape[0] >= 12 else False)
            self.n_points = points.shape[0]
            self.boundary = np.flatnonzero(self._engine.tri.open)
            self.denoised, self.noise = bool(self._engine.denoised), float(self._engine.noise)
        self.n_components = int(self._engine.n_components)
        self.unreached = np.zeros(0, dtype=np.int64)

    # ------------------------------------------------------------------ input
    def _indices(self, name: str, value: ArrayLike, allow_mask: bool) -> np.ndarray:
        n = self.n_points
        arr = np.atleast_1d(np.asarray(value))
        if arr.size == 0:
            raise ValueError(f"{name} must hold at least one particle index")
        if allow_mask and arr.dtype == bool:
            if arr.shape != (n,):
                raise ValueError(f"{name} as a mask must have shape ({n},), got {arr.shape}")
            arr = np.flatnonzero(arr)
        elif not np.issubdtype(arr.dtype, np.integer):
            raise TypeError(f"{name} must be integer particle indices{' or a boolean mask' if allow_mask else ''}, "
                            f"got dtype {arr.dtype}")
        if arr.ndim != 1:
            raise ValueError(f"{name} must be an index or a 1-D array of indices, got shape {arr.shape}")
        if arr.size == 0:
            raise ValueError(f"{name} as a mask must select at least one particle")
        bad = (arr < 0) | (arr >= n)
        if bad.any():
            raise ValueError(f"{name} must lie in [0, {n}), got {arr[bad][:5].tolist()}")
        return arr.astype(np.int64)

    def _sources(self, sources: ArrayLike, offsets: ArrayLike | None) -> tuple[np.ndarray, np.ndarray]:
        """Checked sources and offsets, one entry a source (the smallest offset of a repeated one)."""
        src = self._indices("sources", sources, allow_mask=True)
        if offsets is None:
            off = np.zeros(src.size)
        else:
            if self.method != "wavefront":
                raise ValueError("offsets are supported by method='wavefront' only")
            off = np.atleast_1d(np.asarray(offsets, dtype=np.float64))
            if off.shape != src.shape or not np.all(np.isfinite(off) & (off >= 0)):
                raise ValueError(f"offsets must be {src.size} finite values >= 0 (one a source), got {off!r}")
        order = np.lexsort((off, src))
        src, off = src[order], off[order]
        first = np.concatenate([[True], src[1:] != src[:-1]])
        return src[first], off[first]

    # ------------------------------------------------------------------ queries
    @overload
    def distance(self, sources: ArrayLike, *, to: None = None, offsets: ArrayLike | None = None) -> np.ndarray: ...

    @overload
    def distance(self, sources: ArrayLike, *, to: ArrayLike | None = None, offsets: ArrayLike | None = None) -> np.ndarray | float: ...

    def distance(
        self, sources: ArrayLike, *, to: ArrayLike | None = None, offsets: ArrayLike | None = None
    ) -> np.ndarray | float:
        """Geodesic distance from the nearest of ``sources``.

        Parameters
        ----------
        sources : int, array_like of int, or bool array of shape (N,)
            A particle, particles, or a mask (a set: a boundary, a curve of particles).
        to : int or array_like of int, optional
            Only these particles: the wavefront stops once they are final.
        offsets : array_like, shape (S,), optional
            ``"wavefront"``: a distance each source starts with (the distance from a set of
            weighted points); the straight-line clamp is then off.

        Returns
        -------
        ndarray, shape (N,), or float / ndarray of the shape of ``to``
            ``inf`` where not reached (see :attr:`unreached`).
        """
        if offsets is None and isinstance(sources, (int, np.integer)) and not isinstance(sources, (bool, np.bool_)) \
                and 0 <= sources < self.n_points:  # one particle: nothing to sort or merge
            src, off = np.array([sources], dtype=np.int64), np.zeros(1)
        else:
            src, off = self._sources(sources, offsets)
        targets = None if to is None else self._indices("to", to, allow_mask=False)
        d = self._engine.distance(src, off, targets)
        if self.n_components == 1:  # every particle is reached
            self.unreached = np.zeros(0, dtype=np.int64)
            out, missing = (d if targets is None else d[targets]), 0
        else:
            labels = self._engine.labels
            reached = np.isin(labels, labels[src])
            self.unreached = np.flatnonzero(~reached)
            d[~reached] = np.inf
            if targets is None:
                out, missing = d, self.unreached.size
            else:
                out, missing = d[targets], int(np.count_nonzero(~reached[targets]))
        if missing:
            warnings.warn(
                f"{missing} particle(s) lie in pieces of the cloud that hold no source (the cloud has "
                f"{self.n_components} connected pieces): their distance is inf; see .unreached",
                ManifoldSPHWarning,
                stacklevel=2,
            )
        if to is not None and np.ndim(to) == 0:
            return float(out[0])
        return out

    __call__ = distance

    def integrate(self, directions: ArrayLike, sources: ArrayLike, *, near: ArrayLike | None = None,
                  radius: float | None = None) -> np.ndarray:
        """The distance whose gradient best fits a field of unit directions (the heat method's Poisson step).

        Solves ``K phi = -M div X`` on the stable Laplacian for ``X`` the unit vectors of
        ``directions`` (N, 3), with the particles within ``radius * h`` (default
        ``source_radius``) of ``sources`` held at their straight-line distance, or at the
        distances ``near`` (N,) when given (e.g. the wavefront's, accurate near the sources
        over a wider disk than the straight line); ``method="heat"`` only. :meth:`distance`
        calls it with ``X`` the direction of the heat step's decrease; the log map
        (:mod:`~manifold_sph.geometry.vector_heat`) with its own directions.

        Returns
        -------
        ndarray, shape (N,)
            Never below the straight-line distance to the nearest source; ``inf`` in pieces
            of the cloud without a source.
        """
        if self.method != "heat":
            raise ValueError(f"integrate needs method='heat', this solver's method is {self.method!r}")
        src = np.unique(self._indices("sources", sources, allow_mask=True))
        X = np.asarray(directions, dtype=np.float64)
        if X.shape != (self.n_points, 3) or not np.all(np.isfinite(X)):
            raise ValueError(f"directions must be finite with shape ({self.n_points}, 3), got shape {X.shape}")
        held = None
        if near is not None:
            held = np.asarray(near, dtype=np.float64)
            if held.shape != (self.n_points,):
                raise ValueError(f"near must have shape ({self.n_points},), got shape {held.shape}")
        rad = None if radius is None else check_positive("radius", radius) * np.sqrt(self._engine.h2)
        return self._engine.integrate(unit_rows(X), src, held, rad)

    def pairwise(self, indices: ArrayLike | None = None) -> np.ndarray:
        """Geodesic distances between all pairs of ``indices`` (default: every particle), shape (M, M).

        One sweep a row (stopping once the row's particles are final), symmetrised as the
        mean of the two directions; ``inf`` between particles of different pieces. Refused
        when the matrix would exceed :data:`PAIRWISE_MAX_BYTES`.
        """
        idx = np.arange(self.n_points) if indices is None else self._indices("indices", indices, allow_mask=True)
        m = idx.size
        if 8 * m * m > PAIRWISE_MAX_BYTES:
            raise ValueError(
                f"pairwise: {m} particles need a {8 * m * m / 2**30:.1f} GiB matrix (limit "
                f"{PAIRWISE_MAX_BYTES / 2**30:.0f} GiB); pass indices= a subset, or query rows with distance()"
            )
        D = np.empty((m, m))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ManifoldSPHWarning)
            for r, i in enumerate(idx):
                D[r] = self.distance(int(i), to=idx)
        return 0.5 * (D + D.T)


@overload
def geodesic_distance(cloud: Surface | ArrayLike, sources: ArrayLike, *, to: None = None, method: str = "wavefront",
                      denoise: bool | str = "auto") -> np.ndarray: ...


@overload
def geodesic_distance(
    cloud: Surface | ArrayLike, sources: ArrayLike, *, to: ArrayLike | None = None, method: str = "wavefront",
    denoise: bool | str = "auto",
) -> np.ndarray | float: ...


def geodesic_distance(
    cloud: Surface | ArrayLike,
    sources: ArrayLike,
    *,
    to: ArrayLike | None = None,
    method: str = "wavefront",
    denoise: bool | str = "auto",
) -> np.ndarray | float:
    """Geodesic distance from ``sources`` (a particle, particles or a mask); see :class:`GeodesicSolver`
    (``denoise``: smooth a noisy cloud first).

    On a Surface the solver is cached per method and ``denoise``, so later queries reuse its triangles
    (``"wavefront"``) or factorisations (``"heat"``).

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> c = shapes.sphere(4000)
    >>> d = geodesic_distance(Surface(c), 0)
    >>> exact = np.arccos(np.clip(c.points @ c.points[0], -1, 1))
    >>> bool(np.linalg.norm(d - exact) / np.linalg.norm(exact) < 6e-3)
    True
    """
    check_in("method", method, GEODESIC_METHODS)
    if is_surface(cloud):
        key = ("geodesic_solver", method) if denoise == "auto" else ("geodesic_solver", method, bool(denoise))
        solver = cloud.cached(key, lambda: GeodesicSolver(cloud, method=method, denoise=denoise))
    else:
        solver = GeodesicSolver(cloud, method=method, denoise=denoise)
    return solver.distance(sources, to=to)
