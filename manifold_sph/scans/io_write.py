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
from typing import TYPE_CHECKING, Any

import numpy as np

from .io_lidar import import_laspy
from .io_read import NORMAL_NAMES

if TYPE_CHECKING:
    from ..pointcloud import PointCloud

__all__ = ["LAS_PRECISION", "atomic_target", "check_field_names", "las_scales", "write_format"]


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
_LAS_STANDARD: dict[str, type[np.number]] = {"intensity": np.uint16, "classification": np.uint8, "red": np.uint16, "green": np.uint16,
                 "blue": np.uint16, "gps_time": np.float64, "return_number": np.uint8,
                 "number_of_returns": np.uint8, "user_data": np.uint8, "point_source_id": np.uint16}

#: The other dimensions of LAS point formats 6 and 7 (bit fields and the scan angle, which this writer
#: leaves at zero): a field of one of these names is refused rather than lost.
_LAS_OTHER = ("x", "y", "z", "synthetic", "key_point", "withheld", "overlap", "scanner_channel",
              "scan_direction_flag", "edge_of_flight_line", "classification_flags", "scan_angle", "nir")

#: Column names the readers give a meaning: the coordinates and every normal trio they recognise.
_COORDINATES = ("x", "y", "z")
_NORMAL_COMPONENTS = tuple(c for trio in NORMAL_NAMES for c in trio)


def check_field_names(fmt: str, fields: dict, has_normals: bool) -> None:
    """Refuse field names that the file's reader would read as something else.

    In PLY, PCD, XYZ / CSV / PTS and LAS / LAZ files fields are columns next to the coordinates
    and normals: a field named like a coordinate or a normal component (``x``, ``nx``,
    ``normal_x``... in any case) would collide with them (the reader refuses a name twice) or,
    written without normals, be read back as normals; two fields whose names differ only in case
    collide in the readers too (they compare names case-insensitively). LAS / LAZ also refuse the
    names of their point format's dimensions that this writer does not fill.

    Examples
    --------
    >>> check_field_names("ply", {"u": None}, has_normals=True)
    >>> check_field_names("ply", {"nx": None}, has_normals=True)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: field name 'nx' would collide with the normals' column 'nx' in a PLY file ...; rename the field, e.g. 'nx_field'
    """
    if fmt not in ("ply", "pcd", "xyz", "csv", "pts", "las", "laz"):
        return
    seen: dict[str, str] = {}
    for name in fields:
        low = name.lower()
        if low in _COORDINATES or low in _NORMAL_COMPONENTS:
            what = (f"the coordinate column {low!r}" if low in _COORDINATES else
                    f"the normals' column {low!r}" if has_normals else "a normal component (written without normals, "
                    "a trio of these is read back as the normals)")
            raise ValueError(
                f"field name {name!r} would collide with {what} in a {fmt.upper()} file (its reader takes x, y, z and "
                f"{', '.join(_NORMAL_COMPONENTS)} by name, in any case); rename the field, e.g. {name + '_field'!r}"
                + ("" if has_normals or low in _COORDINATES else ", or pass normals as the cloud's normals")
            )
        if fmt in ("las", "laz") and low in _LAS_OTHER:
            raise ValueError(f"field name {name!r} is a dimension of the LAS point format that this writer leaves at "
                             f"zero; rename the field, e.g. {name + '_field'!r} (fields named {sorted(_LAS_STANDARD)} "
                             "fill those dimensions)")
        if low in seen:
            raise ValueError(f"field names {seen[low]!r} and {name!r} differ only in case: the readers compare names "
                             "case-insensitively and would refuse the file; rename one of them")
        seen[low] = name


#: LAS coordinates are written to within this fraction of the cloud's median nearest-neighbour distance.
LAS_PRECISION = 1e-3

#: The largest integer coordinate used (LAS stores signed 32-bit integers; 2^31 - 1 is their largest).
_LAS_STEPS = 2**30


