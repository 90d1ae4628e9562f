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
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ..exceptions import ManifoldSPHWarning
from .._validation import check_in, check_output_path, check_real_array
from .convert import cloud_arrays, mesh_vertex_normals, usable_normals
from .io_read import ReadError, read_format, read_las_chunks
from .io_write import atomic_target, write_format
from ..pointcloud import PointCloud

__all__ = [
    "ReadError",
    "FORMATS",
    "read",
    "write",
    "read_mesh",
    "read_las_chunks",
]

#: Extension -> format name.
FORMATS = {
    ".ply": "ply",
    ".pcd": "pcd",
    ".xyz": "xyz",
    ".txt": "xyz",
    ".csv": "csv",
    ".pts": "pts",
    ".obj": "obj",
    ".npy": "npy",
    ".npz": "npz",
    ".las": "las",
    ".laz": "laz",
    ".e57": "e57",
    ".vtk": "vtk",
    ".vtp": "vtk",
}

#: Archive and compression extensions: reading them needs unpacking first.
_ARCHIVES = {".zip", ".gz", ".tgz", ".bz2", ".xz", ".7z", ".rar", ".tar", ".zst", ".lzma"}


#: Magic bytes at the start of a file -> its format (binary formats and headed text formats).
_MAGIC = ((b"ply\n", "ply"), (b"ply\r\n", "ply"), (b"\x93NUMPY", "npy"), (b"PK\x03\x04", "npz"), (b"LASF", "las"),
          (b"ASTM-E57", "e57"), (b"# vtk DataFile", "vtk"))


def _sniff(path: Path) -> str | None:
    """The format a file's first bytes announce, or None (plain text, unknown)."""
    with open(path, "rb") as fh:
        head = fh.read(64)
    for magic, fmt in _MAGIC:
        if head.startswith(magic):
            return fmt
    if head.lstrip().startswith(b"<?xml") and b"VTKFile" in head or head.lstrip().startswith(b"<VTKFile"):
        return "vtk"
    return None


def _check_content(path: Path, fmt: str) -> None:
    """Refuse a file whose first bytes announce another format than ``fmt`` (a misnamed file),
    naming the format it looks like, instead of a confusing parse error."""
    seen = _sniff(path)
    same = {"las": {"las", "laz"}, "npz": {"npz"}, "npy": {"npy"}}.get(seen, {seen})
    if seen is not None and fmt not in same:
        raise ReadError(path, f"its first bytes are those of a {seen.upper()} file, not {fmt.upper()}; "
                              f"rename it or pass format={seen!r}")


def _format_of(path: Path, format: str | None) -> str:
    if format is not None:
        check_in("format", format, set(FORMATS.values()))
        return format
    ext = path.suffix.lower()
    if ext in _ARCHIVES:
        raise ValueError(
            f"{str(path)!r} is a compressed file or archive ({ext}); unpack it and read the point-cloud file "
            f"inside (formats: {sorted(set(FORMATS.values()))})"
        )
    if ext not in FORMATS:
        raise ValueError(
            f"cannot tell the format of {str(path)!r} from its extension {ext!r}; "
            f"pass format= one of {sorted(set(FORMATS.values()))}"
        )
    return FORMATS[ext]




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
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such file: {str(path)!r}")
    fmt = _format_of(path, format)
    if fmt in ("ply", "obj"):
        try:
            pts, _, _, faces = read_format(path, fmt, True)
        except (UnicodeDecodeError, IndexError, KeyError, EOFError) as exc:
            raise ReadError(path, f"malformed {fmt.upper()} file ({type(exc).__name__}: {exc})") from None
    elif fmt == "vtk":
        import pyvista as pv

        try:
            mesh = pv.read(str(path)).extract_surface().triangulate()
        except Exception as exc:  # pyvista/vtk raise many types
            raise ReadError(path, f"pyvista could not read it ({type(exc).__name__}: {exc})") from None
        pts, faces = np.asarray(mesh.points, np.float64), np.asarray(mesh.faces).reshape(-1, 4)[:, 1:]
    else:
        raise ValueError(f"read_mesh supports ply, obj and vtk files, got format {fmt!r}")
    faces = np.zeros((0, 3), dtype=np.int64) if faces is None else np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    return pts, faces


