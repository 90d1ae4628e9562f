"""Reading and writing point clouds, and conversions to other libraries.

Formats (chosen from the file extension, or ``format=``):

=========  ======================================  =====================================
format     read                                    write
=========  ======================================  =====================================
ply        ascii, binary little/big endian;        ascii or binary little endian
           vertex x y z, nx ny nz, other scalar
           properties as fields; faces / triangle
           strips for mesh normals
pcd        ascii, binary (binary_compressed via    ascii or binary
           open3d)
xyz, txt,  columns x y z [nx ny nz] [more]; a      x y z [nx ny nz] [fields], header
csv        header line of names is recognised      line of names for csv
obj        ``v`` (and ``vn`` when one per          ``v`` and ``vn`` lines
           vertex); ``f`` for mesh normals
npy, npz   (N, 3) or (N, 6); npz keys ``points``,  same
           ``normals`` and fields
vtk, vtp   via pyvista (point data ``Normals``)    via pyvista (legacy ascii .vtk keeps
                                                   about 11 significant digits)
=========  ======================================  =====================================

Malformed or unreadable files raise :class:`ReadError` (a ``ValueError``) whose
message names the file and the problem; a missing file raises
``FileNotFoundError``. Writing never overwrites an existing file unless
``overwrite=True``.

Conversions: :func:`to_pyvista` / :func:`from_pyvista`, :func:`to_trimesh` /
:func:`from_trimesh`, :func:`to_open3d` / :func:`from_open3d`. The optional
libraries are imported only inside these functions.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from ._validation import check_in
from .pointcloud import PointCloud

__all__ = [
    "ReadError",
    "FORMATS",
    "read",
    "write",
    "read_mesh",
    "mesh_vertex_normals",
    "to_pyvista",
    "from_pyvista",
    "to_trimesh",
    "from_trimesh",
    "to_open3d",
    "from_open3d",
]

#: Extension -> format name.
FORMATS = {
    ".ply": "ply",
    ".pcd": "pcd",
    ".xyz": "xyz",
    ".txt": "xyz",
    ".csv": "csv",
    ".pts": "xyz",
    ".obj": "obj",
    ".npy": "npy",
    ".npz": "npz",
    ".vtk": "vtk",
    ".vtp": "vtk",
}

_NORMAL_NAMES = (("nx", "ny", "nz"), ("normal_x", "normal_y", "normal_z"), ("normalx", "normaly", "normalz"))


class ReadError(ValueError):
    """A point-cloud file could not be read; the message names the file and the problem."""

    def __init__(self, path, problem: str):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"cannot read {str(path)!r}: {problem}")


# ----------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------
def _format_of(path: Path, format: str | None) -> str:
    if format is not None:
        check_in("format", format, set(FORMATS.values()))
        return format
    ext = path.suffix.lower()
    if ext not in FORMATS:
        raise ValueError(
            f"cannot tell the format of {str(path)!r} from its extension {ext!r}; "
            f"pass format= one of {sorted(set(FORMATS.values()))}"
        )
    return FORMATS[ext]


def _split_columns(path, names: list[str], data: np.ndarray):
    """Points, normals and fields from named columns."""
    lower = [n.lower() for n in names]
    try:
        ixyz = [lower.index(c) for c in ("x", "y", "z")]
    except ValueError:
        raise ReadError(path, f"no x, y, z columns among {names}") from None
    inrm = None
    for trio in _NORMAL_NAMES:
        if all(c in lower for c in trio):
            inrm = [lower.index(c) for c in trio]
            break
    used = set(ixyz) | set(inrm or [])
    points = data[:, ixyz]
    normals = None if inrm is None else data[:, inrm]
    fields = {names[i]: data[:, i] for i in range(len(names)) if i not in used}
    return points, normals, fields


def _usable_normals(normals):
    """Normals from a file, or None when they are absent or all zero (placeholders)."""
    if normals is None:
        return None
    normals = np.asarray(normals, dtype=np.float64)
    if not np.all(np.isfinite(normals)) or not np.any(normals):
        return None
    return normals


def mesh_vertex_normals(vertices, faces) -> np.ndarray:
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


def _strips_to_triangles(strips: list[np.ndarray]) -> np.ndarray:
    """Triangle strips (lists possibly separated by -1) to consistently oriented triangles."""
    tris = []
    for strip in strips:
        strip = np.asarray(strip, dtype=np.int64)
        cuts = np.flatnonzero(strip < 0)
        for part in np.split(strip, cuts):
            part = part[part >= 0]
            if part.size < 3:
                continue
            a, b, c = part[:-2], part[1:-1], part[2:]
            odd = (np.arange(a.size) % 2).astype(bool)
            t = np.stack([a, b, c], axis=1)
            t[odd] = np.stack([b[odd], a[odd], c[odd]], axis=1)
            t = t[(t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])]
            tris.append(t)
    return np.concatenate(tris) if tris else np.zeros((0, 3), dtype=np.int64)


def _fan(polys: list[np.ndarray]) -> np.ndarray:
    tris = [np.stack([np.full(len(p) - 2, p[0]), p[1:-1], p[2:]], axis=1) for p in polys if len(p) >= 3]
    return np.concatenate(tris).astype(np.int64) if tris else np.zeros((0, 3), dtype=np.int64)


# ----------------------------------------------------------------------------
# PLY
# ----------------------------------------------------------------------------
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def _ply_header(path, raw: bytes):
    end = raw.find(b"end_header")
    if not raw.startswith(b"ply") or end < 0:
        raise ReadError(path, "not a PLY file (no 'ply' magic line or no 'end_header')")
    nl = raw.find(b"\n", end)
    body_start = len(raw) if nl < 0 else nl + 1
    lines = raw[:end].decode("ascii", errors="replace").splitlines()
    fmt, elements = None, []
    for line in lines[1:]:
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "format":
            fmt = tok[1] if len(tok) > 1 else None
        elif tok[0] == "element":
            if len(tok) != 3 or not tok[2].isdigit():
                raise ReadError(path, f"bad PLY element line {line!r}")
            elements.append({"name": tok[1], "count": int(tok[2]), "props": []})
        elif tok[0] == "property":
            if not elements:
                raise ReadError(path, f"PLY property before any element: {line!r}")
            if len(tok) == 5 and tok[1] == "list":
                if tok[2] not in _PLY_TYPES or tok[3] not in _PLY_TYPES:
                    raise ReadError(path, f"unknown PLY type in {line!r}")
                elements[-1]["props"].append((tok[4], "list", _PLY_TYPES[tok[2]], _PLY_TYPES[tok[3]]))
            elif len(tok) == 3 and tok[1] in _PLY_TYPES:
                elements[-1]["props"].append((tok[2], "scalar", _PLY_TYPES[tok[1]], None))
            else:
                raise ReadError(path, f"bad PLY property line {line!r}")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise ReadError(path, f"unknown PLY format {fmt!r}")
    return fmt, elements, body_start


def _ply_binary_element(path, el, buf: memoryview, pos: int, endian: str, need: bool):
    """Parse one binary element at ``pos``; return (data, new_pos). ``data`` None if not needed."""
    props, count = el["props"], el["count"]
    if all(p[1] == "scalar" for p in props):
        dt = np.dtype([(p[0], endian + p[2]) for p in props])
        nbytes = dt.itemsize * count
        if pos + nbytes > len(buf):
            raise ReadError(path, f"file truncated in element {el['name']!r} ({count} expected)")
        data = np.frombuffer(buf, dtype=dt, count=count, offset=pos) if need else None
        return data, pos + nbytes
    # elements with lists: fast path when there is one list property of constant length
    if len(props) == 1 and count > 0:
        _, _, ct, it = props[0]
        ctype, itype = np.dtype(endian + ct), np.dtype(endian + it)
        first = int(np.frombuffer(buf, dtype=ctype, count=1, offset=pos)[0])
        dt = np.dtype([("n", ctype), ("v", itype, (first,))])
        if pos + dt.itemsize * count <= len(buf):
            arr = np.frombuffer(buf, dtype=dt, count=count, offset=pos)
            if np.all(arr["n"] == first):
                return (arr["v"].astype(np.int64) if need else None), pos + dt.itemsize * count
    rows = []
    for _ in range(count):
        row = []
        for name, kind, ct, it in props:
            if kind == "scalar":
                d = np.dtype(endian + ct)
                row.append(np.frombuffer(buf, dtype=d, count=1, offset=pos)[0])
                pos += d.itemsize
            else:
                ctype, itype = np.dtype(endian + ct), np.dtype(endian + it)
                if pos + ctype.itemsize > len(buf):
                    raise ReadError(path, f"file truncated in element {el['name']!r}")
                m = int(np.frombuffer(buf, dtype=ctype, count=1, offset=pos)[0])
                pos += ctype.itemsize
                if pos + m * itype.itemsize > len(buf):
                    raise ReadError(path, f"file truncated in element {el['name']!r}")
                row.append(np.frombuffer(buf, dtype=itype, count=m, offset=pos).astype(np.int64))
                pos += m * itype.itemsize
        lists = [r for r in row if isinstance(r, np.ndarray)]
        rows.append(lists[0])
    return (rows if need else None), pos


def _read_ply(path, want_faces: bool):
    raw = Path(path).read_bytes()
    fmt, elements, start = _ply_header(path, raw)
    names = [e["name"] for e in elements]
    if "vertex" not in names:
        raise ReadError(path, f"PLY file has no 'vertex' element (elements: {names})")
    vertex, faces = None, None
    if fmt == "ascii":
        lines = raw[start:].decode("ascii", errors="replace").splitlines()
        lines = [ln for ln in lines if ln.strip()]
        pos = 0
        for el in elements:
            chunk = lines[pos : pos + el["count"]]
            if len(chunk) < el["count"]:
                raise ReadError(path, f"file truncated in element {el['name']!r}: {el['count']} rows expected, {len(chunk)} found")
            pos += el["count"]
            if el["name"] == "vertex":
                nprop = len(el["props"])
                if any(p[1] == "list" for p in el["props"]):
                    raise ReadError(path, "list properties in the vertex element are not supported")
                try:
                    arr = np.array([ln.split()[:nprop] for ln in chunk], dtype=np.float64)
                except ValueError as exc:
                    raise ReadError(path, f"non-numeric vertex data ({exc})") from None
                if arr.shape != (el["count"], nprop):
                    raise ReadError(path, f"vertex rows must hold {nprop} values")
                vertex = (arr, [p[0] for p in el["props"]])
            elif want_faces and el["name"] in ("face", "tristrips"):
                polys = []
                for ln in chunk:
                    tok = ln.split()
                    m = int(tok[0])
                    polys.append(np.array(tok[1 : 1 + m], dtype=np.int64))
                faces = _strips_to_triangles(polys) if el["name"] == "tristrips" else _fan(polys)
    else:
        endian = "<" if fmt == "binary_little_endian" else ">"
        buf = memoryview(raw)
        pos = start
        for el in elements:
            need = el["name"] == "vertex" or (want_faces and el["name"] in ("face", "tristrips"))
            after_vertex = vertex is not None
            if after_vertex and not need and not want_faces:
                break
            data, pos = _ply_binary_element(path, el, buf, pos, endian, need)
            if el["name"] == "vertex":
                vertex = (np.column_stack([data[p[0]].astype(np.float64) for p in el["props"]]), [p[0] for p in el["props"]])
            elif need:
                if el["name"] == "tristrips":
                    faces = _strips_to_triangles(list(data))
                elif isinstance(data, np.ndarray) and data.shape[1] == 3:
                    faces = data
                else:
                    faces = _fan(list(data))
            if vertex is not None and (not want_faces or faces is not None):
                break
    arr, names = vertex
    points, normals, fields = _split_columns(path, names, arr)
    return points, normals, fields, faces


def _write_ply(path, points, normals, fields, binary: bool):
    cols = [("x", points[:, 0]), ("y", points[:, 1]), ("z", points[:, 2])]
    if normals is not None:
        cols += [("nx", normals[:, 0]), ("ny", normals[:, 1]), ("nz", normals[:, 2])]
    cols += list(fields.items())
    header = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", "comment written by manifold_sph",
              f"element vertex {points.shape[0]}"]
    header += [f"property double {name}" for name, _ in cols]
    header.append("end_header")
    data = np.column_stack([c for _, c in cols]).astype(np.float64)
    with open(path, "wb") as fh:
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        if binary:
            fh.write(data.astype("<f8").tobytes())
        else:
            np.savetxt(fh, data, fmt="%.17g")


# ----------------------------------------------------------------------------
# PCD
# ----------------------------------------------------------------------------
_PCD_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8",
              ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}


def _read_pcd(path):
    raw = Path(path).read_bytes()
    head, pos = {}, 0
    while True:
        nl = raw.find(b"\n", pos)
        if nl < 0:
            raise ReadError(path, "PCD header has no DATA line")
        line = raw[pos:nl].decode("ascii", errors="replace").strip()
        pos = nl + 1
        if not line or line.startswith("#"):
            continue
        tok = line.split()
        head[tok[0].upper()] = tok[1:]
        if tok[0].upper() == "DATA":
            break
    try:
        names = head["FIELDS"]
        n = int(head["POINTS"][0]) if "POINTS" in head else int(head["WIDTH"][0]) * int(head.get("HEIGHT", ["1"])[0])
        sizes = [int(s) for s in head.get("SIZE", ["4"] * len(names))]
        types = head.get("TYPE", ["F"] * len(names))
        counts = [int(c) for c in head.get("COUNT", ["1"] * len(names))]
        mode = head["DATA"][0].lower()
    except (KeyError, ValueError, IndexError) as exc:
        raise ReadError(path, f"malformed PCD header ({exc!r})") from None
    if not (len(names) == len(sizes) == len(types) == len(counts)):
        raise ReadError(path, "PCD header: FIELDS, SIZE, TYPE and COUNT differ in length")
    cols = []
    for nm, c in zip(names, counts):
        cols += [nm] if c == 1 else [f"{nm}_{k}" for k in range(c)]
    if mode == "ascii":
        try:
            arr = np.loadtxt(raw[pos:].decode("ascii").splitlines(), dtype=np.float64, ndmin=2)
        except ValueError as exc:
            raise ReadError(path, f"malformed PCD ascii data ({exc})") from None
        if arr.shape != (n, len(cols)) and not (n == 0 and arr.size == 0):
            raise ReadError(path, f"PCD data has shape {arr.shape}, the header promises ({n}, {len(cols)})")
    elif mode == "binary":
        try:
            dt = np.dtype([(nm, "<" + _PCD_TYPES[(t.upper(), s)], (c,)) for nm, t, s, c in zip(names, types, sizes, counts)])
        except KeyError as exc:
            raise ReadError(path, f"unknown PCD field type {exc}") from None
        if pos + dt.itemsize * n > len(raw):
            raise ReadError(path, f"PCD file truncated: {n} points of {dt.itemsize} bytes expected")
        rec = np.frombuffer(raw, dtype=dt, count=n, offset=pos)
        arr = np.column_stack([rec[nm].reshape(n, -1).astype(np.float64) for nm in names])
    elif mode == "binary_compressed":
        return _read_open3d(path)
    else:
        raise ReadError(path, f"unknown PCD DATA mode {mode!r}")
    points, normals, fields = _split_columns(path, cols, arr)
    return points, normals, fields, None


def _write_pcd(path, points, normals, fields, binary: bool):
    cols = [("x", points[:, 0]), ("y", points[:, 1]), ("z", points[:, 2])]
    if normals is not None:
        cols += [("normal_x", normals[:, 0]), ("normal_y", normals[:, 1]), ("normal_z", normals[:, 2])]
    cols += list(fields.items())
    n, m = points.shape[0], len(cols)
    header = ["# .PCD v0.7 - written by manifold_sph", "VERSION 0.7", "FIELDS " + " ".join(c for c, _ in cols),
              "SIZE " + " ".join(["8"] * m), "TYPE " + " ".join(["F"] * m), "COUNT " + " ".join(["1"] * m),
              f"WIDTH {n}", "HEIGHT 1", "VIEWPOINT 0 0 0 1 0 0 0", f"POINTS {n}", f"DATA {'binary' if binary else 'ascii'}"]
    data = np.column_stack([c for _, c in cols]).astype(np.float64)
    with open(path, "wb") as fh:
        fh.write(("\n".join(header) + "\n").encode("ascii"))
        if binary:
            fh.write(data.astype("<f8").tobytes())
        else:
            np.savetxt(fh, data, fmt="%.17g")


def _read_open3d(path):
    import open3d as o3d

    pc = o3d.io.read_point_cloud(str(path))
    pts = np.asarray(pc.points, dtype=np.float64)
    if pts.size == 0:
        raise ReadError(path, "open3d read no points")
    nrm = np.asarray(pc.normals, dtype=np.float64) if pc.has_normals() else None
    return pts, nrm, {}, None


# ----------------------------------------------------------------------------
# text, OBJ, numpy, VTK
# ----------------------------------------------------------------------------
def _read_text(path, fmt: str):
    text = Path(path).read_text(errors="replace").splitlines()
    lines = [ln for ln in text if ln.strip() and not ln.lstrip().startswith(("#", "//"))]
    if not lines:
        raise ReadError(path, "the file holds no data rows")
    delim = "," if (fmt == "csv" or "," in lines[0]) else None
    names = None
    first = [t.strip() for t in (lines[0].split(delim) if delim else lines[0].split())]
    if any(re.search(r"[A-Za-z_]", t) and not _is_number(t) for t in first):
        names = first
        lines = lines[1:]
    if not lines:
        raise ReadError(path, "the file holds a header line but no data rows")
    try:
        arr = np.loadtxt(lines, delimiter=delim, dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise ReadError(path, f"malformed numeric data ({exc})") from None
    if names is None:
        m = arr.shape[1]
        if m < 3:
            raise ReadError(path, f"rows must hold at least 3 columns (x y z), got {m}")
        names = ["x", "y", "z"] + (["nx", "ny", "nz"] if m >= 6 else []) + [f"f{k}" for k in range(m - (6 if m >= 6 else 3))]
    if len(names) != arr.shape[1]:
        raise ReadError(path, f"the header names {len(names)} columns but rows hold {arr.shape[1]}")
    return _split_columns(path, names, arr) + (None,)


def _is_number(t: str) -> bool:
    try:
        float(t)
        return True
    except ValueError:
        return False


def _read_obj(path, want_faces: bool):
    v, vn, polys = [], [], []
    with open(path, errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            if line.startswith("v "):
                v.append(line.split()[1:4])
            elif line.startswith("vn "):
                vn.append(line.split()[1:4])
            elif want_faces and line.startswith("f "):
                try:
                    polys.append([int(t.split("/")[0]) for t in line.split()[1:]])
                except ValueError:
                    raise ReadError(path, f"bad face on line {lineno}: {line.strip()!r}") from None
    if not v:
        raise ReadError(path, "no vertex ('v x y z') lines")
    try:
        points = np.array(v, dtype=np.float64)
    except ValueError as exc:
        raise ReadError(path, f"malformed vertex line ({exc})") from None
    if points.ndim != 2 or points.shape[1] != 3:
        raise ReadError(path, "every vertex line needs 3 coordinates")
    normals = None
    if vn and len(vn) == len(v):
        try:
            normals = np.array(vn, dtype=np.float64)
        except ValueError as exc:
            raise ReadError(path, f"malformed normal line ({exc})") from None
    faces = None
    if want_faces:
        n = len(v)
        polys = [np.array([i - 1 if i > 0 else n + i for i in p], dtype=np.int64) for p in polys]
        faces = _fan(polys)
        if faces.size and (faces.min() < 0 or faces.max() >= n):
            raise ReadError(path, "a face refers to a vertex that does not exist")
    return points, normals, {}, faces


def _read_numpy(path, fmt: str):
    try:
        obj = np.load(path, allow_pickle=False)
    except (ValueError, OSError) as exc:
        raise ReadError(path, f"not a readable {fmt.upper()} file ({exc})") from None
    if fmt == "npy":
        arr = np.asarray(obj, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] not in (3, 6):
            raise ReadError(path, f"the array must have shape (N, 3) or (N, 6), got {arr.shape}")
        return arr[:, :3], (arr[:, 3:] if arr.shape[1] == 6 else None), {}, None
    with obj:
        keys = list(obj.keys())
        if "points" not in keys:
            raise ReadError(path, f"the NPZ archive has no 'points' array (keys: {keys})")
        points = np.asarray(obj["points"], dtype=np.float64)
        normals = np.asarray(obj["normals"], dtype=np.float64) if "normals" in keys else None
        fields = {k: np.asarray(obj[k]) for k in keys if k not in ("points", "normals")}
    return points, normals, fields, None


def _read_vtk(path):
    import pyvista as pv

    try:
        mesh = pv.read(str(path))
    except Exception as exc:  # pyvista/vtk raise many types
        raise ReadError(path, f"pyvista could not read it ({type(exc).__name__}: {exc})") from None
    if mesh.n_points == 0:
        raise ReadError(path, "the file holds no points")
    return _from_pv_mesh(mesh) + (None,)


def _from_pv_mesh(mesh):
    points = np.asarray(mesh.points, dtype=np.float64)
    normals, fields = None, {}
    for name in mesh.point_data.keys():
        arr = np.asarray(mesh.point_data[name])
        if name.lower() in ("normals", "normal") and arr.shape == points.shape:
            normals = arr.astype(np.float64)
        else:
            fields[name] = arr
    return points, normals, fields


# ----------------------------------------------------------------------------
# public API
# ----------------------------------------------------------------------------
def read_mesh(path, *, format: str | None = None):
    """Vertices and triangles of a mesh file (PLY faces or triangle strips, OBJ faces, VTK polygons).

    Returns
    -------
    vertices : ndarray, shape (N, 3)
    faces : ndarray of int, shape (F, 3)
        Empty (0, 3) when the file holds no faces.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such file: {str(path)!r}")
    fmt = _format_of(path, format)
    if fmt == "ply":
        pts, _, _, faces = _read_ply(path, True)
    elif fmt == "obj":
        pts, _, _, faces = _read_obj(path, True)
    elif fmt == "vtk":
        import pyvista as pv

        mesh = pv.read(str(path)).extract_surface().triangulate()
        pts, faces = np.asarray(mesh.points, np.float64), np.asarray(mesh.faces).reshape(-1, 4)[:, 1:]
    else:
        raise ValueError(f"read_mesh supports ply, obj and vtk files, got format {fmt!r}")
    faces = np.zeros((0, 3), dtype=np.int64) if faces is None else np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    return pts, faces


