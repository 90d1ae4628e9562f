"""The vector heat method on a point cloud (Sharp, Soliman and Crane 2019).

Tangent vectors at particle ``i`` are complex numbers in its frame ``(u_i, v_i)``
(:attr:`Surface.u`, :attr:`Surface.v`): ``X = a u_i + b v_i`` is ``a + i b``.

- **Connection Laplacian.** The stable Laplacian's stiffness ``K`` (Voronoi fluxes) with
  each off-diagonal entry multiplied by the rotation ``r_ij`` that carries particle ``j``'s
  tangent plane onto particle ``i``'s: the smallest rotation taking ``n_j`` to ``n_i``
  (parallel transport along the short arc between neighbours), written as a unit complex
  number ``r_ij = (R u_j) . (u_i + i v_i)``. ``K_conn`` is Hermitian positive semi-definite
  (``r_ji = conj(r_ij)``); :func:`connection_laplacian`.
- **Parallel transport** (:func:`transport`). One implicit heat step of the vector at the
  source, ``(M + t K_conn) Y = M delta X``; the direction of ``Y`` at each particle is the
  vector transported along the shortest geodesic (its length is kept). The solve is the
  real symmetric form ``[[Re A, -Im A], [Im A, Re A]]`` of the Hermitian system, set up once
  by :func:`manifold_sph.solvers.spd_solver` and reused for every source.
- **Logarithmic map** (:func:`log_map`). The geodesic distance ``r`` and the angle, at each
  particle, between the direction of increasing distance and the transported frame vector
  ``u_source``: ``log(x) = r (cos theta, sin theta)`` in the frame of the source particle.
  The direction of increasing distance is that of ``-grad log u``, ``u`` the scalar heat
  step ``(M + t K) u = delta`` with the same ``t`` (Varadhan: ``-4 t log u`` tends to
  ``r^2``), the gradient from quadric fits over the 96 nearest points
  (:func:`~manifold_sph.geometry.jets.field_gradient`): ``log u`` is smooth where ``u``
  spans many decades, and the wide fits average the irregular cloud's noise. ``r`` is the
  distance whose gradient best fits those directions
  (:meth:`~manifold_sph.geometry.GeodesicSolver.integrate`, the heat method's Poisson
  step, with the wavefront distance held within ``LOG_MAP_HELD`` spacings of the source,
  where the radial field's divergence ``1 / r`` is too steep for the Poisson step:
  ``geodesics="heat"``), or, by default, the wavefront distance.
  Where the diffused vector keeps less than ``ANGLE_TRUST`` of the scalar heat
  (``|Y| < ANGLE_TRUST |X| u``: paths of the diffusion cancel, towards the cut locus, and the
  direction of the small remainder is mostly discretisation error), the angle is instead carried
  outwards along the geodesics from the particles nearer to the source: the angle of a
  geodesic's initial direction is the same all along it.
- **Karcher mean** (:func:`karcher_mean`): the particle ``p`` where the weighted mean of
  ``log_p`` of the given particles vanishes, by the fixed-point iteration
  ``p <- exp_p(mean log_p)`` (the particle nearest to that tangent point in the log map).

The normals must be consistently oriented (a Surface's are): the sign of the angles follows them.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from .._jit.compile import ENABLED, njit
from .._validation import as_field, check_in, check_int, check_positive
from ..exceptions import ManifoldSPHWarning
from .common import SCALE_RANGE, check_scale, check_surface
from .jets import field_gradient

if TYPE_CHECKING:
    from ..surface import Surface
    from .geodesics import GeodesicSolver

__all__ = ["VectorHeatSolver", "connection_laplacian", "karcher_mean", "log_map", "transport"]

#: Heat time of the vector diffusion (and of the log map's scalar heat step), in units of the mean cell area.
VECTOR_HEAT_TIME = 64.0
#: Nearest points of the quadric fits that give the log map's radial directions.
LOG_MAP_NEIGHBORS = 96
#: The log map's radius is integrated from its directions with the wavefront distance held within this many
#: spacings of the source.
LOG_MAP_HELD = 10.0
#: The integrated radius is kept within this relative distance of the wavefront distance.
LOG_MAP_SPREAD = 0.005
#: The log map's angle is read from the diffused vector where it keeps at least this share of the scalar heat
#: (``|Y| >= ANGLE_TRUST |X| u``); elsewhere paths of the diffusion cancel and the angle is carried along the geodesics.
ANGLE_TRUST = 0.5
#: ... and where ``|grad log u|`` keeps at least this share of Varadhan's ``r / 2t`` (less: heat from several routes).
RADIAL_TRUST = 0.9
#: Nearest points searched for the upwind particles of the angle's propagation.
ANGLE_NEIGHBORS = 32


def _carry_angles(order, known, theta, slot, nbr, dist, P, radial, lateral, r):
    """Carry the log map's angle ``theta`` along the radial geodesics into the particles not ``known``.

    Particles are visited by increasing distance ``r``. The angle of a geodesic's initial
    direction is constant along it, so a particle takes, from its neighbours nearer to the
    source that already have an angle, the value at its own position of the weighted fit
    ``theta = c0 + c1 l + c2 a l + c3 l^2`` (``a``, ``l`` the offsets along its radial and
    lateral directions: no term in ``a`` alone, the angle does not change along the geodesic);
    the mean when fewer than six neighbours qualify. Angles are unwrapped about the first one.
    Row ``slot[i]`` of ``nbr`` and ``dist`` holds particle ``i``'s nearest points (itself first).
    """
    n = P.shape[0]
    k = nbr.shape[1]
    done = known.copy()
    out = theta.copy()
    A = np.zeros((4, 4))
    b = np.zeros(4)
    row = np.zeros(4)
    for q in range(n):
        i = order[q]
        if done[i]:
            continue
        s = slot[i]
        width = 1.25 * dist[s, min(8, k - 1)] + 1e-300
        A[:, :] = 0.0
        b[:] = 0.0
        ref = 0.0
        count = 0
        wsum = 0.0
        msum = 0.0
        for jj in range(1, k):
            j = nbr[s, jj]
            if not done[j] or not r[j] < r[i]:
                continue
            a = 0.0
            lat = 0.0
            d2 = 0.0
            for c in range(3):
                e = P[j, c] - P[i, c]
                a += e * radial[i, c]
                lat += e * lateral[i, c]
                d2 += e * e
            if count == 0:
                ref = out[j]
            t = (out[j] - ref + np.pi) % (2.0 * np.pi) - np.pi
            w = np.exp(-d2 / (width * width))
            a /= width
            lat /= width
            row[0] = 1.0
            row[1] = lat
            row[2] = a * lat
            row[3] = lat * lat
            for x in range(4):
                b[x] += w * row[x] * t
                for y in range(4):
                    A[x, y] += w * row[x] * row[y]
            count += 1
            wsum += w
            msum += w * t
        if count == 0:
            continue  # no upwind neighbour with an angle: the diffused vector's stays
        if count >= 6 and wsum > 0.0:
            for x in range(4):
                A[x, x] += 1e-9 * A[0, 0]
            out[i] = ref + np.linalg.solve(A, b)[0]
        elif wsum > 0.0:
            out[i] = ref + msum / wsum
        done[i] = True
    return (out + np.pi) % (2.0 * np.pi) - np.pi


_carry_angles = njit(_carry_angles) if ENABLED else _carry_angles


def _frame_rotations(n: np.ndarray, u: np.ndarray, v: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Unit complex ``r_ij``: particle ``j``'s frame vector ``u_j`` carried by the smallest rotation taking
    ``n_j`` to ``n_i``, in the frame ``(u_i, v_i)``."""
    f, t = n[j], n[i]
    c = np.einsum("pd,pd->p", f, t)
    w = np.cross(f, t)
    a = u[j]
    wa = np.cross(w, a)
    Ra = a + wa + np.cross(w, wa) / np.maximum(1.0 + c, 1e-12)[:, None]
    z = np.einsum("pd,pd->p", Ra, u[i]) + 1j * np.einsum("pd,pd->p", Ra, v[i])
    return z / np.maximum(np.abs(z), 1e-300)


