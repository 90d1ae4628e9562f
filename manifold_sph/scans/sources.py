"""Point-like input as plain arrays: files, other libraries' objects and meshes.

A :class:`Source` is what a file or an object holds: points, normals (or None), triangles
(or None), per-point fields and a label naming it for messages. :func:`file_source` reads one
from a file, :func:`object_source` from an Open3D, PyVista (or VTK) or trimesh object, and
:func:`settle` turns it into the points and normals of a point cloud the way users expect:

- exact duplicate points merged into the first of each group (``duplicates="merge"``,
  the default) or refused (``duplicates="error"``); a mesh's triangles follow the merge;
- normals ``"auto"``: the object's or file's own, else area-weighted vertex normals of its triangles
  when those can be trusted (every vertex in a triangle, one consistent winding; turned
  outward by the signed volume), else none (a :class:`~manifold_sph.Surface` estimates them);
- the triangles are then dropped (the operators work on the points), which the one note
  of the call says, with the merge count.

:func:`manifold_sph.pointcloud.as_cloud` and :func:`manifold_sph.scans.io.read` are built on
these. This module imports no other part of the package but the file parsers
(:mod:`.io_read`), so that the core can read files without an import cycle.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_in

__all__ = [
    "FORMATS",
    "Source",
    "file_source",
    "object_source",
    "is_foreign",
    "settle",
    "mesh_vertex_normals",
    "format_of",
    "announce",
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

#: The libraries whose objects are point-like input (top-level module names).
_FOREIGN = ("open3d", "pyvista", "trimesh", "vtkmodules", "vtk")


@dataclass
class Source:
    """What a file or an object holds, before it becomes a point cloud."""

    points: np.ndarray
    normals: np.ndarray | None = None
    faces: np.ndarray | None = None
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    label: str = "points"


# ----------------------------------------------------------------------------- files
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


def format_of(path: str | os.PathLike[str], format: str | None) -> str:
    """The format name of ``path``: ``format`` if given (checked), else from the extension."""
    path = Path(path)
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


def file_source(path: str | os.PathLike[str], *, format: str | None = None, faces: bool = True) -> Source:
    """The content of a point-cloud or mesh file (``faces``: also its triangles, PLY / OBJ / VTK).

    Raises FileNotFoundError for a missing file and :class:`~manifold_sph.scans.io_read.ReadError`
    (a ValueError naming the file) for a folder, a misnamed or malformed file, or NaN coordinates.
    """
    from .io_read import ReadError, read_format

    path = Path(os.fspath(path))
    if not path.exists():
        raise FileNotFoundError(f"no such file: {str(path)!r}")
    if path.is_dir():
        raise ReadError(path, "it is a folder, not a file")
    if not path.is_file():
        raise ReadError(path, "it is not a regular file")
    fmt = format_of(path, format)
    seen = _sniff(path)
    if seen is not None and fmt not in {"las": {"las", "laz"}, "npz": {"npz"}, "npy": {"npy"}}.get(seen, {seen}):
        raise ReadError(path, f"its first bytes are those of a {seen.upper()} file, not {fmt.upper()}; "
                              f"rename it or pass format={seen!r}")
    want_faces = faces and fmt in ("ply", "obj", "vtk")
    try:
        pts, nrm, fields, tri = read_format(path, fmt, want_faces)
        if want_faces and fmt == "vtk":
            tri = _vtk_faces(path)
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
    if tri is not None and len(tri):
        tri = np.asarray(tri, dtype=np.int64).reshape(-1, 3)
        if tri.min() < 0 or tri.max() >= len(pts):
            raise ReadError(path, f"a face refers to a vertex outside 0..{len(pts) - 1}")
    else:
        tri = None
    fields = {k: np.asarray(v) for k, v in fields.items()}
    return Source(pts, nrm, tri, fields, label=f"{path.name!r}")


def _vtk_faces(path: Path) -> np.ndarray | None:
    import pyvista as pv

    mesh = pv.read(str(path))
    if not isinstance(mesh, pv.PolyData):
        return None
    return _pv_triangles(mesh)


def _pv_triangles(mesh: Any) -> np.ndarray | None:
    """The triangles of a PyVista PolyData's polygons (fanned), or None without polygons."""
    if mesh.n_cells == 0 or len(mesh.faces) == 0:
        return None
    tri = mesh if mesh.is_all_triangles else mesh.triangulate()
    if tri.n_points != mesh.n_points:  # a filter that moved points: the triangles would not index ours
        return None
    faces = np.asarray(tri.faces).reshape(-1, 4)
    return faces[faces[:, 0] == 3, 1:].astype(np.int64)


