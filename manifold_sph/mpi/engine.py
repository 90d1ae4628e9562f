"""The MPI engine of the global solves: PETSc (CG + algebraic multigrid, MUMPS) and SLEPc on the tiles' rows of ``K`` and ``M``.

Run by ``mpirun -n R python -m manifold_sph.mpi JOB.json`` (``TiledSurface`` writes the job
and starts it; on a cluster the same command runs under ``srun``), or on the workers of a Dask
cluster started by ``dask_mpi.initialize`` (each worker is an MPI rank: :func:`run_on_world_ranks`). Each rank owns whole
tiles: a contiguous range of rows in tile order, balanced by particle count, read from
the tile cache directory with memory maps. Nothing is assembled on one rank.

The formulations are those of :mod:`manifold_sph.distributed.solve`; results are written
into ``.npy`` files in the job's work directory, each rank its own rows. Every solve is CG
preconditioned by algebraic multigrid (:func:`multigrid`: hypre's BoomerAMG, or GAMG) but the
geodesic's heat step: its solution decays exponentially away
from the sources, below what a residual tolerance resolves, so up to the job's
``geodesic_direct_max_n`` particles it is a distributed Cholesky (MUMPS) and above it the
windowed bands of :mod:`manifold_sph.distributed.bands` (Jacobi-CG on each band's window).
"""

from __future__ import annotations

import json
import os
import resource
import sys
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["HYPRE_OPTIONS", "RTOL", "main", "multigrid", "rank_tiles", "run_job", "run_on_world_ranks"]

#: Rows of K a rank treats at once where it forms pair arrays (the geodesic's right-hand side; a job's "block_rows").
BLOCK_ROWS = 131_072
#: The tag of ``MPI_Comm_create_group`` when a job runs on some of COMM_WORLD's ranks (Dask workers).
JOB_TAG = 4242
#: Relative residual of every CG solve (equality with the single process's Cholesky to ~1e-10).
RTOL = 1e-12
#: The multigrid of the CG solves where PETSc has hypre: BoomerAMG with aggressive coarsening on the finest
#: level and truncated interpolation (each a PETSc option a user's PETSC_OPTIONS may override): about half of
#: GAMG's hierarchy at the same iterations (docs/distributed.md).
HYPRE_OPTIONS = {"pc_hypre_type": "boomeramg", "pc_hypre_boomeramg_agg_nl": "1", "pc_hypre_boomeramg_coarsen_type": "HMIS",
                 "pc_hypre_boomeramg_interp_type": "ext+i", "pc_hypre_boomeramg_P_max": "2"}


def multigrid(pc: Any) -> str:
    """Make ``pc`` the engine's multigrid: hypre's BoomerAMG with :data:`HYPRE_OPTIONS` where PETSc has hypre,
    GAMG otherwise; returns its name."""
    from petsc4py import PETSc

    if PETSc.Sys.hasExternalPackage("hypre"):
        opts = PETSc.Options()
        for name, value in HYPRE_OPTIONS.items():
            if not opts.hasName(name):
                opts[name] = value
        pc.setType("hypre")
        return "hypre"
    pc.setType("gamg")
    return "gamg"


def rank_tiles(bounds: ArrayLike, size: int, rank: int) -> tuple[int, int]:
    """The tiles ``[t0, t1)`` of ``rank``: contiguous, cut where the particle count crosses ``N r / size``."""
    bounds = np.asarray(bounds)
    n = int(bounds[-1])
    cuts = np.searchsorted(bounds[:-1], [n * r / size for r in range(size + 1)], side="left")
    cuts[-1] = bounds.size - 1
    return int(cuts[rank]), int(cuts[rank + 1])


def _load(job, name):
    """A job's array: from its ``.npy`` file memory-mapped (a rank reads only the slice it uses), or inline."""
    v = job[name]
    return np.load(v["npy"], mmap_mode="r") if isinstance(v, dict) and "npy" in v else v


