"""Validated point clouds, and :func:`as_cloud`: the one way point-like input becomes one.

A :class:`PointCloud` holds points (N, 3) and optional unit normals (N, 3). Every public
entry point that takes points (``Surface``, ``Domain2D``, ``estimate_normals``, ``write``,
the renderers, ``TiledSurface``...) passes what it is given through :func:`as_cloud`, which
accepts an (N, 3) array, a PointCloud (or anything holding one as ``.cloud``, such as a
Surface), a file path, and Open3D, PyVista (VTK) and trimesh objects.
"""

from __future__ import annotations

import importlib
import os
from typing import TYPE_CHECKING, Any, TypeGuard

import numpy as np
from numpy.typing import ArrayLike

from ._validation import as_points, check_in

__all__ = ["PointCloud", "MIN_POINTS", "as_cloud", "is_point_array", "PointViews"]

#: The smallest cloud accepted: fewer points cannot hold one SPH neighbourhood.
MIN_POINTS = 10


class PointViews:
    """Conversions and pictures of anything with ``points`` (N, 3) and ``normals`` (N, 3) or None.

    Shared by :class:`PointCloud` and :class:`~manifold_sph.Surface`. In a notebook the object
    shows as a picture (:meth:`_repr_png_`); :meth:`show` draws a field.
    """

    if TYPE_CHECKING:  # the subclasses' read-only properties, declared for type checkers only

        @property
        def points(self) -> np.ndarray: ...

        @property
        def normals(self) -> np.ndarray | None: ...

    def to_pyvista(self, fields: Any = None) -> Any:
        """A ``pyvista.PolyData`` of the points (one vertex cell each), normals as point data ``Normals``.

        Parameters
        ----------
        fields : mapping of str -> array_like, shape (N,) or (N, k), or one array, optional
            Per-point data (one array is named ``"field"``).

        Examples
        --------
        >>> from manifold_sph.reference import shapes
        >>> cloud = shapes.sphere(30)
        >>> mesh = cloud.to_pyvista({"z": cloud.points[:, 2]})
        >>> mesh.n_points, sorted(mesh.point_data.keys())
        (30, ['Normals', 'z'])
        """
        import pyvista as pv

        pts = np.asarray(self.points, dtype=np.float64)
        n = len(pts)
        mesh = pv.PolyData(pts.copy())
        if self.normals is not None:
            mesh.point_data["Normals"] = np.array(self.normals, dtype=np.float64)
        if fields is None:
            fields = {}
        elif not hasattr(fields, "items"):
            fields = {"field": fields}
        for name, arr in fields.items():
            a = np.asarray(arr)
            if a.shape[:1] != (n,) or a.ndim > 2:
                raise ValueError(f"field {name!r} must have shape ({n},) or ({n}, k), got shape {a.shape}")
            mesh.point_data[str(name)] = a
        return mesh

    def to_open3d(self) -> Any:
        """An ``open3d.geometry.PointCloud`` of the points, with the normals if there are any."""
        import open3d as o3d

        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.array(self.points, dtype=np.float64)))
        if self.normals is not None:
            pc.normals = o3d.utility.Vector3dVector(np.array(self.normals, dtype=np.float64))
        return pc

    def show(self, field: ArrayLike | None = None, **options: Any) -> Any:
        """A picture of the points, or of ``field`` on them: a :class:`manifold_sph.viz.render.Picture`
        (shown in a notebook; ``.image`` the array, ``.save(path)``). Options as in
        :func:`manifold_sph.viz.render.render_field`.
        """
        # The renderer is the pipeline's last stage: it is named here at call time, so that
        # no module of the core imports it (and importing the package loads no renderer).
        render = importlib.import_module("manifold_sph.viz.render")
        return render.show(self, field, **options)

    def _repr_png_(self) -> bytes | None:
        """The notebook picture (None, so the text repr shows, where rendering is unavailable)."""
        try:
            render = importlib.import_module("manifold_sph.viz.render")
            if not render.rendering_available()[0]:
                return None
            return render.show(self, window_size=(480, 360))._repr_png_()
        except Exception:  # noqa: BLE001 - a notebook display never raises; the text repr remains
            return None


