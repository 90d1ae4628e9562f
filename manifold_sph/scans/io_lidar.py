"""LAS/LAZ (laspy) and E57 (pye57) readers behind :func:`manifold_sph.scans.io.read`.

Both libraries are optional extras (``las``, ``e57``); a missing one is a clear ImportError
naming the extra. LAS headers are checked against the records before the first chunk is
trusted (a short header count is an error, never a silently cut cloud).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from .io_read import NORMAL_NAMES, ReadError

if TYPE_CHECKING:
    from .io_read import Reading

__all__ = ["read_las_chunks", "read_las", "read_e57", "import_laspy"]

# ----------------------------------------------------------------------------
# LAS / LAZ (laspy)
# ----------------------------------------------------------------------------
_LAS_SKIP = {"X", "Y", "Z"}


def import_laspy(purpose: str = "reading LAS/LAZ files") -> ModuleType:
    """The ``laspy`` module (with its LAZ backend ``lazrs``), or an ImportError naming the extra to install."""
    try:
        import laspy
    except ImportError:
        raise ImportError(f"{purpose} needs the optional packages laspy and lazrs: pip install 'manifold-sph[las]' "
                          "(or pip install 'laspy[lazrs]')") from None
    return laspy


def _laz_record_count(path, header) -> tuple[int, bool] | None:
    """``(count, exact)``: the number of point records the LAZ chunks of ``path`` hold (``exact``
    False: at least that many), or None when the file does not say.

    Variable-size chunks list their point counts in the chunk table; fixed-size chunks of the
    layered compressor (point formats 6 to 10) store theirs after each chunk's first, raw point;
    for the point-wise compressor (formats 0 to 5) the chunk table bounds the count from below,
    ``(chunks - 1) * chunk_size + 1``, which is returned."""
    import struct

    try:
        import lazrs
    except ImportError:  # pragma: no cover - laspy[lazrs] brings it
        return None
    vlr = next((v for v in header.vlrs if type(v).__name__ == "LasZipVlr"), None)
    if vlr is None:
        return None
    raw = vlr.record_data_bytes()
    lz = lazrs.LazVlr(raw)
    start = int(header.offset_to_point_data)
    with open(path, "rb") as fh:
        fh.seek(start)
        table = lazrs.read_chunk_table(fh, lz)
    if not table:
        return None
    if lz.uses_variable_size_chunks():
        return int(sum(int(c) for c, _ in table)), True
    size = int(lz.chunk_size())
    compressor = struct.unpack_from("<H", raw, 0)[0]
    if compressor != 3:  # point-wise chunks: only a lower bound
        return (len(table) - 1) * size + 1, False
    total, pos = 0, start + 8  # the chunk table's offset first, then the chunks
    record = int(header.point_format.size)
    with open(path, "rb") as fh:
        for _, nbytes in table:
            fh.seek(pos + record)
            word = fh.read(4)
            if len(word) < 4:
                return None
            total += struct.unpack("<I", word)[0]
            pos += int(nbytes)
    return total, True


def _las_split(path, points, dims: dict):
    """Normals from extra dimensions nx/ny/nz (or normal_x...), the other dimensions as fields."""
    lower = {k.lower(): k for k in dims}
    normals = None
    for trio in NORMAL_NAMES:
        if all(c in lower for c in trio):
            normals = np.column_stack([np.asarray(dims.pop(lower[c]), dtype=np.float64) for c in trio])
            break
    return points, normals, dims


def read_las_chunks(path: str | os.PathLike[str],
                    chunk_size: int = 1_000_000) -> Iterator[tuple[np.ndarray, dict[str, np.ndarray]]]:
    """Iterate over a LAS/LAZ file in chunks of at most ``chunk_size`` points.

    Yields ``(points, fields)``: (n, 3) float64 scaled coordinates and a dict of
    the other dimensions (intensity, classification, red, green, blue, gps_time,
    extra bytes...) for the chunk. Memory stays bounded by one chunk. A header whose
    point count disagrees with the records the file holds is a :class:`ReadError`
    before the first chunk.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from manifold_sph.scans import io
    >>> from manifold_sph.reference import shapes
    >>> path = os.path.join(tempfile.mkdtemp(), "s.laz")
    >>> io.write(path, shapes.sphere(50), fields={"intensity": np.arange(50)})
    >>> [(len(p), int(f["intensity"][-1])) for p, f in read_las_chunks(path, chunk_size=20)]
    [(20, 19), (20, 39), (10, 49)]
    """
    from .._validation import check_int

    laspy = import_laspy()
    chunk_size = check_int("chunk_size", chunk_size, minimum=1)
    try:
        reader = laspy.open(str(path))
    except Exception as exc:  # laspy raises its own LaspyException and others
        raise ReadError(path, f"laspy could not read it ({type(exc).__name__}: {exc})") from None
    with reader:
        _check_las_records(path, reader.header)  # a header count that disagrees with the records: never short
        try:
            for pts in reader.chunk_iterator(chunk_size):
                names = [d for d in pts.point_format.dimension_names if d not in _LAS_SKIP]
                xyz = np.column_stack([np.asarray(pts.x), np.asarray(pts.y), np.asarray(pts.z)]).astype(np.float64)
                yield xyz, {d: np.asarray(pts[d]) for d in names}
        except ReadError:
            raise
        except Exception as exc:
            raise ReadError(path, f"laspy could not read it ({type(exc).__name__}: {exc})") from None


def _check_las_records(path, h) -> int:
    """The header's point count of the open file ``path`` (header ``h``), checked against the records the
    file holds (uncompressed: its size; LAZ: :func:`_laz_record_count`); ReadError when they disagree."""
    n = int(h.point_count)
    compressed = bool(h.are_points_compressed) if hasattr(h, "are_points_compressed") else False
    need = int(h.offset_to_point_data) + n * int(h.point_format.size)
    evlr = int(getattr(h, "start_of_first_evlr", 0) or 0) if int(getattr(h, "number_of_evlrs", 0) or 0) else 0
    size = Path(path).stat().st_size
    if not compressed and need > size:
        raise ReadError(path, f"file truncated: the header declares {n} points ({need} bytes with the header), "
                              f"the file holds {size} bytes")
    end = evlr or size  # the point records end where the extended VLRs start, or at the end of the file
    if not compressed and end - need >= int(h.point_format.size):
        raise ReadError(path, f"the file holds {(end - need) // int(h.point_format.size)} point records more than "
                              f"the header's count {n}: the header count is too small")
    if compressed:
        try:
            held = _laz_record_count(path, h)
        except Exception as exc:  # noqa: BLE001 - a damaged chunk table, whatever lazrs raises
            raise ReadError(path, f"its LAZ chunk table could not be read ({type(exc).__name__}: {exc})") from None
        if held is not None and held[0] > n:
            raise ReadError(path, f"the file's compressed chunks hold {'at least ' if not held[1] else ''}{held[0]} "
                                  f"point records, more than the header's count {n}: the header count is too small")
    return n


def read_las(path: str | os.PathLike[str]) -> Reading:
    laspy = import_laspy()

    try:
        with laspy.open(str(path)) as reader:
            n = int(reader.header.point_count)
    except Exception as exc:
        raise ReadError(path, f"laspy could not read it ({type(exc).__name__}: {exc})") from None
    if n == 0:
        raise ReadError(path, "the file holds no points (its header's point count is 0)")
    pts: list[np.ndarray] = []
    cols: dict[str, list[np.ndarray]] = {}  # each field's chunks
    for xyz, f in read_las_chunks(path, chunk_size=max(1, min(n, 2_000_000))):
        pts.append(xyz)
        for k, v in f.items():
            cols.setdefault(k, []).append(v)
    got = sum(len(p) for p in pts)
    if got != n:
        raise ReadError(path, f"the header declares {n} points, the file holds {got}")
    points = np.concatenate(pts)
    dims = {k: np.concatenate(v) for k, v in cols.items()}
    points, normals, fields = _las_split(path, points, dims)
    return points, normals, fields, None


# ----------------------------------------------------------------------------
# E57 (pye57, optional)
# ----------------------------------------------------------------------------
def read_e57(path: str | os.PathLike[str]) -> Reading:
    """Every scan of an E57 file in world coordinates (each scan's pose applied, spherical scans
    converted, invalid points dropped); intensity and colours as fields, ``scan`` the scan index
    when there are several. Needs the optional package pye57."""
    try:
        import pye57
    except ImportError:
        raise ImportError(f"reading {str(path)!r} (E57) needs the package pye57: pip install pye57") from None
    try:
        e57 = pye57.E57(str(path))
    except Exception as exc:  # libE57Format raises its own exception types
        raise ReadError(path, f"pye57 could not read it ({type(exc).__name__}: {exc})") from None
    try:
        scans = []
        for i in range(e57.scan_count):
            d = e57.read_scan(i, intensity=True, colors=True, transform=True, ignore_missing_fields=True)
            scans.append(d)
    except Exception as exc:
        raise ReadError(path, f"pye57 could not read its scans ({type(exc).__name__}: {exc})") from None
    finally:
        close = getattr(e57, "close", None)
        if close is not None:
            close()
    if not scans:
        raise ReadError(path, "the file holds no scans")
    points = np.concatenate([np.column_stack([d["cartesianX"], d["cartesianY"], d["cartesianZ"]]) for d in scans])
    names = {"intensity": "intensity", "colorRed": "red", "colorGreen": "green", "colorBlue": "blue"}
    fields = {}
    for key, name in names.items():
        if all(key in d for d in scans):
            fields[name] = np.concatenate([np.asarray(d[key]) for d in scans])
    if len(scans) > 1:
        fields["scan"] = np.concatenate([np.full(len(d["cartesianX"]), i) for i, d in enumerate(scans)])
    return points.astype(np.float64), None, fields, None