class _Rows:
    """This rank's rows: ``K`` (PETSc Mat over all ranks), ``m``, and the tiles' data."""

    def __init__(self, job, comm):
        from petsc4py import PETSc

        from ..allocator import release_freed_memory
        from ..distributed.tiles import TileData

        self.comm = comm
        t0, t1 = rank_tiles(job["bounds"], comm.getSize(), comm.getRank())
        self.tiles = [TileData(job["tiles"][t]) for t in range(t0, t1)]
        self.lo, self.hi = int(job["bounds"][t0]), int(job["bounds"][t1])
        self.n = int(job["n_points"])
        nloc = self.hi - self.lo
        # PETSc's storage is allocated once from the rows' counts, then filled tile by tile: the transient
        # memory is one tile's rows, never a second copy of the rank's matrix
        d_nnz, o_nnz, m_parts = [], [], []
        for d in self.tiles:
            K, gcol = d["K"], np.asarray(d["cols"])
            inside = (gcol >= self.lo) & (gcol < self.hi)
            rows = np.repeat(np.arange(d.n), np.diff(np.asarray(K.indptr)))
            d_nnz.append(np.bincount(rows, weights=inside[np.asarray(K.indices)], minlength=d.n).astype(PETSc.IntType))
            o_nnz.append((np.diff(np.asarray(K.indptr)) - d_nnz[-1]).astype(PETSc.IntType))
            m_parts.append(np.array(d["M"]))
            del K, gcol, inside, rows
        nnz = tuple(np.concatenate(c) if c else np.zeros(0, PETSc.IntType) for c in (d_nnz, o_nnz))
        self.K = PETSc.Mat().createAIJ(size=((nloc, self.n), (nloc, self.n)), nnz=nnz, comm=comm)
        del d_nnz, o_nnz, nnz
        self.K.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        lo = self.lo
        for d in self.tiles:
            K, gcol = d["K"], np.asarray(d["cols"])
            self.K.setValuesIJV(np.asarray(K.indptr).astype(PETSc.IntType), gcol[np.asarray(K.indices)].astype(PETSc.IntType),
                                np.asarray(K.data), rowmap=np.arange(lo, lo + d.n, dtype=PETSc.IntType))
            lo += d.n
            del K, gcol
            d.release()
        self.K.assemble()
        self.m = np.concatenate(m_parts) if m_parts else np.zeros(0)
        del m_parts
        release_freed_memory()  # the rows' temporaries: back to the system, not kept by malloc
        self.M = self.vec(self.m)
        self.m = self.M.getArray()  # M's own storage: one copy of the masses a rank
        self.mean_m = comm.tompi4py().allreduce(float(self.m.sum())) / self.n
        self.unreached = 0  # the geodesic: particles in pieces that hold no source
        self.methods: list[str] = []  # what solved each system, in order

    def release_tiles(self) -> None:
        """Drop the tiles' memory maps (their pages count in the rank's resident memory while mapped)."""
        for d in self.tiles:
            d.release()

    def vec(self, values=None):
        from petsc4py import PETSc

        v = PETSc.Vec().createMPI((self.hi - self.lo, self.n), comm=self.comm)
        if values is not None:
            v.getArray()[:] = values
        return v

    def ksp(self, A):
        """CG preconditioned by :func:`multigrid`, to :data:`RTOL`; PETSC_OPTIONS apply (no prefix)."""
        from petsc4py import PETSc

        ksp = PETSc.KSP().create(comm=self.comm)
        ksp.setOperators(A)
        ksp.setType("cg")
        multigrid(ksp.getPC())
        ksp.setTolerances(rtol=RTOL, atol=0.0, max_it=2000)
        ksp.setFromOptions()
        return ksp

    def cholesky(self, A):
        """A solver applying a distributed sparse Cholesky factorisation of the SPD ``A`` (MUMPS through PETSc)."""
        from petsc4py import PETSc

        if not PETSc.Sys.hasExternalPackage("mumps"):
            raise RuntimeError("the geodesic heat step needs a PETSc built with MUMPS (Debian/Ubuntu's libpetsc-real-dev "
                               "has it; from source: --download-mumps --download-scalapack)")
        A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        A.setOption(PETSc.Mat.Option.SPD, True)
        ksp = PETSc.KSP().create(comm=self.comm)
        ksp.setOptionsPrefix("direct_")  # a PETSC_OPTIONS -pc_type meant for the CG solves must not replace the factor
        ksp.setOperators(A)
        ksp.setType("preonly")
        ksp.getPC().setType("cholesky")
        ksp.getPC().setFactorSolverType("mumps")
        ksp.setFromOptions()
        return ksp

    def solve(self, ksp, b, x, its, secs):
        """Solve into ``x``; append the iterations (0 for a direct solve) and the seconds (set-up included)."""
        t = time.perf_counter()
        ksp.solve(b, x)
        if ksp.getConvergedReason() < 0:
            raise RuntimeError(f"{ksp.getType()} + {ksp.getPC().getType()} did not converge (reason {ksp.getConvergedReason()}, "
                               f"{ksp.getIterationNumber()} iterations, residual {ksp.getResidualNorm():.3g})")
        its.append(0 if ksp.getType() == "preonly" else int(ksp.getIterationNumber()))
        self.methods.append(ksp.getPC().getFactorSolverType() if ksp.getType() == "preonly"
                            else f"{ksp.getType()}-{ksp.getPC().getType()}")
        secs.append(time.perf_counter() - t)

    def halo(self, values):
        """``values`` (own rows, (nloc,) or (nloc, c)) at every particle the own rows' columns name, in the order of
        :attr:`needed` (sorted tile-order indices): a PETSc scatter of what the rows use, never the whole vector."""
        from petsc4py import PETSc

        if not hasattr(self, "_scatter"):
            self.needed = np.unique(np.concatenate([np.asarray(d["cols"]) for d in self.tiles])) if self.tiles \
                else np.zeros(0, dtype=np.int64)
            self._target = PETSc.Vec().createSeq(self.needed.size, comm=PETSc.COMM_SELF)
            index = PETSc.IS().createGeneral(self.needed.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
            self._source = self.vec()
            self._scatter = PETSc.Scatter().create(self._source, index, self._target, None)
        values = np.asarray(values)
        cols = values.reshape(values.shape[0], -1)
        out = np.empty((self.needed.size, cols.shape[1]))
        for c in range(cols.shape[1]):
            self._source.getArray()[:] = cols[:, c]
            self._scatter.scatter(self._source, self._target, addv=PETSc.InsertMode.INSERT,
                                  mode=PETSc.ScatterMode.FORWARD)
            out[:, c] = self._target.getArray()
        return out.reshape((self.needed.size,) + values.shape[1:])

    def drop_halo(self) -> None:
        """Free what :meth:`halo` set up (it is set up again when next used)."""
        if hasattr(self, "_scatter"):
            for o in (self._scatter, self._source, self._target):
                o.destroy()
            del self._scatter, self._source, self._target, self.needed

    def at(self, cols):
        """Positions of the tile-order indices ``cols`` in :attr:`needed`."""
        return np.searchsorted(self.needed, cols)


def _write(job, name, shape, lo, hi, values, comm):
    path = os.path.join(job["work"], name + ".npy")
    if comm.getRank() == 0:
        np.lib.format.open_memmap(path, mode="w+", dtype=np.float64, shape=shape).flush()
    comm.barrier()
    out = np.load(path, mmap_mode="r+")
    out[lo:hi] = values
    out.flush()
    del out


def _heat(job, R, its, secs):
    A = R.K  # the heat step needs K only through M + a dt K: built in place, no second matrix
    A.scale(float(job["a_dt"]))
    A.setDiagonal(R.M, addv=True)
    ksp = R.ksp(A)
    ksp.setInitialGuessNonzero(True)
    x = R.vec(np.asarray(_load(job, "u0")[R.lo : R.hi]))
    b = R.vec()
    for _ in range(int(job["steps"])):
        b.getArray()[:] = R.m * x.getArray()
        R.solve(ksp, b, x, its, secs)
    return x.getArray().copy()


def _poisson(job, R, its, secs):
    from petsc4py import PETSc

    f = _load(job, "f")
    mpi = R.comm.tompi4py()
    fl = np.asarray(f[R.lo : R.hi])
    pieces = int(job.get("pieces", 1))
    if pieces == 1:
        lab = np.zeros(R.hi - R.lo, dtype=np.int64)
    else:
        lab = np.asarray(_load(job, "labels")[R.lo : R.hi], dtype=np.int64)

    def piece_means(v):  # the M-weighted mean of v on each piece, every rank the same (pieces,)
        sums = np.array([np.bincount(lab, weights=R.m * v, minlength=pieces), np.bincount(lab, weights=R.m, minlength=pieces)])
        sums = mpi.allreduce(sums)
        return sums[0] / sums[1]

    b = R.vec(R.m * (fl - piece_means(fl)[lab]))
    x = R.vec()
    # K has one null vector a piece: one value held on each (its row and column made the identity's) makes the
    # system definite, as on the local engine (a multigrid built on the singular K can be an indefinite
    # preconditioner), then each piece's mean is taken off
    pinned = np.asarray(_load(job, "pinned"), dtype=np.int64) if pieces > 1 else np.zeros(1, dtype=np.int64)
    rows = pinned[(pinned >= R.lo) & (pinned < R.hi)].astype(PETSc.IntType)
    A = R.K
    A.zeroRowsColumns(rows, diag=1.0, x=x, b=b)
    R.solve(R.ksp(A), b, x, its, secs)
    u = x.getArray().copy()
    return u - piece_means(u)[lab]


def _geodesic(job, R, its, secs):
    from mpi4py import MPI
    from petsc4py import PETSc
    from scipy.spatial import cKDTree

    from ..allocator import release_freed_memory
    from ..distributed.bands import BAND_FLOOR, BAND_SHELL, DIRECT_FLOOR
    from ..distributed.solve import GEODESIC_DIRECT_MAX_N, GEODESIC_T, SOURCE_RADIUS
    from ..frames import unit_rows

    src = np.asarray(_load(job, "sources"), dtype=np.int64)
    pts = np.load(job["points"], mmap_mode="r")
    mpi = R.comm.tompi4py()
    nloc = R.hi - R.lo
    # the heat operator M + t K is K itself scaled and shifted in place (undone before the Poisson step): a rank
    # holds one matrix; the fields other rows need arrive by a scatter of the halo only (R.halo)
    c = GEODESIC_T * R.mean_m
    A = R.K
    A.scale(c)
    A.setDiagonal(R.M, addv=True)
    rhs = np.zeros(nloc)
    mine = src[(src >= R.lo) & (src < R.hi)]
    rhs[mine - R.lo] = 1.0
    x = R.vec()

    def set_directions(w, ok, X):  # X[ok] = -grad u / |grad u|, tile by tile, only where ok; no squares of tiny u
        wh = R.halo(w)
        lo = 0
        for d in R.tiles:
            sel = np.flatnonzero(ok[lo : lo + d.n])
            if sel.size:
                uc = wh[R.at(np.asarray(d["cols"]))]
                g = (d["dx"][sel] @ uc)[:, None] * d["u"][sel] + (d["dy"][sel] @ uc)[:, None] * d["v"][sel]
                X[lo + sel] = -unit_rows(g)
                d.release()  # a tile's derivative rows are mapped while used, not for the whole run
            lo += d.n

    # u decays like exp(-d / sqrt(t)) away from the sources, far below CG's residual tolerance, and X needs
    # its far field: a Cholesky factor (MUMPS) keeps every entry's digits; above the size where the local
    # engine factorises, the same windowed bands as its (manifold_sph.distributed.bands)
    if R.n <= int(job.get("geodesic_direct_max_n", GEODESIC_DIRECT_MAX_N)):
        direct = R.cholesky(A)

        def heat(b):
            R.solve(direct, b, x, its, secs)
            return x.getArray().copy()

        floor = DIRECT_FLOOR
    else:
        heat, floor = _WindowedHeat(R, A, np.asarray(pts[R.lo : R.hi]), c, its, secs), BAND_FLOOR
    X_own, done = np.zeros((nloc, 3)), np.zeros(nloc, dtype=bool)
    b = R.vec(rhs)
    del rhs
    while True:
        w = heat(b)
        top = mpi.allreduce(float(np.abs(w).max()) if nloc else 0.0, op=MPI.MAX)
        if not top > 0:
            break
        ok = (w > floor * top) & ~done
        if not mpi.allreduce(bool(ok.any()), op=MPI.LOR):
            break
        set_directions(w, ok, X_own)
        done |= ok
        shell = ok & (w <= BAND_SHELL * floor * top)
        if mpi.allreduce(bool(done.all()), op=MPI.LAND) or not mpi.allreduce(bool(shell.any()), op=MPI.LOR):
            break
        smax = mpi.allreduce(float(w[shell].max()) if shell.any() else 0.0, op=MPI.MAX)
        b.getArray()[:] = np.where(shell, w / smax, 0.0)
    del heat, b, w
    x.destroy()  # the heat step's solution vector
    R.unreached = int(mpi.allreduce(int(np.count_nonzero(~done)), op=MPI.SUM))
    Xh = R.halo(X_own)
    bb = np.zeros(nloc)
    lo, block = 0, int(job.get("block_rows", BLOCK_ROWS))
    for d in R.tiles:  # sum_j w_ij (X_i + X_j) / 2 . (x_i - x_j), the own rows of K, in blocks of rows
        K_t, cols = d["K"], np.asarray(d["cols"])
        for r0 in range(0, d.n, block):
            Kt = K_t[r0 : r0 + block].tocoo()
            off = Kt.row + r0 != Kt.col  # the diagonal: column (tile + halo index) = the own row
            gi, gj, wt = cols[Kt.row[off] + r0], cols[Kt.col[off]], -Kt.data[off]
            dot = np.einsum("pd,pd->p", 0.5 * (X_own[gi - R.lo] + Xh[R.at(gj)]), np.asarray(pts[gi]) - np.asarray(pts[gj]))
            bb[lo + r0 : lo + r0 + Kt.shape[0]] = np.bincount(Kt.row[off], weights=wt * dot, minlength=Kt.shape[0])
            del Kt, off, gi, gj, wt, dot
        lo += d.n
        del K_t
        d.release()
    del Xh, X_own
    R.drop_halo()  # the scatter's vectors and indices: not held through the Poisson step
    release_freed_memory()  # the bands' and the right-hand side's temporaries, before the Poisson step's multigrid
    r = cKDTree(np.asarray(pts[np.sort(src)])).query(np.asarray(pts[R.lo : R.hi]))[0]
    del pts
    held = r <= SOURCE_RADIUS * np.sqrt(R.mean_m)
    held[mine - R.lo] = True
    held &= done  # a particle of another piece near a source is not reached
    pinned = held | ~done  # the pieces holding no source: pinned at 0, then inf
    rows = (np.flatnonzero(pinned) + R.lo).astype(PETSc.IntType)
    xv, bv = R.vec(np.where(held, r, 0.0)), R.vec(bb)
    del r, bb, held, pinned
    K = _heat_to_stiffness(A, R.M, c)
    K.zeroRowsColumns(rows, diag=1.0, x=xv, b=bv)
    xv.destroy()
    del xv, rows
    release_freed_memory()  # what the Poisson step's multigrid set-up can reuse
    phi = R.vec()
    R.solve(R.ksp(K), bv, phi, its, secs)
    out = phi.getArray().copy()
    out[~done] = np.inf
    return out


class _WindowedHeat:
    """A band's heat step on the window around its seed only (:class:`manifold_sph.distributed.bands.WindowedHeat`
    across the ranks): each rank hashes its own particles into the voxels, the seeds' voxels are gathered, and CG
    with a Jacobi preconditioner (options prefix ``band_``) solves the sub-matrix of the window's rows."""

    def __init__(self, R, A, own_points, t, its, secs):
        from mpi4py import MPI

        from ..distributed.bands import BAND_WINDOW, VoxelWindows

        mpi = R.comm.tompi4py()
        lo = own_points.min(axis=0) if own_points.size else np.full(3, np.inf)
        origin = np.array([mpi.allreduce(float(v), op=MPI.MIN) for v in lo])
        self.windows = VoxelWindows(own_points, BAND_WINDOW * float(np.sqrt(t)), origin=origin)
        self.R, self.A, self.its, self.secs = R, A, its, secs

    def __call__(self, b):
        from petsc4py import PETSc

        from ..distributed.bands import BAND_RTOL

        R, w = self.R, np.zeros(self.R.hi - self.R.lo)
        t = time.perf_counter()
        mpi = R.comm.tompi4py()
        local = b.getArray()
        seeds = np.unique(np.concatenate(mpi.allgather(np.unique(self.windows.keys[local != 0]))))
        rows = self.windows.rows(self.windows.around(seeds))
        index = PETSc.IS().createGeneral((rows + R.lo).astype(PETSc.IntType), comm=R.comm)
        sub = self.A.createSubMatrix(index, index)
        ksp = PETSc.KSP().create(comm=R.comm)
        ksp.setOptionsPrefix("band_")
        ksp.setOperators(sub)
        ksp.setType("cg")
        ksp.getPC().setType("jacobi")
        ksp.setTolerances(rtol=BAND_RTOL, atol=0.0, max_it=5000)
        ksp.setFromOptions()
        rhs = b.getSubVector(index)
        xs = sub.createVecRight()
        ksp.solve(rhs, xs)
        b.restoreSubVector(index, rhs)
        if ksp.getConvergedReason() < 0:
            raise RuntimeError(f"a band's Jacobi-CG did not converge (reason {ksp.getConvergedReason()}, "
                               f"{ksp.getIterationNumber()} iterations)")
        w[rows] = xs.getArray()
        self.its.append(int(ksp.getIterationNumber()))
        self.secs.append(time.perf_counter() - t)
        if not R.methods or R.methods[-1] != "cg-jacobi windows":
            R.methods.append("cg-jacobi windows")
        for o in (ksp, sub, xs, index):
            o.destroy()
        return w


def _heat_to_stiffness(A, M, c):
    """``K = (A - M) / c`` in place: the heat operator ``M + c K`` back to the stiffness matrix."""
    minus = M.copy()
    minus.scale(-1.0)
    A.setDiagonal(minus, addv=True)
    A.scale(1.0 / c)
    return A


def _eigs(job, R, its, secs):
    from petsc4py import PETSc
    from slepc4py import SLEPc

    k = int(job["k"])
    nloc = R.hi - R.lo
    Mmat = PETSc.Mat().createAIJ(size=((nloc, R.n), (nloc, R.n)), comm=R.comm,
                                 csr=(np.arange(nloc + 1, dtype=PETSc.IntType),
                                      np.arange(R.lo, R.hi, dtype=PETSc.IntType), R.m.copy()))
    Mmat.assemble()
    mpi = R.comm.tompi4py()
    total = mpi.allreduce(float(R.m.sum()))
    eps = SLEPc.EPS().create(comm=R.comm)
    eps.setOperators(R.K, Mmat)
    eps.setProblemType(SLEPc.EPS.ProblemType.GHEP)
    eps.setDimensions(k)
    eps.setTarget(-1e-2 / total if job.get("sigma") is None else float(job["sigma"]))
    eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_MAGNITUDE)
    eps.setTolerances(1e-12, 1000)
    st = eps.getST()
    st.setType("sinvert")
    ksp = st.getKSP()
    # up to eigs_direct_max_n particles one Cholesky factor of K - sigma M (MUMPS) serves every shift-invert
    # application, as CHOLMOD's does on the local engine; above, each application is a CG solve to RTOL
    if R.n <= int(job.get("eigs_direct_max_n", 0)) and PETSc.Sys.hasExternalPackage("mumps"):
        R.K.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        ksp.setType("preonly")
        ksp.getPC().setType("cholesky")
        ksp.getPC().setFactorSolverType("mumps")
    else:
        ksp.setType("cg")
        multigrid(ksp.getPC())
        ksp.setTolerances(rtol=RTOL, atol=0.0, max_it=2000)
    eps.setFromOptions()  # PETSC_OPTIONS -st_ksp_type / -st_pc_type override either
    t = time.perf_counter()
    eps.solve()
    pc = ksp.getPC()
    R.methods.append(pc.getFactorSolverType() if ksp.getType() == "preonly" else f"{ksp.getType()}-{pc.getType()}")
    secs.append(time.perf_counter() - t)
    its.append(int(eps.getIterationNumber()))
    nconv = eps.getConverged()
    if nconv < k:
        raise RuntimeError(f"SLEPc converged {nconv} of {k} eigenpairs")
    vals, vecs = [], []
    v = R.vec()
    for i in range(nconv):
        vals.append(eps.getEigenpair(i, v).real)
        a = v.getArray().copy()
        a /= np.sqrt(mpi.allreduce(float(np.dot(a * R.m, a))))
        vecs.append(a)
    order = np.argsort(vals)[:k]
    return np.maximum(np.asarray(vals)[order], 0.0), np.stack([vecs[i] for i in order], axis=1)


