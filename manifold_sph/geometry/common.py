"""What the geometry modules share: the surface check, point-like input and the length scale.

Every public function of :mod:`manifold_sph.geometry` takes a
:class:`~manifold_sph.Surface`; the geodesic solver and the smoother also take bare points
(anything :func:`as_cloud_points` accepts). All of them compute in units of the cloud's own
size (:func:`length_scale`), so a cloud scaled by ``1e-100`` or ``1e100`` gives the same
numbers times the scale.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .._validation import as_points
from ..operators import OperatorSet

if TYPE_CHECKING:
    from typing_extensions import TypeIs  # typing.TypeIs from Python 3.13; type checkers only

    from ..surface import Surface

__all__ = ["SCALE_RANGE", "WAVEFRONT_SCALE_RANGE", "as_cloud_points", "check_scale", "check_surface", "is_surface", "length_scale"]

#: Extent of the coordinates (largest bounding-box side) accepted by what uses a Surface's mass matrix
#: (cell areas, ``L^2``) or squared lengths: the heat method, the vector heat method, smoothing. Beyond
#: it areas under- or overflow in float64 (1e-160 squared is subnormal).
SCALE_RANGE = (1e-140, 1e140)
#: Extent accepted by the wavefront geodesics, which work on the cloud divided by its extent.
WAVEFRONT_SCALE_RANGE = (1e-290, 1e290)


def is_surface(obj: Any) -> TypeIs[Surface]:
    """Whether ``obj`` is a :class:`~manifold_sph.Surface` (an operator set on a surface in 3-D)."""
    return isinstance(obj, OperatorSet) and obj.dim == 3 and hasattr(obj, "normals")


def check_surface(surface: Any, name: str = "surface") -> Surface:
    """``surface`` itself if it is a :class:`~manifold_sph.Surface`, else a TypeError naming what it got."""
    if not is_surface(surface):
        raise TypeError(f"{name} must be a Surface, got {type(surface).__name__}")
    return surface


def as_cloud_points(cloud: Any, name: str = "cloud") -> tuple[np.ndarray, np.ndarray | None]:
    """Points (N, 3) and normals (N, 3) or None of a Surface, a PointCloud or point-like input.

    Point-like input: an array of shape (N, 3), a :class:`~manifold_sph.PointCloud`, or any
    object :class:`~manifold_sph.PointCloud` accepts (a path, an Open3D / PyVista / trimesh
    object, when that coercion is available).
    """
    if is_surface(cloud):
        return cloud.points, cloud.normals
    from ..pointcloud import PointCloud

    if isinstance(cloud, PointCloud):
        return cloud.points, cloud.normals
    if isinstance(cloud, (np.ndarray, list, tuple)):
        return as_points(name, cloud), None
    try:
        pc = PointCloud(cloud)
    except (TypeError, ValueError) as exc:
        raise TypeError(
            f"{name} must be a Surface, a PointCloud or points of shape (N, 3), got {type(cloud).__name__}"
        ) from exc
    return pc.points, pc.normals


def length_scale(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and size of a cloud: ``(centre (3,), L)``, ``L`` the largest side of its bounding box.

    Computed without squares, so it is exact for coordinates anywhere in float64's range;
    ``(points - centre) / L`` lies in ``[-1/2, 1/2]^3``.
    """
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = lo + 0.5 * (hi - lo)
    return centre, float(np.max(hi - lo))


def check_scale(points: np.ndarray, what: str, limits: tuple[float, float] = SCALE_RANGE) -> tuple[np.ndarray, float]:
    """:func:`length_scale`, refusing clouds whose size lies outside ``limits`` (a ValueError)."""
    with np.errstate(over="ignore", invalid="ignore"):
        centre, L = length_scale(points)
    if not (limits[0] <= L <= limits[1]):
        raise ValueError(
            f"{what}: the cloud's extent (largest bounding-box side) must lie in [{limits[0]:g}, "
            f"{limits[1]:g}] (lengths or areas under- or overflow in float64 beyond), got {L:g}; "
            "rescale the points (e.g. divide by their extent) and scale the result back"
        )
    return centre, L
