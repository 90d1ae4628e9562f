"""Reading and writing point clouds (conversions to other libraries: :mod:`.convert`).

Formats (chosen from the file extension, or ``format=``):

==========  ======================================  =====================================
format      read                                    write
==========  ======================================  =====================================
ply         ascii, binary little/big endian;        ascii or binary little endian
            vertex x y z, nx ny nz, other scalar
            properties (colours...) as fields;
            faces / triangle strips for mesh
            normals
pcd         ascii, binary, binary_compressed (via   ascii or binary
            open3d); packed ``rgb`` as red, green,
            blue fields
xyz, txt,   columns x y z [nx ny nz or r g b]         x y z [nx ny nz] [fields], header
csv         [more]; a header line of names is       line of names for csv
            recognised, so is a point count first
pts         x y z [intensity] [r g b] (Leica)       as xyz
obj         ``v`` (x y z, or x y z r g b colours    ``v`` (with colours) and ``vn``
            as fields), ``vn`` when one per         lines
            vertex; ``f`` for mesh normals
npy, npz    (N, 3) or (N, 6); npz keys ``points``,  same
            ``normals`` and fields
las, laz    via laspy: intensity, classification,   LAS 1.4 (laz: compressed); fields
            colours, returns, extra bytes as        of those names to the standard
            fields; :func:`read_las_chunks` for     dimensions, others and normals as
            files larger than memory                extra bytes
e57         via pye57 (optional: ``pip install      not written
            pye57``): every scan in world
            coordinates, intensity and colours
vtk, vtp    via pyvista (point data ``Normals``)    via pyvista (legacy ascii .vtk keeps
                                                    about 11 significant digits)
==========  ======================================  =====================================

Malformed or unreadable files raise :class:`ReadError` (a ``ValueError``) whose
message names the file and the problem: a body longer or shorter than its
header declares, a row with more values than the header's properties, a face
index outside the vertices are errors, never cut or wrapped silently. A missing
file raises ``FileNotFoundError``.

Writing goes to a temporary file in the same folder, renamed to the exact name
given once complete (never a truncated file, never a suffix appended by numpy),
and never overwrites an existing file unless ``overwrite=True``. Points must be
finite and real, and the cloud non-empty.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Literal, overload

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_in, check_output_path, check_real_array
from ..pointcloud import PointCloud
from .convert import cloud_arrays
from .io_lidar import read_las_chunks
from .io_read import ReadError
from .io_write import atomic_target, write_format
from .sources import FORMATS, announce, file_source, format_of, settle

__all__ = [
    "ReadError",
    "FORMATS",
    "read",
    "write",
    "read_mesh",
    "read_las_chunks",
]


# ----------------------------------------------------------------------------
# public API
# ----------------------------------------------------------------------------
def read_mesh(path: str | os.PathLike[str], *, format: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of a mesh file (PLY faces or triangle strips, OBJ faces, VTK polygons).

    Returns
    -------
    vertices : ndarray, shape (N, 3)
    faces : ndarray of int, shape (F, 3)
        Empty (0, 3) when the file holds no faces. Every index lies in ``[0, N)``
        (an index outside the vertices is a :class:`ReadError`).

    Examples
    --------
    >>> import tempfile, os
    >>> path = os.path.join(tempfile.mkdtemp(), "t.obj")
    >>> _ = open(path, "w").write("v 0 0 0\\nv 1 0 0\\nv 0 1 0\\nv 1 1 0\\nf 1 2 4 3\\n")
    >>> v, f = read_mesh(path)
    >>> v.shape, f.tolist()
    ((4, 3), [[0, 1, 3], [0, 3, 2]])
    """
    fmt = format_of(path, format)
    if fmt not in ("ply", "obj", "vtk"):
        raise ValueError(f"read_mesh supports ply, obj and vtk files, got format {fmt!r}")
    src = file_source(path, format=fmt, faces=True)
    faces = np.zeros((0, 3), dtype=np.int64) if src.faces is None else src.faces
    return src.points, faces


@overload
def read(path: str | os.PathLike[str], *, format: str | None = None, normals: str = "auto",
         duplicates: str = "merge", return_fields: Literal[False] = False) -> PointCloud: ...


@overload
def read(path: str | os.PathLike[str], *, format: str | None = None, normals: str = "auto",
         duplicates: str = "merge", return_fields: Literal[True]) -> tuple[PointCloud, dict[str, np.ndarray]]: ...


@overload
def read(path: str | os.PathLike[str], *, format: str | None = None, normals: str = "auto",
         duplicates: str = "merge", return_fields: bool = False) -> PointCloud | tuple[PointCloud, dict[str, np.ndarray]]: ...