# ----------------------------------------------------------------------------- objects
def _library(obj: Any) -> str | None:
    root = type(obj).__module__.split(".")[0]
    return root if root in _FOREIGN else None


def is_foreign(obj: Any) -> bool:
    """Whether ``obj`` is an Open3D, PyVista, VTK or trimesh object (checked without importing those)."""
    return _library(obj) is not None


def _colours(fields: dict, rgb: ArrayLike) -> None:
    rgb = np.asarray(rgb)
    if rgb.ndim == 2 and rgb.shape[1] in (3, 4) and len(rgb):
        fields.update(zip(("red", "green", "blue", "alpha"), rgb.T))


def object_source(obj: Any) -> Source:
    """The points, normals, triangles and per-point data of an Open3D, PyVista / VTK or trimesh object.

    Open3D: ``geometry.PointCloud``, ``geometry.TriangleMesh`` and their tensor versions
    (``t.geometry``; every custom point attribute becomes a field). PyVista: any DataSet
    (point data ``Normals`` as normals, the other point data as fields, a PolyData's polygons
    as triangles); VTK data objects are wrapped by PyVista. trimesh: ``Trimesh`` (vertices,
    faces, vertex colours), ``PointCloud`` (normals in ``metadata["normals"]``) and ``Scene``
    (its meshes concatenated).
    """
    lib = _library(obj)
    name = f"{type(obj).__module__.split('.')[0]}.{type(obj).__name__}"
    fields: dict[str, np.ndarray] = {}
    nrm = tri = None
    if lib == "open3d":
        kind = type(obj).__name__
        tensor = ".t." in type(obj).__module__ + "."  # open3d.t.geometry (open3d.cpu.pybind.t.geometry)
        if tensor and kind == "PointCloud":
            attrs = obj.point
            if "positions" not in attrs:
                raise ValueError(f"the {name} holds no points (no 'positions' attribute)")
            pts = attrs["positions"].numpy()
            for key in attrs:
                if key == "positions":
                    continue
                a = attrs[key].numpy()
                a = a.reshape(len(a), -1)
                if key == "normals":
                    nrm = a
                elif key == "colors":
                    _colours(fields, a)
                else:
                    fields[key] = a[:, 0] if a.shape[1] == 1 else a
        elif tensor and kind == "TriangleMesh":
            pts = obj.vertex["positions"].numpy()
            nrm = obj.vertex["normals"].numpy() if "normals" in obj.vertex else None
            tri = obj.triangle["indices"].numpy() if "indices" in obj.triangle else None
        elif kind == "PointCloud":
            pts = np.asarray(obj.points)
            nrm = np.asarray(obj.normals) if obj.has_normals() else None
            if obj.has_colors():
                _colours(fields, np.asarray(obj.colors))
        elif kind == "TriangleMesh":
            pts = np.asarray(obj.vertices)
            nrm = np.asarray(obj.vertex_normals) if obj.has_vertex_normals() else None
            tri = np.asarray(obj.triangles) if obj.has_triangles() else None
            if obj.has_vertex_colors():
                _colours(fields, np.asarray(obj.vertex_colors))
        else:
            raise TypeError(f"cannot take points from an {name}: give an open3d PointCloud or TriangleMesh")
    elif lib in ("pyvista", "vtk", "vtkmodules"):
        import pyvista as pv

        mesh = obj if lib == "pyvista" else pv.wrap(obj)
        if not hasattr(mesh, "points") or not hasattr(mesh, "point_data"):
            raise TypeError(f"cannot take points from a {name}: give a pyvista DataSet (PolyData, grid...)")
        pts = np.asarray(mesh.points)
        for key in mesh.point_data.keys():
            a = np.asarray(mesh.point_data[key])
            if key.lower() in ("normals", "normal") and a.shape == pts.shape:
                nrm = a
            elif a.shape[:1] == (len(pts),) and a.dtype.kind in "biuf":
                fields[key] = a
        if isinstance(mesh, pv.PolyData):
            tri = _pv_triangles(mesh)
    elif lib == "trimesh":
        import trimesh

        if isinstance(obj, trimesh.Scene):
            obj = obj.to_geometry() if hasattr(obj, "to_geometry") else obj.dump(concatenate=True)
        if isinstance(obj, trimesh.Trimesh):
            pts, tri = np.asarray(obj.vertices), np.asarray(obj.faces)
            colours = getattr(obj.visual, "vertex_colors", None) if getattr(obj.visual, "kind", None) == "vertex" else None
            if colours is not None:
                _colours(fields, colours)
        elif isinstance(obj, trimesh.PointCloud):
            pts = np.asarray(obj.vertices)
            nrm = obj.metadata.get("normals")
            if getattr(obj, "colors", None) is not None and len(obj.colors):
                _colours(fields, obj.colors)
        else:
            raise TypeError(f"cannot take points from a {name}: give a trimesh Trimesh, PointCloud or Scene")
    else:
        raise TypeError(f"{name} is not an Open3D, PyVista or trimesh object")
    pts = np.array(pts, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"the {name} must hold points of shape (N, 3), got shape {pts.shape}")
    if nrm is not None:
        nrm = np.array(nrm, dtype=np.float64)
    if tri is not None:
        tri = np.asarray(tri, dtype=np.int64).reshape(-1, 3)
        tri = tri if len(tri) else None
    return Source(pts, nrm, tri, fields, label=f"the {name}")


