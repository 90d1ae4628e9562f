"""File writers behind :func:`manifold_sph.scans.io.write`, and the atomic write they share.

Every writer writes into a temporary file in the target's folder, which is then
renamed to the exact name asked for (:func:`atomic_target`): a run killed midway
leaves no truncated file under the final name, numpy never appends a suffix, and
an existing file is never replaced unless ``overwrite=True`` (even one created
by another process while the file was being written).
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..pointcloud import PointCloud

__all__ = ["atomic_target", "write_format"]


@contextmanager
def atomic_target(path: str | os.PathLike[str], overwrite: bool, suffix: str = "") -> Iterator[Path]:
    """``with atomic_target(path, overwrite) as tmp:`` write ``tmp``; on success it becomes ``path``.

    The temporary file sits in the same folder (so the final rename is atomic)
    and ends with ``suffix`` (for writers that choose the format from the name).
    Without ``overwrite`` the file is linked to its final name, which fails if the
    name was taken meanwhile; on any error the temporary file is removed.

    Examples
    --------
    >>> import tempfile, os
    >>> d = tempfile.mkdtemp(); target = os.path.join(d, "a.txt")
    >>> with atomic_target(target, overwrite=False) as tmp:
    ...     _ = open(tmp, "w").write("done")
    >>> open(target).read(), os.listdir(d)
    ('done', ['a.txt'])
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.part{suffix}")
    try:
        yield tmp
        if overwrite:
            os.replace(tmp, path)
            return
        try:
            os.link(tmp, path)  # fails if the name exists: never replaces a file unasked
        except FileExistsError:
            raise FileExistsError(f"path {str(path)!r} appeared while it was being written; pass "
                                  "overwrite=True to replace it") from None
        except OSError:  # file systems without hard links
            if path.exists():
                raise FileExistsError(f"path {str(path)!r} exists; pass overwrite=True to replace it") from None
            os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _columns(points, normals, fields, normal_names):
    cols = [("x", points[:, 0]), ("y", points[:, 1]), ("z", points[:, 2])]
    if normals is not None:
        cols += [(normal_names[i], normals[:, i]) for i in range(3)]
    cols += list(fields.items())
    return cols


_COLOURS = ("red", "green", "blue", "alpha")


def _is_byte(v) -> bool:
    v = np.asarray(v)
    return v.size > 0 and bool(np.all((v >= 0) & (v <= 255) & (v == np.round(v))))


def _write_ply(fh, points, normals, fields, binary: bool):
    """Doubles, except colours ``red, green, blue (alpha)`` of integers 0..255: ``uchar``, as
    MeshLab, CloudCompare and open3d expect them."""
    cols = _columns(points, normals, fields, ("nx", "ny", "nz"))
    byte = {name for name, v in cols if name in _COLOURS and _is_byte(v)}
    types = [("uchar", "u1", "%d") if name in byte else ("double", "<f8", "%.17g") for name, _ in cols]
    header = ["ply", f"format {'binary_little_endian' if binary else 'ascii'} 1.0", "comment written by manifold_sph",
              f"element vertex {points.shape[0]}"]
    header += [f"property {t[0]} {name}" for (name, _), t in zip(cols, types)]
    header.append("end_header")
    fh.write(("\n".join(header) + "\n").encode("ascii"))
    if binary:
        rec = np.empty(points.shape[0], dtype=[(f"c{k}", t[1]) for k, t in enumerate(types)])
        for k, (_, v) in enumerate(cols):
            rec[f"c{k}"] = v
        fh.write(rec.tobytes())
    else:
        data = np.column_stack([c for _, c in cols]).astype(np.float64)
        np.savetxt(fh, data, fmt=[t[2] for t in types])


def _write_pcd(fh, points, normals, fields, binary: bool):
    cols = _columns(points, normals, fields, ("normal_x", "normal_y", "normal_z"))
    n, m = points.shape[0], len(cols)
    header = ["# .PCD v0.7 - written by manifold_sph", "VERSION 0.7", "FIELDS " + " ".join(c for c, _ in cols),
              "SIZE " + " ".join(["8"] * m), "TYPE " + " ".join(["F"] * m), "COUNT " + " ".join(["1"] * m),
              f"WIDTH {n}", "HEIGHT 1", "VIEWPOINT 0 0 0 1 0 0 0", f"POINTS {n}", f"DATA {'binary' if binary else 'ascii'}"]
    data = np.column_stack([c for _, c in cols]).astype(np.float64)
    fh.write(("\n".join(header) + "\n").encode("ascii"))
    if binary:
        fh.write(data.astype("<f8").tobytes())
    else:
        np.savetxt(fh, data, fmt="%.17g")


def _write_text(fh, points, normals, fields, fmt: str):
    cols = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else []) + list(fields)
    data = np.column_stack([points] + ([normals] if normals is not None else [])
                           + [np.asarray(v, np.float64) for v in fields.values()])
    delim = "," if fmt == "csv" else " "
    # pts: a header line of names keeps normals from being read as the PTS colour columns
    header = delim.join(cols) if (fmt == "csv" or fields or (fmt == "pts" and normals is not None)) else ""
    np.savetxt(fh, data, fmt="%.17g", delimiter=delim, header=header, comments="")