def run_job(job: dict[str, Any], comm: Any) -> None:
    """Run a job (the dict :mod:`manifold_sph.distributed.solve` writes) on the ranks of ``comm``.

    Collective over ``comm`` (a ``petsc4py.PETSc.Comm``): every rank of it calls this with the same job. The
    result goes to the job's work directory (``x.npy`` or ``values.npy`` and ``vectors.npy``, each rank its own
    rows) with ``info.json`` (iterations, seconds, the largest peak memory of a rank in GiB).
    """
    t0 = time.perf_counter()
    R = _Rows(job, comm)
    if job["problem"] != "geodesic":  # only the geodesic reads the tiles again: unmap the rest
        R.release_tiles()
    t_read = time.perf_counter() - t0
    its: list[int] = []  # each solve's iterations and seconds
    secs: list[float] = []
    problem = job["problem"]
    if problem == "eigs":
        lam, V = _eigs(job, R, its, secs)
        _write(job, "vectors", (R.n, V.shape[1]), R.lo, R.hi, V, comm)
        if comm.getRank() == 0:
            np.save(os.path.join(job["work"], "values.npy"), lam)
    else:
        x = {"heat": _heat, "poisson": _poisson, "geodesic": _geodesic}[problem](job, R, its, secs)
        _write(job, "x", (R.n,), R.lo, R.hi, x, comm)
    peak = comm.tompi4py().gather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, root=0)
    if comm.getRank() == 0:
        info = {"iterations": its, "solve_seconds": secs, "read_seconds": t_read, "peak_gb_per_rank": max(peak),
                "method": ("slepc-krylovschur-sinvert-" if problem == "eigs" else "petsc-")
                + ", ".join(dict.fromkeys(R.methods)) if R.methods else problem}
        if problem == "geodesic":
            info["unreached"] = R.unreached
        with open(os.path.join(job["work"], "info.json"), "w") as f:
            json.dump(info, f)
    comm.barrier()


