"""Tiled, out-of-core builds on Dask: :class:`TiledSurface` (docs/distributed.md).

Every operator of a :class:`~manifold_sph.Surface` is local: the row of particle ``i``
needs only the particles inside its support, their area elements (which need *their*
neighbours) and the normals of all of these. So the cloud is cut into spatial tiles
(a k-d split to ``tile_points`` points, or a regular grid), each tile is grown by a
halo wide enough for that chain of local steps, and each tile is built by the
single-machine :class:`~manifold_sph.Surface` on tile + halo on a Dask worker,
keeping only the rows of its own particles. After the build every tile checks that
each of its own rows depends on halo particles whose data are complete (their whole
kernel support, k-nearest-neighbour ball and, for estimated normals, the balls of the
jet fit and its two refits lie inside tile + halo); a tile that fails the check is
built again with a wider halo. The rows kept are then those of the single-process
build with the same options, to round-off.

What is not local is refused or handled globally:

- ``area="numerical"`` (one sparse solve over the whole cloud) is refused; use
  ``"shepard"`` (the default here) or ``"geometric"`` with ``total_area``.
- The uniform smoothing length (``h=None``) is fitted once, on the driver, exactly as
  :class:`~manifold_sph.Surface` fits it.
- Estimated normals: each tile fits and orients its normals consistently; the tiles'
  signs are made to agree through the particles their halos share, and each
  connected group of tiles is then turned outward by the winding-number check of
  :func:`manifold_sph.normals.orient_normals` on a subsample.

Results are Dask arrays in *tile order* (one chunk per tile; :attr:`TiledSurface.order`
maps them to the input order), written out with :meth:`TiledSurface.to_npy` (input
order) or :meth:`TiledSurface.to_zarr`.
"""

from __future__ import annotations

import hashlib
import json
import os
import resource
import shutil
import tempfile
import time
import traceback
import warnings
from collections import OrderedDict
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ._validation import as_field, as_points, check_bool, check_in, check_int, check_positive
from .pointcloud import PointCloud

__all__ = ["TiledSurface", "TileBuildError", "SURFACE_OPTIONS", "LOCAL_AREAS"]

#: Options passed on to :class:`~manifold_sph.Surface` (all others are refused).
SURFACE_OPTIONS = ("scheme", "kernel", "neighbors", "h", "area", "normal_threshold", "total_area", "max_condition")

#: Area elements computed from each particle's neighbourhood alone (exact on tiles).
LOCAL_AREAS = ("shepard", "geometric")

#: Schedulers of :class:`TiledSurface` when no client is given.
SCHEDULERS = ("distributed", "synchronous", "threads")

#: Halo widenings tried by a tile whose rows are not all complete.
_MAX_ATTEMPTS = 5
_WIDEN = 1.6
#: Points of the subsample that decides the outward orientation of estimated normals.
_ORIENT_SAMPLE = 10000
#: Points of the subsample that scales the first halo guess with ``h="adaptive"`` (2D density scaling).
_H_GUESS_SAMPLE = 200_000
_FORMAT = 1  # version of the tile files


class TileBuildError(RuntimeError):
    """One or more tiles failed to build; ``.failures`` lists ``(index, bounding box, message)``."""

    def __init__(self, message: str, failures: list):
        super().__init__(message)
        self.failures = failures


# ----------------------------------------------------------------------------- tiling
def _kd_tiles(pts: np.ndarray, tile_points: int, lo: np.ndarray, hi: np.ndarray):
    """k-d split at medians along the box's longest side until every leaf holds at most ``tile_points``.

    Returns the permutation (leaves in depth-first order, contiguous) and the leaf boxes (T, 2, 3).
    """
    order, boxes = [], []
    stack = [(np.arange(pts.shape[0]), lo.copy(), hi.copy())]
    while stack:
        idx, blo, bhi = stack.pop()
        if idx.size <= tile_points:
            order.append(idx)
            boxes.append(np.stack([blo, bhi]))
            continue
        ax = int(np.argmax(bhi - blo))
        c = pts[idx, ax]
        m = idx.size // 2
        part = np.argpartition(c, m)
        left, right = idx[part[:m]], idx[part[m:]]
        cut = 0.5 * (float(c[part[:m]].max()) + float(c[part[m:]].min()))
        lhi, rlo = bhi.copy(), blo.copy()
        lhi[ax] = rlo[ax] = cut
        stack.append((right, rlo, bhi))  # popped after the left half: depth-first, left first
        stack.append((left, blo, lhi))
    return order, np.array(boxes)


def _grid_tiles(pts: np.ndarray, grid, lo: np.ndarray, hi: np.ndarray):
    """A regular ``nx x ny x nz`` grid over the bounding box (cells may be empty or thinner than the support)."""
    g = np.asarray(grid, dtype=np.int64)
    span = np.where(hi > lo, hi - lo, 1.0)
    cell = np.minimum(((pts - lo) / span * g).astype(np.int64), g - 1)
    lin = (cell[:, 0] * g[1] + cell[:, 1]) * g[2] + cell[:, 2]
    srt = np.argsort(lin, kind="stable")
    counts = np.bincount(lin, minlength=int(g.prod()))
    starts = np.concatenate([[0], np.cumsum(counts)])
    order, boxes = [], []
    edges = [lo[a] + (hi[a] - lo[a]) * np.arange(g[a] + 1) / g[a] for a in range(3)]
    for i in range(g[0]):
        for j in range(g[1]):
            for k in range(g[2]):
                t = (i * g[1] + j) * g[2] + k
                order.append(srt[starts[t] : starts[t + 1]])
                boxes.append([[edges[0][i], edges[1][j], edges[2][k]], [edges[0][i + 1], edges[1][j + 1], edges[2][k + 1]]])
    return order, np.array(boxes, dtype=np.float64)


def _margin(p: np.ndarray, elo: np.ndarray, ehi: np.ndarray, glo: np.ndarray, ghi: np.ndarray) -> np.ndarray:
    """Distance from each point to the faces of the box ``[elo, ehi]`` that lie inside the cloud's bounding box.

    Faces on or beyond the bounding box bound nothing (no point lies beyond them): they count as infinitely far.
    """
    m = np.full(p.shape[0], np.inf)
    for a in range(3):
        if elo[a] > glo[a]:
            m = np.minimum(m, p[:, a] - elo[a])
        if ehi[a] < ghi[a]:
            m = np.minimum(m, ehi[a] - p[:, a])
    return m


def _all_rows(ok: np.ndarray, indptr: np.ndarray, indices: np.ndarray, rows: int) -> np.ndarray:
    """``out[i] = all(ok[indices[indptr[i]:indptr[i+1]]])`` for the first ``rows`` rows (rows are non-empty)."""
    if rows == 0:
        return np.zeros(0, dtype=bool)
    vals = ok[indices[: indptr[rows]]].astype(np.int8)
    return np.minimum.reduceat(vals, indptr[:rows]).astype(bool)


# ----------------------------------------------------------------------------- per-tile work (on workers)
_TILE_CACHE: OrderedDict = OrderedDict()  # (path, mtime, array name) -> array


def _cache_bytes() -> int:
    return int(float(os.environ.get("MANIFOLD_SPH_TILE_CACHE_MB", 512)) * 2**20)