def connection_laplacian(surface: Surface) -> sp.csr_matrix:
    """Complex Hermitian connection Laplacian ``K_conn``, shape (N, N) (module notes); cached on the surface.

    ``K_conn`` has the diagonal of the stiffness ``K`` and off-diagonal entries ``K_ij r_ij``;
    ``-M^-1 K_conn`` is the Bochner (connection) Laplacian on tangent fields written in the
    particles' frames.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> s = Surface(shapes.sphere(1000))
    >>> Kc = connection_laplacian(s)
    >>> bool(abs(Kc - Kc.conj().T).max() < 1e-14), bool(np.allclose(Kc.diagonal(), s.stiffness_matrix().diagonal()))
    (True, True)
    """
    check_surface(surface)

    def compute():
        K = surface.stiffness_matrix().tocoo()
        off = K.row != K.col
        i, j = K.row[off], K.col[off]
        r = _frame_rotations(surface.normals, surface.u, surface.v, i, j)
        n = surface.n_points
        data = np.concatenate([K.data[~off].astype(np.complex128), K.data[off] * r])
        rows = np.concatenate([K.row[~off], i])
        cols = np.concatenate([K.col[~off], j])
        A = sp.csr_matrix((data, (rows, cols)), shape=(n, n))
        return (0.5 * (A + A.conj().T)).tocsr()  # Hermitian to round-off

    return surface.cached("connection_laplacian", compute)


