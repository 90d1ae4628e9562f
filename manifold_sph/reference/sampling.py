"""Point samplers for implicit surfaces and for the planar square.

* ``fibonacci``: the golden-spiral lattice on the sphere (deterministic, exactly
  ``n`` points, near uniform).
* ``random``: area-uniform random points (each shape provides an exact or
  mesh-based area-uniform generator).
* ``poisson``: near-uniform "blue noise": area-uniform random start, then
  repulsion iterations. Each iteration finds the 6 nearest neighbours with a
  ``cKDTree``, pushes each point away from the neighbours closer than the
  target hexagonal spacing ``R = sqrt(2 A / (sqrt(3) n))`` (displacement
  ``0.35 (R - d)`` along the pair direction, summed), keeps the tangential part
  and projects back onto the surface; a final exact projection ends it.
  Vectorised; loops run over iterations only.
* ``variable``: density proportional to ``density_ratio ** s`` with ``s`` in
  [-1, 1] the shape's axis coordinate (z / r on the sphere and torus, the arc
  angle on the sausage, x on the double torus, y in the square): rejection
  sampling of the area-uniform points, then the same repulsion with a target
  spacing proportional to ``density^(-1/2)``. The density at ``s = 1/2`` is
  ``density_ratio`` times that at ``s = -1/2`` (the ends ``s = +-1`` differ by
  ``density_ratio**2``); on the sphere the point counts of the two hemispheres
  are in the ratio ``density_ratio``.
* ``halton`` (square only): scrambled Halton sequence (scipy.stats.qmc).

Every random sampler takes ``seed`` and is reproducible
(``numpy.random.default_rng(seed)``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol, cast

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from .._validation import as_points, check_finite, check_in, check_int, check_positive
from ..pointcloud import MIN_POINTS
from ..threads import get_num_threads


class ImplicitShape(Protocol):
    """What the surface samplers need of a shape (:class:`manifold_sph.reference.shapes.ImplicitShape`)."""

    @property
    def area(self) -> float: ...

    def normal(self, x: ArrayLike) -> np.ndarray: ...

    def project(self, x: ArrayLike) -> np.ndarray: ...

    def project_near(self, x: np.ndarray) -> np.ndarray: ...

    def axis_coordinate(self, x: ArrayLike) -> np.ndarray: ...

    def uniform_random_points(self, n: int, rng: np.random.Generator) -> np.ndarray: ...


class FibonacciShape(ImplicitShape, Protocol):
    """A shape with the ``"fibonacci"`` sampling among its ``samplings`` (the sphere)."""

    def fibonacci_points(self, n: int) -> np.ndarray: ...


__all__ = [
    "as_rng",
    "SURFACE_SAMPLINGS",
    "SPHERE_SAMPLINGS",
    "SQUARE_SAMPLINGS",
    "POISSON_ITERATIONS",
    "fibonacci_sphere",
    "sample_surface",
    "sample_triangles",
    "square",
    "nearest_neighbor_distances",
    "nearest_neighbor_cv",
    "local_density",
]

SURFACE_SAMPLINGS = ("poisson", "random", "variable")
SPHERE_SAMPLINGS = ("fibonacci", "poisson", "random", "variable")
SQUARE_SAMPLINGS = ("poisson", "halton", "random", "variable")

#: Number of repulsion iterations of the "poisson" and "variable" samplings.
POISSON_ITERATIONS = 20

_K = 6  # neighbours per repulsion step
_BETA = 1.0  # repulsion radius / target spacing
_STEP = 0.35  # relaxation step (fraction of the summed displacement)
_HEX = 2.0 / math.sqrt(3.0)  # area per point of a hexagonal lattice of unit spacing


def as_rng(seed: int | np.random.Generator | None) -> np.random.Generator:
    """A numpy Generator from a seed (a non-negative int or None) or the Generator itself."""
    if isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, bool) or not (seed is None or isinstance(seed, (int, np.integer))):
        raise TypeError(f"seed must be an int, None or a numpy Generator, got {type(seed).__name__} {seed!r}")
    if seed is not None and seed < 0:
        raise ValueError(f"seed must be non-negative, got {seed}")
    return np.random.default_rng(seed)


def fibonacci_sphere(n: int) -> np.ndarray:
    """Golden-spiral Fibonacci lattice: ``n`` near-uniform points on the unit sphere.

    Point ``i`` has ``z = 1 - (2 i + 1) / n`` and azimuth ``i * pi (3 - sqrt 5)``;
    every point gets the same area ``4 pi / n`` in z, no point is at a pole.

    Parameters
    ----------
    n : int
        Number of points (at least 10).

    Returns
    -------
    ndarray, shape (n, 3)

    Examples
    --------
    >>> p = fibonacci_sphere(12)
    >>> p.shape, bool(np.allclose(np.linalg.norm(p, axis=1), 1))
    ((12, 3), True)
    >>> p[:, 2].round(4).tolist()[:3]
    [0.9167, 0.75, 0.5833]
    """
    n = check_int("n", n, minimum=MIN_POINTS)
    i = np.arange(n, dtype=np.float64)
    z = 1.0 - (2.0 * i + 1.0) / n
    rad = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    az = i * (math.pi * (3.0 - math.sqrt(5.0)))
    return np.stack([rad * np.cos(az), rad * np.sin(az), z], axis=1)


def nearest_neighbor_distances(points: ArrayLike) -> np.ndarray:
    """Distance from each point to its nearest other point, (N,).

    Examples
    --------
    >>> nearest_neighbor_distances(np.array([[0.0, 0], [1, 0], [3, 0]])).tolist()
    [1.0, 1.0, 2.0]
    """
    p = as_points("points", points, dim=(2, 3))
    d, _ = cKDTree(p).query(p, 2)
    return d[:, 1]


def nearest_neighbor_cv(points: ArrayLike) -> float:
    """Coefficient of variation (std / mean) of nearest-neighbour distances.

    About 0.52 for area-uniform random points on a surface; below ~0.1 for the
    "poisson" sampling.

    Examples
    --------
    >>> g = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), -1).reshape(-1, 2)
    >>> nearest_neighbor_cv(g)
    0.0
    """
    d = nearest_neighbor_distances(points)
    return float(d.std() / d.mean())


def local_density(points: ArrayLike, k: int = 10) -> np.ndarray:
    """Points per unit area near each point: ``k / (pi d_k^2)``, (N,).

    ``d_k`` is the distance to the k-th nearest other point (the disc holds the
    point itself and ``k`` others, so ``k`` rather than ``k + 1`` is the
    unbiased count for a uniform density). For surface samples it is a 2D
    density as long as ``d_k`` is small against the curvature radii.

    Examples
    --------
    >>> g = np.stack(np.meshgrid(np.arange(40.0), np.arange(40.0)), -1).reshape(-1, 2)
    >>> round(float(np.median(local_density(g, k=12))), 2)  # unit lattice: ~1 per unit area
    0.95
    """
    p = as_points("points", points, dim=(2, 3))
    k = check_int("k", k, minimum=1)
    if k >= len(p):
        raise ValueError(f"k must be smaller than the number of points {len(p)}, got {k}")
    d, _ = cKDTree(p).query(p, k + 1)
    return k / (math.pi * d[:, k] ** 2)


def _density_weight(s: np.ndarray, density_ratio: float) -> np.ndarray:
    return density_ratio ** np.asarray(s)


# ----------------------------------------------------------------------------
# repulsion
# ----------------------------------------------------------------------------
def _relax(P, spacing, move, n_iter, ghosts=None):
    """Repulsion relaxation of ``P`` (n, d).

    ``spacing(P)`` gives the target spacing per point, ``move(P, disp)`` applies
    a displacement under the constraint (tangential move + projection, or
    clipping), ``ghosts(P, s)`` optionally returns mirror points and spacings.
    The points are reordered once along the kd-tree leaves (cache-friendly
    queries); the returned array is in that order.
    """
    P = P[cKDTree(P).indices]
    for _ in range(n_iter):
        s = spacing(P)
        if ghosts is not None:
            G, sg = ghosts(P, s)
            A = np.vstack([P, G])
            sa = np.concatenate([s, sg])
        else:
            A, sa = P, s
        tree = cKDTree(A, balanced_tree=False, compact_nodes=False)
        d, j = tree.query(P, _K + 1, workers=get_num_threads(), distance_upper_bound=_BETA * float(sa.max()))
        d, j = d[:, 1:], j[:, 1:]
        missing = j >= len(A)  # fewer than _K neighbours within reach
        j[missing] = 0
        d[missing] = np.inf
        R = (0.5 * _BETA) * (s[:, None] + sa[j])
        w = np.clip(1.0 - d / R, 0.0, None) * R / np.maximum(d, 1e-300)
        disp = w.sum(axis=1)[:, None] * P
        for c in range(_K):
            disp -= w[:, c, None] * A[j[:, c]]
        P = move(P, _STEP * disp)
    return P


def _surface_move(shape):
    def move(P, disp):
        n = shape.normal(P)
        disp = disp - np.einsum("ni,ni->n", disp, n)[:, None] * n
        return shape.project_near(P + disp)

    return move


def sample_surface(
    shape: ImplicitShape,
    n: int,
    sampling: str = "poisson",
    seed: int | np.random.Generator | None = 0,
    density_ratio: float = 4.0,
    iterations: int | None = None,
) -> np.ndarray:
    """Sample ``n`` points on an implicit shape (see :mod:`manifold_sph.reference.shapes`).

    Parameters
    ----------
    shape : ImplicitShape
    n : int
        Number of points (at least 10).
    sampling : {"poisson", "random", "variable", "fibonacci"}
        "fibonacci" only for shapes that provide it (the sphere).
    seed : int, None or numpy.random.Generator
    density_ratio : float
        For "variable": density at ``s = 1/2`` over density at ``s = -1/2``.
    iterations : int, optional
        Repulsion iterations ("poisson", "variable"); default
        :data:`POISSON_ITERATIONS`.

    Returns
    -------
    ndarray, shape (n, 3)
        Distinct points on the surface.

    Examples
    --------
    >>> from manifold_sph.reference.shapes import Torus
    >>> p = sample_surface(Torus(), 500, "poisson", seed=3)
    >>> p.shape, nearest_neighbor_cv(p) < 0.2
    ((500, 3), True)
    """
    n = check_int("n", n, minimum=MIN_POINTS)
    allowed = getattr(shape, "samplings", SURFACE_SAMPLINGS)
    check_in("sampling", sampling, allowed)
    density_ratio = check_positive("density_ratio", density_ratio)
    iterations = POISSON_ITERATIONS if iterations is None else check_int("iterations", iterations, minimum=0)
    if sampling == "fibonacci":  # in the allowed samplings of a FibonacciShape only
        return cast(FibonacciShape, shape).fibonacci_points(n)
    rng = as_rng(seed)
    if sampling == "random":
        return shape.uniform_random_points(n, rng)
    area = shape.area
    if sampling == "poisson":
        P = shape.uniform_random_points(n, rng)
        s0 = math.sqrt(_HEX * area / n)
        P = _relax(P, lambda Q: np.full(len(Q), s0), _surface_move(shape), iterations)
        return shape.project(P)
    # variable: rejection sampling, then relaxation with spacing ~ density^(-1/2)
    q = density_ratio
    wmax = max(q, 1.0 / q)
    acc, wsum, m_total = [], 0.0, 0
    got = 0
    while got < n:
        m = int(2.5 * wmax * (n - got)) + 64
        cand = shape.uniform_random_points(m, rng)
        w = _density_weight(shape.axis_coordinate(cand), q)
        wsum += float(w.sum())
        m_total += m
        keep = rng.random(m) * wmax <= w
        acc.append(cand[keep])
        got += int(keep.sum())
    P = np.vstack(acc)[:n]
    mean_w = wsum / m_total  # ~ (1/A) integral of w dA

    def spacing(Q):
        dens = n * _density_weight(shape.axis_coordinate(Q), q) / (mean_w * area)
        return np.sqrt(_HEX / dens)

    return shape.project(_relax(P, spacing, _surface_move(shape), iterations))


# ----------------------------------------------------------------------------
# planar square
# ----------------------------------------------------------------------------
def sample_triangles(vertices: ArrayLike, faces: ArrayLike, n: int, seed: int | None = 0) -> tuple[np.ndarray, np.ndarray]:
    """Area-uniform random points on a triangle mesh (the uniformly random samples of a model).

    Each point picks a face with probability proportional to its area, then a
    uniform point in it (two uniforms, reflected when their sum exceeds 1).

    Parameters
    ----------
    vertices : array_like, shape (V, 3)
    faces : array_like of int, shape (F, 3)
        Vertex indices; at least one face of positive area.
    n : int
        Number of points (>= 1).
    seed : int, None or numpy Generator
        Reproducible draws.

    Returns
    -------
    points : ndarray, shape (n, 3)
    face : ndarray of int, shape (n,)
        The face each point lies on (its normal is the face's).

    Raises
    ------
    ValueError
        On non-finite vertices, faces that are not (F, 3) indices into them, or a
        mesh without area.

    Examples
    --------
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    >>> p, f = sample_triangles(V, [[0, 1, 2], [1, 3, 2]], 1000, seed=0)
    >>> p.shape, bool(np.all((p >= 0) & (p <= 1))), bool(np.allclose(p[:, 2], 0))
    ((1000, 3), True, True)
    """
    U = np.asarray(vertices, dtype=np.float64)
    if U.ndim != 2 or U.shape[1] != 3 or not np.isfinite(U).all():
        raise ValueError(f"vertices must be a finite (V, 3) array, got shape {U.shape}")
    F = np.asarray(faces)
    if F.ndim != 2 or F.shape[1] != 3 or not np.issubdtype(F.dtype, np.integer) or F.size == 0:
        raise ValueError(f"faces must be a non-empty (F, 3) integer array, got shape {F.shape} of {F.dtype}")
    if F.min() < 0 or F.max() >= len(U):
        raise ValueError(f"faces must index the {len(U)} vertices, got indices {F.min()}..{F.max()}")
    n = check_int("n", n, minimum=1)
    A = np.linalg.norm(np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]]), axis=1)
    if not A.sum() > 0:
        raise ValueError("faces have no area: cannot sample the mesh")
    rng = as_rng(seed)
    f = rng.choice(len(F), n, p=A / A.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    P = U[F[f, 0]] + u[:, None] * (U[F[f, 1]] - U[F[f, 0]]) + v[:, None] * (U[F[f, 2]] - U[F[f, 0]])
    return P, f


def _as_bounds(bounds):
    try:
        b = np.asarray(bounds, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"bounds must be 4 numbers (xmin, xmax, ymin, ymax), got {type(bounds).__name__}") from exc
    if b.shape != (4,):
        raise ValueError(f"bounds must be 4 numbers (xmin, xmax, ymin, ymax), got shape {b.shape}")
    check_finite("bounds", b)
    if not (b[0] < b[1] and b[2] < b[3]):
        raise ValueError(f"bounds must satisfy xmin < xmax and ymin < ymax, got {tuple(b.tolist())}")
    return b


def square(
    n: int,
    bounds: Sequence[float] = (-1.0, 1.0, -1.0, 1.0),
    sampling: str = "poisson",
    seed: int | np.random.Generator | None = 0,
    density_ratio: float = 4.0,
) -> np.ndarray:
    """Sample ``n`` distinct points in the rectangle ``[xmin, xmax] x [ymin, ymax]``.

    Parameters
    ----------
    n : int
        Number of points (at least 10).
    bounds : sequence of 4 floats
        ``(xmin, xmax, ymin, ymax)``.
    sampling : {"poisson", "halton", "random", "variable"}
        "poisson": near-uniform (repulsion with the points mirrored in the sides,
        so the rows nearest the sides sit about half a spacing inside);
        "halton": scrambled Halton sequence; "random": uniform;
        "variable": density proportional to ``density_ratio ** s``,
        ``s = (2 y - ymin - ymax) / (ymax - ymin)``, then relaxed.
    seed : int, None or numpy.random.Generator
    density_ratio : float
        For "variable": density at ``s = 1/2`` over density at ``s = -1/2``.

    Returns
    -------
    ndarray, shape (n, 2)
        Points strictly inside the rectangle.

    Examples
    --------
    >>> p = square(1007, seed=0)
    >>> p.shape, bool(np.all(np.abs(p) < 1))
    ((1007, 2), True)
    >>> square(4, sampling="grid")
    Traceback (most recent call last):
    ...
    ValueError: n must be at least 10, got 4
    """
    n = check_int("n", n, minimum=MIN_POINTS)
    b = _as_bounds(bounds)
    check_in("sampling", sampling, SQUARE_SAMPLINGS)
    density_ratio = check_positive("density_ratio", density_ratio)
    lo, hi = b[[0, 2]], b[[1, 3]]
    width = hi - lo
    rng = as_rng(seed)
    if sampling == "halton":
        from scipy.stats import qmc

        P = lo + width * qmc.Halton(d=2, scramble=True, seed=rng).random(n)
    elif sampling == "random":
        P = lo + width * rng.random((n, 2))
    else:
        area = float(width[0] * width[1])
        if sampling == "poisson":
            P = lo + width * rng.random((n, 2))
            s0 = math.sqrt(_HEX * area / n)

            def spacing(Q):
                return np.full(len(Q), s0)

        else:
            q = density_ratio
            wmax = max(q, 1.0 / q)
            acc, got, wsum, m_total = [], 0, 0.0, 0
            while got < n:
                m = int(2.5 * wmax * (n - got)) + 64
                cand = lo + width * rng.random((m, 2))
                w = _density_weight(2 * (cand[:, 1] - lo[1]) / width[1] - 1, q)
                wsum += float(w.sum())
                m_total += m
                keep = rng.random(m) * wmax <= w
                acc.append(cand[keep])
                got += int(keep.sum())
            P = np.vstack(acc)[:n]
            mean_w = wsum / m_total

            def spacing(Q):
                dens = n * _density_weight(2 * (Q[:, 1] - lo[1]) / width[1] - 1, q) / (mean_w * area)
                return np.sqrt(_HEX / dens)

        eps = 1e-9 * float(width.min())

        def move(Q, disp):
            return np.clip(Q + disp, lo + eps, hi - eps)

        def ghosts(Q, s):
            reach = 1.5 * _BETA * s
            G, sg = [], []
            for axis in (0, 1):
                for side, sign in ((lo[axis], 1.0), (hi[axis], -1.0)):
                    near = sign * (Q[:, axis] - side) < reach
                    g = Q[near].copy()
                    g[:, axis] = 2 * side - g[:, axis]
                    G.append(g)
                    sg.append(s[near])
            # corners: reflect in both sides
            for cx in (lo[0], hi[0]):
                for cy in (lo[1], hi[1]):
                    near = (np.abs(Q[:, 0] - cx) < reach) & (np.abs(Q[:, 1] - cy) < reach)
                    G.append(np.stack([2 * cx - Q[near, 0], 2 * cy - Q[near, 1]], axis=1))
                    sg.append(s[near])
            return np.vstack(G), np.concatenate(sg)

        P = _relax(P, spacing, move, POISSON_ITERATIONS + 10, ghosts=ghosts)
    if len(np.unique(P, axis=0)) != n:  # pragma: no cover - probability zero
        raise RuntimeError("square sampling produced duplicate points; try another seed")
    return P