# ----------------------------------------------------------------------------- meshes
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
        vn[:, 0] += np.bincount(f[:, a], fn[:, 0], minlength=len(v))
        vn[:, 1] += np.bincount(f[:, a], fn[:, 1], minlength=len(v))
        vn[:, 2] += np.bincount(f[:, a], fn[:, 2], minlength=len(v))
    norm = np.linalg.norm(vn, axis=1)
    ok = norm > 0
    vn[ok] /= norm[ok, None]
    return vn


def _trusted_face_normals(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray | None, str]:
    """Vertex normals from ``faces`` when they can be trusted, with a note; else (None, why not)."""
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])]
    n = len(points)
    vn = mesh_vertex_normals(points, faces)
    alone = int((~(np.abs(vn).sum(axis=1) > 0)).sum())
    if alone:
        return None, f"{alone} of its {n} points are in no face (or in zero-area faces only)"
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = edges[:, 0] * np.int64(n) + edges[:, 1]
    key.sort()
    twice = int((key[1:] == key[:-1]).sum())  # a directed edge used twice: two neighbours wound oppositely
    if twice:
        return None, f"the faces are not wound consistently ({twice} edges run the same way in two faces)"
    v = points - points.mean(axis=0)
    volume = float(np.einsum("ij,ij->i", v[faces[:, 0]], np.cross(v[faces[:, 1]], v[faces[:, 2]])).sum())
    if volume < 0:  # wound clockwise seen from outside: turn every normal outward
        vn = -vn
    return vn, ""