def _write_obj(fh, points, normals, fields):
    colour = [k for k in ("red", "green", "blue") if k in fields]
    other = [k for k in fields if k not in ("red", "green", "blue")]
    if other or (colour and len(colour) != 3):
        raise ValueError(f"OBJ files cannot hold per-point fields other than red, green, blue colours, got "
                         f"{sorted(fields)}; use ply, pcd, csv, npz, las or vtk")
    fh.write(b"# written by manifold_sph\n")
    if colour:
        rgb = np.column_stack([np.asarray(fields[k], np.float64) for k in colour])
        np.savetxt(fh, np.hstack([points, rgb]), fmt="v %.17g %.17g %.17g %.17g %.17g %.17g")
    else:
        np.savetxt(fh, points, fmt="v %.17g %.17g %.17g")
    if normals is not None:
        np.savetxt(fh, normals, fmt="vn %.17g %.17g %.17g")


#: LAS standard dimensions a field of the same name goes to (with its LAS type).
_LAS_STANDARD = {"intensity": np.uint16, "classification": np.uint8, "red": np.uint16, "green": np.uint16,
                 "blue": np.uint16, "gps_time": np.float64, "return_number": np.uint8,
                 "number_of_returns": np.uint8, "user_data": np.uint8, "point_source_id": np.uint16}


def _write_las(tmp, points, normals, fields, compress: bool):
    """LAS 1.4, point format 7 (with colour) or 6; other fields and normals as float64 extra bytes.

    Coordinates are stored as 32-bit integers: the scale is chosen so that the
    largest extent spans about 2^30 steps (relative precision ~1e-9)."""
    import laspy

    fmt = 7 if any(k in fields for k in ("red", "green", "blue")) else 6
    header = laspy.LasHeader(point_format=fmt, version="1.4")
    lo, hi = points.min(axis=0), points.max(axis=0)
    extent = float(np.max(hi - lo)) or max(1.0, float(np.abs(lo).max()))
    header.offsets = (lo + hi) / 2
    header.scales = np.full(3, extent / 2**30)
    extra = {k: v for k, v in fields.items() if k not in _LAS_STANDARD}
    if normals is not None:
        extra = {"nx": normals[:, 0], "ny": normals[:, 1], "nz": normals[:, 2], **extra}
    for name in extra:
        if len(name) > 32:
            raise ValueError(f"LAS extra dimension names hold at most 32 characters, got {name!r}")
    header.add_extra_dims([laspy.ExtraBytesParams(name=k, type=np.float64) for k in extra])
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    for name, typ in _LAS_STANDARD.items():
        if name in fields:
            v = np.asarray(fields[name])
            info = np.iinfo(typ) if np.issubdtype(typ, np.integer) else None
            if info is not None and (np.any(v != np.round(v)) or v.min() < info.min or v.max() > info.max):
                raise ValueError(f"field {name!r} goes to the LAS dimension of type {np.dtype(typ).name}: its values must "
                                 f"be integers in [{info.min}, {info.max}], got range [{v.min()}, {v.max()}]")
            las[name] = v.astype(typ)
    for name, v in extra.items():
        las[name] = np.asarray(v, dtype=np.float64)
    with open(tmp, "wb") as fh:
        las.write(fh, do_compress=compress)


def write_format(tmp: Path, fmt: str, points: np.ndarray, normals: np.ndarray | None, flat: dict[str, np.ndarray],
                 raw_fields: dict[str, np.ndarray], binary: bool, cloud_for_vtk: PointCloud | np.ndarray) -> None:
    """Write the data in format ``fmt`` to the temporary file ``tmp``."""
    if fmt == "vtk":
        from .convert import to_pyvista

        to_pyvista(cloud_for_vtk, raw_fields).save(str(tmp), binary=binary)
        return
    if fmt in ("las", "laz"):
        _write_las(tmp, points, normals, flat, compress=fmt == "laz")
        return
    with open(tmp, "wb") as fh:
        if fmt == "ply":
            _write_ply(fh, points, normals, flat, binary)
        elif fmt == "pcd":
            _write_pcd(fh, points, normals, flat, binary)
        elif fmt in ("xyz", "csv", "pts"):
            _write_text(fh, points, normals, flat, fmt)
        elif fmt == "obj":
            _write_obj(fh, points, normals, flat)
        elif fmt == "npy":
            if flat:
                raise ValueError("NPY files cannot hold per-point fields; use npz")
            np.save(fh, points if normals is None else np.hstack([points, normals]))  # a file object: no suffix added
        elif fmt == "npz":
            np.savez(fh, points=points, **({"normals": normals} if normals is not None else {}), **raw_fields)
        else:  # pragma: no cover - FORMATS and this list agree
            raise ValueError(f"no writer for format {fmt!r}")