def read(path: str | os.PathLike[str], *, format: str | None = None, normals: str = "auto",
         duplicates: str = "merge", return_fields: bool = False) -> PointCloud | tuple[PointCloud, dict[str, np.ndarray]]:
    """Read a point cloud file.

    Parameters
    ----------
    path : str or Path
    format : str, optional
        One of ``ply, pcd, xyz, csv, pts, obj, npy, npz, las, laz, e57, vtk`` (default:
        from the extension).
    normals : {"auto", "file", "mesh", "none"}
        "auto" (default): the normals stored in the file (all-zero placeholders count as
        none), else, for a mesh (PLY, OBJ, VTK faces), area-weighted vertex normals of its
        faces when every point is in a face and the faces are wound consistently (turned
        outward), else none (a Surface estimates them). "file": the stored normals only;
        "mesh": from the faces (required), vertices in no face dropped, ``fields["index"]``
        keeping the original indices; "none": no normals.
    duplicates : {"merge", "error"}
        "merge" (default): exact repeats of a point are merged into the first of each group
        (normals averaged), ``fields["index"]`` holds the original indices; "error": refuse
        a file with repeats (:class:`ReadError` giving the count).
    return_fields : bool
        Also return a dict of the other per-point arrays (colours, intensities...).

    Returns
    -------
    PointCloud, or (PointCloud, dict) if ``return_fields``

    Warns
    -----
    ManifoldSPHWarning
        One, when duplicates were merged or a mesh's faces were dropped (with the counts).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ReadError
        A ``ValueError`` naming the file and the problem, for malformed files.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(50)
    >>> path = os.path.join(tempfile.mkdtemp(), "s.ply")
    >>> write(path, cloud)
    >>> back = read(path)
    >>> bool(np.array_equal(back.points, cloud.points)), back.normals is not None
    (True, True)
    """
    check_in("normals", normals, {"auto", "file", "mesh", "none"})
    check_in("duplicates", duplicates, {"error", "merge"})
    fmt = format_of(path, format)
    if normals == "mesh" and fmt not in ("ply", "obj", "vtk"):
        raise ValueError(f"normals='mesh' needs a mesh file (ply, obj, vtk), got format {fmt!r}")
    src = file_source(path, format=fmt, faces=normals in ("auto", "mesh"))
    try:
        src, note = settle(src, normals=normals, duplicates=duplicates)
        cloud = PointCloud(src.points, src.normals)
    except ValueError as exc:
        raise ReadError(Path(path), str(exc).replace(f"{src.label} ", "it ")) from None
    announce(note)
    return (cloud, src.fields) if return_fields else cloud


def _check_fields(fields, n: int, flatten: bool) -> dict:
    """Per-point fields as arrays of ``n`` rows: real, names usable in the format; (n, k) fields
    split into ``name_0, name_1...`` when ``flatten``."""
    if fields is None:
        return {}
    if not isinstance(fields, dict):
        raise TypeError(f"fields must be a dict of name -> array, got {type(fields).__name__}")
    out = {}
    for name, arr in fields.items():
        if flatten and (not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name)):
            raise ValueError(f"field names must be identifiers, got {name!r}")
        if not flatten and name in ("points", "normals", "Normals"):
            raise ValueError(f"field name {name!r} is reserved")
        a = np.asarray(check_real_array(f"field {name!r}", arr))
        if a.dtype.kind not in "biuf":
            raise TypeError(f"field {name!r} must be numeric, got dtype {a.dtype}")
        if a.shape[:1] != (n,) or a.ndim > 2:
            raise ValueError(f"field {name!r} must have shape ({n},) or ({n}, k), got shape {a.shape}")
        if flatten and a.ndim == 2:
            for k in range(a.shape[1]):
                out[f"{name}_{k}"] = a[:, k]
        else:
            out[str(name)] = a
    return out


def write(path: str | os.PathLike[str], cloud: PointCloud | ArrayLike, fields: Mapping[str, ArrayLike] | None = None, *,
          format: str | None = None, binary: bool = True, overwrite: bool = False) -> None:
    """Write a point cloud (points, normals if any, and per-point fields).

    The file is written under a temporary name in the same folder and renamed to
    exactly ``path`` once complete: an interrupted write leaves no partial file,
    and no suffix is ever appended (``write("data.bin", c, format="npy")`` writes
    ``data.bin``).

    Parameters
    ----------
    path : str or Path
    cloud : PointCloud or array_like, shape (N, 3)
        At least one point; finite, real coordinates.
    fields : dict of str -> array_like, shape (N,) or (N, k), optional
        Per-point real data (e.g. a heat solution, colours ``red, green, blue``).
        Vector fields are split into ``name_0, name_1, ...`` columns except in
        VTK, NPZ files.
    format : str, optional
        Default: from the extension.
    binary : bool
        Binary PLY / PCD / VTK (ascii otherwise).
    overwrite : bool
        Replace an existing file (default: refuse with ``FileExistsError``).

    Raises
    ------
    FileExistsError
        ``path`` exists and ``overwrite`` is false.
    IsADirectoryError, FileNotFoundError
        ``path`` is a folder, or its folder does not exist.
    TypeError, ValueError
        Complex, masked, non-finite or empty input; fields of the wrong length.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(20)
    >>> path = os.path.join(tempfile.mkdtemp(), "s.csv")
    >>> write(path, cloud, fields={"u": cloud.points[:, 2]})
    >>> open(path).readline().strip()
    'x,y,z,nx,ny,nz,u'
    """
    path = Path(path)
    check_output_path("path", path, overwrite)
    fmt = format_of(path, format)
    if fmt == "e57":
        raise ValueError("E57 files are read, not written; write las, laz, ply or pcd instead")
    pts, nrm = cloud_arrays(cloud)
    n = pts.shape[0]
    keep_shape = fmt in ("npz", "vtk")
    checked = _check_fields(fields, n, flatten=not keep_shape)
    flat = {} if keep_shape else checked
    raw_fields = checked if keep_shape else {}
    suffix = {"vtk": path.suffix if path.suffix.lower() in (".vtk", ".vtp") else ".vtk"}.get(fmt, "")
    cloud_for_vtk = cloud if isinstance(cloud, PointCloud) else pts
    with atomic_target(path, overwrite, suffix) as tmp:
        write_format(tmp, fmt, pts, nrm, flat, raw_fields, binary, cloud_for_vtk)