def _merge_exact(src: Source) -> tuple[Source, np.ndarray]:
    """``src`` with exact duplicate points merged into the first of each group; the kept indices."""
    pts = src.points
    _, first, inverse = np.unique(pts + 0.0, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    order = np.argsort(first)  # groups numbered in the order of their first point: the input order kept
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    labels = rank[inverse]
    keep = first[order]
    nrm = None
    if src.normals is not None:
        total = np.zeros((keep.size, 3))
        ref = src.normals[keep][labels]
        signs = np.where(np.einsum("ij,ij->i", src.normals, ref) < 0, -1.0, 1.0)
        for c in range(3):
            total[:, c] = np.bincount(labels, src.normals[:, c] * signs, minlength=keep.size)
        length = np.linalg.norm(total, axis=1)
        nrm = np.where(length[:, None] > 0, total / np.where(length > 0, length, 1.0)[:, None], src.normals[keep])
    faces = None if src.faces is None else labels[src.faces]
    fields = {k: (v[keep] if v.shape[:1] == (len(pts),) else v) for k, v in src.fields.items()}
    return Source(pts[keep], nrm, faces, fields, src.label), keep


def _usable_normals(normals: np.ndarray | None, n: int) -> np.ndarray | None:
    """Stored normals, or None when absent, all zero (placeholders), of the wrong shape or not finite."""
    if normals is None:
        return None
    normals = np.asarray(normals, dtype=np.float64)
    if normals.shape != (n, 3) or not np.all(np.isfinite(normals)) or not np.any(normals):
        return None
    return normals


def settle(src: Source, *, normals: str = "auto", duplicates: str = "merge") -> tuple[Source, str]:
    """The points and normals of a point cloud from ``src``, and a note of what was done ("" if nothing).

    Parameters
    ----------
    src : Source
    normals : {"auto", "file", "mesh", "none"}
        "auto": the stored normals if usable, else vertex normals of its triangles when
        every point is in one and they are wound consistently, else none. "file": its own
        only. "mesh": from the triangles (required), points in no triangle dropped
        (``fields["index"]`` keeps the original indices). "none": no normals.
    duplicates : {"merge", "error"}
        Exact repeats of a point merged into the first (normals averaged; ``fields["index"]``
        keeps the original indices), or a ValueError giving the count.

    Returns
    -------
    (Source, str)
        ``faces`` is None in the result: the triangles served the normals only.
    """
    check_in("normals", normals, {"auto", "file", "mesh", "none"})
    check_in("duplicates", duplicates, {"merge", "error"})
    n0 = len(src.points)
    notes = []
    own = _usable_normals(src.normals, n0)
    if normals == "mesh" and src.faces is None:
        raise ValueError(f"normals='mesh' was asked but {src.label} holds no faces")
    src = Source(src.points, own if normals in ("auto", "file") else None, src.faces, dict(src.fields), src.label)
    index = np.arange(n0)
    _, counts = np.unique(src.points + 0.0, axis=0, return_counts=True)
    extra = int((counts - 1).sum())
    if extra and duplicates == "error":
        raise ValueError(
            f"{src.label} holds {extra} exact duplicate point(s); pass duplicates='merge' to merge them "
            "into the first of each group"
        )
    if extra:
        src, index = _merge_exact(src)
        notes.append(f"merged {extra} exact duplicate point(s) ({len(src.points)} kept; fields['index'] holds "
                     "the original indices)")
    if src.faces is not None:
        faces = src.faces
        nf = len(faces)
        if normals == "mesh":
            vn = mesh_vertex_normals(src.points, faces)
            keep = np.abs(vn).sum(axis=1) > 0
            index = index[keep]
            src = Source(src.points[keep], vn[keep], None,
                         {k: (v[keep] if v.shape[:1] == keep.shape else v) for k, v in src.fields.items()}, src.label)
        elif normals == "auto" and src.normals is None:
            fn, why = _trusted_face_normals(src.points, faces)
            if fn is not None:
                src.normals = fn
                notes.append(f"normals from its {nf} faces, which are not kept (the operators work on the points)")
            else:
                notes.append(f"its {nf} faces are not kept and give no normals: {why}")
        else:
            notes.append(f"its {nf} faces are not kept (the operators work on the points)")
        src.faces = None
    if len(index) != n0 or normals == "mesh":
        src.fields["index"] = index
    note = f"{src.label}: " + "; ".join(notes) if notes else ""
    return src, note


def announce(note: str) -> None:
    """Say ``note`` in one :class:`~manifold_sph.ManifoldSPHWarning`, pointing at the caller's code; inside a
    Surface build, as an entry of its report (the build's one warning)."""
    if not note:
        return
    from ..diagnostics import note as report_note

    report_note("input", note)