class PointCloud(PointViews):
    """A surface sample: points and (optionally) outward unit normals.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Finite coordinates. Duplicated points are rejected (:func:`as_cloud` merges them
        on request: ``as_cloud(points, duplicates="merge")``).
    normals : array_like, shape (N, 3), optional
        Normals, normalised to unit length on input. Zero normals are rejected.
    geometry : object, optional
        The exact geometry the cloud samples (an implicit shape from
        :mod:`manifold_sph.reference.shapes`), giving exact references. ``None`` for scans.

    Raises
    ------
    ValueError
        On NaN or inf, wrong shapes, zero normals, duplicate points or N < 10.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import PointCloud
    >>> rng = np.random.default_rng(0)
    >>> p = rng.normal(size=(20, 3))
    >>> cloud = PointCloud(p, normals=2 * p)
    >>> len(cloud), bool(np.allclose(np.linalg.norm(cloud.normals, axis=1), 1))
    (20, True)
    """

    def __init__(
        self,
        points: ArrayLike,
        normals: ArrayLike | None = None,
        *,
        geometry: Any = None,
    ) -> None:
        pts = as_points("points", points)
        n = pts.shape[0]
        if n < MIN_POINTS:
            raise ValueError(f"points must hold at least {MIN_POINTS} points, got {n}")
        _check_duplicates(pts)
        self._points = pts.copy()
        self._points.flags.writeable = False
        self._normals = None
        if normals is not None:
            nrm = as_points("normals", normals)
            if nrm.shape[0] != n:
                raise ValueError(f"normals must have shape ({n}, 3) to match points, got shape {nrm.shape}")
            length = np.linalg.norm(nrm, axis=1)
            tiny = length <= 1e-12 * float(length.max())  # relative: uniformly tiny normals are fine
            if tiny.any():
                idx = np.flatnonzero(tiny)
                raise ValueError(
                    f"normals must be non-zero, but {idx.size} normal(s) have zero length or are shorter than "
                    f"1e-12 times the longest (first indices {idx[:5].tolist()})"
                )
            self._normals = nrm / length[:, None]
            self._normals.flags.writeable = False
        #: The exact geometry the cloud samples (a :mod:`manifold_sph.reference.shapes` shape), or None.
        self.geometry: Any = geometry

    @property
    def points(self) -> np.ndarray:
        """(N, 3) float64 coordinates (read-only)."""
        return self._points

    @property
    def normals(self) -> np.ndarray | None:
        """(N, 3) float64 unit normals (read-only), or None."""
        return self._normals

    @property
    def n_points(self) -> int:
        return self._points.shape[0]

    def __len__(self) -> int:
        return self._points.shape[0]

    def __repr__(self) -> str:
        g = self.geometry
        geo = "" if g is None else f", geometry={getattr(g, 'name', type(g).__name__)}"
        return f"PointCloud(n_points={len(self)}, normals={'yes' if self._normals is not None else 'no'}{geo})"


def _check_duplicates(pts: np.ndarray) -> None:
    """Raise ValueError if two rows of ``pts`` are identical, reporting how many.

    Rows are hashed to one 64-bit key each (a sort of N integers); only rows
    whose keys collide are compared exactly (131,072 points: 10 ms; a row-wise comparison of every row takes 27 ms).
    """
    bits = np.ascontiguousarray(pts + 0.0).view(np.uint64)  # + 0.0: -0.0 and 0.0 are the same point
    key = np.zeros(bits.shape[0], dtype=np.uint64)
    for c in range(bits.shape[1]):
        key = (key * np.uint64(0x9E3779B97F4A7C15)) ^ bits[:, c] ^ (bits[:, c] >> np.uint64(29))
    ordered = np.sort(key)  # a plain sort first: 5x faster than the argsort, needed only on a collision
    if not (ordered[1:] == ordered[:-1]).any():
        return
    order = np.argsort(key, kind="stable")
    same = key[order[1:]] == key[order[:-1]]
    if not same.any():
        return
    cand = np.unique(np.concatenate([order[1:][same], order[:-1][same]]))
    _, inverse, counts = np.unique(pts[cand] + 0.0, axis=0, return_inverse=True, return_counts=True)
    extra = int((counts - 1).sum())
    if extra:
        first = cand[np.flatnonzero(counts[inverse.ravel()] > 1)[:6]]
        raise ValueError(
            f"points must be distinct, but {extra} point(s) duplicate others "
            f"(indices involved include {first.tolist()}); merge them with "
            "manifold_sph.as_cloud(points, duplicates='merge')"
        )


