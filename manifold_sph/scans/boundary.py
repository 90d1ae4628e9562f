"""Open boundaries: finding the particles whose neighbourhood is one-sided.

A scan with holes (the bunny is open at the bottom) has particles on the rim of
each hole. In the tangent plane of such a particle its neighbours all lie on one
side. Two measures of that, per particle, from the projected neighbour offsets
``x_ij`` (docs/method.md section 2.3):

- ``gap``: the largest angle between consecutive neighbour directions around the
  particle (radians). Interior particles of a cloud with ~20 neighbours have gaps
  well under 90 degrees; a particle on a straight rim has a gap near 180 degrees.
- ``offset``: ``|mean_j x_ij| / mean_j |x_ij|``, the centroid shift of the
  neighbourhood, ~0 inside and ~0.64 on a straight rim of a uniform cloud.

A particle is on the boundary when both ``gap > max_gap`` and ``offset > max_offset``
(either alone flags interior particles of clumpy random samples; both together
did not in the tests: on a uniformly random hemisphere of 2000 points, interior
gaps reach about 120 degrees at the 99th percentile and offsets 0.5, but rarely
together, while rim particles have gaps of 130-190 degrees and offsets above 0.4).

What the operators and PDEs do there
------------------------------------
No ghost particles are added on an open surface: the operators use the one-sided
neighbourhood as it is. The corrected schemes (cspm, msph, ncsph) stay
consistent there (their moment matrices are built from the actual neighbours,
so linear fields, and for msph/ncsph quadratics, are still differentiated
exactly), at the price of larger errors and condition numbers; ill-conditioned
particles fall back to lower-order schemes (``Surface.fallback``). The standard
scheme is not consistent at a boundary (its gradient of a linear field is wrong
there). The standard (Taylor) Laplacian with positive area elements
(``area="shepard"``) has non-negative off-diagonal weights and zero row sums: a
weighted graph Laplacian, so heat (:func:`manifold_sph.pde.heat`) with no other
condition behaves as an insulated (homogeneous Neumann, "natural") boundary:
no heat leaves, values stay within the initial bounds, and the solution tends to
a constant on every connected piece. For Dirichlet data hold the boundary
particles: ``heat(surface, u0, dt, steps, fixed=mask, fixed_values=...)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from .._validation import as_points, check_int, check_positive
from ..frames import project_pairs, tangent_frames
from ..pointcloud import PointCloud
from ..threads import get_num_threads

if TYPE_CHECKING:
    from ..operators import OperatorSet

__all__ = ["BoundaryReport", "detect_boundary", "angular_gaps"]


@dataclass(frozen=True)
class BoundaryReport:
    """Boundary particles and the measures behind the decision.

    Attributes
    ----------
    mask : ndarray of bool, shape (N,)
        True on boundary particles.
    gap : ndarray, shape (N,)
        Largest angular gap between neighbour directions (radians).
    offset : ndarray, shape (N,)
        Centroid shift of the neighbourhood over its mean radius.
    n_loops : int
        Connected pieces of the boundary (holes, rims) in the neighbour graph.
    labels : ndarray of int, shape (N,)
        Boundary piece of each boundary particle, -1 elsewhere.
    """

    mask: np.ndarray
    gap: np.ndarray
    offset: np.ndarray
    n_loops: int
    labels: np.ndarray

    @property
    def indices(self) -> np.ndarray:
        return np.flatnonzero(self.mask)

    @property
    def n_boundary(self) -> int:
        return int(self.mask.sum())

    @property
    def report(self) -> str:
        n = self.mask.size
        if not self.n_boundary:
            return f"no boundary: all {n} particles have two-sided neighbourhoods (closed surface)"
        sizes = np.bincount(self.labels[self.mask]) if self.n_loops else np.zeros(0, int)
        top = ", ".join(str(int(s)) for s in np.sort(sizes)[::-1][:5])
        return (
            f"{self.n_boundary} of {n} particles ({100 * self.n_boundary / n:.2f}%) are on an open boundary, "
            f"in {self.n_loops} connected piece(s) (largest: {top} particles)"
        )

    def __str__(self) -> str:
        return self.report


def angular_gaps(xy: np.ndarray, indptr: np.ndarray) -> np.ndarray:
    """Largest angle between consecutive directions in each row of CSR-stored 2D offsets.

    Zero offsets (the particle itself) are ignored; rows with fewer than two
    directions get ``2 pi``.

    Examples
    --------
    >>> import numpy as np
    >>> xy = np.array([[0.0, 0], [1, 0], [0, 1], [-1, 0], [0, -1], [1, 0], [0, 1], [-1, 0.01]])
    >>> np.degrees(angular_gaps(xy, np.array([0, 5, 8]))).round(1).tolist()
    [90.0, 180.6]
    """
    n = indptr.size - 1
    counts = np.diff(indptr)
    rows = np.repeat(np.arange(n), counts)
    r = np.hypot(xy[:, 0], xy[:, 1])
    ok = r > 0
    ang = np.arctan2(xy[ok, 1], xy[ok, 0])
    rows = rows[ok]
    m = np.bincount(rows, minlength=n)
    width = int(m.max()) if m.size else 0
    if width == 0:
        return np.full(n, 2 * np.pi)
    table = np.full((n, width), np.inf)
    start = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(m, out=start[1:])
    col = np.arange(rows.size) - start[rows]
    table[rows, col] = ang
    table.sort(axis=1)
    idx = np.arange(width)
    valid = idx[None, :] < m[:, None]
    with np.errstate(invalid="ignore"):  # inf - inf in the padding
        diffs = np.where(valid[:, 1:], np.diff(table, axis=1), -np.inf) if width > 1 else np.full((n, 0), -np.inf)
    # rows with no direction at all (every neighbour filtered out) hold only the inf
    # padding: inf - inf would be NaN (a RuntimeWarning); they get 2 pi below anyway
    first = np.where(m > 0, table[:, 0], 0.0)
    last = np.where(m > 0, table[np.arange(n), np.maximum(m - 1, 0)], 0.0)
    wrap = first + 2 * np.pi - last
    gap = np.max(np.concatenate([diffs, wrap[:, None]], axis=1), axis=1)
    return np.where(m >= 2, gap, 2 * np.pi)


def detect_boundary(
    surface: OperatorSet | PointCloud | ArrayLike,
    normals: ArrayLike | None = None,
    *,
    k: int = 20,
    max_gap: float = 110.0,
    max_offset: float = 0.3,
    normal_threshold: float = 0.0,
) -> BoundaryReport:
    """Find the particles on open boundaries (holes, rims) of a point-cloud surface.

    Parameters
    ----------
    surface : Surface, PointCloud or array_like (N, 3)
        A :class:`~manifold_sph.Surface` is analysed with its own neighbourhood
        and tangent frames; otherwise the ``k`` nearest neighbours (filtered by
        normals, which are estimated if missing) are used.
    normals : array_like, shape (N, 3), optional
        For a bare array of points.
    k : int
        Neighbours (itself included) when ``surface`` is not a Surface.
    max_gap : float
        Angular gap (degrees) that a boundary particle exceeds.
    max_offset : float
        Centroid shift (fraction of the mean neighbour distance) that a boundary
        particle also exceeds.
    normal_threshold : float
        Neighbours need ``n_i . n_j > normal_threshold`` (not for a Surface).

    Returns
    -------
    BoundaryReport

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph.reference import shapes
    >>> detect_boundary(shapes.sphere(1000)).n_boundary
    0
    >>> g = np.linspace(0, 1, 20)
    >>> x, y = np.meshgrid(g, g)
    >>> plate = np.c_[x.ravel(), y.ravel(), np.zeros(400)]
    >>> rep = detect_boundary(plate, np.tile([0.0, 0, 1], (400, 1)))
    >>> rep.n_boundary, rep.n_loops                # the 76 particles on the square's edges
    (76, 1)
    """
    from ..operators import OperatorSet

    if isinstance(surface, OperatorSet):
        nb = surface.neighborhood
        xy = surface.pair_offsets()
        indptr, rows, cols = nb.indptr, nb.rows, nb.indices
        n = nb.n_rows
    else:
        if isinstance(surface, PointCloud):
            pts = surface.points
            nrm = surface.normals if normals is None else as_points("normals", normals)
        else:
            pts = as_points("points", surface)
            nrm = None if normals is None else as_points("normals", normals)
        n = pts.shape[0]
        k = check_int("k", k, minimum=3)
        if k > n:
            raise ValueError(f"k must be at most the number of points {n}, got {k}")
        if nrm is None:
            from .normals import estimate_normals

            nrm = estimate_normals(pts)
        elif nrm.shape != pts.shape:
            raise ValueError(f"normals must have shape {pts.shape} to match points, got shape {nrm.shape}")
        nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
        _, idx = cKDTree(pts).query(pts, k=k, workers=get_num_threads())
        keep = np.einsum("nd,nkd->nk", nrm, nrm[idx]) > normal_threshold
        counts = keep.sum(axis=1)
        indptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        rows = np.repeat(np.arange(n), counts)
        cols = idx[keep]
        u, v = tangent_frames(nrm)
        xy = project_pairs(pts, u, v, rows, cols)
    max_gap = np.radians(check_positive("max_gap", max_gap))
    max_offset = check_positive("max_offset", max_offset)
    gap = angular_gaps(xy, indptr)
    r = np.hypot(xy[:, 0], xy[:, 1])
    cnt = np.maximum(np.diff(indptr), 1)
    mean_xy = np.stack([np.bincount(rows, weights=xy[:, a], minlength=n) for a in range(2)], axis=1) / cnt[:, None]
    mean_r = np.bincount(rows, weights=r, minlength=n) / cnt
    offset = np.where(mean_r > 0, np.hypot(mean_xy[:, 0], mean_xy[:, 1]) / np.where(mean_r > 0, mean_r, 1.0), 1.0)
    mask = (gap > max_gap) & (offset > max_offset)
    labels = np.full(n, -1, dtype=np.int64)
    n_loops = 0
    if mask.any():
        both = mask[rows] & mask[cols] & (rows != cols)
        G = sp.coo_matrix((np.ones(int(both.sum())), (rows[both], cols[both])), shape=(n, n))
        _, lab = csgraph.connected_components(G, directed=False)
        _, lab_b = np.unique(lab[mask], return_inverse=True)
        labels[mask] = lab_b.ravel()
        n_loops = int(lab_b.max()) + 1
    return BoundaryReport(mask=mask, gap=gap, offset=offset, n_loops=n_loops, labels=labels)