def run_on_world_ranks(path: str | None, world_ranks: Sequence[int], all_ranks: Sequence[int]) -> int | None:
    """Run the job file ``path`` on the processes of ``MPI.COMM_WORLD`` ranked ``world_ranks`` (Dask workers).

    Called at once in every process of ``all_ranks`` (the Dask workers started by ``dask_mpi.initialize``; the
    scheduler's and the client's ranks do not take part, so nothing here is collective over COMM_WORLD).
    The first call of a process initialises PETSc on the communicator of ``all_ranks``; the job runs on the
    communicator of ``world_ranks`` (both made by ``MPI_Comm_create_group``, collective over their group
    alone); processes of ``all_ranks`` outside ``world_ranks``, or with ``path`` None, only initialise.
    Returns this process's rank among ``world_ranks``, or None.
    """
    from mpi4py import MPI

    ranks, everyone = [int(r) for r in world_ranks], [int(r) for r in all_ranks]
    me = MPI.COMM_WORLD.Get_rank()
    if me not in everyone or not set(ranks) <= set(everyone):
        raise ValueError(f"all_ranks: this process is rank {me} of COMM_WORLD; got world_ranks={ranks}, "
                         f"all_ranks={everyone}")
    _petsc_on(everyone)
    if path is None or me not in ranks:
        return None
    comm = _group_comm(ranks)
    try:
        with open(path) as f:
            job = json.load(f)
        from petsc4py import PETSc

        run_job(job, PETSc.Comm(comm))
        return int(comm.Get_rank())
    finally:
        comm.Free()


