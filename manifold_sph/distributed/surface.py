"""The driver of a tiled build: :class:`TiledSurface` (docs/distributed.md).

Every operator of a :class:`~manifold_sph.Surface` is local: the row of particle ``i``
needs only the particles inside its support, their area elements (which need *their*
neighbours) and the normals of all of these. So the cloud is cut into spatial tiles
(a k-d split to ``tile_points`` points, or a regular grid), each tile is grown by a
halo wide enough for that chain of local steps, and each tile is built by the
single-machine :class:`~manifold_sph.Surface` on tile + halo on a Dask worker,
keeping only the rows of its own particles (:mod:`manifold_sph.distributed.tiles`).
A tile whose rows turn out to depend on particles outside its halo is built again
with a wider halo, so the rows kept are those of the single-process build with the
same options, to round-off (bit for bit in the tests).

What is not local is refused or handled globally:

- ``area="numerical"`` (one sparse solve over the whole cloud) is refused; use
  ``"shepard"`` (the default here) or ``"geometric"`` with ``total_area``.
- The uniform smoothing length (``h=None``) is fitted once, on the driver, exactly as
  :class:`~manifold_sph.Surface` fits it.
- Estimated normals: each tile fits and orients its normals consistently; the tiles'
  signs are made to agree through the particles their halos share, and each
  connected group of tiles is then turned outward by the winding-number check of
  :func:`manifold_sph.normals.orient_normals` on a subsample.
- The global solves (implicit heat, Poisson, geodesics, eigenpairs) run on the tiles'
  rows of ``K`` and ``M`` with PETSc/SLEPc on MPI ranks, or on one process
  (:mod:`manifold_sph.distributed.solve`).

Results are Dask arrays in *tile order* (one chunk per tile; :attr:`TiledSurface.order`
maps them to the input order), written out with :meth:`TiledSurface.to_npy` (input
order) or :meth:`TiledSurface.to_zarr`.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from .._validation import as_points, check_bool, check_in, check_int, check_positive
from ..pointcloud import PointCloud
from .operators import DRIVER_PREFIX, TiledOperators

if TYPE_CHECKING:  # dask is the optional "distributed" extra, imported where it is used
    from dask.array import Array as DaskArray
    from dask.distributed import Client
from .tiles import KEEP, TILE_FORMAT, TileData, build_tile, dependency_k
from .tiling import grid_tiles, kd_tiles

__all__ = ["LOCAL_AREAS", "SCHEDULERS", "SURFACE_OPTIONS", "TileBuildError", "TiledSurface"]

#: Options passed on to :class:`~manifold_sph.Surface` (all others are refused).
SURFACE_OPTIONS = ("scheme", "kernel", "neighbors", "h", "area", "normal_threshold", "total_area", "max_condition")

#: Area elements computed from each particle's neighbourhood alone (exact on tiles).
LOCAL_AREAS = ("shepard", "geometric")

#: Schedulers of :class:`TiledSurface` when no client is given.
SCHEDULERS = ("distributed", "synchronous", "threads")

#: Points of the subsample that decides the outward orientation of estimated normals.
_ORIENT_SAMPLE = 10000
#: Points of the subsample that scales the first halo guess with ``h="adaptive"`` (2D density scaling).
_H_GUESS_SAMPLE = 200_000


class TileBuildError(RuntimeError):
    """One or more tiles failed to build; ``.failures`` lists ``(index, bounding box, message)``."""

    def __init__(self, message: str, failures: list[tuple[int, list[list[float]], str]]) -> None:
        super().__init__(message)
        self.failures = failures


class TiledSurface(TiledOperators):
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
    keep : tuple of {"laplacian", "derivatives", "stable"}
        What each tile builds and stores (plain ``.npy`` files, 12 bytes per pair and
        matrix): ``"laplacian"`` the Laplacian's rows (the explicit steps, and mean
        curvature from ``L x``); ``"derivatives"`` the tangent-plane ``Dx``, ``Dy`` (gradient,
        divergence, mean curvature from the normals, geodesics); ``"stable"`` the stable
        Laplacian's ``K`` and ``M`` rows, equal bit for bit to the single process's (the
        global solves: implicit heat, Poisson, geodesics, eigenpairs). Only what is kept is
        built. Normals, ``h`` and area elements are always kept.
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

    def __init__(self, source: ArrayLike | PointCloud | str | os.PathLike[str],
                 normals: ArrayLike | str | os.PathLike[str] | None = None, *, tile_points: int = 1_000_000,
                 grid: Sequence[int] | None = None, halo: float | None = None, client: Client | None = None,
                 scheduler: str = "distributed", n_workers: int = 2, memory_limit: str | int | None = None,
                 cache_dir: str | os.PathLike[str] | None = None, progress: bool = False,
                 normal_options: dict[str, Any] | None = None, keep: str | Sequence[str] = ("laplacian", "derivatives"),
                 _fail_tiles: Iterable[int] = (), **surface_options: Any) -> None:
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
            check_in("keep", k, KEEP)
        self.keep = keep
        self._client = client
        self._own_cluster: Any = None  # the LocalCluster this surface started, if any
        self.scheduler = "distributed" if client is not None else scheduler
        self.memory_limit = memory_limit
        opts = self._check_surface_options(surface_options)
        if self.normal_options.get("method", "jet") == "jet" and "degree" not in self.normal_options:
            # as Surface: jets of the scheme's Taylor degree (2 to 4)
            from ..schemes import get_scheme

            self.normal_options["degree"] = int(min(max(getattr(get_scheme(opts["scheme"]), "degree", 2), 2), 4))
        # --- the work directory
        self._tmp = cache_dir is None
        self.cache_dir = Path(tempfile.mkdtemp(prefix="msph-tiles-") if cache_dir is None else cache_dir)
        if self.cache_dir.exists() and not self.cache_dir.is_dir():
            raise ValueError(f"cache_dir must be a directory, got the file {str(self.cache_dir)!r}")
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        pts, nrm = self._read_source(source, normals)
        n = pts.shape[0]
        from ..pointcloud import MIN_POINTS

        if n < MIN_POINTS:
            raise ValueError(f"source must hold at least {MIN_POINTS} points, got {n}")
        if opts["neighbors"] >= n:
            raise ValueError(f"neighbors must be smaller than the number of points {n}, got {opts['neighbors']}")
        self.n_points = n
        self.normals_estimated = nrm is None
        # --- uniform h, exactly as Surface fits it (on the input order)
        h = opts["h"]
        hv_file = None
        from ..kernels import get_kernel
        from ..neighbors import smoothing_length_for_count

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
            parts, boxes = kd_tiles(pts, self.tile_points, glo, ghi)
        else:
            g = np.asarray(grid)
            if g.shape != (3,) or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1 for v in grid):
                raise ValueError(f"grid must be three positive integers (nx, ny, nz), got {grid!r}")
            if int(np.prod(g.astype(float))) > 100_000_000:
                raise ValueError(f"grid must have at most 1e8 cells, got {grid!r}")
            parts, boxes = grid_tiles(pts, g, glo, ghi)
        self.order = np.concatenate(parts).astype(np.int64)
        self.chunks = tuple(int(p.size) for p in parts)
        self.bounds = np.concatenate([[0], np.cumsum(self.chunks)]).astype(np.int64)
        self.boxes = boxes
        self.bbox = np.stack([glo, ghi])
        # support radii chained: the row, the neighbours' area elements, and with estimated normals the jet
        # fit's k-nearest ball and its two refits (k-th neighbour distance ~ sqrt(k / neighbors) support radii,
        # times 1.5 for the spread of irregular clouds); h="adaptive" varies the radius per particle (x 1.2)
        chain: float = 1 + (1 if opts["area"] == "shepard" else 0)
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
                "normal_options": self.normal_options, "tile_points": self.tile_points,
                "grid": None if grid is None else list(map(int, grid)), "keep": list(keep),
                "halo": self.halo, "format": TILE_FORMAT, "source": key_src.hexdigest()}
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
        from ..kernels import get_kernel
        from ..schemes import get_scheme

        area = o.get("area", "shepard")
        if area == "numerical":
            raise ValueError(
                "area='numerical' solves one sparse system over the whole cloud and cannot be tiled exactly; "
                "use a local one: area='shepard' (the default here) or area='geometric' with total_area="
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
                pts, nrm = self._read_las(path)
            else:
                from ..scans.io import read

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

    def _read_las(self, path: Path):
        """Points (and normals, when the file stores them as extra dimensions) as memory-mapped .npy copies."""
        import laspy

        from ..scans.io_lidar import read_las_chunks
        from ..scans.io_read import NORMAL_NAMES

        st = path.stat()
        tag = hashlib.blake2b(f"{path.resolve()}|{st.st_size}|{st.st_mtime_ns}".encode(), digest_size=8).hexdigest()
        target, ntarget = str(self.cache_dir / f"las-{tag}.npy"), str(self.cache_dir / f"las-{tag}-normals.npy")
        with laspy.open(str(path)) as f:
            n = int(f.header.point_count)
        out = np.lib.format.open_memmap(target, mode="w+", dtype=np.float64, shape=(n, 3))
        nout, names, pos = None, None, 0
        for xyz, fields in read_las_chunks(path, chunk_size=1 << 20):
            m = xyz.shape[0]
            if pos + m > n:
                raise ValueError(f"source: {str(path)!r} holds more points than its header's count {n}")
            out[pos : pos + m] = xyz
            if pos == 0:
                names = next((trio for trio in NORMAL_NAMES if all(k in fields for k in trio)), None)
                if names is not None:
                    nout = np.lib.format.open_memmap(ntarget, mode="w+", dtype=np.float64, shape=(n, 3))
            if nout is not None and names is not None:  # set together, from the first chunk
                nout[pos : pos + m] = np.stack([np.asarray(fields[k], dtype=np.float64) for k in names], axis=1)
            pos += m
        if pos != n:
            raise ValueError(f"source: {str(path)!r} declares {n} points in its header and holds {pos}")
        out.flush()
        del out
        nrm = None
        if nout is not None:
            nout.flush()
            del nout
            nrm = np.load(ntarget, mmap_mode="r")
        return np.load(target, mmap_mode="r"), nrm

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
    def client(self) -> Client | None:
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

        if self.scheduler == "distributed" and not all(str(getattr(o, "name", "")).startswith(DRIVER_PREFIX) for o in objs):
            client = self.client
            assert client is not None  # the "distributed" scheduler always has one
            futures = client.compute(list(objs))
            if self.progress:
                from dask.distributed import progress

                progress(futures)
            return client.gather(futures)
        # a global solve's result is already on the driver: slicing it there beats sending it to the cluster
        scheduler = "synchronous" if self.scheduler == "distributed" else self.scheduler
        if self.progress:
            from dask.diagnostics import ProgressBar

            with ProgressBar():
                return list(dask.compute(*objs, scheduler=scheduler))
        return list(dask.compute(*objs, scheduler=scheduler))

    def compute(self, x: DaskArray) -> np.ndarray:
        """Compute a Dask array (in tile order) on this surface's scheduler; returns numpy."""
        self._check_open()
        return self._compute(x)[0]

    def _check_open(self) -> None:
        if getattr(self, "_closed", False):
            raise RuntimeError(
                f"this TiledSurface was closed (close() or the end of its with block); its tiles in "
                f"{str(self.cache_dir)!r} are {'removed' if self._tmp else 'kept'}: build a new TiledSurface"
                + ("" if self._tmp else " with the same cache_dir= to reuse them")
            )

    def gather(self, x: DaskArray) -> np.ndarray:
        """Compute a Dask array in tile order and return it as numpy in the input order."""
        v = self.compute(x)
        out = np.empty_like(v)
        out[self.order] = v
        return out

    def _shutdown(self) -> None:
        if self._own_cluster is not None:
            if self._client is not None:  # the client of the cluster this surface started
                self._client.close()
            self._own_cluster.close()
            self._client = self._own_cluster = None

    def close(self) -> None:
        """Shut the LocalCluster down (if this object started it) and remove a temporary cache directory."""
        self._shutdown()
        self._closed = True
        if self._tmp and self.cache_dir.exists():
            shutil.rmtree(self.cache_dir, ignore_errors=True)

    def __enter__(self) -> TiledSurface:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ build
    def _normal_k(self) -> int:
        """Nearest neighbours of the normal estimation (estimate_normals' default for the options)."""
        from ..normals import DEFAULT_JET_K

        k = self.normal_options.get("k")
        if k is None:
            jet = self.normal_options.get("method", "jet") == "jet"
            k = DEFAULT_JET_K[self.normal_options.get("degree") or 2] if jet else 16
        return int(dependency_k(k, self.normal_options))

    def _tile_path(self, t: int) -> str:
        return str(self.cache_dir / f"tile-{self._key}-{t:05d}")

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
                "bbox": self.bbox.tolist(), "boxes": blist, "bounds": bnds, "chain": self._chain,
                "points": self._points_file, "normals": self._normals_file,
                "h_file": self._h_file, "options": self.options, "normal_options": self.normal_options, "halo": self.halo,
                "kq": kq, "keep": self.keep, "order": self._order_file, "path": self._tile_path(t),
                "key": f"{self._key}-{t}", "reuse": True,
                "threads": 1 if self.scheduler != "synchronous" else None, "_fail": t in fail_tiles,
            })
        tasks = [delayed(build_tile, pure=False)(s, dask_key_name=f"msph-tile-{self._key[:8]}-{s['tile']}") for s in specs]
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
        self.fallback: dict[str, int] = {}  # particles per fallback scheme, over the tiles
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
                d = TileData(self._tile_path(u))
                own_n[u] = np.asarray(d["normals_s"][: d.n])
            return own_n[u]

        rows, cols, vals = [], [], []
        for t in range(T):
            if self.chunks[t] == 0:
                continue
            d = TileData(self._tile_path(t))
            shared, n_own = np.asarray(d["shared"]), d.n
            nrm_halo = np.asarray(d["normals_s"][n_own:])
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
        from ..normals import orient_normals

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

    def __repr__(self) -> str:
        return (f"TiledSurface(n_points={self.n_points}, tiles={len(self.chunks)}, scheme={self.options['scheme']!r}, "
                f"area={self.options['area']!r}, halo={self.halo:.4g}, scheduler={self.scheduler!r})")