def is_point_array(obj: object) -> TypeGuard[ArrayLike]:
    """Whether ``obj`` is plain array data (an ndarray, a list or tuple, or has ``__array__``),
    not a path, a PointCloud or another library's object."""
    from .scans.sources import is_foreign

    if isinstance(obj, (str, bytes, os.PathLike, PointCloud)) or is_foreign(obj):
        return False
    if isinstance(getattr(obj, "cloud", None), PointCloud):
        return False
    return isinstance(obj, (np.ndarray, list, tuple)) or hasattr(obj, "__array__")


def as_cloud(obj: Any, *, normals: ArrayLike | None = None, duplicates: str | None = None) -> PointCloud:
    """A :class:`PointCloud` from anything point-like.

    Parameters
    ----------
    obj : array_like (N, 3), PointCloud, str or os.PathLike, or an Open3D / PyVista / VTK / trimesh object
        - an array: the points (with ``normals`` if given);
        - a PointCloud, or an object holding one as ``.cloud`` (a Surface): that cloud;
        - a path: the file, read by :func:`manifold_sph.read` (any of its formats);
        - ``open3d.geometry.PointCloud`` / ``TriangleMesh`` (and their ``open3d.t`` versions),
          any ``pyvista.DataSet`` (or VTK data object), ``trimesh.Trimesh`` / ``PointCloud`` /
          ``Scene``: their points and normals.

        Without normals of its own, a mesh (file or object) gives area-weighted vertex normals
        of its faces when every point is in a face and the faces are wound consistently (turned
        outward); otherwise the cloud has no normals and a Surface estimates them. The faces
        are not kept: the operators work on the points, which the one warning of the call says.
    normals : array_like, shape (N, 3), optional
        Normals replacing the input's own (N after any merge of duplicates).
    duplicates : {"merge", "error"}, optional
        Exact repeats of a point: "merge" keeps the first of each group (normals averaged)
        and says how many in one :class:`~manifold_sph.ManifoldSPHWarning`; "error" refuses
        them. Default: "merge" for files and other libraries' objects (reading as users expect),
        "error" for arrays (whose rows the caller's own per-point data follow).

    Returns
    -------
    PointCloud
        ``obj`` itself when it is a PointCloud and nothing is changed.

    Raises
    ------
    TypeError
        For an object that is none of these.
    ValueError, FileNotFoundError
        As :class:`PointCloud` and :func:`manifold_sph.read` raise them.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import as_cloud
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(100)
    >>> as_cloud(cloud) is cloud, len(as_cloud(cloud.points))
    (True, 100)
    >>> import pyvista as pv
    >>> as_cloud(pv.Sphere(theta_resolution=8, phi_resolution=8))  # doctest: +SKIP
    PointCloud(n_points=50, normals=yes)
    """
    if duplicates is not None:
        check_in("duplicates", duplicates, {"merge", "error"})
    if isinstance(obj, PointCloud) or isinstance(getattr(obj, "cloud", None), PointCloud):
        cloud = obj if isinstance(obj, PointCloud) else obj.cloud
        if normals is None:
            return cloud
        return PointCloud(cloud.points, normals, geometry=cloud.geometry)
    from .scans import sources

    if isinstance(obj, (str, os.PathLike)):
        src = sources.file_source(obj)
    elif sources.is_foreign(obj):
        src = sources.object_source(obj)
    elif isinstance(obj, bytes):
        raise TypeError("points must be an array, a PointCloud, a path (str), or an Open3D, PyVista or trimesh "
                        "object, got bytes (decode a path first)")
    else:
        if not is_point_array(obj):
            raise TypeError(
                f"points must be an (N, 3) array, a PointCloud, a file path, or an Open3D, PyVista or trimesh "
                f"object, got {type(obj).__module__}.{type(obj).__name__}"
            )
        if duplicates != "merge":
            return PointCloud(obj, normals)
        src = sources.Source(as_points("points", obj), None if normals is None else as_points("normals", normals))
        normals = None
    src, note = sources.settle(src, normals="auto", duplicates=duplicates or "merge")
    cloud = PointCloud(src.points, src.normals if normals is None else normals)
    sources.announce(note)
    return cloud