def read(path, *, format: str | None = None, normals: str = "file", duplicates: str = "error", return_fields: bool = False):
    """Read a point cloud file.

    Parameters
    ----------
    path : str or Path
    format : str, optional
        One of ``ply, pcd, xyz, csv, obj, npy, npz, vtk`` (default: from the extension).
    normals : {"file", "mesh", "none"}
        "file": the normals stored in the file, if any (all-zero placeholders
        count as none); "mesh": area-weighted vertex normals of the file's faces
        (PLY, OBJ, VTK), vertices in no face are dropped and ``fields["index"]``
        keeps the original indices; "none": ignore stored normals.
    duplicates : {"error", "merge"}
        Repeated points are rejected by :class:`~manifold_sph.PointCloud`;
        "merge" merges them first (:func:`manifold_sph.cleaning.merge_duplicates`,
        the normals averaged) and records the original indices in ``fields["index"]``.
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
    >>> from manifold_sph import shapes
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
    if not path.is_file():
        raise ReadError(path, "it is not a regular file")
    fmt = _format_of(path, format)
    check_in("normals", normals, {"file", "mesh", "none"})
    check_in("duplicates", duplicates, {"error", "merge"})
    want_faces = normals == "mesh"
    if want_faces and fmt not in ("ply", "obj", "vtk"):
        raise ValueError(f"normals='mesh' needs a mesh file (ply, obj, vtk), got format {fmt!r}")
    try:
        if fmt == "ply":
            pts, nrm, fields, faces = _read_ply(path, want_faces)
        elif fmt == "pcd":
            pts, nrm, fields, faces = _read_pcd(path)
        elif fmt in ("xyz", "csv"):
            pts, nrm, fields, faces = _read_text(path, fmt)
        elif fmt == "obj":
            pts, nrm, fields, faces = _read_obj(path, want_faces)
        elif fmt in ("npy", "npz"):
            pts, nrm, fields, faces = _read_numpy(path, fmt)
        else:
            pts, nrm, fields, faces = _read_vtk(path)
            if want_faces:
                faces = read_mesh(path, format="vtk")[1]
    except ReadError:
        raise
    except (UnicodeDecodeError, IndexError, KeyError, ValueError, TypeError) as exc:
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
        vn = mesh_vertex_normals(pts, faces)
        keep = np.linalg.norm(vn, axis=1) > 0
        idx = np.flatnonzero(keep)
        pts, nrm = pts[keep], vn[keep]
        fields = {k: v[keep] for k, v in fields.items() if len(v) == len(keep)}
        fields["index"] = idx
    else:
        nrm = _usable_normals(nrm)
    if duplicates == "merge":
        from .cleaning import merge_duplicates

        res = merge_duplicates(pts, nrm, tolerance=0.0)
        base = fields.get("index", np.arange(len(res.keep_mask)))
        fields = {k: (v[res.keep_mask] if len(v) == len(res.keep_mask) else v) for k, v in fields.items()}
        fields["index"] = base[res.keep_mask]
        pts, nrm = res.points, res.normals
    try:
        cloud = PointCloud(pts, nrm)
    except ValueError as exc:
        raise ReadError(path, str(exc)) from None
    return (cloud, fields) if return_fields else cloud


def _as_cloud_arrays(cloud):
    if isinstance(cloud, PointCloud):
        return cloud.points, cloud.normals
    pts = np.asarray(cloud, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"cloud must be a PointCloud or an array of shape (N, 3), got shape {pts.shape}")
    return pts, None


def _check_fields(fields, n: int) -> dict:
    out = {}
    for name, arr in (fields or {}).items():
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
            raise ValueError(f"field names must be identifiers, got {name!r}")
        a = np.asarray(arr)
        if a.shape[:1] != (n,) or a.ndim > 2:
            raise ValueError(f"field {name!r} must have shape ({n},) or ({n}, k), got shape {a.shape}")
        if a.ndim == 2:
            for k in range(a.shape[1]):
                out[f"{name}_{k}"] = a[:, k]
        else:
            out[name] = a
    return out


def write(path, cloud, fields=None, *, format: str | None = None, binary: bool = True, overwrite: bool = False) -> None:
    """Write a point cloud (points, normals if any, and per-point fields).

    Parameters
    ----------
    path : str or Path
    cloud : PointCloud or array_like, shape (N, 3)
    fields : dict of str -> array_like, shape (N,) or (N, k), optional
        Per-point data (e.g. a heat solution). Vector fields are split into
        ``name_0, name_1, ...`` columns except in VTK, NPZ files.
    format : str, optional
        Default: from the extension.
    binary : bool
        Binary PLY / PCD / VTK (ascii otherwise).
    overwrite : bool
        Replace an existing file (default: refuse with ``FileExistsError``).

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from manifold_sph import shapes
    >>> cloud = shapes.sphere(20)
    >>> path = os.path.join(tempfile.mkdtemp(), "s.csv")
    >>> write(path, cloud, fields={"u": cloud.points[:, 2]})
    >>> open(path).readline().strip()
    'x,y,z,nx,ny,nz,u'
    """
    path = Path(path)
    fmt = _format_of(path, format)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{str(path)!r} exists; pass overwrite=True to replace it")
    pts, nrm = _as_cloud_arrays(cloud)
    n = pts.shape[0]
    if fmt in ("npz", "vtk"):
        raw_fields = {}
        for name, arr in (fields or {}).items():
            a = np.asarray(arr)
            if a.shape[:1] != (n,):
                raise ValueError(f"field {name!r} must have shape ({n},) or ({n}, k), got shape {a.shape}")
            if name in ("points", "normals", "Normals"):
                raise ValueError(f"field name {name!r} is reserved")
            raw_fields[str(name)] = a
    else:
        flat = _check_fields(fields, n)
    if fmt == "ply":
        _write_ply(path, pts, nrm, flat, binary)
    elif fmt == "pcd":
        _write_pcd(path, pts, nrm, flat, binary)
    elif fmt in ("xyz", "csv"):
        cols = ["x", "y", "z"] + (["nx", "ny", "nz"] if nrm is not None else []) + list(flat)
        data = np.column_stack([pts] + ([nrm] if nrm is not None else []) + [np.asarray(v, np.float64) for v in flat.values()])
        delim = "," if fmt == "csv" else " "
        header = delim.join(cols) if (fmt == "csv" or flat) else ""
        np.savetxt(path, data, fmt="%.17g", delimiter=delim, header=header, comments="")
    elif fmt == "obj":
        if flat:
            raise ValueError("OBJ files cannot hold per-point fields; use ply, pcd, csv, npz or vtk")
        with open(path, "w") as fh:
            fh.write("# written by manifold_sph\n")
            np.savetxt(fh, pts, fmt="v %.17g %.17g %.17g")
            if nrm is not None:
                np.savetxt(fh, nrm, fmt="vn %.17g %.17g %.17g")
    elif fmt == "npy":
        if flat:
            raise ValueError("NPY files cannot hold per-point fields; use npz")
        np.save(path, pts if nrm is None else np.hstack([pts, nrm]))
        _rename_numpy(path, ".npy")
    elif fmt == "npz":
        arrays = {"points": pts, **({"normals": nrm} if nrm is not None else {}), **raw_fields}
        np.savez(path, **arrays)
        _rename_numpy(path, ".npz")
    else:
        mesh = to_pyvista(cloud, raw_fields)
        mesh.save(str(path), binary=binary)


def _rename_numpy(path: Path, ext: str) -> None:
    """numpy appends ``ext`` to names without it; keep the name the caller gave."""
    if path.suffix.lower() != ext:
        os.replace(str(path) + ext, path)


# ----------------------------------------------------------------------------
# conversions
# ----------------------------------------------------------------------------
def to_pyvista(cloud, fields=None):
    """A ``pyvista.PolyData`` of the points (vertex cells), normals as point data ``Normals``.

    Examples
    --------
    >>> from manifold_sph import shapes
    >>> mesh = to_pyvista(shapes.sphere(30), {"u": list(range(30))})
    >>> mesh.n_points, sorted(mesh.point_data.keys())
    (30, ['Normals', 'u'])
    """
    import pyvista as pv

    pts, nrm = _as_cloud_arrays(cloud)
    mesh = pv.PolyData(pts.copy())
    if nrm is not None:
        mesh.point_data["Normals"] = nrm
    for name, arr in (fields or {}).items():
        a = np.asarray(arr)
        if a.shape[:1] != (pts.shape[0],):
            raise ValueError(f"field {name!r} must have {pts.shape[0]} rows, got shape {a.shape}")
        mesh.point_data[name] = a
    return mesh


def from_pyvista(mesh, *, return_fields: bool = False):
    """A PointCloud from any ``pyvista.DataSet`` (points; point data ``Normals`` if present)."""
    if not hasattr(mesh, "points") or not hasattr(mesh, "point_data"):
        raise TypeError(f"mesh must be a pyvista DataSet, got {type(mesh).__name__}")
    pts, nrm, fields = _from_pv_mesh(mesh)
    cloud = PointCloud(pts, _usable_normals(nrm))
    return (cloud, fields) if return_fields else cloud


def to_trimesh(cloud):
    """A ``trimesh.PointCloud``; normals (if any) in ``metadata["normals"]``."""
    import trimesh

    pts, nrm = _as_cloud_arrays(cloud)
    pc = trimesh.PointCloud(pts.copy())
    if nrm is not None:
        pc.metadata["normals"] = nrm.copy()
    return pc


def from_trimesh(obj, *, normals: bool = True):
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
        return PointCloud(pts, _usable_normals(nrm))
    raise TypeError(f"obj must be a trimesh.Trimesh or trimesh.PointCloud, got {type(obj).__name__}")


def to_open3d(cloud):
    """An ``open3d.geometry.PointCloud`` with normals if the cloud has them."""
    import open3d as o3d

    pts, nrm = _as_cloud_arrays(cloud)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.array(pts, dtype=np.float64)))
    if nrm is not None:
        pc.normals = o3d.utility.Vector3dVector(np.array(nrm, dtype=np.float64))
    return pc


def from_open3d(pc):
    """A PointCloud from an ``open3d.geometry.PointCloud`` (or the vertices of a TriangleMesh)."""
    import open3d as o3d

    if isinstance(pc, o3d.geometry.TriangleMesh):
        pts = np.asarray(pc.vertices, dtype=np.float64)
        nrm = np.asarray(pc.vertex_normals, dtype=np.float64) if pc.has_vertex_normals() else None
        return PointCloud(pts, _usable_normals(nrm))
    if not isinstance(pc, o3d.geometry.PointCloud):
        raise TypeError(f"pc must be an open3d PointCloud or TriangleMesh, got {type(pc).__name__}")
    pts = np.asarray(pc.points, dtype=np.float64)
    nrm = np.asarray(pc.normals, dtype=np.float64) if pc.has_normals() else None
    return PointCloud(pts, _usable_normals(nrm))