def _to_complex(surface, i, vector):
    return vector @ surface.u[i] + 1j * (vector @ surface.v[i])


def _to_ambient(surface, z):
    return z.real[:, None] * surface.u + z.imag[:, None] * surface.v


class VectorHeatSolver:
    """The vector heat method on a Surface, with its systems set up once.

    Parameters
    ----------
    surface : Surface
    t : float, optional
        Heat time of the vector diffusion (default the mean cell area times
        ``VECTOR_HEAT_TIME``).
    geodesics : {"wavefront", "heat"}
        The log map's distances: ``"wavefront"`` (default; the
        :class:`~manifold_sph.geometry.GeodesicSolver` default, second order on smooth surfaces;
        docs/geometry.md compares the two) or ``"heat"`` (the distance integrated
        from the radial directions, held to the wavefront within ``LOG_MAP_SPREAD``).
    denoise : {"auto", True, False}
        The wavefront distances of the log map measured over the cloud smoothed onto its local
        quadrics (:class:`~manifold_sph.geometry.GeodesicSolver`'s ``denoise``; "auto": when
        the cloud reads noisy).
    """

    def __init__(self, surface: Surface, *, t: float | None = None, geodesics: str = "wavefront",
                 denoise: bool | str = "auto") -> None:
        from ..solvers import spd_solver

        check_surface(surface)
        check_scale(surface.points, "vector heat method", SCALE_RANGE)
        self.surface = surface
        self.geodesics = check_in("geodesics", geodesics, ("heat", "wavefront"))
        from .geodesics import check_denoise

        self.denoise = check_denoise(denoise)
        m = np.asarray(surface.mass_matrix().diagonal(), dtype=np.float64)
        self._h2 = float(m.mean())
        self.t = VECTOR_HEAT_TIME * self._h2 if t is None else check_positive("t", t)
        A = sp.diags(m / self._h2) + (self.t / self._h2) * connection_laplacian(surface)  # units of the mean cell
        Ar, Ai = A.real.tocsr(), A.imag.tocsr()
        self._m = m / self._h2
        self._solve = spd_solver(sp.bmat([[Ar, -Ai], [Ai, Ar]], format="csr")).solve
        self._distance: GeodesicSolver | None = None
        self._wavefront: Any = None
        self._heat: Any = None  # the scalar heat step of the log map, set up at its first call
        self._tree: cKDTree | None = None

    def _source(self, source) -> int:
        n = self.surface.n_points
        if isinstance(source, (bool, np.bool_)) or not isinstance(source, (int, np.integer)):
            raise TypeError(f"source must be a particle index (int), got {type(source).__name__}")
        if not 0 <= source < n:
            raise ValueError(f"source must lie in [0, {n}), got {source}")
        return int(source)

    def diffuse(self, source: int, vector: ArrayLike) -> np.ndarray:
        """The vector heat step's solution ``Y`` (complex, in the particles' frames), shape (N,)."""
        i = self._source(source)
        vec = as_field("vector", np.reshape(np.asarray(vector, dtype=np.float64), (1, 3)), 1, 3)[0]
        z = _to_complex(self.surface, i, vec)
        if z == 0:
            raise ValueError(f"vector must have a non-zero component in the tangent plane of particle {i}, got {vec.tolist()}")
        n = self.surface.n_points
        b = np.zeros(2 * n)
        b[i], b[n + i] = z.real, z.imag  # an impulse at the source: its size does not change the directions
        y = self._solve(b)
        return y[:n] + 1j * y[n:]

    def transport(self, source: int, vector: ArrayLike) -> np.ndarray:
        """``vector`` (3,) at ``source`` (projected to its tangent plane) carried to every particle, shape (N, 3)."""
        i = self._source(source)
        Y = self.diffuse(i, vector)
        vec = np.asarray(vector, dtype=np.float64).reshape(3)
        length = abs(_to_complex(self.surface, i, vec))
        mag = np.abs(Y)
        lost = mag <= 1e-300 * max(mag.max(), 1e-300)
        if lost.any():
            warnings.warn(f"transport: {int(lost.sum())} particle(s) got no share of the diffused vector (pieces "
                          "without the source): their vector is NaN", ManifoldSPHWarning, stacklevel=2)
        Z = np.where(lost, np.nan, Y / np.where(lost, 1.0, mag) * length)
        return _to_ambient(self.surface, Z)

    def log_map(self, source: int) -> np.ndarray:
        """Logarithmic map at ``source``: (N, 2) coordinates in the frame ``(u, v)`` of the source particle.

        Their length is the geodesic distance; their angle that of the initial direction of
        the shortest geodesic from the source.
        """
        from ..solvers import cholesky_available, spd_solver
        from .geodesics import GeodesicSolver

        s = self.surface
        i = self._source(source)
        n = s.n_points
        if self._heat is None:  # Cholesky keeps the far field's small values to their last digits
            A = (sp.diags(self._m) + (self.t / self._h2) * s.stiffness_matrix()).tocsr()
            self._heat = spd_solver(A, method="cholesky" if cholesky_available() else "auto")
        if self._distance is None:
            self._wavefront = GeodesicSolver(s, denoise=self.denoise)
            self._distance = GeodesicSolver(s, method="heat") if self.geodesics == "heat" else self._wavefront
        b = np.zeros(n)
        b[i] = 1.0
        u = self._heat.solve(b)
        ok = u > 1e-300 * u.max()
        logu = np.full(n, np.nan)
        logu[ok] = np.log(u[ok] / u.max())
        if self._tree is None:
            self._tree = cKDTree(s.points)
        g = -field_gradient(s.points, s.u, s.v, logu, neighbors=LOG_MAP_NEIGHBORS, tree=self._tree)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ManifoldSPHWarning)
            r = self._wavefront.distance(i)
            if self.geodesics == "heat":  # within LOG_MAP_SPREAD of the wavefront, never below the straight line
                wf = r
                r = self._distance.integrate(g, i, near=wf, radius=LOG_MAP_HELD)
                r = np.maximum(np.clip(r, (1.0 - LOG_MAP_SPREAD) * wf, (1.0 + LOG_MAP_SPREAD) * wf),
                               np.linalg.norm(s.points - s.points[i], axis=1))
        lost = np.isfinite(r) & ~ok
        if lost.any():
            warnings.warn(f"log_map: the heat step's solution is below the solver's accuracy or float64's range at "
                          f"{int(lost.sum())} particle(s): their directions are fitted from their neighbours' only "
                          "(a larger t reaches farther)", ManifoldSPHWarning, stacklevel=2)
        radial = np.einsum("nd,nd->n", g, s.u) + 1j * np.einsum("nd,nd->n", g, s.v)
        Y = self.diffuse(i, s.u[i])
        theta = np.angle(radial * np.conj(Y))
        known = ~(np.abs(Y) < ANGLE_TRUST * np.abs(_to_complex(s, i, s.u[i])) * u) | ~np.isfinite(r)
        known &= ~(np.linalg.norm(g, axis=1) * np.sqrt(self.t) < RADIAL_TRUST)
        if not known.all():  # paths of the diffusion cancel: carry the angle along the geodesics
            slot = np.cumsum(~known) - 1
            dist, nbr = self._tree.query(s.points[~known], k=min(ANGLE_NEIGHBORS, n), workers=-1)
            e_r = g / np.maximum(np.linalg.norm(g, axis=1), 1e-300)[:, None]
            theta = _carry_angles(np.argsort(r, kind="stable"), known, theta, slot, nbr.astype(np.int64), dist,
                                  s.points, e_r, np.cross(s.normals, e_r), r)
        out = np.stack([r * np.cos(theta), r * np.sin(theta)], axis=1)
        out[i] = 0.0
        out[~np.isfinite(r)] = np.nan
        return out

    def karcher_mean(self, indices: ArrayLike, weights: ArrayLike | None = None, *, start: int | None = None,
                     max_iter: int = 20) -> int:
        """Weighted Karcher (Frechet) mean of particles ``indices``: the particle index where the mean log map vanishes."""
        s = self.surface
        idx = np.atleast_1d(np.asarray(indices))
        if idx.ndim != 1 or idx.size == 0 or not np.issubdtype(idx.dtype, np.integer):
            raise ValueError(f"indices must be a non-empty 1-D array of particle indices, got {idx!r}")
        if np.any((idx < 0) | (idx >= s.n_points)):
            raise ValueError(f"indices must lie in [0, {s.n_points})")
        w = np.ones(idx.size) if weights is None else as_field("weights", weights, idx.size)
        if np.any(w < 0) or w.sum() <= 0:
            raise ValueError("weights must be non-negative with a positive sum")
        w = w / w.sum()
        max_iter = check_int("max_iter", max_iter, minimum=1)
        if start is None:  # the particle nearest the extrinsic mean
            c = (w[:, None] * s.points[idx]).sum(axis=0)
            start = int(np.argmin(np.einsum("nd,nd->n", s.points - c, s.points - c)))
        p = self._source(start)
        seen = {p}
        for _ in range(max_iter):
            L = self.log_map(p)
            step = (w[:, None] * L[idx]).sum(axis=0)
            q = int(np.nanargmin(np.einsum("nd,nd->n", L - step, L - step)))
            if q == p or q in seen:
                return q if q == p else p
            seen.add(q)
            p = q
        return p


