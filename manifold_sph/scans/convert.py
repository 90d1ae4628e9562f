"""Conversions between point clouds and PyVista, trimesh and Open3D objects, and mesh vertex normals.

:func:`to_pyvista` / :func:`from_pyvista`, :func:`to_trimesh` / :func:`from_trimesh`,
:func:`to_open3d` / :func:`from_open3d`. The libraries are imported only inside these functions.
"""

from __future__ import annotations

from typing import TYPE_CHECKING
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_points, check_real_array
from ..pointcloud import PointCloud
from .io_read import from_pv_mesh

if TYPE_CHECKING:  # the interchange libraries load only inside the functions that use them
    import open3d as o3d
    import pyvista as pv
    import trimesh

__all__ = [
    "cloud_arrays",
    "usable_normals",
    "mesh_vertex_normals",
    "to_pyvista",
    "from_pyvista",
    "to_trimesh",
    "from_trimesh",
    "to_open3d",
    "from_open3d",
]


def usable_normals(normals):
    """Normals from a file, or None when they are absent or all zero (placeholders)."""
    if normals is None:
        return None
    normals = np.asarray(normals, dtype=np.float64)
    if not np.all(np.isfinite(normals)) or not np.any(normals):
        return None
    return normals


def mesh_vertex_normals(vertices: ArrayLike, faces: ArrayLike) -> np.ndarray:
    """Area-weighted vertex normals of a triangle mesh (zero for vertices in no face).

    Parameters
    ----------
    vertices : array_like, shape (N, 3)
    faces : array_like of int, shape (F, 3)

    Returns
    -------
    ndarray, shape (N, 3)
        Unit normals, or zero rows for unreferenced vertices.

    Examples
    --------
    >>> import numpy as np
    >>> v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]])
    >>> mesh_vertex_normals(v, [[0, 1, 2]]).tolist()
    [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # |fn| = 2 * area
    vn = np.zeros_like(v)
    for a in range(3):
        np.add.at(vn, f[:, a], fn)
    norm = np.linalg.norm(vn, axis=1)
    ok = norm > 0
    vn[ok] /= norm[ok, None]
    return vn


def cloud_arrays(cloud):
    """Points and normals (or None) of a PointCloud or an (N, 3) array: real, finite, non-empty."""
    if isinstance(cloud, PointCloud):
        return cloud.points, cloud.normals
    check_real_array("cloud", cloud)
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
    """A ``pyvista.PolyData`` of the points (vertex cells), normals as point data ``Normals``.

    Examples
    --------
    >>> from manifold_sph.reference import shapes
    >>> mesh = to_pyvista(shapes.sphere(30), {"u": list(range(30))})
    >>> mesh.n_points, sorted(mesh.point_data.keys())
    (30, ['Normals', 'u'])
    """
    import pyvista as pv

    pts, nrm = cloud_arrays(cloud)
    mesh = pv.PolyData(pts.copy())
    if nrm is not None:
        mesh.point_data["Normals"] = nrm
    for name, arr in (fields or {}).items():
        a = np.asarray(arr)
        if a.shape[:1] != (pts.shape[0],):
            raise ValueError(f"field {name!r} must have {pts.shape[0]} rows, got shape {a.shape}")
        mesh.point_data[name] = a
    return mesh


def from_pyvista(mesh: pv.DataSet, *, return_fields: bool = False) -> PointCloud | tuple[PointCloud, dict[str, np.ndarray]]:
    """A PointCloud from any ``pyvista.DataSet`` (points; point data ``Normals`` if present)."""
    if not hasattr(mesh, "points") or not hasattr(mesh, "point_data"):
        raise TypeError(f"mesh must be a pyvista DataSet, got {type(mesh).__name__}")
    pts, nrm, fields = from_pv_mesh(mesh)
    cloud = PointCloud(pts, usable_normals(nrm))
    return (cloud, fields) if return_fields else cloud


def to_trimesh(cloud: PointCloud | ArrayLike) -> trimesh.PointCloud:
    """A ``trimesh.PointCloud``; normals (if any) in ``metadata["normals"]``."""
    import trimesh

    pts, nrm = cloud_arrays(cloud)
    pc = trimesh.PointCloud(pts.copy())
    if nrm is not None:
        pc.metadata["normals"] = nrm.copy()
    return pc


def from_trimesh(obj: trimesh.Trimesh | trimesh.PointCloud, *, normals: bool = True) -> PointCloud:
    """A PointCloud from a ``trimesh.Trimesh`` (vertices, vertex normals) or ``trimesh.PointCloud``.

    ``normals=False`` drops them; a Trimesh's vertices in no face are dropped when
    ``normals=True`` (they have no normal).
    """
    import trimesh

    if isinstance(obj, trimesh.Trimesh):
        pts = np.asarray(obj.vertices, dtype=np.float64)
        if not normals:
            return PointCloud(pts)
        vn = mesh_vertex_normals(pts, np.asarray(obj.faces))
        keep = np.linalg.norm(vn, axis=1) > 0
        return PointCloud(pts[keep], vn[keep])
    if isinstance(obj, trimesh.PointCloud):
        pts = np.asarray(obj.vertices, dtype=np.float64)
        nrm = obj.metadata.get("normals") if normals else None
        return PointCloud(pts, usable_normals(nrm))
    raise TypeError(f"obj must be a trimesh.Trimesh or trimesh.PointCloud, got {type(obj).__name__}")


def to_open3d(cloud: PointCloud | ArrayLike) -> o3d.geometry.PointCloud:
    """An ``open3d.geometry.PointCloud`` with normals if the cloud has them."""
    import open3d as o3d

    pts, nrm = cloud_arrays(cloud)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.array(pts, dtype=np.float64)))
    if nrm is not None:
        pc.normals = o3d.utility.Vector3dVector(np.array(nrm, dtype=np.float64))
    return pc


def from_open3d(pc: o3d.geometry.PointCloud | o3d.t.geometry.PointCloud | o3d.geometry.TriangleMesh, *,
                return_fields: bool = False) -> PointCloud | tuple[PointCloud, dict[str, np.ndarray]]:
    """A PointCloud from an open3d point cloud (legacy ``open3d.geometry.PointCloud`` or tensor
    ``open3d.t.geometry.PointCloud``) or the vertices of a ``TriangleMesh``.

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
    import open3d as o3d

    fields = {}
    if isinstance(pc, o3d.geometry.TriangleMesh):
        pts = np.asarray(pc.vertices, dtype=np.float64)
        nrm = np.asarray(pc.vertex_normals, dtype=np.float64) if pc.has_vertex_normals() else None
        if pc.has_vertex_colors():
            fields = dict(zip(("red", "green", "blue"), np.asarray(pc.vertex_colors).T))
    elif isinstance(pc, o3d.geometry.PointCloud):
        pts = np.asarray(pc.points, dtype=np.float64)
        nrm = np.asarray(pc.normals, dtype=np.float64) if pc.has_normals() else None
        if pc.has_colors():
            fields = dict(zip(("red", "green", "blue"), np.asarray(pc.colors).T))
    elif isinstance(pc, o3d.t.geometry.PointCloud):
        if "positions" not in pc.point:
            raise ValueError("pc holds no points (no 'positions' attribute)")
        pts = pc.point.positions.numpy().astype(np.float64)
        nrm = pc.point.normals.numpy().astype(np.float64) if "normals" in pc.point else None
        for key in pc.point:
            if key in ("positions", "normals"):
                continue
            a = pc.point[key].numpy()
            a = a.reshape(len(a), -1)
            if key == "colors" and a.shape[1] in (3, 4):
                fields.update(zip(("red", "green", "blue", "alpha"), a.T))
            elif a.shape[1] == 1:
                fields[key] = a[:, 0]
            else:
                fields[key] = a
    else:
        raise TypeError(f"pc must be an open3d PointCloud (legacy or tensor) or TriangleMesh, got {type(pc).__name__}")
    cloud = PointCloud(pts, usable_normals(nrm))
    return (cloud, fields) if return_fields else cloud