def las_scales(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(offsets, scales)`` of LAS coordinates for ``points``, or ValueError when LAS cannot hold them.

    LAS stores ``x = X * scale + offset`` with ``X`` a 32-bit integer: the offsets are the centre of
    the bounding box and each axis' scale its half-extent over 2^30 (the finest that fits). The
    points are then quantised and checked: every coordinate must come back within
    :data:`LAS_PRECISION` times the median nearest-neighbour distance, and no two distinct points
    may land on one. A cloud of small spacing spread over a large extent (one stray point far
    away) fails this, and the error says so rather than writing points on top of each other.
    """
    from scipy.spatial import cKDTree

    lo, hi = points.min(axis=0), points.max(axis=0)
    offsets = (lo + hi) / 2
    extent = hi - lo
    big = float(extent.max())
    fallback = big if big > 0 else max(1.0, float(np.abs(lo).max()))
    scales = np.where(extent > 0, extent, fallback) / (2 * _LAS_STEPS) * 1.0000001
    q = np.round((points - offsets) / scales).astype(np.int64)
    back = q * scales + offsets
    err = float(np.abs(back - points).max())
    n = points.shape[0]
    sample = points[np.linspace(0, n - 1, min(n, 10000)).round().astype(np.int64)] if n > 1 else points
    spacing = float(np.median(cKDTree(points).query(sample, k=2)[0][:, 1])) if n > 1 else np.inf
    key = np.lexsort(q.T[::-1])
    same = np.all(q[key[1:]] == q[key[:-1]], axis=1)
    merged = int(same.sum()) - int(np.all(points[key[1:]] == points[key[:-1]], axis=1)[same].sum())
    if merged or not err <= LAS_PRECISION * spacing:
        far = ""
        if np.isfinite(spacing) and spacing > 0:
            centre = np.median(points, axis=0)
            r = np.linalg.norm(points - centre, axis=1)
            out = int((r > 10 * np.quantile(r, 0.99) + 1e3 * spacing).sum())
            far = f"; {out} point(s) lie far from the rest (beyond 10 times the 99th-percentile radius)" if out else ""
        raise ValueError(
            f"LAS cannot hold this cloud: it stores coordinates as 32-bit integers of one scale per axis, and the cloud "
            f"spans {big:.3g} while its points are {spacing:.3g} apart (median nearest-neighbour distance), so they "
            f"would be stored only to within {err:.3g} ({err / spacing if spacing > 0 else np.inf:.2g} spacings, "
            f"more than {LAS_PRECISION:g})" + (f" and {merged} point(s) would land on others" if merged else "")
            + f"{far}; remove the far points (manifold_sph.scans.cleaning.remove_outliers) or write a format of "
            "doubles (ply, pcd, npz)"
        )
    return offsets, scales


def _write_las(tmp, points, normals, fields, compress: bool):
    """LAS 1.4, point format 7 (with colour) or 6; other fields and normals as float64 extra bytes.

    Coordinates are stored as 32-bit integers: the scale is chosen so that each axis' extent spans
    2^31 steps (relative precision ~5e-10), checked against the point spacing (:func:`las_scales`)."""
    laspy = import_laspy("writing LAS/LAZ files")

    fmt = 7 if any(k in fields for k in ("red", "green", "blue")) else 6
    header = laspy.LasHeader(point_format=fmt, version="1.4")
    header.offsets, header.scales = las_scales(points)
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
            info = np.iinfo(typ) if issubclass(typ, np.integer) else None
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
    check_field_names(fmt, flat if flat else raw_fields, normals is not None)
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
            arrays: dict[str, Any] = {"points": points, **({"normals": normals} if normals is not None else {}), **raw_fields}
            np.savez(fh, **arrays)
        else:  # pragma: no cover - FORMATS and this list agree
            raise ValueError(f"no writer for format {fmt!r}")