def _solver(surface, geodesics="wavefront"):
    check_surface(surface)
    return surface.cached(("vector_heat", geodesics), lambda: VectorHeatSolver(surface, geodesics=geodesics))


def transport(surface: Surface, source: int, vector: ArrayLike) -> np.ndarray:
    """Parallel transport of ``vector`` (3,) at particle ``source`` to every particle, shape (N, 3).

    See :class:`VectorHeatSolver`; its systems are cached on the surface.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> s = Surface(shapes.sphere(4000))
    >>> Y = transport(s, 0, s.u[0])
    >>> bool(np.allclose(np.linalg.norm(Y, axis=1), 1.0)), bool(np.abs(np.einsum("nd,nd->n", Y, s.normals)).max() < 1e-12)
    (True, True)
    """
    return _solver(surface).transport(source, vector)


def log_map(surface: Surface, source: int, *, geodesics: str = "wavefront") -> np.ndarray:
    """Logarithmic map at particle ``source``, shape (N, 2), in the frame ``(u, v)`` of ``source``.

    The length of each row is the geodesic distance (``geodesics="wavefront"``, the default: the
    wavefront distance; ``"heat"``: integrated from the radial directions by
    :meth:`~manifold_sph.geometry.GeodesicSolver.integrate`), its angle that of the initial
    direction of the shortest geodesic. See :class:`VectorHeatSolver`.
    """
    return _solver(surface, check_in("geodesics", geodesics, ("heat", "wavefront"))).log_map(source)


def karcher_mean(surface: Surface, indices: ArrayLike, weights: ArrayLike | None = None, *, geodesics: str = "wavefront") -> int:
    """Weighted Karcher (Frechet) mean of particles ``indices``, as a particle index; see :class:`VectorHeatSolver`."""
    return _solver(surface, check_in("geodesics", geodesics, ("heat", "wavefront"))).karcher_mean(indices, weights)