_PETSC_WORLD: list[Any] = []  # the communicator PETSc was initialised on in this process (never freed)


def _group_comm(ranks):
    from mpi4py import MPI

    world = MPI.COMM_WORLD
    group = world.Get_group().Incl(sorted(ranks))
    try:
        return world.Create_group(group, tag=JOB_TAG)
    finally:
        group.Free()


def _petsc_on(ranks):
    """Initialise PETSc once in this process with ``PETSC_COMM_WORLD`` = the communicator of ``ranks``."""
    if _PETSC_WORLD:
        if _PETSC_WORLD[0][0] != sorted(ranks):
            raise RuntimeError(f"PETSc was initialised here on the ranks {_PETSC_WORLD[0][0]}, not {sorted(ranks)}: "
                               "the dask-mpi engine's workers changed")
        return
    import petsc4py

    comm = _group_comm(ranks)
    petsc4py.init([], comm=comm)
    _PETSC_WORLD.append((sorted(ranks), comm))


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: mpirun -n RANKS python -m manifold_sph.mpi JOB.json  (written by TiledSurface)", file=sys.stderr)
        return 2
    with open(argv[0]) as f:
        job = json.load(f)
    import petsc4py

    petsc4py.init([])
    from petsc4py import PETSc

    run_job(job, PETSc.COMM_WORLD)
    return 0