class _Tile:
    """Lazy view of a finished tile's file: arrays are read on first use and kept in a per-process
    cache of at most ``MANIFOLD_SPH_TILE_CACHE_MB`` (512 MB by default), least recently used first out."""

    def __init__(self, path: str):
        self.path = path
        self.stamp = os.path.getmtime(path)
        with np.load(path, allow_pickle=False) as z:
            self.n = int(z["n_own"])
            self.ns = int(z["cols"].size)

    def __getitem__(self, name: str):
        key = (self.path, self.stamp, name)
        if key in _TILE_CACHE:
            _TILE_CACHE.move_to_end(key)
            return _TILE_CACHE[key]
        with np.load(self.path, allow_pickle=False) as z:
            if name in ("lap", "dx", "dy"):
                val = sp.csr_matrix((z[name + "_data"], z[name + "_indices"], z[name + "_indptr"]), shape=(self.n, self.ns))
                size = val.data.nbytes + val.indices.nbytes + val.indptr.nbytes
            else:
                val = z[name]
                size = val.nbytes
        budget = _cache_bytes()
        if size <= budget:
            _TILE_CACHE[key] = val
            _CACHE_SIZE[key] = size
            while sum(_CACHE_SIZE.values()) > budget:
                old, _ = _TILE_CACHE.popitem(last=False)
                del _CACHE_SIZE[old]
        return val


_CACHE_SIZE: dict = {}


def _load_tile(path: str) -> _Tile:
    return _Tile(path)


def _tile_surface(spts, snrm, opts, normal_options, estimate):
    """``(Surface, normals used)`` on tile + halo; normals estimated with a consistent orientation if asked."""
    from .normals import estimate_normals
    from .surface import Surface

    if estimate:
        snrm = estimate_normals(spts, orient="consistent", **normal_options)
    s = Surface(spts, snrm, **opts)
    return s, snrm


def _dependency_k(k: int, normal_options: dict) -> int:
    """Nearest neighbours a normal depends on: the fit's ``k``, and with ``refine`` (the default) the
    ``ROW_K`` nearest of steps 2b and 7 (normals.tuning; rows lying on a line search further, rarely)."""
    from .normals import tuning

    return max(int(k), tuning.ROW_K) if normal_options.get("refine", True) else int(k)


def _complete_rows(s, spts, n_own, margin, opts, normal_options, estimate, kq):
    """Which own rows are complete (their result equals the whole cloud's), and the reach they need.

    A particle's own data are complete when the ball they come from lies inside
    tile + halo (``margin`` >= its radius); the checks follow the chain
    normals (jet fit, two refits) -> smoothing length -> neighbourhood (the
    normal filter looks at every point in the support) -> area element -> row.
    """
    from .normals import DEFAULT_JET_K

    ns = spts.shape[0]
    nb = s.neighborhood
    reach = nb.support * nb.h
    tree = s._tree
    kn = 0
    if estimate or opts.get("h") == "adaptive":
        kn = kq
    if kn:
        dist, knn = tree.query(spts, k=min(kn, ns))
    if estimate:
        k_est = normal_options.get("k")
        if k_est is None:
            k_est = DEFAULT_JET_K[normal_options.get("degree") or 2] if normal_options.get("method", "jet") == "jet" else 16
        k_graph = min(max(_dependency_k(k_est, normal_options), 10), ns)
        ok = margin >= dist[:, k_graph - 1]  # the jet fit's, the orientation graph's and steps 2b/7's ball
        ptr = np.arange(0, ns * k_est + 1, k_est)
        for _ in range(2):  # the two refits use the neighbours' previous normals
            ok = ok & _all_rows(ok, ptr, np.ascontiguousarray(knn[:, :k_est]).ravel(), ns)
        normal_ok = ok
    else:
        normal_ok = np.ones(ns, dtype=bool)
    h_ok = np.ones(ns, dtype=bool)
    if opts.get("h") == "adaptive":
        h_ok = margin >= dist[:, min(s.neighbors, ns - 1)]
    wid = np.asarray(s.widened)
    if wid.size:  # widened supports came from a 4 * neighbors nearest search
        kw = min(4 * s.neighbors, ns)
        dw, _ = tree.query(spts[wid], k=kw)
        h_ok[wid] &= margin[wid] >= dw[:, -1]
    bad = np.flatnonzero(~normal_ok)
    if bad.size:
        d_bad, _ = cKDTree(spts[bad]).query(spts, k=1)
    else:
        d_bad = np.full(ns, np.inf)
    nbhd_ok = (margin >= reach) & h_ok & (d_bad >= reach)
    row_ok = nbhd_ok[:n_own]
    if s.scheme.uses_area and s._area_args[0] == "shepard":
        row_ok = row_ok & _all_rows(nbhd_ok, nb.indptr, nb.indices, n_own)
    return row_ok, float(reach[:n_own].max()) if n_own else 0.0


