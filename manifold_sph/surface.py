"""Differential operators on a point-cloud surface (docs/method.md sections 2-4)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from .diagnostics import BuildReport, note
from .frames import FramePair, PairOffsets, check_frames, project_pairs, tangent_frames
from .neighbors import GRID_MIN_POINTS, Neighborhood, build_tree, find_neighbors
from .operators import OperatorSet
from .pointcloud import PointCloud, PointViews, as_cloud

if TYPE_CHECKING:
    from .kernels import Kernel
    from .schemes import Scheme

__all__ = ["Surface"]


def _estimate_normals(points: np.ndarray, scheme: Scheme) -> np.ndarray:
    """Normals for a cloud without them: a jet fit of the scheme's Taylor degree (2 to 4)."""
    from .normals import estimate_normals

    degree = int(min(max(getattr(scheme, "degree", 2), 2), 4))
    return estimate_normals(points, degree=degree)


class Surface(OperatorSet, PointViews):
    """Gradient, divergence and Laplace-Beltrami on a point cloud sampling a surface.

    The neighbourhood (KD-tree radius search plus normal filter), tangent frames,
    projection to local 2D coordinates, area elements and the operator matrices
    are built once, at construction.

    Parameters
    ----------
    points : array_like (N, 3), PointCloud, file path, or Open3D / PyVista / trimesh object
        Anything :func:`~manifold_sph.as_cloud` takes (a file is read with its defaults:
        duplicates merged, a mesh's faces giving the normals).
    normals : array_like, shape (N, 3), optional
        Unit (or unnormalised, non-zero) normals. When neither ``normals`` nor the
        PointCloud has them, they are estimated with
        :func:`manifold_sph.normals.estimate_normals` (jet fits, oriented outward),
        of the scheme's Taylor degree: 2, and 3 / 4 / 4 for ``msph3`` / ``msph4`` /
        ``msph5`` (whose order needs normals that accurate; the high-degree fit is
        guarded, so thin parts keep the robust degree-2 normal).
    scheme : {"msph", "cspm", "ncsph", "standard", "msph3", "msph4", "msph5"} or Scheme
        ``"msph"`` by default: on uniformly random points cspm's Laplacian has
        O(1) errors (relative error 410 at N = 100,000, 3.0 at 2,000,000, measured
        on the unit sphere) because its second derivatives reuse first derivatives
        that are only first-order accurate there; msph solves for both at once
        (0.004 on the same points) and equals cspm on near-uniform clouds.
        ``msph3/4/5`` carry the corrected system to Taylor degree 3/4/5 (higher order,
        more neighbours by default, and they need accurate normals).
    kernel : {"quintic", "cubic", "gaussian", "wendland2", "quartic"} or Kernel
    neighbors : int, optional
        Target mean number of particles inside the support (itself included); by
        default the scheme's own choice (27 for the second-order schemes).
    h : None, float, "adaptive" or ndarray of shape (N,)
        Smoothing length: ``None`` chooses a uniform ``h`` giving ``neighbors`` on
        average; ``"adaptive"`` a per-particle ``h_i`` giving exactly ``neighbors``
        to every particle (variable density).
    area : {"numerical", "geometric", "shepard"}
        Area elements (docs/method.md section 3). ``"geometric"`` needs ``total_area``
        or a cloud with a known shape.
    normal_threshold : float
        Neighbours need ``n_i . n_j > normal_threshold``.
    total_area : float, optional
        Surface area for ``area="geometric"``.
    max_condition : float
        Particles whose local systems have a larger condition number fall back to
        a lower-order scheme (ncsph, msph -> cspm -> standard), recorded in
        :meth:`report`; :attr:`fallback` has the indices.

    Attributes
    ----------
    cloud : PointCloud
    neighborhood : Neighborhood
    u, v : ndarray, shape (N, 3)
        Tangent frames.
    area : AreaElements
        ``area.dV``, ``area.n_negative``.
    widened, flipped : ndarray of int
        Particles given a wider support, and whose normals were flipped.

    Notes
    -----
    What the build adapts to the cloud (normals estimated or flipped, supports widened,
    fallbacks, merged near-duplicates) is summarised in at most one
    :class:`~manifold_sph.ManifoldSPHWarning` per build; :meth:`report` has the details.
    :meth:`laplacian` uses the more accurate of the scheme's and the stable Laplacian on
    this cloud (:attr:`laplacian_form`).

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(2000)
    >>> s = Surface(cloud)
    >>> x = cloud.points
    >>> f = x[:, 0] * x[:, 1] * x[:, 2]           # Lap_S(xyz) = -12 xyz on the unit sphere
    >>> err = np.linalg.norm(s.laplacian(f) + 12 * f) / np.linalg.norm(12 * f)
    >>> bool(err < 0.02)
    True
    """

    _dim = 3

    def __init__(
        self,
        points: ArrayLike | PointCloud,
        normals: ArrayLike | None = None,
        *,
        scheme: str | Scheme = "msph",
        kernel: str | Kernel | type[Kernel] = "quintic",
        neighbors: int | None = None,
        h: float | str | ArrayLike | None = None,
        area: str = "numerical",
        normal_threshold: float = 0.0,
        total_area: float | None = None,
        max_condition: float = 1e8,
    ) -> None:
        self._build_report = BuildReport("Surface")
        with self._collect():  # one warning at the end summarises what the build adapted
            cloud = as_cloud(points, normals=normals)
            self._build_report.subject = f"Surface of {len(cloud.points):,} points"
            self._build(cloud, kernel, scheme, neighbors, h, area, normal_threshold, total_area, max_condition)

    def _build(self, cloud, kernel, scheme, neighbors, h, area, normal_threshold, total_area, max_condition) -> None:
        #: Whether the normals were estimated here from the points (none were given).
        self.normals_estimated = cloud.normals is None
        self._resolve(kernel, scheme, neighbors, max_condition)
        if cloud.normals is None:
            degree = int(min(max(getattr(self.scheme, "degree", 2), 2), 4))
            cloud = PointCloud(cloud.points, _estimate_normals(cloud.points, self.scheme), geometry=cloud.geometry)
            note("normals", "normals were estimated from the points", severity="info",
                 detail=f"None were given: jet fits of degree {degree}, oriented outward. Pass normals= to use your own.")
        self.cloud = cloud
        pts, nrm = cloud.points, cloud.normals
        # The KD-tree is built here for small clouds (its k-NN query is reused by the neighbour
        # search) and h="adaptive"; large clouds search on a grid, and build it on first use.
        self._kdtree = build_tree(pts) if pts.shape[0] < GRID_MIN_POINTS or isinstance(h, str) else None
        tree = self._kdtree
        hv = self._smoothing_length(h, pts, tree)
        nb = find_neighbors(
            pts, nrm, h=hv, support=self.kernel.support, normal_threshold=normal_threshold, tree=tree,
            knn=getattr(self, "_knn", None),
        )
        self._knn = None
        nb, nrm = self._widen_lonely(nb, pts, nrm, hv, normal_threshold, tree)
        if nrm is not cloud.normals:  # some normals were flipped to agree with their neighbours
            self.cloud = cloud = PointCloud(cloud.points, nrm, geometry=cloud.geometry)
        self.normal_threshold = float(normal_threshold)
        self.u, self.v = tangent_frames(nrm)
        check_frames(nrm, self.u, self.v)
        xy = PairOffsets(pts, self.u, self.v, nb.indptr, nb.indices)  # projected per chunk when read, never stored
        if total_area is None and cloud.geometry is not None:
            total_area = getattr(cloud.geometry, "area", None)
        self._setup(nb, xy, FramePair(self.u, self.v), area, total_area, column_normals=nrm)  # not stacked: 48 B a point

    @property
    def _tree(self):
        """The KD-tree of the points (built on first use for clouds searched on a grid)."""
        if self._kdtree is None:
            self._kdtree = build_tree(self.points)
        return self._kdtree

    @property
    def points(self) -> np.ndarray:
        """(N, 3) coordinates."""
        return self.cloud.points

    @property
    def normals(self) -> np.ndarray:
        """(N, 3) unit normals."""
        return self.cloud.normals

    # ------------------------------------------------------------- geometry (manifold_sph.geometry, imported lazily)
    def shape_operator(self, *, scale: float | str | None = None) -> np.ndarray:
        """(N, 2, 2) shape operator in the frames ``(u, v)``; see :func:`manifold_sph.geometry.shape_operator`."""
        from .geometry import shape_operator

        return shape_operator(self, scale=scale)

    def mean_curvature(self, method: str = "auto", *, scale: float | str | None = None) -> np.ndarray:
        """(N,) mean curvature ``(k1 + k2) / 2``, pointwise or at a ``scale``; see :func:`manifold_sph.geometry.mean_curvature`."""
        from .geometry import mean_curvature

        return mean_curvature(self, method, scale=scale)

    def gaussian_curvature(self, *, scale: float | str | None = None) -> np.ndarray:
        """(N,) Gaussian curvature ``k1 k2``; see :func:`manifold_sph.geometry.gaussian_curvature`."""
        from .geometry import gaussian_curvature

        return gaussian_curvature(self, scale=scale)

    def principal_curvatures(
        self, *, scale: float | str | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(k1, k2, d1, d2)``; see :func:`manifold_sph.geometry.principal_curvatures`."""
        from .geometry import principal_curvatures

        return principal_curvatures(self, scale=scale)

    def geodesic_distance(
        self, sources: ArrayLike, *, to: ArrayLike | None = None, method: str = "wavefront"
    ) -> np.ndarray | float:
        """(N,) geodesic distance from ``sources`` (or to ``to`` only); see :func:`manifold_sph.geometry.geodesic_distance`."""
        from .geometry import geodesic_distance

        return geodesic_distance(self, sources, to=to, method=method)

    def transport(self, source: int, vector: ArrayLike) -> np.ndarray:
        """(N, 3) the tangent ``vector`` at particle ``source`` carried to every particle; see :func:`manifold_sph.geometry.transport`."""
        from .geometry import transport

        return transport(self, source, vector)

    def log_map(self, source: int) -> np.ndarray:
        """(N, 2) logarithmic map at particle ``source`` in its frame ``(u, v)``; see :func:`manifold_sph.geometry.log_map`."""
        from .geometry import log_map

        return log_map(self, source)

    def smooth(
        self, *, method: str = "jet", scale: float | None = None, iterations: int = 3, features: bool = True
    ) -> PointCloud:
        """A smoothed (denoised) copy of the cloud as a PointCloud; see :func:`manifold_sph.geometry.smooth`."""
        from .geometry import smooth

        return smooth(self, method=method, scale=scale, iterations=iterations, features=features)

    def _widen_lonely(self, nb, pts, nrm, hv, normal_threshold, tree):
        """Give particles with fewer than the scheme's minimum of neighbours (isolated points, sparse
        parts of a scan) a support reaching ``neighbors`` normal-compatible neighbours.

        A normal that agrees with none of its nearest points is flipped first when the flip makes it
        agree. Both go to the build's report; :attr:`widened` and :attr:`flipped` hold the indices.
        Returns the neighbourhood and the (possibly flipped) normals.
        """
        need = max(self.scheme.min_neighbors, 2)
        lonely = np.flatnonzero(nb.counts < need)
        self.widened, self.flipped = lonely, lonely[:0]
        if not lonely.size:
            return nb, nrm
        tree = self._tree if tree is None else tree
        n = pts.shape[0]
        k = min(n, 4 * self.neighbors)
        dist, idx = tree.query(pts[lonely], k=k)
        dots = np.einsum("rkd,rd->rk", nrm[idx], nrm[lonely])
        dots[:, 0] = np.inf  # the particle itself
        flip = ((dots > normal_threshold).sum(axis=1) < need) & ((-dots > normal_threshold).sum(axis=1) >= need)
        if flip.any():
            nrm = nrm.copy()
            nrm[lonely[flip]] *= -1.0
            dots[flip] *= -1.0
            self.flipped = lonely[flip]
            note(
                "flipped", f"{int(flip.sum())} normal(s) pointed against all their neighbours' and were flipped",
                detail=f"Each disagreed with every nearby point's normal (n_i . n_j <= normal_threshold = "
                f"{normal_threshold:g}) and agrees once flipped: a wrongly oriented normal. Check the orientation of "
                "the normals given, or give none to have them estimated.",
                count=int(flip.sum()), indices=self.flipped,
            )
        rank = np.cumsum(dots > normal_threshold, axis=1)  # compatible neighbours up to each candidate
        hopeless = lonely[rank[:, -1] < need]
        if hopeless.size:
            raise ValueError(
                f"{hopeless.size} particle(s) have fewer than {need} neighbours whose normals agree with theirs "
                f"(n_i . n_j > normal_threshold = {normal_threshold:g}) among their {k} nearest points (first "
                f"indices {hopeless[:8].tolist()}): their normals disagree with every nearby point (wrong "
                "orientation?) or they are outliers; check the normals, lower normal_threshold, or remove them"
            )
        target = min(self.neighbors, n - 1)
        enough = np.minimum(target, rank[:, -1])  # all compatible ones when fewer than the target
        reach = dist[np.arange(lonely.size), np.argmax(rank >= enough[:, None], axis=1)]
        hv = np.array(np.broadcast_to(hv, (n,)), dtype=np.float64)
        hv[lonely] = np.maximum(hv[lonely], 1.0001 * reach / self.kernel.support)
        note(
            "widened", f"{lonely.size} isolated or sparse point(s) got wider supports (reaching {target} neighbours)",
            detail=f"They had fewer than {need} neighbours inside the kernel support (stray points, or sparse parts "
            "of the cloud); their smoothing length was widened, so their operators are smoother and less "
            "accurate there. Remove stray points, or sample those parts more densely.",
            count=lonely.size, indices=lonely,
        )
        if flip.any():  # flipped normals change other rows' normal filter: search every row again
            nb = find_neighbors(pts, nrm, h=hv, support=self.kernel.support, normal_threshold=normal_threshold,
                                tree=tree)
        else:  # only the widened rows change (a row's neighbours lie within its own support): search them
            # alone and splice them in (a full search with the widened h takes the slower KD-tree path everywhere)
            nb = _splice_rows(nb, lonely, pts, nrm, hv, self.kernel.support, normal_threshold, tree)
        self._check_isolated(nb, "their normals disagree with their neighbours'")  # a flip elsewhere can only add
        return nb, nrm

    def _wider_candidates(self, rows: np.ndarray):
        """The ``_WIDER_K`` nearest neighbours of ``rows`` (normal filter applied), projected."""
        pts, nrm = self.points, self.normals
        k = min(self._WIDER_K, pts.shape[0])
        dist, idx = self._tree.query(pts[rows], k=k)
        keep = np.einsum("rkd,rd->rk", nrm[idx], nrm[rows]) > self.normal_threshold
        keep[:, 0] = True  # the particle itself (distance 0) comes first
        pair_rows = np.repeat(rows, keep.sum(axis=1))
        xy = project_pairs(pts, self.u, self.v, pair_rows, idx[keep])
        indptr = np.concatenate([[0], np.cumsum(keep.sum(axis=1))])
        radius = dist[:, -1] if k < pts.shape[0] else np.full(rows.size, np.inf)
        return indptr, xy, idx[keep], radius, self._pair_heights(pair_rows, idx[keep])

    def _pair_heights(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Offsets ``n_i . (x_j - x_i)`` of pairs along the row particle's normal (threaded chunks of pairs)."""
        from .threads import run_chunks

        pts, nrm = np.ascontiguousarray(self.points.T), np.ascontiguousarray(self.normals.T)  # one take a coordinate
        out = np.zeros(rows.size)
        step = 1 << 16

        def chunk(k):
            r, c, o = rows[k * step : (k + 1) * step], cols[k * step : (k + 1) * step], out[k * step : (k + 1) * step]
            for a in range(3):
                d = np.take(pts[a], c)
                d -= np.take(pts[a], r)
                d *= np.take(nrm[a], r)
                o += d

        run_chunks(chunk, -(-rows.size // step))
        return out

    def _tangential(self, F: np.ndarray) -> np.ndarray:
        n = self.normals
        return F - np.einsum("ij,ij->i", F, n)[:, None] * n

    def __repr__(self) -> str:
        return (
            f"Surface(n_points={self.n_points}, scheme={self.scheme.name!r}, kernel={self.kernel.name!r}, "
            f"mean neighbours={self.neighborhood.counts.mean():.1f}, area={self._area_args[0]!r})"
        )


def _splice_rows(nb, rows, pts, nrm, hv, support, normal_threshold, tree):
    """``nb`` with the neighbour lists of ``rows`` searched again with the smoothing lengths ``hv``.

    The same arrays as a search of every row with ``hv`` (each row's list depends only on its own
    support; rows keep the search's order, the particle first).
    """
    def search(h):
        return find_neighbors(pts[rows], nrm[rows], h=h, support=support, normal_threshold=normal_threshold,
                              candidates=pts, candidate_normals=nrm, tree=tree)

    new, old = search(hv[rows]), search(nb.h[rows])
    counts = nb.counts.copy()
    counts[rows] = new.counts
    indptr = np.zeros(counts.size + 1, dtype=nb.indptr.dtype)
    np.cumsum(counts, out=indptr[1:])
    indices = np.empty(int(indptr[-1]), dtype=nb.indices.dtype)
    keep = np.ones(counts.size, dtype=bool)
    keep[rows] = False
    r = nb.rows
    mask = keep[r]
    pos = np.flatnonzero(mask)
    indices[indptr[r[mask]] + (pos - nb.indptr[r[mask]])] = nb.indices[mask]
    owner = np.repeat(np.arange(rows.size), new.counts)
    indices[indptr[rows[owner]] + (np.arange(new.indices.size) - new.indptr[owner])] = new.indices
    return Neighborhood(indptr=indptr, indices=indices, h=hv, support=nb.support,
                        n_filtered=nb.n_filtered - old.n_filtered + new.n_filtered)
