"""Differential operators on a planar domain: the surface pipeline with the identity projection."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ._validation import as_points, check_finite, check_spread
from .neighbors import build_tree, find_neighbors
from .operators import OperatorSet
from .pointcloud import as_cloud, is_point_array

if TYPE_CHECKING:
    from .kernels import Kernel
    from .schemes import Scheme

__all__ = ["Domain2D", "mirror_ghosts", "planar_points"]


def _check_bounds(bounds) -> tuple[float, float, float, float]:
    try:
        b = np.asarray(bounds, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"bounds must be four numbers (xmin, xmax, ymin, ymax), got {bounds!r}") from None
    if b.shape != (4,):
        raise ValueError(f"bounds must be (xmin, xmax, ymin, ymax), got shape {b.shape}")
    check_finite("bounds", b)
    if not (b[0] < b[1] and b[2] < b[3]):
        raise ValueError(f"bounds must satisfy xmin < xmax and ymin < ymax, got {tuple(b.tolist())}")
    return float(b[0]), float(b[1]), float(b[2]), float(b[3])


def mirror_ghosts(points: np.ndarray, bounds: Sequence[float], width: float) -> tuple[np.ndarray, np.ndarray]:
    """Ghost copies of the strips of ``width`` along each side of a rectangle, translated periodically.

    Parameters
    ----------
    points : ndarray, shape (N, 2)
    bounds : (xmin, xmax, ymin, ymax)
    width : float

    Returns
    -------
    ghosts : ndarray, shape (G, 2)
    owner : ndarray, shape (G,)
        Index of the particle each ghost copies.

    Examples
    --------
    >>> import numpy as np
    >>> g, o = mirror_ghosts(np.array([[0.05, 0.5], [0.5, 0.5]]), (0, 1, 0, 1), 0.1)
    >>> g.tolist(), o.tolist()
    ([[1.05, 0.5]], [0])
    """
    x0, x1, y0, y1 = _check_bounds(bounds)
    lx, ly = x1 - x0, y1 - y0
    ghosts, owner = [], []
    idx = np.arange(points.shape[0])
    for sx in (-lx, 0.0, lx):
        for sy in (-ly, 0.0, ly):
            if sx == 0.0 and sy == 0.0:
                continue
            q = points + np.array([sx, sy])
            keep = (q[:, 0] > x0 - width) & (q[:, 0] < x1 + width) & (q[:, 1] > y0 - width) & (q[:, 1] < y1 + width)
            ghosts.append(q[keep])
            owner.append(idx[keep])
    return np.concatenate(ghosts), np.concatenate(owner)


def planar_points(points: Any) -> np.ndarray:
    """(N, 2) coordinates of planar point-like input: an (N, 2) array as it is; anything else
    :func:`~manifold_sph.as_cloud` takes (an (N, 3) array, a file, a mesh...) when one of
    its coordinates is constant (the plane x, y or z = c), without that coordinate."""
    if is_point_array(points) and np.ndim(points) == 2 and np.shape(points)[1] == 2:
        return as_points("points", points, dim=2)
    if is_point_array(points):
        pts = as_points("points", points, dim=(2, 3))
    else:
        pts = as_cloud(points).points
    if pts.shape[0] == 0:
        raise ValueError(f"points must hold at least 10 points, got an empty array of shape {pts.shape}")
    ext = np.ptp(pts, axis=0)
    flat = np.flatnonzero(ext <= 1e-9 * max(float(ext.max()), 1e-300))
    if flat.size == 0:
        raise ValueError(
            f"points must be planar for a Domain2D: an (N, 2) array or points with one constant coordinate "
            f"(x, y or z), got extents {ext.round(6).tolist()} in x, y, z"
        )
    keep = [a for a in range(3) if a != flat[-1]]
    return np.ascontiguousarray(pts[:, keep])


class Domain2D(OperatorSet):
    """Gradient, divergence and Laplacian on points of a planar domain.

    Parameters
    ----------
    points : array_like (N, 2), or planar point-like input
        An (N, 2) array, or anything :func:`~manifold_sph.as_cloud` takes (an (N, 3) array,
        a file, a mesh) whose points have one constant coordinate: the other two are used.
    scheme, kernel, neighbors, h, area, max_condition
        As for :class:`~manifold_sph.Surface`. ``area="geometric"`` uses the
        rectangle ``bounds``.
    bounds : (xmin, xmax, ymin, ymax), optional
        The rectangle the points fill; required by ``mirror=True`` and
        ``area="geometric"``.
    mirror : bool
        Add ghost copies of the strips of width ``kappa h`` along each side,
        translated periodically (docs/method.md section 3): the domain behaves as a
        periodic one, which suits periodic functions.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Domain2D
    >>> rng = np.random.default_rng(0)
    >>> p = rng.uniform(-1, 1, size=(800, 2))
    >>> d = Domain2D(p, scheme="msph")
    >>> f = p[:, 0] ** 2 + p[:, 0] * p[:, 1]      # msph is exact on quadratics
    >>> bool(np.allclose(d.laplacian(f), 2.0, atol=1e-8))
    True
    """

    _dim = 2

    def __init__(
        self,
        points: ArrayLike,
        *,
        scheme: str | Scheme = "msph",
        kernel: str | Kernel | type[Kernel] = "quintic",
        neighbors: int | None = None,
        h: float | str | ArrayLike | None = None,
        area: str = "numerical",
        bounds: Sequence[float] | None = None,
        mirror: bool = False,
        max_condition: float = 1e8,
    ) -> None:
        pts = planar_points(points)
        if pts.shape[0] < 10:
            raise ValueError(f"points must hold at least 10 points, got {pts.shape[0]}")
        if np.unique(pts, axis=0).shape[0] != pts.shape[0]:
            raise ValueError(
                f"points must be distinct, but {pts.shape[0] - np.unique(pts, axis=0).shape[0]} point(s) duplicate others"
            )
        check_spread("points", pts)
        self._points = pts
        self._resolve(kernel, scheme, neighbors, max_condition)
        self.bounds = None if bounds is None else _check_bounds(bounds)
        self.mirror = bool(mirror)
        if self.bounds is not None:
            x0, x1, y0, y1 = self.bounds
            outside = (pts[:, 0] < x0) | (pts[:, 0] > x1) | (pts[:, 1] < y0) | (pts[:, 1] > y1)
            if outside.any():
                raise ValueError(f"points must lie inside bounds {self.bounds}, but {int(outside.sum())} lie outside")
        if self.mirror and self.bounds is None:
            raise ValueError("mirror=True needs bounds=(xmin, xmax, ymin, ymax): the rectangle to repeat periodically")
        hv = self._smoothing_length(h, pts, build_tree(pts))
        n = pts.shape[0]
        columns = None
        cand = pts
        if self.mirror:
            assert self.bounds is not None  # refused above
            ghosts, owner = mirror_ghosts(pts, self.bounds, self.kernel.support * float(np.max(hv)))
            cand = np.concatenate([pts, ghosts])
            owner = np.concatenate([np.arange(n), owner])
        self._cand, self._owner = cand, (owner if self.mirror else None)
        nb = find_neighbors(pts, h=hv, support=self.kernel.support, candidates=cand)
        self._check_isolated(nb, "increase neighbors or h")
        if self.mirror:
            columns = owner[nb.indices]
        xy = cand[nb.indices] - pts[nb.rows]
        total_area = None
        if self.bounds is not None:
            x0, x1, y0, y1 = self.bounds
            total_area = (x1 - x0) * (y1 - y0)
        frames = np.broadcast_to(np.eye(2), (n, 2, 2))
        self._setup(nb, xy, frames, area, total_area, columns=columns)

    def _wider_candidates(self, rows: np.ndarray):
        """The ``_WIDER_K`` nearest candidates (ghosts included) of ``rows``."""
        k = min(self._WIDER_K, self._cand.shape[0])
        dist, idx = build_tree(self._cand).query(self._points[rows], k=k)
        xy = self._cand[idx] - self._points[rows][:, None, :]
        cols = idx if self._owner is None else self._owner[idx]
        indptr = np.arange(0, rows.size * k + 1, k)
        radius = dist[:, -1] if k < self._cand.shape[0] else np.full(rows.size, np.inf)
        return indptr, xy.reshape(-1, 2), cols.ravel(), radius

    @property
    def points(self) -> np.ndarray:
        """(N, 2) coordinates."""
        return self._points

    def __repr__(self) -> str:
        return (
            f"Domain2D(n_points={self.n_points}, scheme={self.scheme.name!r}, kernel={self.kernel.name!r}, "
            f"mirror={self.mirror}, area={self._area_args[0]!r})"
        )