def _build_tile(spec: dict) -> dict:
    """Build one tile (tile + halo on one worker), save its own rows, return a small summary.

    Never raises: a failure comes back as ``{"error": ...}`` for the driver to report.
    """
    t0 = time.perf_counter()
    t = spec["tile"]
    try:
        if spec.get("_fail"):
            raise RuntimeError("failure injected for testing (_fail_tiles)")
        out = spec["path"]
        if spec["reuse"] and os.path.exists(out):
            with np.load(out, allow_pickle=False) as z:
                if str(z["key"]) == spec["key"]:
                    return json.loads(str(z["summary"])) | {"reused": True}
        from . import threads

        with threads.limit(spec["threads"]):
            summary = _build_tile_arrays(spec)
        summary["seconds"] = time.perf_counter() - t0
        summary["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        return summary
    except Exception as exc:  # reported with the tile's index and box by the driver
        return {"tile": t, "error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc()}


def _build_tile_arrays(spec: dict) -> dict:
    t, lo, hi = spec["tile"], spec["lo"], spec["hi"]
    n_own = hi - lo
    pts_all = np.load(spec["points"], mmap_mode="r")
    nrm_all = None if spec["normals"] is None else np.load(spec["normals"], mmap_mode="r")
    h_all = None if spec["h_file"] is None else np.load(spec["h_file"], mmap_mode="r")
    box = np.asarray(spec["box"])
    glo, ghi = np.asarray(spec["bbox"][0]), np.asarray(spec["bbox"][1])
    opts = dict(spec["options"])
    estimate = nrm_all is None
    halo = spec["halo"]
    base = {"tile": t, "n_own": n_own, "key": spec["key"]}
    if n_own == 0:
        _save_empty(spec)
        return base | {"n_halo": 0, "halo": halo, "attempts": 0, "contrib": [t], "warnings": [], "fallback": {},
                       "shared_idx": [], "gershgorin": 0.0}
    boxes, bounds = np.asarray(spec["boxes"]), spec["bounds"]
    for attempt in range(1, _MAX_ATTEMPTS + 1):
        elo, ehi = box[0] - halo, box[1] + halo
        parts, contrib, gather, offset = [np.arange(lo, hi)], [t], [np.arange(n_own)], n_own
        meet = np.all((boxes[:, 0] <= ehi) & (boxes[:, 1] >= elo), axis=1)
        for u in np.flatnonzero(meet):
            ulo, uhi = int(bounds[u]), int(bounds[u + 1])
            if u == t or uhi == ulo:
                continue
            block = pts_all[ulo:uhi]
            inside = np.flatnonzero(np.all((block >= elo) & (block <= ehi), axis=1))
            if inside.size:
                parts.append(ulo + inside)
                contrib.append(u)
                gather.append(offset + inside)
                offset += uhi - ulo
        cols = np.concatenate(parts)
        spts = np.asarray(pts_all[cols])
        snrm = None if estimate else np.asarray(nrm_all[cols])
        if h_all is not None:
            opts["h"] = np.asarray(h_all[cols])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            s, snrm = _tile_surface(spts, snrm, opts, spec["normal_options"], estimate)
        margin = _margin(spts, elo, ehi, glo, ghi)
        row_ok, rmax = _complete_rows(s, spts, n_own, margin, opts, spec["normal_options"], estimate, spec["kq"])
        if row_ok.all():
            break
        halo = max(halo * _WIDEN, 1.1 * spec["chain"] * rmax)
    else:
        bad = np.flatnonzero(~row_ok)
        raise ValueError(
            f"{bad.size} own row(s) still depend on particles outside tile + halo after {_MAX_ATTEMPTS} widenings "
            f"(halo {halo:.4g}; widened supports or sparse parts?); pass a larger halo="
        )
    n_s = cols.size
    nrm_s = np.asarray(s.normals)
    L = _head_rows(s.laplacian_matrix(), n_own)
    dx, dy = (_head_rows(m, n_own) for m in s.derivative_matrices())
    # H from the shape operator's trace, u . d n/du + v . d n/dv (geometry.mean_curvature(s, "normals") on the own
    # rows only: that function builds the whole (3 N, N) gradient matrix of tile + halo, half the tile's time)
    u_own, v_own = np.asarray(s.u[:n_own]), np.asarray(s.v[:n_own])
    H_n = 0.5 * (np.einsum("ij,ij->i", u_own, dx @ nrm_s) + np.einsum("ij,ij->i", v_own, dy @ nrm_s))
    LX = L @ spts
    H_l = -0.5 * np.einsum("ij,ij->i", LX, nrm_s[:n_own])
    fallback = {k: int(np.count_nonzero(np.asarray(v) < n_own)) for k, v in s.fallback.items()}
    fallback = {k: v for k, v in fallback.items() if v}
    widened = int(np.count_nonzero(np.asarray(s.widened) < n_own))
    # row sums of |L| without scipy's abs(), which sorts the rows' entries in place
    absrow = np.bincount(np.repeat(np.arange(n_own), np.diff(L.indptr)), weights=np.abs(L.data), minlength=n_own)
    # normals of halo particles whose normals are complete: they stitch the tiles' orientations
    shared = np.arange(n_own, n_s)
    summary = base | {
        "n_halo": int(n_s - n_own), "halo": float(halo), "attempts": attempt, "contrib": [int(c) for c in contrib],
        "warnings": sorted({str(w.message).split(";")[0][:160] for w in caught}), "fallback": fallback,
        "widened": widened, "max_reach": rmax, "gershgorin": float(absrow.max()),
    }
    arrays = {
        "n_own": np.int64(n_own), "cols": cols, "gather": np.concatenate(gather), "contrib": np.array(contrib),
        "normals_s": nrm_s, "u": np.asarray(s.u[:n_own]), "v": np.asarray(s.v[:n_own]), "h": np.asarray(s.h[:n_own]),
        "dV": np.asarray(s.dV[:n_own]), "H_normals": H_n, "H_laplacian": H_l,
        "shared": cols[shared],
    }
    mats = [("lap", L)] if "laplacian" in spec["keep"] else []
    mats += [("dx", dx), ("dy", dy)] if "derivatives" in spec["keep"] else []
    for name, m in mats:
        arrays[name + "_data"], arrays[name + "_indices"], arrays[name + "_indptr"] = m.data, m.indices, m.indptr
    _save(spec, arrays, summary)
    return summary


def _head_rows(m: sp.csr_matrix, n: int) -> sp.csr_matrix:
    """The first ``n`` rows, each row's entries in their stored order (the neighbours' distance order):
    scipy's slicing may sort them, and the order of the sums is part of the result's round-off."""
    end = int(m.indptr[n])
    return sp.csr_matrix((m.data[:end], m.indices[:end], m.indptr[: n + 1]), shape=(n, m.shape[1]), copy=True)


def _save(spec, arrays, summary):
    tmp = spec["path"] + ".tmp.npz"
    np.savez(tmp, key=np.array(spec["key"]), summary=np.array(json.dumps(summary)), **arrays)
    os.replace(tmp, spec["path"])  # atomic: a killed build leaves no half-written tile


def _save_empty(spec):
    e, z3 = np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    arrays = {"n_own": np.int64(0), "cols": e, "gather": e, "contrib": np.array([spec["tile"]]), "normals_s": z3,
              "u": z3, "v": z3, "h": np.zeros(0), "dV": np.zeros(0), "H_normals": np.zeros(0),
              "H_laplacian": np.zeros(0), "shared": e}
    for name in ("lap", "dx", "dy"):
        arrays[name + "_data"], arrays[name + "_indices"], arrays[name + "_indptr"] = np.zeros(0), e.astype(np.int32), np.zeros(1, np.int32)
    summary = {"tile": spec["tile"], "n_own": 0, "key": spec["key"], "n_halo": 0, "halo": spec["halo"], "attempts": 0,
               "contrib": [spec["tile"]], "warnings": [], "fallback": {}, "widened": 0, "gershgorin": 0.0}
    _save(spec, arrays, summary)


def _tile_apply(path: str, kind: str, sign: float, extra, *chunks):
    """One tile's rows of an operator applied to the field chunks of the tiles it reads.

    ``extra``: own-row arrays of the time steps (the previous state, the initial velocity).
    """
    d = _load_tile(path)
    n = d.n
    if n == 0:
        return np.zeros((0, 3)) if kind == "gradient" else np.zeros(0)
    x = np.concatenate(chunks, axis=0)[d["gather"]]
    if kind == "laplacian":
        return d["lap"] @ x
    if kind == "gradient":
        return (d["dx"] @ x)[:, None] * d["u"] + (d["dy"] @ x)[:, None] * d["v"]
    if kind == "divergence":
        nr = d["normals_s"]
        F = x - np.einsum("ij,ij->i", x, nr)[:, None] * nr
        return np.einsum("nk,nk->n", d["u"], d["dx"] @ F) + np.einsum("nk,nk->n", d["v"], d["dy"] @ F)
    if kind == "heat":  # one explicit Euler step; ``sign`` carries k dt
        return x[:n] + sign * (d["lap"] @ x)
    if kind == "wave1":  # u1 = u0 + dt v0 + b/2 L u0; ``sign`` carries b = (c dt)^2, extra = (dt v0,)
        return x[:n] + extra[0] + 0.5 * sign * (d["lap"] @ x)
    if kind == "wave":  # u' = 2 u - prev + b L u, extra = (prev,)
        return 2 * x[:n] - extra[0] + sign * (d["lap"] @ x)
    raise ValueError(kind)  # pragma: no cover


def _tile_field(path: str, name: str, sign: float):
    d = _load_tile(path)
    if name == "normals":
        return sign * d["normals_s"][: d.n]
    if name in ("H_normals", "H_laplacian"):
        return sign * d[name]
    return d[name]


def _tile_points(points_file: str, lo: int, hi: int, func=None):
    p = np.asarray(np.load(points_file, mmap_mode="r")[lo:hi])
    return p if func is None else np.asarray(func(p), dtype=np.float64)


def _write_rows(block, path: str, order_file: str, lo: int):
    """Write one tile's rows into the input-order .npy memory map (disjoint rows per tile)."""
    idx = np.load(order_file, mmap_mode="r")[lo : lo + block.shape[0]]
    out = np.load(path, mmap_mode="r+")
    out[np.asarray(idx)] = block
    out.flush()
    return np.zeros(1)


# ----------------------------------------------------------------------------- the driver
class TiledSurface:
    """A :class:`~manifold_sph.Surface` built tile by tile on Dask workers, for clouds larger than one process holds.

    Parameters
    ----------
    source : array_like (N, 3), PointCloud, or str / Path
        Points in memory, a ``.npy`` file (read through a memory map), a LAS/LAZ file
        (read in chunks with laspy) or any file :func:`manifold_sph.scans.io.read` reads
        (with its normals, if it stores some).
    normals : array_like (N, 3), str or None
        Normals (or a ``.npy`` file of them). ``None``: taken from ``source`` when it
        has them, else estimated per tile (jet fits, consistent orientation across
        tiles, outward; see the module notes).
    tile_points : int
        Largest number of own particles of a tile (k-d split at medians).
    grid : (int, int, int), optional
        Cut the bounding box into a regular grid instead of the k-d split (tiles may
        then be empty or thinner than the kernel support; both are handled).
    halo : float, optional
        Initial halo width (length). By default from the support radius ``kappa h``
        times the number of chained local steps (neighbourhood, area elements,
        estimated normals). A tile whose own rows turn out to need more is rebuilt
        with a wider halo, so the default is only a first guess.
    client : dask.distributed.Client, optional
        Any Dask cluster (LocalCluster, dask-jobqueue on Slurm/PBS, Kubernetes).
        Workers must see ``cache_dir`` (a shared file system on a real cluster).
    scheduler : {"distributed", "synchronous", "threads"}
        Without ``client``: ``"distributed"`` starts a LocalCluster of ``n_workers``
        processes (one thread each) on first use; the other two run in this process.
    n_workers : int
        Workers of the LocalCluster.
    memory_limit : str or int, optional
        Memory limit per LocalCluster worker (Dask's syntax, e.g. ``"4GB"``).
    cache_dir : str or Path, optional
        Where the tiles' points and built rows live. A re-run with the same cache
        directory, cloud and options reuses every finished tile. Default: a new
        temporary directory, removed by :meth:`close`.
    progress : bool
        Show Dask's progress bar while tiles build.
    normal_options : dict, optional
        Passed to :func:`manifold_sph.estimate_normals` (``k``, ``method``, ``degree``;
        ``degree`` defaults to the scheme's Taylor degree, 2 to 4, as in ``Surface``).
    keep : tuple of {"laplacian", "derivatives"}
        The operator rows stored per tile (on disk, 12 bytes per pair and matrix):
        ``"derivatives"`` (the tangent-plane ``Dx``, ``Dy``) serve the gradient and
        divergence. Normals, ``h``, area elements and mean curvature are always kept.
    **surface_options
        ``scheme``, ``kernel``, ``neighbors``, ``h`` (None, a number, ``"adaptive"`` or
        an (N,) array), ``area`` (``"shepard"`` by default, or ``"geometric"`` with
        ``total_area``; ``"numerical"`` is refused), ``normal_threshold``,
        ``max_condition``: as for :class:`~manifold_sph.Surface`.

    Attributes
    ----------
    order : ndarray, shape (N,)
        Input index of every particle in tile order (the order of all results).
    chunks : tuple of int
        Own particles per tile.
    boxes : ndarray, shape (T, 2, 3)
        Tile boxes (low and high corners).
    report : list of dict
        Per tile: own and halo particles, halo width used, attempts, seconds, peak
        resident memory of the worker (MB), fallbacks and warnings among its own rows.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> from manifold_sph.distributed import TiledSurface
    >>> cloud = shapes.sphere(1500)
    >>> ts = TiledSurface(cloud.points, cloud.normals, tile_points=400, scheduler="synchronous")
    >>> len(ts.chunks), ts.n_points
    (4, 1500)
    >>> f = cloud.points[:, 0] * cloud.points[:, 1]
    >>> lap = ts.gather(ts.laplacian(f))                 # input order, numpy
    >>> ref = Surface(cloud.points, cloud.normals, area="shepard").laplacian(f)
    >>> bool(np.abs(lap - ref).max() <= 1e-12 * np.abs(ref).max())
    True
    >>> ts.close()
    """

    def __init__(self, source, normals=None, *, tile_points: int = 1_000_000, grid=None, halo=None, client=None,
                 scheduler: str = "distributed", n_workers: int = 2, memory_limit=None, cache_dir=None,
                 progress: bool = False, normal_options=None, keep=("laplacian", "derivatives"), _fail_tiles=(),
                 **surface_options):
        unknown = sorted(set(surface_options) - set(SURFACE_OPTIONS))
        if unknown:
            raise TypeError(f"unexpected option(s) {unknown}; TiledSurface takes the Surface options {list(SURFACE_OPTIONS)}")
        self.tile_points = check_int("tile_points", tile_points, minimum=1)
        check_in("scheduler", scheduler, SCHEDULERS)
        self.n_workers = check_int("n_workers", n_workers, minimum=1)
        self.progress = check_bool("progress", progress)
        if client is not None and not hasattr(client, "submit"):
            raise TypeError(f"client must be a dask.distributed.Client or None, got {type(client).__name__}")
        if normal_options is None:
            normal_options = {}
        if not isinstance(normal_options, dict):
            raise TypeError(f"normal_options must be a dict, got {type(normal_options).__name__}")
        bad = sorted(set(normal_options) - {"k", "method", "degree"})
        if bad:
            raise TypeError(f"normal_options takes 'k', 'method' and 'degree', got {bad}")
        self.normal_options = dict(normal_options)
        if isinstance(keep, str):
            keep = (keep,)
        keep = tuple(keep)
        for k in keep:
            check_in("keep", k, ("laplacian", "derivatives"))
        self.keep = keep
        self._client, self._own_cluster = client, None
        self.scheduler = "distributed" if client is not None else scheduler
        self.memory_limit = memory_limit
        opts = self._check_surface_options(surface_options)
        if self.normal_options.get("method", "jet") == "jet" and "degree" not in self.normal_options:
            # as Surface: jets of the scheme's Taylor degree (2 to 4)
            from .schemes import get_scheme

            self.normal_options["degree"] = int(min(max(getattr(get_scheme(opts["scheme"]), "degree", 2), 2), 4))
        # --- the work directory
        self._tmp = cache_dir is None
        self.cache_dir = Path(tempfile.mkdtemp(prefix="msph-tiles-") if cache_dir is None else cache_dir)
        if self.cache_dir.exists() and not self.cache_dir.is_dir():
            raise ValueError(f"cache_dir must be a directory, got the file {str(self.cache_dir)!r}")
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        pts, nrm = self._read_source(source, normals)
        n = pts.shape[0]
        from .pointcloud import MIN_POINTS

        if n < MIN_POINTS:
            raise ValueError(f"source must hold at least {MIN_POINTS} points, got {n}")
        if opts["neighbors"] >= n:
            raise ValueError(f"neighbors must be smaller than the number of points {n}, got {opts['neighbors']}")
        self.n_points = n
        self.normals_estimated = nrm is None
        # --- uniform h, exactly as Surface fits it (on the input order)
        h = opts["h"]
        hv_file = None
        from .kernels import get_kernel
        from .neighbors import smoothing_length_for_count

        support = get_kernel(opts["kernel"]).support
        if h is None:  # exact: the fit of Surface, on every point (a KD-tree of the whole cloud on the driver)
            opts["h"] = h_scale = smoothing_length_for_count(pts, opts["neighbors"], support)
        elif isinstance(h, str):  # "adaptive": only the first halo guess needs a scale; a strided subsample gives it
            m = min(n, _H_GUESS_SAMPLE)
            sub = np.asarray(pts[np.linspace(0, n - 1, m).round().astype(np.int64)])
            h_scale = smoothing_length_for_count(sub, min(opts["neighbors"], m - 1), support) * np.sqrt(m / n)
        elif np.ndim(h) == 0:
            h_scale = float(h)
        else:
            hv = np.asarray(h, dtype=np.float64)
            if hv.shape != (n,) or not np.all(np.isfinite(hv) & (hv > 0)):
                raise ValueError(f"h must be positive and finite with shape ({n},), got shape {hv.shape}")
            h_scale = float(hv.max())
        # --- tiles
        glo, ghi = pts.min(axis=0), pts.max(axis=0)
        if grid is None:
            parts, boxes = _kd_tiles(pts, self.tile_points, glo, ghi)
        else:
            g = np.asarray(grid)
            if g.shape != (3,) or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1 for v in grid):
                raise ValueError(f"grid must be three positive integers (nx, ny, nz), got {grid!r}")
            parts, boxes = _grid_tiles(pts, g, glo, ghi)
        self.order = np.concatenate(parts).astype(np.int64)
        self.chunks = tuple(int(p.size) for p in parts)
        self.bounds = np.concatenate([[0], np.cumsum(self.chunks)]).astype(np.int64)
        self.boxes = boxes
        self.bbox = np.stack([glo, ghi])
        # support radii chained: the row, the neighbours' area elements, and with estimated normals the jet
        # fit's k-nearest ball and its two refits (k-th neighbour distance ~ sqrt(k / neighbors) support radii,
        # times 1.5 for the spread of irregular clouds); h="adaptive" varies the radius per particle (x 1.2)
        chain = 1 + (1 if opts["area"] == "shepard" else 0)
        if nrm is None:
            chain += 3 * 1.5 * np.sqrt(self._normal_k() / opts["neighbors"])
        if isinstance(h, str):
            chain *= 1.2
        self._chain = chain
        if halo is None:
            halo = 1.1 * chain * support * h_scale
        self.halo = check_positive("halo", halo)
        # --- the tile-order copies the workers read
        key_src = hashlib.blake2b(digest_size=16)
        for arr in (pts, nrm):
            if arr is not None:
                for lo in range(0, n, 1 << 20):
                    key_src.update(np.ascontiguousarray(arr[lo : lo + (1 << 20)]).tobytes())
        if isinstance(h, np.ndarray) or (h is not None and np.ndim(h) == 1):
            key_src.update(np.asarray(h, dtype=np.float64).tobytes())
        meta = {"n": n, "options": {k: (v if isinstance(v, (str, int, float, type(None))) else repr(v)) for k, v in opts.items()},
                "normal_options": self.normal_options, "tile_points": self.tile_points, "grid": None if grid is None else list(map(int, grid)), "keep": list(keep),
                "halo": self.halo, "format": _FORMAT, "source": key_src.hexdigest()}
        self._key = hashlib.blake2b(json.dumps(meta, sort_keys=True, default=str).encode(), digest_size=16).hexdigest()
        self._points_file = str(self.cache_dir / f"points-{self._key}.npy")
        self._order_file = str(self.cache_dir / f"order-{self._key}.npy")
        self._write_sorted(self._points_file, pts)
        np.save(self._order_file, self.order)
        self._normals_file = None
        if nrm is not None:
            self._normals_file = str(self.cache_dir / f"normals-{self._key}.npy")
            self._write_sorted(self._normals_file, nrm)
        if isinstance(h, np.ndarray) or (h is not None and not isinstance(h, str) and np.ndim(h) == 1):
            hv_file = str(self.cache_dir / f"h-{self._key}.npy")
            np.save(hv_file, np.asarray(h, dtype=np.float64)[self.order])
            opts["h"] = None  # read per tile
        self._h_file = hv_file
        self.options = opts
        del pts, nrm
        # --- build
        self.tile_sign = np.ones(len(self.chunks))
        self._build(set(_fail_tiles))

    # ------------------------------------------------------------------ input
    @staticmethod
    def _check_surface_options(o: dict) -> dict:
        from .kernels import get_kernel
        from .schemes import get_scheme

        area = o.get("area", "shepard")
        if area == "numerical":
            raise ValueError(
                "area='numerical' solves one sparse system over the whole cloud and cannot be tiled exactly; "
                f"use a local one: area='shepard' (the default here) or area='geometric' with total_area="
            )
        check_in("area", area, LOCAL_AREAS)
        total_area = o.get("total_area")
        if area == "geometric":
            if total_area is None:
                raise ValueError("area='geometric' needs total_area (the surface area, > 0)")
            total_area = check_positive("total_area", total_area)
        scheme = get_scheme(o.get("scheme", "msph"))
        get_kernel(o.get("kernel", "quintic"))  # raises on an unknown kernel
        neighbors = o.get("neighbors")
        if neighbors is None:
            neighbors = scheme.default_neighbors
        neighbors = check_int("neighbors", neighbors, minimum=scheme.min_neighbors)
        h = o.get("h")
        if isinstance(h, str) and h != "adaptive":
            raise ValueError(f"h must be None, 'adaptive', a positive number or an (N,) array, got {h!r}")
        if h is not None and not isinstance(h, str) and np.ndim(h) == 0:
            h = check_positive("h", h)
        thr = o.get("normal_threshold", 0.0)
        if isinstance(thr, bool) or not isinstance(thr, (int, float, np.integer, np.floating)) or not -1.0 <= thr < 1.0:
            raise ValueError(f"normal_threshold must be a number in [-1, 1), got {thr!r}")
        out = {"scheme": o.get("scheme", "msph"), "kernel": o.get("kernel", "quintic"), "neighbors": neighbors, "h": h,
               "area": area, "normal_threshold": float(thr), "max_condition": check_positive("max_condition", o.get("max_condition", 1e8))}
        if total_area is not None:
            out["total_area"] = total_area
        return out

    def _read_source(self, source, normals):
        nrm = None
        if isinstance(source, PointCloud):
            pts, nrm = source.points, source.normals
        elif isinstance(source, (str, os.PathLike)):
            path = Path(source)
            if not path.exists():
                raise FileNotFoundError(f"source: no such file: {str(path)!r}")
            suffix = path.suffix.lower()
            if suffix == ".npy":
                pts = np.load(path, mmap_mode="r")
                if pts.ndim != 2 or pts.shape[1] != 3:
                    raise ValueError(f"source must hold an (N, 3) array, got shape {pts.shape} in {str(path)!r}")
            elif suffix in (".las", ".laz"):
                pts = self._read_las(path)
            else:
                from .scans.io import read

                cloud = read(path)
                pts, nrm = cloud.points, cloud.normals
        else:
            pts = as_points("source", source)
        if pts.dtype != np.float64 or not isinstance(pts, np.ndarray):
            pts = np.asarray(pts, dtype=np.float64)
        for lo in range(0, pts.shape[0], 1 << 20):  # finite, without loading everything at once
            if not np.all(np.isfinite(pts[lo : lo + (1 << 20)])):
                as_points("source", pts[lo : lo + (1 << 20)])
        if normals is not None:
            if isinstance(normals, (str, os.PathLike)):
                normals = np.load(normals, mmap_mode="r")
            nrm = as_points("normals", normals)
            if nrm.shape != pts.shape:
                raise ValueError(f"normals must have shape {pts.shape} to match source, got shape {nrm.shape}")
        return pts, nrm

    def _read_las(self, path: Path) -> np.ndarray:
        import laspy

        st = path.stat()
        tag = hashlib.blake2b(f"{path.resolve()}|{st.st_size}|{st.st_mtime_ns}".encode(), digest_size=8).hexdigest()
        target = str(self.cache_dir / f"las-{tag}.npy")
        with laspy.open(str(path)) as f:
            n = int(f.header.point_count)
            out = np.lib.format.open_memmap(target, mode="w+", dtype=np.float64, shape=(n, 3))
            pos = 0
            for chunk in f.chunk_iterator(1 << 20):
                m = len(chunk)
                out[pos : pos + m] = np.stack([np.asarray(chunk.x), np.asarray(chunk.y), np.asarray(chunk.z)], axis=1)
                pos += m
        out.flush()
        del out
        return np.load(target, mmap_mode="r")

    def _write_sorted(self, path: str, arr) -> None:
        if os.path.exists(path):
            return  # same key: same cloud in the same order
        tmp = path + ".tmp.npy"
        out = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float64, shape=(self.n_points, 3))
        step = 1 << 20
        for lo in range(0, self.n_points, step):
            out[lo : lo + step] = arr[self.order[lo : lo + step]]
        out.flush()
        del out
        os.replace(tmp, path)

    # ------------------------------------------------------------------ scheduling
    @property
    def client(self):
        """The Dask client (a LocalCluster is started on first use), or None for the local schedulers."""
        if self.scheduler != "distributed":
            return None
        if self._client is None:
            from dask.distributed import Client, LocalCluster

            self._own_cluster = LocalCluster(n_workers=self.n_workers, threads_per_worker=1, processes=True,
                                             memory_limit=self.memory_limit or "auto", dashboard_address=":0",
                                             silence_logs=40)
            self._client = Client(self._own_cluster, set_as_default=False)
        return self._client

    def _compute(self, *objs):
        import dask

        if self.scheduler == "distributed":
            client = self.client
            futures = client.compute(list(objs))
            if self.progress:
                from dask.distributed import progress

                progress(futures)
            return client.gather(futures)
        if self.progress:
            from dask.diagnostics import ProgressBar

            with ProgressBar():
                return list(dask.compute(*objs, scheduler=self.scheduler))
        return list(dask.compute(*objs, scheduler=self.scheduler))

    def compute(self, x):
        """Compute a Dask array (in tile order) on this surface's scheduler; returns numpy."""
        return self._compute(x)[0]

    def gather(self, x) -> np.ndarray:
        """Compute a Dask array in tile order and return it as numpy in the input order."""
        v = self.compute(x)
        out = np.empty_like(v)
        out[self.order] = v
        return out

    def _shutdown(self) -> None:
        if self._own_cluster is not None:
            self._client.close()
            self._own_cluster.close()
            self._client = self._own_cluster = None

    def close(self) -> None:
        """Shut the LocalCluster down (if this object started it) and remove a temporary cache directory."""
        self._shutdown()
        _TILE_CACHE.clear()
        _CACHE_SIZE.clear()
        if self._tmp and self.cache_dir.exists():
            shutil.rmtree(self.cache_dir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------ build
    def _normal_k(self) -> int:
        """Nearest neighbours of the normal estimation (estimate_normals' default for the options)."""
        from .normals import DEFAULT_JET_K

        k = self.normal_options.get("k")
        if k is None:
            jet = self.normal_options.get("method", "jet") == "jet"
            k = DEFAULT_JET_K[self.normal_options.get("degree") or 2] if jet else 16
        return int(_dependency_k(k, self.normal_options))

    def _tile_path(self, t: int) -> str:
        return str(self.cache_dir / f"tile-{self._key}-{t:05d}.npz")

    def _build(self, fail_tiles) -> None:
        from dask import delayed

        T = len(self.chunks)
        boxes = self.boxes
        kq = 0
        if self.normals_estimated or self.options["h"] == "adaptive":
            kq = max(self._normal_k(), 10) if self.normals_estimated else 0
            if self.options["h"] == "adaptive":
                kq = max(kq, self.options["neighbors"] + 1)
        specs = []
        blist, bnds = boxes.tolist(), self.bounds.tolist()
        for t in range(T):
            specs.append({
                "tile": t, "lo": int(self.bounds[t]), "hi": int(self.bounds[t + 1]), "box": boxes[t].tolist(),
                "bbox": self.bbox.tolist(), "boxes": blist, "bounds": bnds, "chain": self._chain, "points": self._points_file, "normals": self._normals_file,
                "h_file": self._h_file, "options": self.options, "normal_options": self.normal_options, "halo": self.halo,
                "kq": kq, "keep": self.keep, "path": self._tile_path(t), "key": f"{self._key}-{t}", "reuse": True,
                "threads": 1 if self.scheduler != "synchronous" else None, "_fail": t in fail_tiles,
            })
        tasks = [delayed(_build_tile, pure=False)(s, dask_key_name=f"msph-tile-{self._key[:8]}-{s['tile']}") for s in specs]
        try:
            results = self._compute(*tasks)
        except Exception as exc:  # a worker died (out of memory?) or the cluster failed: name the tile if the key says
            import re

            self._shutdown()
            found = re.search(r"msph-tile-[0-9a-f]+-(\d+)", str(exc))
            where = ""
            if found:
                t = int(found.group(1))
                where = (f" while building tile {t} (bounding box {np.round(boxes[t, 0], 6).tolist()} - "
                         f"{np.round(boxes[t, 1], 6).tolist()}, {self.chunks[t]} points)")
            raise TileBuildError(
                f"the tile builds failed on the cluster{where}: {type(exc).__name__}: {exc}. A worker killed for "
                "memory needs smaller tiles (tile_points) or a larger memory_limit; the finished tiles are kept in "
                f"{str(self.cache_dir)!r} (pass it as cache_dir= to reuse them)",
                [] if not found else [(t, boxes[t].tolist(), f"{type(exc).__name__}: {exc}")],
            ) from exc
        failures = [(r["tile"], boxes[r["tile"]].tolist(), r["error"]) for r in results if "error" in r]
        self.report = results
        if failures:
            self._shutdown()
            lines = [f"tile {t} (bounding box {np.round(b[0], 6).tolist()} - {np.round(b[1], 6).tolist()}, "
                     f"{self.chunks[t]} points): {msg}" for t, b, msg in failures]
            raise TileBuildError(
                f"{len(failures)} of {T} tile(s) failed to build:\n  " + "\n  ".join(lines)
                + f"\nThe {T - len(failures)} finished tile(s) are kept in {str(self.cache_dir)!r}: a re-run with "
                "cache_dir= set to it reuses them (see .failures for the tracebacks' first lines)",
                [(t, b, msg) for t, b, msg in failures],
            )
        self._contrib = [r["contrib"] for r in results]
        self.fallback = {}
        for r in results:
            for k, v in r.get("fallback", {}).items():
                self.fallback[k] = self.fallback.get(k, 0) + v
        if self.normals_estimated:
            self._orient_tiles()

    def _orient_tiles(self) -> None:
        """Signs per tile that make the normals agree across shared particles, then outward (module notes)."""
        from scipy.sparse.csgraph import breadth_first_order, connected_components

        T = len(self.chunks)
        tile_of = np.repeat(np.arange(T), self.chunks)
        own_n = [None] * T

        def own(u):
            if own_n[u] is None:
                d = np.load(self._tile_path(u))
                own_n[u] = d["normals_s"][: int(d["n_own"])]
            return own_n[u]

        rows, cols, vals = [], [], []
        for t in range(T):
            if self.chunks[t] == 0:
                continue
            with np.load(self._tile_path(t)) as d:
                shared, n_own = d["shared"], int(d["n_own"])
                nrm_halo = d["normals_s"][n_own:]
            owner = tile_of[shared]
            for u in np.unique(owner):
                sel = owner == u
                agree = float(np.einsum("ij,ij->", nrm_halo[sel], own(u)[shared[sel] - self.bounds[u]]))
                rows.append(t)
                cols.append(int(u))
                vals.append(agree)
        A = sp.coo_matrix((np.array(vals, dtype=float), (rows, cols)), shape=(T, T)).tocsr()
        A = (A + A.T).tocsr()
        A.data[A.data == 0] = 1e-300
        n_comp, label = connected_components(abs(A), directed=False)
        sign = np.ones(T)
        for c in range(n_comp):
            members = np.flatnonzero(label == c)
            root = members[np.argmax(np.array(self.chunks)[members])]
            order_, pred = breadth_first_order(abs(A), root, directed=False, return_predecessors=True)
            for node in order_[1:]:
                p = pred[node]
                sign[node] = sign[p] * (1.0 if A[node, p] > 0 else -1.0)
        # outward: the winding-number check on a subsample, per connected group of tiles
        from .normals import orient_normals

        pts = np.load(self._points_file, mmap_mode="r")
        take = np.unique(np.linspace(0, self.n_points - 1, min(_ORIENT_SAMPLE, self.n_points)).round().astype(np.int64))
        sub_n = np.empty((take.size, 3))
        for u in range(T):
            sel = tile_of[take] == u
            if sel.any():
                sub_n[sel] = own(u)[take[sel] - self.bounds[u]] * sign[u]
        out, _ = orient_normals(np.asarray(pts[take]), sub_n, k=min(16, take.size), orient="outward")
        agree = np.einsum("ij,ij->i", out, sub_n)
        vote = np.bincount(label[tile_of[take]], weights=agree, minlength=n_comp)
        sign *= np.where(vote[label] < 0, -1.0, 1.0)
        self.tile_sign = sign

    # ------------------------------------------------------------------ results
    def _field(self, name: str, width=None):
        import dask.array as da
        from dask import delayed

        blocks = []
        for t, n in enumerate(self.chunks):
            sign = self.tile_sign[t] if name in ("normals", "H_normals", "H_laplacian") else 1.0
            shape = (n,) if width is None else (n, width)
            blocks.append(da.from_delayed(delayed(_tile_field, pure=True)(self._tile_path(t), name, float(sign)),
                                          shape=shape, dtype=np.float64))
        return da.concatenate(blocks, axis=0)

    @property
    def normals(self):
        """(N, 3) Dask array of unit normals (tile order): the given ones, or the estimated and oriented ones."""
        return self._field("normals", 3)

    @property
    def h(self):
        """(N,) Dask array of smoothing lengths (tile order)."""
        return self._field("h")

    @property
    def dV(self):
        """(N,) Dask array of area elements (tile order)."""
        return self._field("dV")

    @property
    def points(self):
        """(N, 3) Dask array of the coordinates in tile order (read from the cache directory)."""
        return self._points_array(None, 3)

    def mean_curvature(self, method: str = "auto"):
        """(N,) Dask array of the mean curvature; ``method`` as :func:`manifold_sph.geometry.mean_curvature`.

        ``"auto"`` is ``"normals"`` (the shape operator's trace), as for ``Surface``.
        """
        check_in("method", method, ("auto", "normals", "laplacian"))
        return self._field("H_" + ("normals" if method == "auto" else method))

    def _points_array(self, func, width):
        import dask.array as da
        from dask import delayed

        blocks = []
        for t, n in enumerate(self.chunks):
            shape = (n,) if width is None else (n, width)
            lo, hi = int(self.bounds[t]), int(self.bounds[t + 1])
            blocks.append(da.from_delayed(delayed(_tile_points, pure=True)(self._points_file, lo, hi, func), shape=shape, dtype=np.float64))
        return da.concatenate(blocks, axis=0)

    def field(self, values, width=None):
        """A field as a Dask array in tile order, chunk = tile.

        Parameters
        ----------
        values : array_like (N,) or (N, width) in the input order, a Dask array in tile
            order (e.g. a result of this object), or a callable ``f(points) -> values``
            evaluated tile by tile on the (M, 3) coordinates (out of core).
        width : int, optional
            ``None`` for scalars, 3 for vector fields.
        """
        import dask.array as da

        n = self.n_points
        want = (n,) if width is None else (n, width)
        if callable(values) and not isinstance(values, (np.ndarray, da.Array)):
            return self._points_array(values, width)
        if isinstance(values, da.Array):
            if values.shape != want:
                raise ValueError(f"field must have shape {want}, got shape {values.shape}")
            return values.rechunk((self.chunks,) + values.chunks[1:])
        arr = as_field("field", values, n, width)[self.order]
        return da.from_array(arr, chunks=(self.chunks,) + (() if width is None else (width,)))

    def _apply(self, kind: str, x, scale: float = 1.0, *extra):
        import dask.array as da
        from dask import delayed

        need = "derivatives" if kind in ("gradient", "divergence") else "laplacian"
        if need not in self.keep:
            raise ValueError(f"{kind} needs the {need} matrices, which were not kept (keep={self.keep!r}); "
                             f"build with keep=(..., {need!r})")
        xb = x.to_delayed(optimize_graph=False).ravel()
        eb = [e.to_delayed(optimize_graph=False).ravel() for e in extra]
        blocks = []
        for t, n in enumerate(self.chunks):
            shape = (n, 3) if kind == "gradient" else (n,)
            args = [xb[u] for u in self._contrib[t]]
            ex = [e[t] for e in eb]
            blocks.append(da.from_delayed(delayed(_tile_apply, pure=True)(self._tile_path(t), kind, scale, ex, *args),
                                          shape=shape, dtype=np.float64))
        return da.concatenate(blocks, axis=0)

    def laplacian(self, f):
        """Laplace-Beltrami of a scalar field, (N,) Dask array in tile order. ``f`` as in :meth:`field`."""
        return self._apply("laplacian", self.field(f))

    def gradient(self, f):
        """Tangential gradient of a scalar field, (N, 3) Dask array in tile order. ``f`` as in :meth:`field`."""
        return self._apply("gradient", self.field(f))

    def divergence(self, F):
        """Divergence of the tangential part of a vector field, (N,) Dask array in tile order."""
        return self._apply("divergence", self.field(F, 3))

    def heat(self, u0, dt: float, steps: int, *, k: float = 1.0, every: int | None = None, check: bool = True):
        """Explicit Euler heat steps ``u <- u + k dt L u``, one halo exchange per step.

        Parameters
        ----------
        u0 : field (see :meth:`field`)
        dt : float
        steps : int
        k : float
            Diffusivity.
        every : int, optional
            Also return the state every ``every`` steps.
        check : bool
            Refuse ``dt > 2 / (k G)``, ``G`` the largest absolute row sum of ``L`` (an
            upper bound of its spectral radius, so this limit is at most the
            single-process one of :func:`manifold_sph.pde.explicit_dt_limit`).

        Returns
        -------
        Dask array (N,) in tile order, or a list of them (every ``every`` steps and the last).
        Implicit steps are not supported on tiles (they need a distributed solver).
        """
        dt, k = check_positive("dt", dt), check_positive("k", k)
        steps = check_int("steps", steps, minimum=1)
        if every is not None:
            every = check_int("every", every, minimum=1)
        if check_bool("check", check):
            G = max((r.get("gershgorin", 0.0) for r in self.report), default=0.0)
            if G > 0 and dt > 2.0 / (k * G):
                raise ValueError(
                    f"dt = {dt:g} is above the explicit heat limit {2.0 / (k * G):.4g} (2 / (k G), G = {G:.4g} the largest "
                    "absolute row sum of L); use a smaller dt, or check=False if you know the spectral radius is smaller"
                )
        u = self.field(u0)
        snaps = []
        for step in range(1, steps + 1):
            u = self._apply("heat", u, k * dt)
            if self.scheduler == "distributed" and step % 10 == 0:
                u = self.client.persist(u)  # keep the task graph short
            if every is not None and step % every == 0:
                snaps.append(u)
        return snaps if every is not None else u

    def wave(self, u0, dt: float, steps: int, *, c: float = 1.0, v0=None, every: int | None = None, check: bool = True):
        """Centred wave steps ``u' = 2 u - u_prev + (c dt)^2 L u`` (as :func:`manifold_sph.pde.wave`), one halo exchange per step.

        Started with ``u1 = u0 + dt v0 + (c dt)^2 L u0 / 2``. ``check`` refuses
        ``dt > 2 / (c sqrt(G))``, ``G`` the largest absolute row sum of ``L``.
        Returns the state after ``steps`` steps (Dask array, tile order), or a list every ``every`` steps.
        """
        dt, c = check_positive("dt", dt), check_positive("c", c)
        steps = check_int("steps", steps, minimum=1)
        if every is not None:
            every = check_int("every", every, minimum=1)
        if check_bool("check", check):
            G = max((r.get("gershgorin", 0.0) for r in self.report), default=0.0)
            if G > 0 and dt > 2.0 / (c * np.sqrt(G)):
                raise ValueError(
                    f"dt = {dt:g} is above the centred wave limit {2.0 / (c * np.sqrt(G)):.4g} (2 / (c sqrt(G)), "
                    f"G = {G:.4g} the largest absolute row sum of L); use a smaller dt, or check=False"
                )
        b = (c * dt) ** 2
        prev = self.field(u0)
        v = self.field(np.zeros(self.n_points) if v0 is None else v0) * dt
        u = self._apply("wave1", prev, b, v)
        snaps = [u] if every == 1 else []
        for step in range(2, steps + 1):
            prev, u = u, self._apply("wave", u, b, prev)
            if self.scheduler == "distributed" and step % 10 == 0:
                prev, u = self.client.persist([prev, u])
            if every is not None and step % every == 0:
                snaps.append(u)
        return snaps if every is not None else u

    def laplacian_matrix(self, order: str = "input") -> sp.csr_matrix:
        """The global Laplacian matrix (N, N), assembled on the driver: for moderate N only.

        ``order="input"`` (rows and columns in the order of ``source``) or ``"tile"``.
        """
        return self._global_matrix("lap", order)

    def derivative_matrices(self, order: str = "input"):
        """The global tangent-plane derivative matrices ``(Dx, Dy)`` in each particle's frame."""
        return self._global_matrix("dx", order), self._global_matrix("dy", order)

    def _global_matrix(self, name, order):
        check_in("order", order, ("input", "tile"))
        need = "laplacian" if name == "lap" else "derivatives"
        if need not in self.keep:
            raise ValueError(f"the {need} matrices were not kept (keep={self.keep!r})")
        rows, cols, vals = [], [], []
        for t, n in enumerate(self.chunks):
            if n == 0:
                continue
            d = _load_tile(self._tile_path(t))
            m = d[name].tocoo()
            rows.append(m.row + self.bounds[t])
            cols.append(d["cols"][m.col])
            vals.append(m.data)
        r, c, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
        if order == "input":
            r, c = self.order[r], self.order[c]
        N = self.n_points
        return sp.csr_matrix((v, (r, c)), shape=(N, N))

    # ------------------------------------------------------------------ output
    def to_npy(self, x, path, *, order: str = "input") -> None:
        """Write a Dask array (tile order) to a ``.npy`` file, tile by tile (never whole in memory).

        ``order="input"`` writes row ``i`` of the input cloud at row ``i``; the workers
        write disjoint rows of one memory-mapped file (a shared file system on clusters).
        """
        import dask.array as da
        from dask import delayed

        check_in("order", order, ("input", "tile"))
        path = str(path)
        if order == "tile":
            np.lib.format.open_memmap(path, mode="w+", dtype=np.float64, shape=x.shape).flush()
            self._compute(da.store(x, np.load(path, mmap_mode="r+"), lock=False, compute=False))
            return
        np.lib.format.open_memmap(path, mode="w+", dtype=np.float64, shape=x.shape).flush()
        xb = x.to_delayed().ravel() if x.ndim == 1 else x.to_delayed()[:, 0]
        tasks = [delayed(_write_rows, pure=False)(xb[t], path, self._order_file, int(self.bounds[t])) for t in range(len(self.chunks))]
        self._compute(*tasks)

    def to_zarr(self, x, url, component=None, **kwargs):
        """Write a Dask array (tile order, chunk = tile) to zarr; the input order is :attr:`order`."""
        import dask.array as da

        self._compute(da.to_zarr(x, url, component=component, compute=False, **kwargs))

    def __repr__(self) -> str:
        return (f"TiledSurface(n_points={self.n_points}, tiles={len(self.chunks)}, scheme={self.options['scheme']!r}, "
                f"area={self.options['area']!r}, halo={self.halo:.4g}, scheduler={self.scheduler!r})")
