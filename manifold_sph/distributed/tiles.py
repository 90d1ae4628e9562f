"""One tile's work on a worker: build tile + halo, check its rows, write them as plain ``.npy`` files.

A finished tile is a directory ``tile-<key>-<t>/`` of ``.npy`` arrays and a ``meta.json``
(key and summary), written under a temporary name and renamed, so a killed build leaves
no half-written tile. Readers memory-map the arrays: nothing is copied or decompressed,
and the operating system's page cache keeps what is used often.

Arrays of a tile with ``n`` own particles and ``ns`` tile + halo particles:

- ``cols`` (ns,): tile-order index of every tile + halo particle (the own ones first);
  ``gather`` (ns,): where each sits in the concatenation of the chunks of the tiles in
  ``contrib``; ``shared``: the halo particles, ``normals_s`` (ns, 3) their normals too;
- ``u``, ``v`` (n, 3) tangent frames, ``h``, ``dV`` (n,);
- ``lap_*``, ``dx_*``, ``dy_*``: CSR arrays (``data``, ``indices`` into ``cols``, ``indptr``) of
  the own rows of the Laplacian and the tangent-plane derivatives, as kept;
- ``K_*`` (CSR, columns into ``cols``) and ``M`` (n,): the own rows of the stable
  Laplacian's stiffness and mass, equal bit for bit to the single process's;
- ``H_normals`` (with the derivatives), ``H_laplacian`` (with the Laplacian): mean curvature.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import time
import traceback
import warnings
from collections.abc import Callable, Collection, Sequence
from typing import Any, Literal, overload

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from .tiling import all_rows, margin

__all__ = ["KEEP", "TILE_FORMAT", "TileData", "TileDamagedError", "build_tile", "read_meta", "tile_apply", "tile_field",
           "tile_points", "write_rows"]

#: What a tile can keep: the Laplacian's rows, the derivatives' rows, the stable Laplacian's K and M rows.
KEEP = ("laplacian", "derivatives", "stable")
TILE_FORMAT = 2
#: Halo widenings tried by a tile whose rows are not all complete.
MAX_ATTEMPTS = 5
WIDEN = 1.6
#: Nearest neighbours of the stable Laplacian's wider search (operators.OperatorSet._WIDER_K).
STABLE_WIDER_K = 64


class TileDamagedError(RuntimeError):
    """A tile's files in the cache directory cannot be read."""


def _arrays_of(keep) -> list[str]:
    names = ["cols", "gather", "contrib", "shared", "normals_s", "u", "v", "h", "dV"]
    if "laplacian" in keep:
        names += ["lap_data", "lap_indices", "lap_indptr", "H_laplacian"]
    if "derivatives" in keep:
        names += [f"{m}_{p}" for m in ("dx", "dy") for p in ("data", "indices", "indptr")] + ["H_normals"]
    if "stable" in keep:
        names += ["K_data", "K_indices", "K_indptr", "M"]
    return names


def read_meta(path: str, keep: Collection[str] | None = None) -> dict[str, Any] | None:
    """The tile's ``meta.json`` if the tile is complete and readable (every kept array's header), else None."""
    try:
        with open(os.path.join(path, "meta.json")) as f:
            meta = json.load(f)
        for name in _arrays_of(meta["keep"] if keep is None else keep):
            np.load(os.path.join(path, name + ".npy"), mmap_mode="r")
        return meta
    except (OSError, ValueError, KeyError, TypeError, EOFError):
        return None


class TileData:
    """A finished tile's arrays, memory-mapped on first use."""

    def __init__(self, path: str) -> None:
        self.path = path
        meta = read_meta(path)
        if meta is None:
            raise TileDamagedError(
                f"the tile files in {path!r} are missing or damaged; build the TiledSurface again with the same "
                "cache_dir (damaged tiles are rebuilt, the others reused)"
            )
        self.meta = meta
        self.n = int(meta["summary"]["n_own"])
        self._arrays: dict = {}

    def release(self) -> None:
        """Forget the arrays read so far (their memory maps close once no other reference holds them)."""
        self._arrays.clear()

    @overload
    def __getitem__(self, name: Literal["lap", "dx", "dy", "K"]) -> sp.csr_matrix: ...

    @overload
    def __getitem__(self, name: str) -> np.ndarray: ...

    def __getitem__(self, name: str) -> sp.csr_matrix | np.ndarray:
        if name not in self._arrays:
            if name in ("lap", "dx", "dy", "K"):
                ns = int(self["cols"].size)
                self._arrays[name] = sp.csr_matrix((self[name + "_data"], self[name + "_indices"], self[name + "_indptr"]),
                                                   shape=(self.n, ns), copy=False)
            else:
                try:
                    self._arrays[name] = np.load(os.path.join(self.path, name + ".npy"), mmap_mode="r")
                except (OSError, ValueError) as exc:
                    raise TileDamagedError(f"tile {self.path!r}: {name}.npy cannot be read ({exc}); build again with "
                                           "the same cache_dir to rebuild it") from None
        return self._arrays[name]