def read(path: str | os.PathLike[str], *, format: str | None = None, normals: str = "file", duplicates: str = "error",
         return_fields: bool = False) -> PointCloud | tuple[PointCloud, dict[str, np.ndarray]]:
    """Read a point cloud file.

    Parameters
    ----------
    path : str or Path
    format : str, optional
        One of ``ply, pcd, xyz, csv, pts, obj, npy, npz, las, laz, e57, vtk`` (default:
        from the extension).
    normals : {"file", "mesh", "none"}
        "file": the normals stored in the file, if any (all-zero placeholders
        count as none); "mesh": area-weighted vertex normals of the file's faces
        (PLY, OBJ, VTK), vertices in no face are dropped and ``fields["index"]``
        keeps the original indices; "none": ignore stored normals.
    duplicates : {"error", "merge"}
        Repeated points are rejected by :class:`~manifold_sph.PointCloud`;
        "merge" merges exact repeats first (:func:`manifold_sph.scans.cleaning.merge_duplicates`,
        the normals averaged), records the original indices in ``fields["index"]``
        and reports how many were merged in a :class:`~manifold_sph.ManifoldSPHWarning`.
    return_fields : bool
        Also return a dict of the other per-point arrays (colours, intensities...).

    Returns
    -------
    PointCloud, or (PointCloud, dict) if ``return_fields``

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
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such file: {str(path)!r}")
    if path.is_dir():
        raise ReadError(path, "it is a folder, not a file")
    if not path.is_file():
        raise ReadError(path, "it is not a regular file")
    fmt = _format_of(path, format)
    check_in("normals", normals, {"file", "mesh", "none"})
    check_in("duplicates", duplicates, {"error", "merge"})
    want_faces = normals == "mesh"
    if want_faces and fmt not in ("ply", "obj", "vtk"):
        raise ValueError(f"normals='mesh' needs a mesh file (ply, obj, vtk), got format {fmt!r}")
    _check_content(path, fmt)
    try:
        pts, nrm, fields, faces = read_format(path, fmt, want_faces)
        if want_faces and fmt == "vtk":
            faces = read_mesh(path, format="vtk")[1]
    except ReadError:
        raise
    except (UnicodeDecodeError, IndexError, KeyError, ValueError, TypeError, EOFError, OSError) as exc:
        raise ReadError(path, f"malformed {fmt.upper()} file ({type(exc).__name__}: {exc})") from None
    pts = np.asarray(pts, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0:
        raise ReadError(path, f"no points found (shape {pts.shape})")
    if not np.all(np.isfinite(pts)):
        bad = int((~np.isfinite(pts).all(axis=1)).sum())
        raise ReadError(path, f"{bad} point(s) have NaN or inf coordinates")
    fields = {k: np.asarray(v) for k, v in fields.items()}
    if normals == "none":
        nrm = None
    elif normals == "mesh":
        if faces is None or len(faces) == 0:
            raise ReadError(path, "normals='mesh' was asked but the file holds no faces")
        faces = np.asarray(faces, dtype=np.int64)
        if faces.size and (faces.min() < 0 or faces.max() >= len(pts)):
            raise ReadError(path, f"a face refers to a vertex outside 0..{len(pts) - 1}")
        vn = mesh_vertex_normals(pts, faces)
        keep = np.linalg.norm(vn, axis=1) > 0
        idx = np.flatnonzero(keep)
        pts, nrm = pts[keep], vn[keep]
        fields = {k: v[keep] for k, v in fields.items() if len(v) == len(keep)}
        fields["index"] = idx
    else:
        nrm = usable_normals(nrm)
    if duplicates == "merge":
        from .cleaning import merge_duplicates

        res = merge_duplicates(pts, nrm, tolerance=0.0)
        base = fields.get("index", np.arange(len(res.keep_mask)))
        fields = {k: (v[res.keep_mask] if len(v) == len(res.keep_mask) else v) for k, v in fields.items()}
        fields["index"] = base[res.keep_mask]
        merged = int((~res.keep_mask).sum())
        if merged:
            warnings.warn(
                f"read {str(path)!r}: merged {merged} exact duplicate point(s) into the first of each group "
                f"({len(res.points)} points kept; fields['index'] holds their original indices)",
                ManifoldSPHWarning,
                stacklevel=2,
            )
        pts, nrm = res.points, res.normals
    try:
        cloud = PointCloud(pts, nrm)
    except ValueError as exc:
        msg = str(exc).replace("merge duplicates first", "pass duplicates='merge' to merge exact repeats")
        raise ReadError(path, msg) from None
    return (cloud, fields) if return_fields else cloud


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
    fmt = _format_of(path, format)
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
