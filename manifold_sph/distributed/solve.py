"""Global solves on a tiled cloud: implicit heat, Poisson, geodesic distance and eigenpairs.

The tiles keep the own rows of the stable Laplacian's ``K`` and ``M`` (``keep=("stable",)``)
and, for geodesics, of the tangent-plane derivatives. Two engines solve with them:

``"mpi"``
    PETSc/SLEPc through petsc4py/slepc4py (the ``mpi`` extra): ``mpirun -n R python -m
    manifold_sph.mpi JOB`` is started on this machine (or the same command is run by the
    user under ``srun``/``mpirun`` on a cluster); each rank reads its own tiles' rows from
    the cache directory and solves with CG preconditioned by algebraic multigrid (hypre's
    BoomerAMG, or PETSc's GAMG), the geodesic's heat step as below, eigenpairs with SLEPc
    (Krylov-Schur, shift-invert on one MUMPS Cholesky factor up to :data:`EIGS_DIRECT_MAX_N`
    particles, through the same CG above).
``"dask-mpi"``
    The same engine on the workers of the Dask cluster that built the tiles, when that cluster was
    started by ``dask_mpi.initialize`` under ``mpirun``/``srun`` (each worker is an MPI rank; the
    ``mpi`` extra has dask-mpi): the job runs as a task on each of ``ranks`` workers (all of them
    by default), which make their communicator among themselves; nothing else is launched.
``"local"``
    One process: ``K`` and ``M`` assembled from the tiles and solved with
    :mod:`manifold_sph.solvers` (sparse Cholesky or AMG-CG) and :mod:`manifold_sph.spectrum`.

``engine="auto"`` takes ``"dask-mpi"`` when the tiles' Dask workers are MPI ranks, else ``"mpi"`` when
petsc4py and ``mpirun`` are installed and ``ranks`` > 1, ``"local"`` otherwise, and says so in a warning
when it falls back for want of the engine.

Formulations (the same on both engines, so their results agree to the solver tolerance):

- implicit Euler heat: ``(M + a dt K) u' = M u``;
- Poisson ``-Lap u = f`` on a closed surface: ``K u = M (f - mean_M f)``, the solution of zero mean;
  on a cloud of several pieces (:func:`piece_labels`) the means are each piece's and one value a
  piece is held while solving (``K`` is singular once a piece);
- geodesic distance (heat method, as :class:`manifold_sph.geometry.GeodesicSolver`):
  ``(M + t K) u = e_s`` with ``t = 4 mean(M)``, ``X = -grad u / |grad u|``, ``b_i = sum_j w_ij
  (X_i + X_j) / 2 . (x_i - x_j)``, then ``K phi = b`` with ``phi`` held at the Euclidean
  distance within ``3 sqrt(mean M)`` of the sources. ``u`` decays like ``exp(-d / sqrt(t))``,
  far below the residual tolerance of any iterative solve, and ``X`` needs its far field. Up to
  :data:`GEODESIC_DIRECT_MAX_N` particles the heat step is a sparse Cholesky solve (CHOLMOD,
  MUMPS on MPI), which keeps every entry's digits. Above, it is solved in bands
  (:mod:`manifold_sph.distributed.bands`), each band with Jacobi-CG on a window around its seed,
  so a band costs its window's work and no factor or multigrid is held;
- eigenpairs of ``K v = lambda M v`` nearest a shift just below zero.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from ..exceptions import ManifoldSPHWarning
from .bands import BAND_FLOOR, BAND_RTOL, DIRECT_FLOOR, WindowedHeat, band_directions

if TYPE_CHECKING:
    from .operators import TiledOperators

__all__ = ["EIGS_DIRECT_MAX_N", "ENGINES", "GEODESIC_DIRECT_MAX_N", "GEODESIC_T", "SOURCE_RADIUS",
           "dask_mpi_workers", "engine_available", "geodesic_from_matrices", "piece_labels", "run"]

ENGINES = ("auto", "mpi", "dask-mpi", "local")
#: Geodesic heat time in units of the mean area element, and the held radius in units of the spacing.
GEODESIC_T = 4.0
SOURCE_RADIUS = 3.0
#: Particles up to which the geodesic's heat step is a direct (Cholesky) solve on both engines; above, bands.
GEODESIC_DIRECT_MAX_N = 2_000_000
#: Particles up to which the MPI engine's eigensolver shift-inverts with a MUMPS Cholesky factor of
#: ``K - sigma M`` (as the local engine does with CHOLMOD); above, each application is a multigrid CG solve.
EIGS_DIRECT_MAX_N = 2_000_000


def engine_available() -> str | None:
    """None when the MPI engine can run here, else the reason it cannot."""
    import importlib.util

    missing = [m for m in ("mpi4py", "petsc4py", "slepc4py") if importlib.util.find_spec(m) is None]
    if missing:
        return f"{', '.join(missing)} not installed (pip install 'manifold-sph[mpi]', docs/distributed.md)"
    if shutil.which("mpirun") is None and shutil.which("mpiexec") is None:
        return "no mpirun or mpiexec on the PATH"
    return None


def job_description(ts: TiledOperators) -> dict[str, Any]:
    """What an MPI rank needs to read the tiles: sizes, tile files, points and order files."""
    return {"n_points": int(ts.n_points), "bounds": [int(b) for b in ts.bounds],
            "tiles": [ts._tile_path(t) for t in range(len(ts.chunks))], "points": ts._points_file,
            "order": ts._order_file, "keep": list(ts.keep)}


# ----------------------------------------------------------------------------- local engine
def assemble(ts: TiledOperators, name: str) -> sp.csr_matrix:
    """A kept operator over the whole cloud, tile order."""
    return ts._global_matrix(name, "tile")


def tile_vector(ts: TiledOperators, name: str, width: int | None = None) -> np.ndarray:
    from .tiles import TileData

    parts = [np.asarray(TileData(ts._tile_path(t))[name]) for t in range(len(ts.chunks))]
    return np.concatenate(parts) if parts else np.zeros((0,) if width is None else (0, width))


def _local_heat(ts, u, a_dt, steps):
    from ..solvers import spd_solver

    K, m = assemble(ts, "K"), tile_vector(ts, "M")
    solver = spd_solver(sp.diags(m) + a_dt * K)
    its = []
    for _ in range(steps):
        u = solver.solve(m * u)
        its.append(solver.info.iterations)
    return u, {"iterations": its, "method": solver.method}


def piece_labels(ts: TiledOperators) -> tuple[int, np.ndarray]:
    """``(pieces, labels (N,))``: the connected pieces of ``K``'s graph, tile order, read tile by tile.

    Each tile labels the components of its own rows' graph (own and halo particles); a halo
    particle joins its tile's component to the one its own tile gave it, and the components
    of those joins are the pieces. Memory: one label a particle plus one join a halo particle,
    never the whole matrix.
    """
    from scipy.sparse.csgraph import connected_components

    from .tiles import TileData

    n = int(ts.n_points)
    own = np.empty(n, dtype=np.int64)  # the global component id each particle's own tile gave it
    halo_ids, halo_cols = [], []
    offset = 0
    for t in range(len(ts.chunks)):
        lo, hi = int(ts.bounds[t]), int(ts.bounds[t + 1])
        if hi == lo:
            continue
        d = TileData(ts._tile_path(t))
        K, cols = d["K"], np.asarray(d["cols"])
        ptr = np.asarray(K.indptr)
        ptr = np.r_[ptr, np.full(cols.size - (hi - lo), ptr[-1])]  # own rows first; the halo's rows are empty
        graph = sp.csr_matrix((np.ones(K.indices.size, dtype=np.int8), np.asarray(K.indices), ptr),
                              shape=(cols.size, cols.size))
        count, lab = connected_components(graph, directed=False)
        own[lo:hi] = lab[: hi - lo] + offset
        halo_ids.append(lab[hi - lo :] + offset)
        halo_cols.append(cols[hi - lo :])
        offset += count
        d.release()
    a = np.concatenate(halo_ids) if halo_ids else np.zeros(0, dtype=np.int64)
    b = own[np.concatenate(halo_cols)] if halo_cols else np.zeros(0, dtype=np.int64)
    joins = sp.csr_matrix((np.ones(a.size, dtype=np.int8), (a, b)), shape=(offset, offset))
    pieces, merged = connected_components(joins, directed=False)
    _, labels = np.unique(merged[own], return_inverse=True)  # pieces numbered 0, 1, ... by first appearance order
    return int(labels.max()) + 1 if n else 0, labels.astype(np.int64)


def _local_poisson(ts, f):
    from ..solvers import spd_solver

    K, m = assemble(ts, "K"), tile_vector(ts, "M")
    pieces, labels = piece_labels(ts)
    area = np.bincount(labels, weights=m, minlength=pieces)
    b = m * (f - (np.bincount(labels, weights=m * f, minlength=pieces) / area)[labels])  # zero mean on every piece
    free = np.ones(m.size, dtype=bool)
    free[np.unique(labels, return_index=True)[1]] = False  # one value held a piece; the zero-mean shift makes it unique
    solver = spd_solver(K[free][:, free])
    u = np.zeros(m.size)
    u[free] = solver.solve(b[free])
    u -= (np.bincount(labels, weights=m * u, minlength=pieces) / area)[labels]
    return u, {"iterations": [solver.info.iterations], "method": solver.method, "pieces": int(pieces)}


def geodesic_rhs(K: sp.spmatrix | sp.sparray, pts: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``b_i = sum_j w_ij (X_i + X_j) / 2 . (x_i - x_j)`` over the off-diagonal ``w_ij = -K_ij`` of ``K``'s rows."""
    Kc = K.tocoo()
    off = Kc.row != Kc.col
    i, j, w = Kc.row[off], Kc.col[off], -Kc.data[off]
    return np.bincount(i, weights=w * np.einsum("pd,pd->p", 0.5 * (X[i] + X[j]), pts[i] - pts[j]),
                       minlength=K.shape[0])