def _save(path: str, arrays: dict, meta: dict) -> None:
    tmp = f"{path}.tmp-{os.getpid()}-{time.monotonic_ns()}"
    os.makedirs(tmp)
    for name, a in arrays.items():
        np.save(os.path.join(tmp, name + ".npy"), a)
    with open(os.path.join(tmp, "meta.json"), "w") as f:
        json.dump(meta, f)
    if os.path.exists(path):  # a damaged tile being rebuilt
        shutil.rmtree(path, ignore_errors=True)
    os.replace(tmp, path)  # atomic: a killed build leaves no half-written tile


def build_tile(spec: dict) -> dict:
    """Build one tile (tile + halo on one worker), save its own rows, return a small summary.

    Never raises: a failure comes back as ``{"error": ...}`` for the driver to report.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    t = spec["tile"]
    try:
        if spec.get("_fail"):
            raise RuntimeError("failure injected for testing (_fail_tiles)")
        out = spec["path"]
        rebuilt = None
        if spec["reuse"] and os.path.exists(out):
            meta = read_meta(out, spec["keep"])
            if meta is not None and meta.get("key") == spec["key"]:
                return meta["summary"] | {"reused": True}
            rebuilt = "damaged" if meta is None else "stale"
        from .. import threads
        from ..allocator import build_heap

        with threads.limit(spec["threads"]), build_heap():  # heap reuse also in a Dask worker (allocator's notes)
            arrays, summary = _build_tile_arrays(spec)
        summary["seconds"] = time.perf_counter() - t0
        summary["cpu_seconds"] = time.process_time() - c0
        summary["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        if rebuilt:
            summary["rebuilt"] = rebuilt
        _save(out, arrays, {"key": spec["key"], "keep": list(spec["keep"]), "format": TILE_FORMAT, "summary": summary})
        return summary
    except Exception as exc:  # reported with the tile's index and box by the driver
        return {"tile": t, "error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc()}


def _tile_surface(spts, snrm, opts, normal_options, estimate):
    """``(Surface, normals used)`` on tile + halo; normals estimated with a consistent orientation if asked."""
    from ..surface import Surface

    if estimate:
        from ..normals import estimate_normals

        snrm = estimate_normals(spts, orient="consistent", **normal_options)
    return Surface(spts, snrm, **opts), snrm


def dependency_k(k: int, normal_options: dict) -> int:
    """Nearest neighbours a normal depends on: the fit's ``k``, and with ``refine`` (the default) the
    ``ROW_K`` nearest of the refinement steps (normals.tuning)."""
    from ..normals import tuning

    return max(int(k), tuning.ROW_K) if normal_options.get("refine", True) else int(k)


def _complete_rows(s, spts, n_own, mrg, opts, normal_options, estimate, kq, keep):
    """Which own rows are complete (their result equals the whole cloud's), and the reach they need.

    A particle's own data are complete when the ball they come from lies inside tile +
    halo (margin >= its radius); the checks follow the chain normals (jet fit, two
    refits) -> smoothing length -> neighbourhood (the normal filter looks at every point
    in the support) -> area element -> row; for the stable Laplacian -> the Voronoi cells
    of the row's neighbours (their fluxes enter the row) -> the row.
    """
    from ..normals import DEFAULT_JET_K

    ns = spts.shape[0]
    nb = s.neighborhood
    reach = nb.support * nb.h
    tree = cKDTree(spts) if getattr(s, "_tree", None) is None else s._tree
    if estimate or opts.get("h") == "adaptive":
        dist, knn = tree.query(spts, k=min(kq, ns))
    if estimate:
        k_est = normal_options.get("k")
        if k_est is None:
            k_est = DEFAULT_JET_K[normal_options.get("degree") or 2] if normal_options.get("method", "jet") == "jet" else 16
        k_graph = min(max(dependency_k(k_est, normal_options), 10), ns)
        ok = mrg >= dist[:, k_graph - 1]  # the jet fit's, the orientation graph's and the refinement's ball
        ptr = np.arange(0, ns * k_est + 1, k_est)
        for _ in range(2):  # the two refits use the neighbours' previous normals
            ok = ok & all_rows(ok, ptr, np.ascontiguousarray(knn[:, :k_est]).ravel(), ns)
        normal_ok = ok
    else:
        normal_ok = np.ones(ns, dtype=bool)
    h_ok = np.ones(ns, dtype=bool)
    if opts.get("h") == "adaptive":
        h_ok = mrg >= dist[:, min(s.neighbors, ns - 1)]
    wid = np.asarray(s.widened)
    if wid.size:  # widened supports came from a 4 * neighbors nearest search
        kw = min(4 * s.neighbors, ns)
        dw, _ = tree.query(spts[wid], k=kw)
        h_ok[wid] &= mrg[wid] >= dw[:, -1]
    bad = np.flatnonzero(~normal_ok)
    d_bad = cKDTree(spts[bad]).query(spts, k=1)[0] if bad.size else np.full(ns, np.inf)
    nbhd_ok = (mrg >= reach) & h_ok & (d_bad >= reach)
    row_ok = nbhd_ok[:n_own]
    rmax = float(reach.max())
    if s.scheme.uses_area and s._area_args[0] == "shepard":
        row_ok = row_ok & all_rows(nbhd_ok, nb.indptr, nb.indices, n_own)
    stable_ok = None
    if "stable" in keep:
        cell_ok = nbhd_ok.copy()
        rep = s.stable_report
        if rep["widened"] or rep["refitted"] or rep["boundary"]:  # cells from a 64-nearest search (and their neighbours')
            d64 = tree.query(spts, k=min(STABLE_WIDER_K, ns))[0][:, -1]
            cell_ok &= mrg >= d64 + rmax
        K = s.stiffness_matrix()
        stable_ok = (cell_ok[:n_own] & all_rows(cell_ok, nb.indptr, nb.indices, n_own)
                     & all_rows(cell_ok, K.indptr, K.indices, n_own) & (mrg[:n_own] >= rmax))
    return row_ok, stable_ok, rmax


def _build_tile_arrays(spec: dict):
    t, lo, hi = spec["tile"], spec["lo"], spec["hi"]
    n_own = hi - lo
    keep = spec["keep"]
    pts_all = np.load(spec["points"], mmap_mode="r")
    nrm_all = None if spec["normals"] is None else np.load(spec["normals"], mmap_mode="r")
    h_all = None if spec["h_file"] is None else np.load(spec["h_file"], mmap_mode="r")
    box = np.asarray(spec["box"])
    glo, ghi = np.asarray(spec["bbox"][0]), np.asarray(spec["bbox"][1])
    opts = dict(spec["options"])
    estimate = nrm_all is None
    halo = spec["halo"]
    boxes, bounds = np.asarray(spec["boxes"]), spec["bounds"]
    for attempt in range(1, MAX_ATTEMPTS + 1):
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
        snrm = None if nrm_all is None else np.asarray(nrm_all[cols])  # None: estimate
        if h_all is not None:
            opts["h"] = np.asarray(h_all[cols])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            s, snrm = _tile_surface(spts, snrm, opts, spec["normal_options"], estimate)
            mrg = margin(spts, elo, ehi, glo, ghi)
            row_ok, stable_ok, rmax = _complete_rows(s, spts, n_own, mrg, opts, spec["normal_options"], estimate,
                                                     spec["kq"], keep)
        done = row_ok.all() and (stable_ok is None or stable_ok.all())
        if done:
            break
        halo = max(halo * WIDEN, 1.1 * spec["chain"] * rmax)
    else:
        bad = int(np.count_nonzero(~row_ok)) + (0 if stable_ok is None else int(np.count_nonzero(~stable_ok)))
        raise ValueError(
            f"{bad} own row(s) still depend on particles outside tile + halo after {MAX_ATTEMPTS} widenings "
            f"(halo {halo:.4g}; widened supports or sparse parts?); pass a larger halo="
        )
    n_s = cols.size
    nrm_s = np.asarray(s.normals)
    arrays = {"cols": cols, "gather": np.concatenate(gather), "contrib": np.array(contrib), "shared": cols[n_own:],
              "normals_s": nrm_s, "u": np.asarray(s.u[:n_own]), "v": np.asarray(s.v[:n_own]),
              "h": np.asarray(s.h[:n_own]), "dV": np.asarray(s.dV[:n_own])}
    gersh = 0.0
    if "laplacian" in keep:
        L = _head_rows(s.laplacian_matrix(form="strong"), n_own)
        arrays |= _csr_arrays("lap", L)
        arrays["H_laplacian"] = -0.5 * np.einsum("ij,ij->i", L @ spts, nrm_s[:n_own])
        # row sums of |L| without scipy's abs(), which sorts the rows' entries in place
        absrow = np.bincount(np.repeat(np.arange(n_own), np.diff(L.indptr)), weights=np.abs(L.data), minlength=n_own)
        gersh = float(absrow.max())
    if "derivatives" in keep:
        dx, dy = (_head_rows(m, n_own) for m in s.derivative_matrices())
        arrays |= _csr_arrays("dx", dx) | _csr_arrays("dy", dy)
        # H from the shape operator's trace, u . d n/du + v . d n/dv, on the own rows only
        arrays["H_normals"] = 0.5 * (np.einsum("ij,ij->i", arrays["u"], dx @ nrm_s)
                                     + np.einsum("ij,ij->i", arrays["v"], dy @ nrm_s))
    if "stable" in keep:
        arrays |= _stable_rows(s, n_own, np.load(spec["order"], mmap_mode="r"), cols)
    fallback = {k: int(np.count_nonzero(np.asarray(v) < n_own)) for k, v in s.fallback.items()}
    summary = {
        "tile": t, "n_own": n_own, "n_halo": int(n_s - n_own), "halo": float(halo), "attempts": attempt,
        "contrib": [int(c) for c in contrib], "warnings": sorted({str(w.message).split(";")[0][:160] for w in caught}),
        "fallback": {k: v for k, v in fallback.items() if v}, "widened": int(np.count_nonzero(np.asarray(s.widened) < n_own)),
        "max_reach": rmax, "gershgorin": gersh,
    }
    return arrays, summary


def _csr_arrays(name: str, m: sp.csr_matrix) -> dict:
    return {name + "_data": m.data, name + "_indices": m.indices, name + "_indptr": m.indptr}


def _head_rows(m: sp.csr_matrix, n: int) -> sp.csr_matrix:
    """The first ``n`` rows, each row's entries in their stored order (the neighbours' distance order):
    scipy's slicing may sort them, and the order of the sums is part of the result's round-off. No copy."""
    end = int(m.indptr[n])
    return sp.csr_matrix((m.data[:end], m.indices[:end], m.indptr[: n + 1]), shape=(n, m.shape[1]), copy=False)


def _stable_rows(s, n_own: int, order: np.ndarray, cols: np.ndarray) -> dict:
    """Own rows of K (columns into ``cols``) and M, equal bit for bit to the single process.

    The single process sums each diagonal ``K_ii = sum_j w_ij`` over the row's fluxes sorted by
    input index; the tile's local order differs, so the diagonal is summed again in that order.
    """
    K = _head_rows(s.stiffness_matrix(), n_own).tocoo()
    off = K.row != K.col
    r, c, w = K.row[off], K.col[off], -K.data[off]
    inp = np.asarray(order[cols])
    W = sp.csr_matrix((w, (r, inp[c])), shape=(n_own, int(inp.max()) + 1))
    W.sum_duplicates()  # sorted by input index, as the single process's W
    diag = np.asarray(W.sum(axis=1)).ravel()
    rows = np.concatenate([r, np.arange(n_own)])
    colsl = np.concatenate([c, np.arange(n_own)])
    vals = np.concatenate([-w, diag])
    Kt = sp.csr_matrix((vals, (rows, colsl)), shape=(n_own, cols.size))
    Kt.sort_indices()
    return _csr_arrays("K", Kt) | {"M": np.asarray(s.mass_matrix().diagonal()[:n_own])}


# ----------------------------------------------------------------------------- reading tiles (on workers)
def tile_apply(path: str, kind: str, sign: float, extra: Sequence[np.ndarray], *chunks: np.ndarray) -> np.ndarray:
    """One tile's rows of an operator applied to the field chunks of the tiles it reads.

    ``extra``: own-row arrays of the time steps (the previous state, the initial velocity).
    """
    d = TileData(path)
    n = d.n
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


def tile_field(path: str, name: str, sign: float) -> np.ndarray:
    d = TileData(path)
    if name == "normals":
        return sign * np.asarray(d["normals_s"][: d.n])
    if name in ("H_normals", "H_laplacian"):
        return sign * np.asarray(d[name])
    return np.asarray(d[name])


def tile_points(points_file: str, lo: int, hi: int, func: Callable[[np.ndarray], ArrayLike] | None = None) -> np.ndarray:
    p = np.asarray(np.load(points_file, mmap_mode="r")[lo:hi])
    return p if func is None else np.asarray(func(p), dtype=np.float64)


def write_rows(block: np.ndarray, path: str, order_file: str, lo: int) -> np.ndarray:
    """Write one tile's rows into the input-order .npy memory map (disjoint rows per tile)."""
    idx = np.load(order_file, mmap_mode="r")[lo : lo + block.shape[0]]
    out = np.load(path, mmap_mode="r+")
    out[np.asarray(idx)] = block
    out.flush()
    return np.zeros(1)
