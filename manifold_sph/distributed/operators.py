"""What a built :class:`~manifold_sph.distributed.TiledSurface` computes: fields, local operators, time steps,
global solves and output, as Dask arrays in tile order (one chunk per tile).

A mixin of :class:`~manifold_sph.distributed.TiledSurface`: it uses the driver's tile
layout (``chunks``, ``bounds``, ``order``, ``_tile_path``, ``_contrib``), its scheduler
(``_compute``) and :meth:`_check_open`.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from .._validation import as_field, check_bool, check_in, check_int, check_positive
from .tiles import TileData, tile_apply, tile_field, tile_points, write_rows

if TYPE_CHECKING:  # dask is the optional "distributed" extra, imported where it is used
    from dask.array import Array as DaskArray

__all__ = ["DRIVER_PREFIX", "FieldLike", "TiledOperators"]

#: Name prefix of the Dask arrays wrapping results held by the driver (the global solves'): computed there.
DRIVER_PREFIX = "msph-driver-"

#: A field given to :meth:`TiledOperators.field`: values (N,) or (N, width) in the input order, a Dask
#: array in tile order, or a callable ``f(points (M, 3)) -> values`` evaluated tile by tile.
FieldLike: TypeAlias = "ArrayLike | DaskArray | Callable[[np.ndarray], ArrayLike]"


class TiledOperators:
    """Results of a tiled build (mixin of :class:`~manifold_sph.distributed.TiledSurface`)."""

    if TYPE_CHECKING:  # the state and helpers of TiledSurface that these methods use, for type checkers
        n_points: int
        chunks: tuple[int, ...]
        bounds: np.ndarray
        order: np.ndarray
        tile_sign: np.ndarray
        keep: tuple[str, ...]
        scheduler: str
        report: list[dict[str, Any]]
        _contrib: list[Any]
        _points_file: str
        _order_file: str

        @property
        def client(self) -> Any: ...

        def compute(self, x: DaskArray) -> np.ndarray: ...

        def _compute(self, *objs: Any) -> list[Any]: ...

        def _check_open(self) -> None: ...

        def _tile_path(self, t: int) -> str: ...

    # ------------------------------------------------------------------ results
    def _field(self, name: str, width=None):
        import dask.array as da
        from dask import delayed

        self._check_open()

        blocks = []
        for t, n in enumerate(self.chunks):
            sign = self.tile_sign[t] if name in ("normals", "H_normals", "H_laplacian") else 1.0
            shape = (n,) if width is None else (n, width)
            blocks.append(da.from_delayed(delayed(tile_field, pure=True)(self._tile_path(t), name, float(sign)),
                                          shape=shape, dtype=np.float64))
        return da.concatenate(blocks, axis=0)

    @property
    def normals(self) -> DaskArray:
        """(N, 3) Dask array of unit normals (tile order): the given ones, or the estimated and oriented ones."""
        return self._field("normals", 3)

    @property
    def h(self) -> DaskArray:
        """(N,) Dask array of smoothing lengths (tile order)."""
        return self._field("h")

    @property
    def dV(self) -> DaskArray:
        """(N,) Dask array of area elements (tile order)."""
        return self._field("dV")

    @property
    def points(self) -> DaskArray:
        """(N, 3) Dask array of the coordinates in tile order (read from the cache directory)."""
        return self._points_array(None, 3)

    def mean_curvature(self, method: str = "auto") -> DaskArray:
        """(N,) Dask array of the mean curvature; ``method`` as :func:`manifold_sph.geometry.mean_curvature`.

        ``"auto"`` is ``"normals"`` (the shape operator's trace), as for ``Surface``, when the
        derivatives were kept, else ``"laplacian"``.
        """
        check_in("method", method, ("auto", "normals", "laplacian"))
        if method == "auto":
            method = "normals" if "derivatives" in self.keep else "laplacian"
        need = "derivatives" if method == "normals" else "laplacian"
        if need not in self.keep:
            raise ValueError(f"mean_curvature(method={method!r}) needs the {need} rows, which were not kept "
                             f"(keep={self.keep!r}); build with keep=(..., {need!r})")
        return self._field("H_" + method)

    def _points_array(self, func, width):
        import dask.array as da
        from dask import delayed

        self._check_open()

        blocks = []
        for t, n in enumerate(self.chunks):
            shape = (n,) if width is None else (n, width)
            lo, hi = int(self.bounds[t]), int(self.bounds[t + 1])
            blocks.append(da.from_delayed(delayed(tile_points, pure=True)(self._points_file, lo, hi, func), shape=shape, dtype=np.float64))
        return da.concatenate(blocks, axis=0)

    def field(self, values: FieldLike, width: int | None = None) -> DaskArray:
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

        self._check_open()
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
            blocks.append(da.from_delayed(delayed(tile_apply, pure=True)(self._tile_path(t), kind, scale, ex, *args),
                                          shape=shape, dtype=np.float64))
        return da.concatenate(blocks, axis=0)

    def laplacian(self, f: FieldLike) -> DaskArray:
        """Laplace-Beltrami of a scalar field, (N,) Dask array in tile order. ``f`` as in :meth:`field`."""
        return self._apply("laplacian", self.field(f))

    def gradient(self, f: FieldLike) -> DaskArray:
        """Tangential gradient of a scalar field, (N, 3) Dask array in tile order. ``f`` as in :meth:`field`."""
        return self._apply("gradient", self.field(f))

    def divergence(self, F: FieldLike) -> DaskArray:
        """Divergence of the tangential part of a vector field, (N,) Dask array in tile order."""
        return self._apply("divergence", self.field(F, 3))

    def heat(self, u0: FieldLike, dt: float, steps: int, *, diffusivity: float = 1.0, method: str = "explicit",
             every: int | None = None, check: bool = True, engine: str = "auto",
             ranks: int | None = None) -> DaskArray | list[DaskArray]:
        """Heat steps: explicit Euler on the tiles' Laplacian, or implicit Euler on the stable Laplacian.

        Parameters
        ----------
        u0 : field (see :meth:`field`)
        dt : float
        steps : int
        diffusivity : float
        method : {"explicit", "implicit"}
            ``"explicit"``: ``u <- u + a dt L u`` on the Dask workers, one halo exchange a step
            (needs ``keep`` "laplacian"). ``"implicit"``: ``(M + a dt K) u' = M u``, unconditionally
            stable, solved globally on ``engine`` (needs ``keep`` "stable"; :mod:`manifold_sph.distributed.solve`).
        every : int, optional
            Explicit steps only: also return the state every ``every`` steps.
        check : bool
            Explicit steps: refuse ``dt > 2 / (a G)``, ``G`` the largest absolute row sum of ``L``
            (an upper bound of its spectral radius, so this limit is at most the single-process
            one of :func:`manifold_sph.pde.explicit_dt_limit`).
        engine : {"auto", "mpi", "dask-mpi", "local"}
            Implicit steps: PETSc on ``ranks`` MPI ranks, or one process (module notes of
            :mod:`manifold_sph.distributed.solve`). :attr:`last_solve` reports iterations and times.
        ranks : int or None
            MPI ranks of the ``"mpi"`` engine (None: 2), or workers of the ``"dask-mpi"`` engine (None: all).

        Returns
        -------
        Dask array (N,) in tile order, or a list of them (every ``every`` steps and the last).
        """
        dt, a = check_positive("dt", dt), check_positive("diffusivity", diffusivity)
        steps = check_int("steps", steps, minimum=1)
        check_in("method", method, ("explicit", "implicit"))
        if method == "implicit":
            if every is not None:
                raise ValueError("every= is for explicit steps; implicit steps return the final state")
            out = self._global("heat", engine, ranks, u0=self._tile_values(u0), a_dt=a * dt, steps=steps)
            return self._as_dask(out)
        if every is not None:
            every = check_int("every", every, minimum=1)
        if check_bool("check", check):
            G = max((r.get("gershgorin", 0.0) for r in self.report), default=0.0)
            if G > 0 and dt > 2.0 / (a * G):
                raise ValueError(
                    f"dt = {dt:g} is above the explicit heat limit {2.0 / (a * G):.4g} (2 / (a G), G = {G:.4g} the "
                    "largest absolute row sum of L); use a smaller dt, method='implicit', or check=False if you know "
                    "the spectral radius is smaller"
                )
        u = self.field(u0)
        snaps = []
        for step in range(1, steps + 1):
            u = self._apply("heat", u, a * dt)
            if self.scheduler == "distributed" and step % 10 == 0:
                u = self.client.persist(u)  # keep the task graph short
            if every is not None and step % every == 0:
                snaps.append(u)
        return snaps if every is not None else u

    # ------------------------------------------------------------------ global solves
    def _global(self, problem, engine, ranks, **args):
        from .solve import ENGINES, run

        self._check_open()
        check_in("engine", engine, ENGINES)
        ranks = None if ranks is None else check_int("ranks", ranks, minimum=1)
        out, self.last_solve = run(self, problem, engine=engine, ranks=ranks, **args)
        return out

    def _tile_values(self, values) -> np.ndarray:
        """A scalar field in tile order as numpy: arrays reordered here, Dask arrays and callables computed."""
        import dask.array as da

        if callable(values) or isinstance(values, da.Array):
            return np.asarray(self.compute(self.field(values)))
        return as_field("field", values, self.n_points)[self.order]

    def _as_dask(self, x):
        """A result held by the driver (a global solve's) as a Dask array; computing it alone stays on the driver."""
        import uuid

        import dask.array as da

        return da.from_array(np.asarray(x), chunks=(self.chunks,) + tuple((s,) for s in np.shape(x)[1:]),
                             name=DRIVER_PREFIX + uuid.uuid4().hex)

    def poisson(self, f: FieldLike, *, engine: str = "auto", ranks: int | None = None) -> DaskArray:
        """The zero-mean solution of ``-Lap u = f - mean(f)`` on the stable Laplacian, ``K u = M (f - mean_M f)``.

        ``f`` as in :meth:`field`; ``engine``, ``ranks`` as in :meth:`heat`. Returns a Dask array (N,) in tile order.
        """
        return self._as_dask(self._global("poisson", engine, ranks, f=self._tile_values(f)))

    def geodesic_distance(self, sources: ArrayLike, *, engine: str = "auto", ranks: int | None = None) -> DaskArray:
        """Geodesic distance from ``sources`` (input indices) by the heat method on the stable Laplacian.

        The formulation of :class:`manifold_sph.geometry.GeodesicSolver` (module notes of
        :mod:`manifold_sph.distributed.solve`); needs ``keep`` "stable" and "derivatives".
        Returns a Dask array (N,) in tile order; ``inf`` in the pieces of the cloud that hold no
        source (with a warning; ``last_solve["unreached"]`` counts them).
        """
        src = np.atleast_1d(np.asarray(sources))
        if src.size == 0 or not np.issubdtype(src.dtype, np.integer) or src.ndim != 1:
            raise ValueError(f"sources must be one or more integer particle indices, got {sources!r}")
        if src.min() < 0 or src.max() >= self.n_points:
            raise ValueError(f"sources must lie in [0, {self.n_points}), got {src[(src < 0) | (src >= self.n_points)][:5].tolist()}")
        where = np.empty(self.n_points, dtype=np.int64)
        where[self.order] = np.arange(self.n_points)
        d = self._global("geodesic", engine, ranks, sources=np.unique(where[src]))
        missing = int(self.last_solve.get("unreached", 0))
        if missing:
            import warnings

            from ..exceptions import ManifoldSPHWarning

            warnings.warn(f"{missing} particle(s) lie in pieces of the cloud that hold no source: their distance is inf",
                          ManifoldSPHWarning, stacklevel=2)
        return self._as_dask(d)

    def eigs(self, k: int = 50, *, sigma: float | None = None, engine: str = "auto",
             ranks: int | None = None) -> tuple[np.ndarray, DaskArray]:
        """The ``k`` smallest eigenpairs of ``K v = lambda M v`` (or those nearest ``sigma``), whole cloud.

        Returns ``(values (k,), vectors)``, the vectors a (N, k) Dask array in tile order, M-orthonormal.
        """
        k = check_int("k", k, minimum=1)
        if k > self.n_points - 2:
            raise ValueError(f"k must be smaller than the number of points minus 1 ({self.n_points - 1}), got {k}")
        if sigma is not None and (isinstance(sigma, bool) or not np.isfinite(sigma)):
            raise ValueError(f"sigma must be a finite number or None, got {sigma!r}")
        lam, V = self._global("eigs", engine, ranks, k=k, sigma=None if sigma is None else float(sigma))
        return lam, self._as_dask(V)

    def stiffness_matrix(self, order: str = "input") -> sp.csr_matrix:
        """The stable Laplacian's stiffness ``K`` (N, N) assembled on the driver (moderate N); needs ``keep`` "stable"."""
        return self._global_matrix("K", order)

    def mass_matrix(self, order: str = "input") -> sp.csr_matrix:
        """The stable Laplacian's diagonal mass ``M`` (N, N); needs ``keep`` "stable"."""
        from .solve import tile_vector

        self._check_open()
        if "stable" not in self.keep:
            raise ValueError(f"the stable matrices were not kept (keep={self.keep!r})")
        m = tile_vector(self, "M")
        if order == "input":
            out = np.empty_like(m)
            out[self.order] = m
            m = out
        return sp.diags(m).tocsr()

    def wave(self, u0: FieldLike, dt: float, steps: int, *, c: float = 1.0, v0: FieldLike | None = None,
             every: int | None = None, check: bool = True) -> DaskArray | list[DaskArray]:
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

    def derivative_matrices(self, order: str = "input") -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """The global tangent-plane derivative matrices ``(Dx, Dy)`` in each particle's frame."""
        return self._global_matrix("dx", order), self._global_matrix("dy", order)

    def _global_matrix(self, name, order):
        self._check_open()
        check_in("order", order, ("input", "tile"))
        need = {"lap": "laplacian", "K": "stable"}.get(name, "derivatives")
        if need not in self.keep:
            raise ValueError(f"the {need} matrices were not kept (keep={self.keep!r})")
        rows, cols, vals = [], [], []
        for t, n in enumerate(self.chunks):
            if n == 0:
                continue
            d = TileData(self._tile_path(t))
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
    def to_npy(self, x: DaskArray, path: str | os.PathLike[str], *, order: str = "input") -> None:
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
        tasks = [delayed(write_rows, pure=False)(xb[t], path, self._order_file, int(self.bounds[t])) for t in range(len(self.chunks))]
        self._compute(*tasks)

    def to_zarr(self, x: DaskArray, url: object, component: str | None = None, **kwargs: Any) -> None:
        """Write a Dask array (tile order, chunk = tile) to zarr; the input order is :attr:`order`.

        ``url``, ``component`` and ``kwargs`` as for :func:`dask.array.to_zarr` (a path, a URL or a zarr store).
        """
        import dask.array as da

        self._compute(da.to_zarr(x, url, component=component, compute=False, **kwargs))

