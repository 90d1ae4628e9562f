"""The implicit-surface base class: exact differential-geometry references from ``phi``.

A shape is a closed surface ``S = {x : phi(x) = 0}`` with ``phi < 0`` inside, so
``n = grad phi / |grad phi|`` is the OUTWARD unit normal. From ``grad phi`` and the
Hessian of ``phi`` :class:`ImplicitShape` gives, at any point, the exact references of
docs/method.md section 5 for a smooth function ``f`` (or field ``F``) defined in R^3:

* ``div n = (tr H - n^T H n) / |grad phi|`` (sum of principal curvatures),
* ``grad_S f = grad f - (n . grad f) n``,
* ``Lap_S f = Lap f - n^T (Hess f) n - (div n)(n . grad f)``,
* ``div_S(P F) = tr(DF) - n^T DF n - (F . n)(div n)`` with ``P = I - n n^T``.

The concrete shapes are in :mod:`manifold_sph.reference.shapes`.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_field, as_points, check_finite, check_in, check_int, check_positive
from ..exceptions import ManifoldSPHWarning
from ..pointcloud import MIN_POINTS, PointCloud
from . import sampling as _sampling

__all__ = ["ImplicitShape", "TINY", "AXIS_MIN", "AREA_CACHE", "as_center"]

#: Smallest gradient norm or distance treated as non-zero.
TINY = 1e-300
#: Distance to an axis below which axis-singular derivatives are clamped.
AXIS_MIN = 1e-100


# ----------------------------------------------------------------------------
# validation helpers
# ----------------------------------------------------------------------------
def as_center(center: ArrayLike) -> np.ndarray:
    try:
        c = np.asarray(center, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"center must be a sequence of 3 numbers, got {type(center).__name__}") from exc
    if c.shape != (3,):
        raise ValueError(f"center must have shape (3,), got shape {c.shape}")
    check_finite("center", c)
    return c


def _as_tensor(name: str, a, n: int) -> np.ndarray:
    """Return ``a`` as a finite float64 array of shape (n, 3, 3)."""
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a numeric array of shape ({n}, 3, 3), got {type(a).__name__}") from exc
    if arr.shape != (n, 3, 3):
        raise ValueError(f"{name} must have shape ({n}, 3, 3), got shape {arr.shape}")
    check_finite(name, arr)
    return arr


def _marching_cubes(phi, bounds, spacing):
    """Triangulate ``{phi = 0}`` on a regular grid (VTK flying edges via pyvista).

    Returns vertices (V, 3) float64 and triangles (F, 3) int64.
    """
    import pyvista as pv  # lazy: pyvista is slow to import

    lo = np.asarray(bounds[0::2], dtype=float) - 2 * spacing
    hi = np.asarray(bounds[1::2], dtype=float) + 2 * spacing
    dims = np.ceil((hi - lo) / spacing).astype(int) + 1
    grid = pv.ImageData(dimensions=tuple(int(d) for d in dims), spacing=(spacing,) * 3, origin=tuple(lo))
    grid.point_data["phi"] = phi(np.asarray(grid.points, dtype=np.float64))
    surf = grid.contour([0.0], scalars="phi", method="flying_edges").triangulate()
    if surf.n_points == 0:
        raise RuntimeError("marching cubes found no surface: spacing too coarse for this shape")
    faces = np.asarray(surf.faces).reshape(-1, 4)[:, 1:].astype(np.int64)
    return np.asarray(surf.points, dtype=np.float64), faces


def _triangle_areas(vertices, faces) -> np.ndarray:
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def _subdivide(vertices, faces):
    """Split every triangle into four at its edge midpoints (shared midpoints merged)."""
    nv = len(vertices)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges.sort(axis=1)
    uniq, inv = np.unique(edges, axis=0, return_inverse=True)
    inv = inv.ravel()
    mid = 0.5 * (vertices[uniq[:, 0]] + vertices[uniq[:, 1]])
    nf = len(faces)
    m01, m12, m20 = (nv + inv[k * nf:(k + 1) * nf] for k in range(3))
    v0, v1, v2 = faces[:, 0], faces[:, 1], faces[:, 2]
    new_faces = np.concatenate(
        [
            np.stack([v0, m01, m20], 1),
            np.stack([v1, m12, m01], 1),
            np.stack([v2, m20, m12], 1),
            np.stack([m01, m12, m20], 1),
        ]
    )
    return np.vstack([vertices, mid]), new_faces


# Numerical areas are deterministic and cost up to 2 s; keep them.
AREA_CACHE: dict = {}



# ----------------------------------------------------------------------------
# base class
# ----------------------------------------------------------------------------
class ImplicitShape:
    """A closed surface ``phi(x) = 0`` with exact normals, curvature and operators.

    Subclasses implement ``_phi``, ``_grad`` and ``_hess`` on validated (N, 3)
    arrays; everything else (normals, curvature, projection, the reference
    operators of docs/method.md section 5, sampling) is generic. The operators are
    evaluated with the normal of the level set of ``phi`` through ``x``, so they
    are the exact surface operators when ``x`` lies on the surface.

    Attributes
    ----------
    name : str
        Short identifier ("sphere", "torus", ...).
    samplings : tuple of str
        Sampling names accepted by :meth:`sample`.
    area_is_exact : bool
        Whether :attr:`area` is a closed form (True) or a numerical estimate.

    Examples
    --------
    Exact Laplace-Beltrami of ``f = xyz`` (a degree-3 spherical harmonic, so
    ``Lap_S f = -12 f`` on the unit sphere) from its ambient derivatives:

    >>> import numpy as np
    >>> from manifold_sph.reference.shapes import Sphere
    >>> s = Sphere()
    >>> x = np.array([[0.48, 0.6, 0.64]])
    >>> X, Y, Z = x.T
    >>> grad = np.stack([Y * Z, X * Z, X * Y], axis=1)
    >>> hess = np.array([[[0, Z[0], Y[0]], [Z[0], 0, X[0]], [Y[0], X[0], 0]]])
    >>> s.laplace_beltrami(x, grad, hess).round(10).tolist(), (-12 * X * Y * Z).round(10).tolist()
    ([-2.21184], [-2.21184])
    """

    name = "implicit"
    samplings: tuple = _sampling.SURFACE_SAMPLINGS
    default_sampling = "poisson"
    area_is_exact = False
    #: grid spacing of the marching-cubes mesh used for area-uniform sampling
    _mesh_spacing = 0.05
    #: largest Newton step of :meth:`project` (keeps far points from jumping across)
    _max_step = 0.5

    # -- to implement ------------------------------------------------------
    def _phi(self, x: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _grad(self, x: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _hess(self, x: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def bounds(self) -> tuple[float, ...]:
        """Axis-aligned bounding box ``(xmin, xmax, ymin, ymax, zmin, zmax)``."""
        raise NotImplementedError  # pragma: no cover - abstract

    def axis_coordinate(self, x: ArrayLike) -> np.ndarray:
        """Normalised coordinate ``s`` in [-1, 1] along which "variable" sampling varies.

        The "variable" density is proportional to ``density_ratio ** s``.
        """
        raise NotImplementedError  # pragma: no cover - abstract

    def _key(self) -> tuple:
        raise NotImplementedError  # pragma: no cover - abstract

    # -- implicit function ---------------------------------------------------
    def phi(self, x: ArrayLike) -> np.ndarray:
        """Implicit function, (N,); the surface is ``phi = 0``, ``phi < 0`` inside."""
        return self._phi(as_points("x", x))

    def grad_phi(self, x: ArrayLike) -> np.ndarray:
        """Gradient of :meth:`phi`, (N, 3)."""
        return self._grad(as_points("x", x))

    def hess_phi(self, x: ArrayLike) -> np.ndarray:
        """Hessian of :meth:`phi`, (N, 3, 3)."""
        return self._hess(as_points("x", x))

    def _unit_normal(self, x: np.ndarray):
        g = self._grad(x)
        gn = np.linalg.norm(g, axis=1)
        if np.any(gn <= TINY):
            idx = np.flatnonzero(gn <= TINY)
            raise ValueError(
                f"x holds {idx.size} point(s) where grad phi vanishes and the normal is undefined "
                f"(first indices {idx[:5].tolist()})"
            )
        return g / gn[:, None], gn

    def normal(self, x: ArrayLike) -> np.ndarray:
        """Outward unit normal ``grad phi / |grad phi|``, (N, 3)."""
        return self._unit_normal(as_points("x", x))[0]

    def _div_n(self, x: np.ndarray, n: np.ndarray, gn: np.ndarray) -> np.ndarray:
        H = self._hess(x)
        return (np.trace(H, axis1=1, axis2=2) - np.einsum("ni,nij,nj->n", n, H, n)) / gn

    def mean_curvature(self, x: ArrayLike) -> np.ndarray:
        """``div n``, the SUM of the principal curvatures, (N,).

        ``div n = (tr H - n^T H n) / |grad phi|``; it is ``2 / r`` on a sphere of
        radius ``r`` (positive for convex surfaces with the outward normal).
        """
        x = as_points("x", x)
        n, gn = self._unit_normal(x)
        return self._div_n(x, n, gn)

    def gaussian_curvature(self, x: ArrayLike) -> np.ndarray:
        """Gaussian curvature ``K = grad phi^T adj(H) grad phi / |grad phi|^4``, (N,)."""
        x = as_points("x", x)
        g = self._grad(x)
        H = self._hess(x)
        a, b, c = H[:, 0], H[:, 1], H[:, 2]
        cof = np.stack([np.cross(b, c), np.cross(c, a), np.cross(a, b)], axis=1)
        gn2 = np.einsum("ni,ni->n", g, g)
        return np.einsum("ni,nij,nj->n", g, cof, g) / (gn2 * gn2)

    def principal_curvatures(self, x: ArrayLike) -> np.ndarray:
        """Principal curvatures (N, 2), largest first, signed like :meth:`mean_curvature`."""
        half = 0.5 * self.mean_curvature(x)
        disc = np.sqrt(np.maximum(half * half - self.gaussian_curvature(x), 0.0))
        return np.stack([half + disc, half - disc], axis=1)

    # -- projection ------------------------------------------------------------
    def _phi_grad(self, x: np.ndarray):
        return self._phi(x), self._grad(x)

    def _newton_step(self, x: np.ndarray):
        """One clamped Newton step towards phi = 0; returns new x and |phi|/|grad phi|."""
        f, g = self._phi_grad(x)
        g2 = np.einsum("ni,ni->n", g, g)
        bad = g2 <= TINY
        if bad.any():
            raise ValueError(
                f"cannot project {int(bad.sum())} point(s) where grad phi vanishes "
                f"(first indices {np.flatnonzero(bad)[:5].tolist()})"
            )
        step = (f / g2)[:, None] * g
        slen = np.linalg.norm(step, axis=1)
        big = slen > self._max_step
        step[big] *= (self._max_step / slen[big])[:, None]
        return x - step, np.abs(f) / np.sqrt(g2)

    def project_near(self, x: np.ndarray) -> np.ndarray:
        """Cheap projection for points already near the surface (two Newton steps)."""
        x, _ = self._newton_step(x)
        x, _ = self._newton_step(x)
        return x

    def project(self, x: ArrayLike, tol: float = 1e-13, maxiter: int = 50) -> np.ndarray:
        """Project points onto ``phi = 0`` by Newton steps along ``grad phi``.

        Each step is ``x <- x - phi grad phi / |grad phi|^2`` (length clamped), run
        per point until the distance estimate ``|phi| / |grad phi|`` is below
        ``tol`` (one more step is then taken, so converged points sit on the
        surface to rounding). Meant for points near the surface: the result is a
        nearby surface point (the closest one to second order), not always the
        closest one.

        Parameters
        ----------
        x : array_like, shape (N, 3)
        tol : float, optional
            Convergence threshold on ``|phi| / |grad phi|`` (a length).
        maxiter : int, optional
            Maximum number of Newton steps; a RuntimeWarning names the points
            that did not converge.

        Returns
        -------
        ndarray, shape (N, 3)
        """
        p = as_points("x", x).copy()
        tol = check_positive("tol", tol)
        maxiter = check_int("maxiter", maxiter, minimum=1)
        active = np.arange(len(p))
        for _ in range(maxiter):
            p[active], dist = self._newton_step(p[active])
            active = active[dist > tol]
            if active.size == 0:
                break
        else:
            f, g = self._phi_grad(p[active])
            still = np.abs(f) / np.linalg.norm(g, axis=1) > tol
            if still.any():
                warnings.warn(
                    f"project: {int(still.sum())} point(s) did not converge in {maxiter} "
                    f"iterations (first indices {active[still][:5].tolist()})",
                    ManifoldSPHWarning,
                    stacklevel=2,
                )
        return p

    # -- exact surface operators ---------------------------------------------------
    def surface_gradient(self, x: ArrayLike, grad_f: ArrayLike) -> np.ndarray:
        """Tangential gradient ``grad_S f = grad f - (n . grad f) n``, (N, 3).

        Parameters
        ----------
        x : array_like, shape (N, 3)
            Points (on the surface for the surface gradient).
        grad_f : array_like, shape (N, 3)
            Ambient gradient of ``f`` at ``x``.
        """
        x = as_points("x", x)
        gf = as_field("grad_f", grad_f, len(x), 3)
        n, _ = self._unit_normal(x)
        return gf - np.einsum("ni,ni->n", n, gf)[:, None] * n

    def laplace_beltrami(self, x: ArrayLike, grad_f: ArrayLike, hess_f: ArrayLike) -> np.ndarray:
        """``Lap_S f = Lap f - n^T (Hess f) n - (div n)(n . grad f)``, (N,).

        Parameters
        ----------
        x : array_like, shape (N, 3)
        grad_f : array_like, shape (N, 3)
            Ambient gradient of ``f`` at ``x``.
        hess_f : array_like, shape (N, 3, 3)
            Ambient Hessian of ``f`` at ``x``.
        """
        x = as_points("x", x)
        gf = as_field("grad_f", grad_f, len(x), 3)
        hf = _as_tensor("hess_f", hess_f, len(x))
        n, gn = self._unit_normal(x)
        return (
            np.trace(hf, axis1=1, axis2=2)
            - np.einsum("ni,nij,nj->n", n, hf, n)
            - self._div_n(x, n, gn) * np.einsum("ni,ni->n", n, gf)
        )

    def divergence(self, x: ArrayLike, F: ArrayLike, DF: ArrayLike) -> np.ndarray:
        """Surface divergence of the tangent projection ``P F`` of an ambient field.

        ``div_S(P F) = tr(DF) - n^T DF n - (F . n)(div n)``, (N,). For a tangent
        field (``F . n = 0`` on the surface) it is the divergence of ``F`` itself.

        Parameters
        ----------
        x : array_like, shape (N, 3)
        F : array_like, shape (N, 3)
            Field values at ``x``.
        DF : array_like, shape (N, 3, 3)
            Jacobian, ``DF[k, a, b] = dF_a / dx_b`` at ``x[k]``.
        """
        x = as_points("x", x)
        F = as_field("F", F, len(x), 3)
        DF = _as_tensor("DF", DF, len(x))
        n, gn = self._unit_normal(x)
        return (
            np.trace(DF, axis1=1, axis2=2)
            - np.einsum("ni,nij,nj->n", n, DF, n)
            - np.einsum("ni,ni->n", F, n) * self._div_n(x, n, gn)
        )

    # -- meshes, area, sampling ------------------------------------------------
    def triangle_mesh(self, spacing: float | None = None, subdivisions: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Triangulate the surface: marching cubes, vertices projected onto it.

        Parameters
        ----------
        spacing : float, optional
            Grid spacing of the marching-cubes grid (default: a shape-specific
            value resolving its thinnest part).
        subdivisions : int, optional
            Number of midpoint subdivisions (each splits every triangle into
            four), new vertices projected too.

        Returns
        -------
        vertices : ndarray, shape (V, 3)
        faces : ndarray of int, shape (F, 3)
        """
        spacing = self._mesh_spacing if spacing is None else check_positive("spacing", spacing)
        subdivisions = check_int("subdivisions", subdivisions, minimum=0)
        v, f = _marching_cubes(self._phi, self.bounds, spacing)
        v = self.project(v)
        for _ in range(subdivisions):
            nv = len(v)
            v, f = _subdivide(v, f)
            v[nv:] = self.project(v[nv:])
        return v, f

    def _numerical_area(self) -> float:
        """Area of the projected mesh, midpoint-subdivided twice, Richardson-extrapolated.

        The inscribed mesh area converges like h^2 under subdivision, so
        ``A2 + (A2 - A1) / 3`` from the last two levels is accurate to ~1e-6
        relative (checked on the sphere and torus, whose areas are known).
        """
        key = self._key()
        if key not in AREA_CACHE:
            v, f = _marching_cubes(self._phi, self.bounds, self._mesh_spacing)
            v = self.project(v)
            areas = []
            for level in range(3):
                if level:
                    nv = len(v)
                    v, f = _subdivide(v, f)
                    v[nv:] = self.project(v[nv:])
                areas.append(float(_triangle_areas(v, f).sum()))
            AREA_CACHE[key] = areas[2] + (areas[2] - areas[1]) / 3.0
        return AREA_CACHE[key]

    @property
    def area(self) -> float:
        """Surface area: exact when known, else a numerical estimate (see subclass)."""
        return self._numerical_area()

    def uniform_random_points(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` area-uniform random points (default: via a fine triangle mesh).

        Triangles of the projected, once-subdivided marching-cubes mesh are drawn
        with probability proportional to their area, a uniform point is drawn in
        each, and the points are projected onto the surface. The density is
        uniform up to O((kappa h)^2) from the projection (below 1% here).
        """
        key = ("mesh",) + self._key()
        if key not in AREA_CACHE:
            v, f = self.triangle_mesh(subdivisions=1)
            a = _triangle_areas(v, f)
            AREA_CACHE[key] = (v, f, np.cumsum(a) / a.sum())
        v, f, cdf = AREA_CACHE[key]
        tri = np.minimum(np.searchsorted(cdf, rng.random(n), side="right"), len(f) - 1)
        r1 = np.sqrt(rng.random(n))
        r2 = rng.random(n)
        a, b, c = (v[f[tri, k]] for k in range(3))
        p = (1 - r1)[:, None] * a + (r1 * (1 - r2))[:, None] * b + (r1 * r2)[:, None] * c
        return self.project(p)

    def sample(
        self, n: int, sampling: str | None = None, seed: int | np.random.Generator | None = 0, density_ratio: float = 4.0
    ) -> PointCloud:
        """Sample ``n`` distinct surface points with exact outward normals.

        Parameters
        ----------
        n : int
            Number of points (at least 10).
        sampling : str, optional
            One of :attr:`samplings` (default :attr:`default_sampling`):
            "poisson" (near-uniform blue noise: area-uniform random start, then
            tangential repulsion with re-projection), "random" (area-uniform),
            "variable" (density proportional to ``density_ratio ** s`` with ``s``
            the :meth:`axis_coordinate`, relaxed like "poisson"); the sphere also
            has "fibonacci".
        seed : int or None, optional
            Seed of ``numpy.random.default_rng``; equal seeds give equal clouds.
        density_ratio : float, optional
            For "variable": the density at ``s = 1/2`` over the density at
            ``s = -1/2`` (so the ends ``s = +-1`` differ by its square).

        Returns
        -------
        PointCloud
            With ``normals`` exact and ``shape`` set to this shape.
        """
        pts = self._sample_points(n, sampling, seed, density_ratio)
        return PointCloud(pts, self.normal(pts), geometry=self)

    def _sample_points(self, n, sampling, seed, density_ratio) -> np.ndarray:
        n = check_int("n", n, minimum=MIN_POINTS)
        sampling = self.default_sampling if sampling is None else sampling
        check_in("sampling", sampling, self.samplings)
        density_ratio = check_positive("density_ratio", density_ratio)
        return _sampling.sample_surface(self, n, sampling, seed=seed, density_ratio=density_ratio)

    def __repr__(self) -> str:
        params = ", ".join(f"{k}={v!r}" for k, v in self._params().items())
        return f"{type(self).__name__}({params})"

    def _params(self) -> dict:
        return {}
