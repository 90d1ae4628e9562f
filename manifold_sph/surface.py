"""Differential operators on a point-cloud surface (docs/method.md sections 2-4)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ._validation import check_spread
from .diagnostics import BuildReport, note
from .frames import FramePair, PairOffsets, check_frames, project_pairs, tangent_frames
from .neighbors import GRID_MIN_POINTS, build_tree, check_scale, find_neighbors, widen_lonely
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
        check_spread("points", cloud.points)
        #: Whether the normals were estimated here from the points (none were given).
        self.normals_estimated = cloud.normals is None
        self._resolve(kernel, scheme, neighbors, max_condition)
        if cloud.normals is None:
            check_scale(cloud.points)  # before the normals' fit: a cloud too large for double precision is refused
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
        self, sources: ArrayLike, *, to: ArrayLike | None = None, method: str = "wavefront", denoise: bool | str = "auto"
    ) -> np.ndarray | float:
        """(N,) geodesic distance from ``sources`` (or to ``to`` only); see :func:`manifold_sph.geometry.geodesic_distance`."""
        from .geometry import geodesic_distance

        return geodesic_distance(self, sources, to=to, method=method, denoise=denoise)

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
        parts of a scan, normals that disagree with their neighbours') enough neighbours, repairing
        their normals where needed: :func:`manifold_sph.neighbors.widen_lonely`. RuntimeWarnings give
        the counts; :attr:`widened`, :attr:`flipped`, :attr:`repaired`, :attr:`unfiltered` and :attr:`strays`
        the indices.
        Returns the neighbourhood and the (possibly repaired) normals.
        """
        need = max(self.scheme.min_neighbors, 2)
        if tree is None and np.any(nb.counts < need):
            tree = self._tree  # built once, kept
        fix = widen_lonely(nb, pts, nrm, hv, need=need, target=self.neighbors, normal_threshold=normal_threshold,
                           tree=tree)
        self.widened, self.flipped, self.repaired, self.unfiltered = fix.widened, fix.flipped, fix.repaired, fix.unfiltered
        self.strays = fix.strays
        for key, summary, detail, idx in fix.entries():
            note(key, summary, detail=detail, count=idx.size, indices=idx)
        return fix.neighborhood, fix.normals

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

