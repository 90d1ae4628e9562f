"""Conversions between point clouds and PyVista, trimesh and Open3D objects.

:func:`to_pyvista` / :func:`from_pyvista`, :func:`to_trimesh` / :func:`from_trimesh`,
:func:`to_open3d` / :func:`from_open3d`. The libraries are imported only inside these functions.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_points, check_real_array
from ..pointcloud import PointCloud, PointViews, as_cloud, is_point_array
from .sources import announce, mesh_vertex_normals, object_source, settle

if TYPE_CHECKING:  # the interchange libraries load only inside the functions that use them
    import open3d as o3d
    import pyvista as pv
    import trimesh

__all__ = [
    "cloud_arrays",
    "mesh_vertex_normals",
    "to_pyvista",
    "from_pyvista",
    "to_trimesh",
    "from_trimesh",
    "to_open3d",
    "from_open3d",
]


def cloud_arrays(cloud: object) -> tuple[np.ndarray, np.ndarray | None]:
    """Points and normals (or None) of anything point-like (:func:`~manifold_sph.as_cloud`); an
    array is taken as it is (any number of points, repeats allowed): real, finite, non-empty."""
    if not is_point_array(cloud):
        c = as_cloud(cloud)
        return c.points, c.normals
    check_real_array("cloud", cloud)
    if np.asarray(cloud).dtype == np.bool_:  # a mask passed for the coordinates
        raise TypeError("cloud must be numeric coordinates, got a bool array (a mask?)")
    try:
        pts = np.asarray(cloud, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"cloud must be a PointCloud or an array of shape (N, 3), got {type(cloud).__name__}") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"cloud must be a PointCloud or an array of shape (N, 3), got shape {pts.shape}")
    if pts.shape[0] == 0:
        raise ValueError("cloud must hold at least one point, got an empty array of shape (0, 3)")
    return as_points("cloud", pts), None


def to_pyvista(cloud: PointCloud | ArrayLike, fields: Mapping[str, ArrayLike] | None = None) -> pv.PolyData:
    """A ``pyvista.PolyData`` of the points (vertex cells), normals as point data ``Normals``
    (:meth:`PointCloud.to_pyvista <manifold_sph.pointcloud.PointViews.to_pyvista>` for anything point-like).

    Examples
    --------
    >>> from manifold_sph.reference import shapes
    >>> mesh = to_pyvista(shapes.sphere(30), {"u": list(range(30))})
    >>> mesh.n_points, sorted(mesh.point_data.keys())
    (30, ['Normals', 'u'])
    """
    pts, nrm = cloud_arrays(cloud)
    return _Arrays(pts, nrm).to_pyvista(fields)


class _Arrays(PointViews):
    """Bare arrays (any number of points, repeats allowed) with the conversions of a PointCloud."""

    points: np.ndarray
    normals: np.ndarray | None

    def __init__(self, points, normals):
        self.points, self.normals = points, normals


def _from(obj, return_fields: bool, normals: bool = True):
    src, note = settle(object_source(obj), normals="auto" if normals else "none")
    cloud = PointCloud(src.points, src.normals)
    announce(note)
    return (cloud, src.fields) if return_fields else cloud


def from_pyvista(mesh: pv.DataSet, *, return_fields: bool = False) -> PointCloud | tuple[PointCloud, dict[str, np.ndarray]]:
    """A PointCloud from any ``pyvista.DataSet`` (points; point data ``Normals``, else a PolyData's
    faces for normals, as :func:`~manifold_sph.as_cloud`), and with ``return_fields`` the other point data."""
    if type(mesh).__module__.split(".")[0] not in ("pyvista", "vtk", "vtkmodules"):
        raise TypeError(f"mesh must be a pyvista DataSet, got {type(mesh).__name__}")
    return _from(mesh, return_fields)


def to_trimesh(cloud: PointCloud | ArrayLike) -> trimesh.PointCloud:
    """A ``trimesh.PointCloud``; normals (if any) in ``metadata["normals"]``."""
    import trimesh

    pts, nrm = cloud_arrays(cloud)
    pc = trimesh.PointCloud(pts.copy())
    if nrm is not None:
        pc.metadata["normals"] = nrm.copy()
    return pc


def from_trimesh(obj: trimesh.Trimesh | trimesh.PointCloud, *, normals: bool = True,
                 return_fields: bool = False) -> PointCloud | tuple[PointCloud, dict[str, np.ndarray]]:
    """A PointCloud from a ``trimesh.Trimesh`` (vertices; normals from its faces, as
    :func:`~manifold_sph.as_cloud`), ``trimesh.PointCloud`` (normals in ``metadata["normals"]``)
    or ``trimesh.Scene``. ``normals=False`` leaves the normals out."""
    if type(obj).__module__.split(".")[0] != "trimesh":
        raise TypeError(f"obj must be a trimesh.Trimesh, PointCloud or Scene, got {type(obj).__name__}")
    return _from(obj, return_fields, normals)


def to_open3d(cloud: PointCloud | ArrayLike) -> o3d.geometry.PointCloud:
    """An ``open3d.geometry.PointCloud`` with normals if the cloud has them."""
    pts, nrm = cloud_arrays(cloud)
    return _Arrays(pts, nrm).to_open3d()


def from_open3d(pc: o3d.geometry.PointCloud | o3d.t.geometry.PointCloud | o3d.geometry.TriangleMesh, *,
                return_fields: bool = False) -> PointCloud | tuple[PointCloud, dict[str, np.ndarray]]:
    """A PointCloud from an open3d point cloud (legacy ``open3d.geometry.PointCloud`` or tensor
    ``open3d.t.geometry.PointCloud``) or a ``TriangleMesh`` (its vertex normals, else its faces').

    With ``return_fields`` also a dict of the per-point data: colours as ``red, green,
    blue`` and, for tensor clouds, every custom attribute (intensity, labels...).

    Examples
    --------
    >>> import numpy as np, open3d as o3d
    >>> from manifold_sph.reference import shapes
    >>> pc = o3d.t.geometry.PointCloud(o3d.core.Tensor(shapes.sphere(30).points.copy()))
    >>> pc.point.intensity = o3d.core.Tensor(np.arange(30.0)[:, None])
    >>> cloud, fields = from_open3d(pc, return_fields=True)
    >>> len(cloud), fields["intensity"][:3].tolist()
    (30, [0.0, 1.0, 2.0])
    """
    if type(pc).__module__.split(".")[0] != "open3d":
        raise TypeError(f"pc must be an open3d PointCloud (legacy or tensor) or TriangleMesh, got {type(pc).__name__}")
    return _from(pc, return_fields)