def held_particles(pts: np.ndarray, src: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(held mask, Euclidean distance to the nearest source)``: the particles within the source radius."""
    from scipy.spatial import cKDTree

    r = cKDTree(pts[src]).query(pts)[0]
    held = r <= SOURCE_RADIUS * np.sqrt(m.mean())
    held[src] = True
    return held, r


def _local_geodesic(ts, src):
    K, m = assemble(ts, "K"), tile_vector(ts, "M")
    dx, dy = assemble(ts, "dx"), assemble(ts, "dy")
    U, V = tile_vector(ts, "u", 3), tile_vector(ts, "v", 3)
    pts = np.asarray(np.load(ts._points_file, mmap_mode="r"))
    return geodesic_from_matrices(K, m, dx, dy, U, V, pts, src)


def geodesic_from_matrices(K: sp.csr_matrix, m: np.ndarray, dx: sp.csr_matrix, dy: sp.csr_matrix, U: np.ndarray,
                           V: np.ndarray, pts: np.ndarray, src: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    """The geodesic heat method of the module notes on whole-cloud matrices; ``(distance, info)``.

    ``K``, ``m``: the stable Laplacian; ``dx``, ``dy`` the tangent-plane derivative matrices in
    the frames ``U``, ``V`` (N, 3); ``pts`` (N, 3); ``src`` source indices.
    """
    from ..frames import unit_rows
    from ..solvers import cholesky_available, spd_solver

    n = m.size
    rhs = np.zeros(n)
    rhs[src] = 1.0
    A = sp.diags(m) + GEODESIC_T * m.mean() * K

    def directions(u):  # u's far field is tiny: no squares of it
        return -unit_rows((dx @ u)[:, None] * U + (dy @ u)[:, None] * V)

    heat: Any
    if n <= GEODESIC_DIRECT_MAX_N and cholesky_available():
        heat, floor = spd_solver(A, method="cholesky"), DIRECT_FLOOR
    else:
        heat, floor = WindowedHeat(A, pts, GEODESIC_T * m.mean(), rtol=BAND_RTOL), BAND_FLOOR
    X, heat_its, reached = band_directions(heat, rhs, directions, floor=floor)
    b = geodesic_rhs(K, pts, X)
    held, r = held_particles(pts, src, m)
    held &= reached  # a particle of another piece near a source is not reached
    free = reached & ~held
    Kf = K[free]
    poisson = spd_solver(Kf[:, free])
    phi = np.where(reached, r, np.inf)  # the pieces holding no source: inf
    phi[free] = poisson.solve(b[free] - Kf[:, held] @ r[held])
    return phi, {"iterations": heat_its + [poisson.info.iterations], "method": f"{heat.method} heat step, {poisson.method}",
                 "unreached": int(n - np.count_nonzero(reached))}


def _local_eigs(ts, k, sigma):
    from ..spectrum import stable_eigenpairs

    K, m = assemble(ts, "K"), tile_vector(ts, "M")
    ev = stable_eigenpairs(K, m, k, sigma=sigma, component="all")
    return ev.values, ev.vectors, {"iterations": [], "method": ev.method}


# ----------------------------------------------------------------------------- dispatch
def run(ts: TiledOperators, problem: str, *, engine: str, ranks: int | None, **args: Any) -> tuple[Any, dict[str, Any]]:
    """Run a global solve on ``engine``; returns ``(result in tile order, info dict)``.

    ``ranks``: MPI ranks of the ``"mpi"`` engine (None: 2), workers of the ``"dask-mpi"`` engine (None: all).
    """
    need = ["stable"] + (["derivatives"] if problem == "geodesic" else [])
    missing = [k for k in need if k not in ts.keep]
    if missing:
        raise ValueError(f"{problem} needs the tiles' {' and '.join(missing)} rows, which were not kept "
                         f"(keep={ts.keep!r}); build with keep=(..., {', '.join(map(repr, missing))})")
    workers = dask_mpi_workers(ts.client) if engine in ("auto", "dask-mpi") else None
    if engine == "dask-mpi" and not workers:
        raise ValueError("engine='dask-mpi' needs a Dask cluster started by dask_mpi.initialize (each worker an "
                         "MPI rank, worker_class distributed.Worker): the tiles' workers are not MPI ranks")
    if engine == "auto":
        why = engine_available()
        if workers:
            engine = "dask-mpi"
        elif why is None and (ranks or 2) > 1:
            engine = "mpi"
        else:
            engine = "local"
            if why is not None:
                warnings.warn(f"the MPI engine is not available ({why}): solving on one process with "
                              "scipy/pyamg/cholespy instead", ManifoldSPHWarning, stacklevel=3)
    if engine == "dask-mpi":
        assert workers is not None
        if ranks is not None and ranks > len(workers):
            raise ValueError(f"ranks: the dask-mpi engine has {len(workers)} worker(s) (MPI ranks), got ranks={ranks}")
        everyone, workers = workers, dict(list(workers.items())[: ranks or len(workers)])
        ranks = len(workers)
    else:
        ranks = ranks or 2
    t0 = time.perf_counter()
    if engine in ("mpi", "dask-mpi"):
        if problem == "poisson":  # the ranks see their own rows only: the pieces are labelled here
            pieces, labels = piece_labels(ts)
            args = args | {"pieces": pieces, "labels": labels.astype(np.int32 if pieces < 2**31 else np.int64),
                           "pinned": np.unique(labels, return_index=True)[1].astype(np.int64)}
        out, info = _run_mpi(ts, problem, ranks, args,
                             workers=(workers, everyone) if engine == "dask-mpi" else None)
        if problem == "poisson":
            info["pieces"] = int(args["pieces"])
    elif problem == "heat":
        out, info = _local_heat(ts, args["u0"], args["a_dt"], args["steps"])
    elif problem == "poisson":
        out, info = _local_poisson(ts, args["f"])
    elif problem == "geodesic":
        out, info = _local_geodesic(ts, args["sources"])
    else:
        lam, V, info = _local_eigs(ts, args["k"], args.get("sigma"))
        out = (lam, V)
    info = {"engine": engine, "ranks": ranks if engine != "local" else 1, "seconds": time.perf_counter() - t0} | info
    return out, info


def dask_mpi_workers(client: Any) -> dict[str, int] | None:
    """The workers of ``client`` that are MPI ranks, ``{address: rank in COMM_WORLD}`` in rank order.

    None when the client has no worker, or any of its workers is not a rank of a COMM_WORLD of several
    processes in which the worker has already initialised MPI (as ``dask_mpi.initialize`` does). Asks the
    workers without importing mpi4py there.
    """
    if client is None:
        return None
    try:
        found = client.run(_world_rank)
    except Exception:  # a closed or unreachable cluster: no dask-mpi engine
        return None
    if not found or any(r is None for r in found.values()):
        return None
    return dict(sorted(((str(a), int(r)) for a, r in found.items()), key=lambda item: item[1]))


def _world_rank() -> int | None:
    """This process's rank in COMM_WORLD if it has initialised MPI and COMM_WORLD has several processes."""
    MPI = sys.modules.get("mpi4py.MPI")
    if MPI is None or not MPI.Is_initialized() or MPI.Is_finalized() or MPI.COMM_WORLD.Get_size() < 2:
        return None
    return int(MPI.COMM_WORLD.Get_rank())


def _worker_job(path: str | None, world_ranks: list[int], all_ranks: list[int]) -> int | None:
    """A Dask task on each MPI worker: its part of the job at ``path`` (collective over ``world_ranks``)."""
    import importlib

    engine = importlib.import_module("manifold_sph.mpi.engine")  # the engine, as ``python -m manifold_sph.mpi``
    return engine.run_on_world_ranks(path, world_ranks, all_ranks)


def _run_mpi(ts, problem, ranks, args, *, workers=None):
    work = tempfile.mkdtemp(prefix="msph-mpi-", dir=str(ts.cache_dir))
    try:
        job = job_description(ts) | {"problem": problem, "work": work, "geodesic_direct_max_n": GEODESIC_DIRECT_MAX_N,
                                     "eigs_direct_max_n": EIGS_DIRECT_MAX_N}
        for name, value in args.items():
            if isinstance(value, np.ndarray):
                path = os.path.join(work, name + ".npy")
                np.save(path, value)
                job[name] = {"npy": path}
            else:
                job[name] = value
        path = os.path.join(work, "job.json")
        with open(path, "w") as f:
            json.dump(job, f)
        if workers is not None:
            _launch_on_workers(ts.client, path, *workers)
        else:
            _launch_mpirun(path, ranks)
        with open(os.path.join(work, "info.json")) as f:
            info = json.load(f)
        if problem == "eigs":
            out = (np.load(os.path.join(work, "values.npy")), np.load(os.path.join(work, "vectors.npy")))
        else:
            out = np.load(os.path.join(work, "x.npy"))
        return out, info
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _launch_mpirun(path, ranks):
    launcher = shutil.which("mpirun") or shutil.which("mpiexec")
    if launcher is None:
        raise RuntimeError("the MPI engine needs mpirun or mpiexec on the PATH")
    cmd = [launcher, "-n", str(ranks)]
    if _is_openmpi(launcher):  # Open MPI refuses root and more ranks than cores unless told
        cmd += ["--allow-run-as-root", "--oversubscribe"]
    cmd += [sys.executable, "-m", "manifold_sph.mpi", path]
    env = dict(os.environ, OMPI_MCA_rmaps_base_oversubscribe="1")
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one thread a rank unless told
        env.setdefault(name, "1")
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"the MPI engine failed (exit {proc.returncode}): {' '.join(cmd)}\n{proc.stderr[-3000:]}")


def _launch_on_workers(client, path, workers, everyone):
    """The job as one task on every MPI worker of ``everyone`` at once (``{address: world rank}``): those of
    ``workers`` solve, the others only take part in PETSc's first initialisation (collective over all of them)."""
    ranks, all_ranks = list(workers.values()), list(everyone.values())
    tag = os.path.basename(os.path.dirname(path))
    futures = [client.submit(_worker_job, path if address in workers else None, ranks, all_ranks,
                             workers=[address], allow_other_workers=False, pure=False,
                             key=f"manifold-sph-mpi-{rank}-{tag}")
               for address, rank in everyone.items()]
    client.gather(futures)


def _is_openmpi(launcher: str) -> bool:
    try:
        out = subprocess.run([launcher, "--version"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        return False
    return "Open MPI" in out or "OpenRTE" in out
