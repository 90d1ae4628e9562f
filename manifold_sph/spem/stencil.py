"""Repeated-stencil runs of the TMz step operators: the lattice fast path of :class:`.solver.TMzSolver`.

On a lattice (and any layout with repeated rows) most rows of the derivative
matrices have the same column offsets, counted from the row's first stored
column, and the same weights, and most particles the same update coefficients
(vacuum, no PML). :func:`find_runs` groups the rows whose offsets, weights (to
``rtol`` times the operator's largest entry) and coefficients (exactly) agree,
and cuts them into *runs*: consecutive rows of one group whose output index and
first column each advance by one per row. A run is then applied by a
fixed-stencil kernel that streams its rows (a few numbers per run instead of
an index and a weight per entry). Among the other rows, those that share only
their offsets (PML corners, graded materials, the corrected rows by the walls)
form *weighted runs*: each row keeps its own weights and coefficients, stored
run by run so that they are read in order, without column indices. The rest
keep their CSR form. The kernels (:func:`manifold_sph.spem.compiled.tmz_e_half`,
:func:`manifold_sph.spem.compiled.tmz_h_half`) form the sums of a block of rows weight
by weight, so the rows run in SIMD lanes; each row's sum is still the same
sequence of operations as in CSR.

Measured (``python benchmarks/spem_vs_yee.py --cost``): 98-99.6 % of the rows of
Yee lattices of 1e4-1e6 unknowns, with or without PML, are in runs, and the
step costs 1.4-1.6x a numpy Yee step per unknown on a PEC square and 0.7-1.3x
with PML (the CSR step: 1.6-6.8x); on jittered and Poisson layouts almost no
row repeats and the step is the CSR one.

The weights of a run's rows are those of its group's first row (its
*representative*): a row's own weights differ from them by less than
``rtol * max |D|``. :meth:`StencilRuns.snapped` gives the matrix with exactly
these weights, which the numpy step uses, so the compiled and numpy steps
agree bit for bit; both differ from the step with the assembled matrices by
round-off only.

Examples
--------
>>> import scipy.sparse as sp
>>> D = sp.diags([-np.ones(9), np.ones(9)], [0, 1], shape=(9, 10)).tocsr()  # forward differences
>>> runs = find_runs([D], np.arange(9), np.ones((9, 1)))
>>> runs.run_row.tolist(), runs.run_len.tolist(), runs.rest.tolist()
([0], [9], [])
>>> runs.offsets[0].tolist(), runs.weights[0].tolist()
([0, 1], [-1.0, 1.0])
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

__all__ = ["StencilRuns", "find_runs", "pack_e", "pack_h", "RTOL", "MIN_RUN"]

#: Weights of rows in one group differ by less than this times the operator's largest |entry|.
RTOL = 1e-13
#: Shortest run applied by the stencil kernels (shorter ones stay in CSR form).
MIN_RUN = 4

_PRIME = np.uint64(0x100000001B3)  # FNV-1a multiplier (64 bit)
_BASIS = np.uint64(0xCBF29CE484222325)
_PAD = np.int64(-(2**62))  # offset/weight key of a slot beyond a row's entries


@dataclass(frozen=True)
class StencilRuns:
    """Runs of repeated rows of one or several CSR operators with the same rows (see :func:`find_runs`).

    Attributes
    ----------
    run_row, run_len, run_pat : (R,) int64 arrays
        First row, number of rows and pattern of each run.
    run_col : (R, M) int64 array
        First stored column of each operator's row at the run's first row; row
        ``run_row + k`` reads columns ``run_col + k + offsets``.
    ptr : tuple of M (P + 1,) int64 arrays
        Pattern ``p`` of operator ``m`` is ``offsets[m][ptr[m][p]:ptr[m][p + 1]]``, same for ``weights``.
    offsets : tuple of M int64 arrays
    weights : tuple of M float64 arrays
    run_w : (R, M) int64 array
        -1 for a stencil run (the pattern's weights); for a weighted run, where its rows' weights start in
        ``row_weights[m]``: row ``run_row + k``'s weight ``s`` is ``row_weights[m][run_w + s run_len + k]``.
    row_weights : tuple of M float64 arrays
    run_c : (R,) int64 array
        -1 for a stencil run (the pattern's coefficients), else the run's first row in ``row_coef``.
    row_coef : (N, C) float64 array
        The coefficients of the weighted runs' rows, run after run.
    coef : (P, C) float64 array
        The (common) coefficients of each stencil pattern's rows.
    rest : (n_rest,) int64 array
        Rows in no run.
    n_rows : int
    """

    run_row: np.ndarray
    run_len: np.ndarray
    run_pat: np.ndarray
    run_col: np.ndarray
    ptr: tuple
    run_w: np.ndarray
    run_c: np.ndarray
    row_coef: np.ndarray
    offsets: tuple
    weights: tuple
    row_weights: tuple
    coef: np.ndarray
    rest: np.ndarray
    n_rows: int

    @property
    def covered(self) -> int:
        """Number of rows in runs."""
        return int(self.run_len.sum())

    def _row_entries(self, m: int, D: sp.csr_matrix):
        """(positions in D's data, positions in the pattern weights) of every stencil-run row's entries."""
        st = self.run_w[:, m] < 0
        rows = np.repeat(self.run_row[st], self.run_len[st]) + _ramp(self.run_len[st])
        pats = np.repeat(self.run_pat[st], self.run_len[st])
        K = np.diff(self.ptr[m])[pats]
        local = _ramp(K)
        return np.repeat(D.indptr[rows], K) + local, np.repeat(self.ptr[m][pats], K) + local

    def snapped(self, m: int, D: sp.spmatrix) -> sp.csr_matrix:
        """Operator ``m`` (``D``, the matrix the runs were found in) with each stencil-run row's weights replaced
        by its pattern's (the numbers the kernels use; the same stored order)."""
        D = sp.csr_matrix(D)
        data = np.array(D.data, dtype=np.float64)
        dst, src = self._row_entries(m, D)
        data[dst] = self.weights[m][src]
        return sp.csr_matrix((data, D.indices, D.indptr), shape=D.shape)

    def rest_csr(self, D: sp.spmatrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(indptr, indices, data)`` of the rows :attr:`rest` of ``D``, entries in their stored order."""
        D = sp.csr_matrix(D)
        K = np.diff(D.indptr)[self.rest]
        indptr = np.zeros(len(self.rest) + 1, dtype=np.int64)
        np.cumsum(K, out=indptr[1:])
        pos = np.repeat(D.indptr[self.rest].astype(np.int64), K) + _ramp(K)
        return indptr, np.ascontiguousarray(D.indices[pos], dtype=np.int64), np.ascontiguousarray(D.data[pos],
                                                                                                   dtype=np.float64)


def _ramp(counts: np.ndarray) -> np.ndarray:
    """``concatenate([arange(c) for c in counts])``, vectorised."""
    counts = np.asarray(counts, dtype=np.int64)
    total = int(counts.sum())
    start = np.cumsum(counts) - counts
    return np.arange(total, dtype=np.int64) - np.repeat(start, counts)


def _key_columns(mats, firsts, scales, coef_bits, with_weights):
    """The integer key of every row, one (n,) column at a time: per operator the entry count, then per slot
    the offset from the first column and (``with_weights``) the weight in units of the operator's tolerance;
    the coefficients' bits."""
    for D, first, q in zip(mats, firsts, scales):
        K = np.diff(D.indptr).astype(np.int64)
        yield K
        if not D.nnz:
            continue
        start = D.indptr[:-1].astype(np.int64)
        last = D.nnz - 1
        for s in range(int(K.max(initial=0))):
            has = s < K
            pos = np.minimum(start + s, last)
            yield np.where(has, D.indices[pos].astype(np.int64) - first, _PAD)
            if with_weights:
                w = D.data[pos]
                wq = np.rint(w / q).astype(np.int64) if q else np.ascontiguousarray(w, dtype=np.float64).view(np.int64)
                yield np.where(has, wq, _PAD)
    for c in coef_bits.T:
        yield c


def _group_runs(mats, firsts, scales, coef_bits, targets, eligible, with_weights, min_run):
    """Runs among the ``eligible`` rows: ``(run_row, run_len, representative row of each run's group)``."""
    n = len(targets)
    # group the rows by a 64-bit hash of their key, then check every row against its group's first row
    h = np.full(n, _BASIS, dtype=np.uint64)
    with np.errstate(over="ignore"):
        h = (h ^ eligible.astype(np.uint64)) * _PRIME
        for col in _key_columns(mats, firsts, scales, coef_bits, with_weights):
            h = (h ^ col.view(np.uint64)) * _PRIME
    _, rep, group, count = np.unique(h, return_index=True, return_inverse=True, return_counts=True)
    group = group.reshape(-1)
    ok = eligible & (count[group] >= min_run)
    rep_row = rep[group]
    for col in _key_columns(mats, firsts, scales, coef_bits, with_weights):
        ok &= col == col[rep_row]  # a hash collision leaves the row out
    # runs: consecutive rows of one group whose target and first columns advance by one
    cont = np.zeros(n, dtype=bool)
    if n > 1:
        c = ok[1:] & ok[:-1] & (group[1:] == group[:-1]) & (targets[1:] == targets[:-1] + 1)
        for f in firsts:
            c &= f[1:] == f[:-1] + 1
        cont[1:] = c
    starts = np.flatnonzero(ok & ~cont)
    run_id = np.cumsum(ok & ~cont) - 1
    lengths = np.bincount(run_id[ok], minlength=len(starts)) if len(starts) else np.zeros(0, dtype=np.int64)
    keep = lengths >= int(min_run)
    run_row = starts[keep].astype(np.int64)
    return run_row, lengths[keep].astype(np.int64), rep_row[run_row]


def find_runs(mats: Sequence[sp.spmatrix], targets: ArrayLike, coefs: ArrayLike, *, rtol: float = RTOL,
              min_run: int = MIN_RUN, row_weights: bool = True) -> StencilRuns:
    """Runs of rows that share one stencil in every operator of ``mats`` and the same coefficients.

    First the rows whose offsets, weights (to ``rtol``) and coefficients agree (*stencil runs*: the
    weights of the group's first row); then, with ``row_weights``, among the other rows those whose
    offsets agree (*weighted runs*: each row keeps its own weights and coefficients, stored per run so
    that the kernels read them in order, with no column indices: PML corners, graded materials).

    Parameters
    ----------
    mats : sequence of sparse matrices
        ``M`` operators with the same number ``n`` of rows (the rows of one update).
    targets : (n,) int array
        The output index of each row (a run needs consecutive targets).
    coefs : (n, C) float array
        The update coefficients of each row (equal within a pattern, bit for bit).
    rtol : float
        Weights of one stencil differ by less than ``rtol`` times the operator's largest |entry|
        (0: bit for bit).
    min_run : int
        Runs shorter than this are left to the CSR rows (:attr:`StencilRuns.rest`).
    row_weights : bool
        Also form the weighted runs.

    Returns
    -------
    StencilRuns
    """
    mats = [sp.csr_matrix(D) for D in mats]
    if not mats:
        raise ValueError("mats must hold at least one operator")
    n = mats[0].shape[0]
    if any(D.shape[0] != n for D in mats):
        raise ValueError(f"every operator in mats must have {n} rows, got {[D.shape[0] for D in mats]}")
    targets = np.asarray(targets, dtype=np.int64)
    if targets.shape != (n,):
        raise ValueError(f"targets must have shape ({n},), got {targets.shape}")
    coefs = np.ascontiguousarray(coefs, dtype=np.float64)
    if coefs.ndim != 2 or coefs.shape[0] != n:
        raise ValueError(f"coefs must have shape ({n}, C), got {coefs.shape}")
    if not (rtol == 0.0 or 1e-18 <= rtol < 1e-6):
        raise ValueError(f"rtol must be 0 (exact) or lie in [1e-18, 1e-6), got {rtol!r}")
    if int(min_run) < 1:
        raise ValueError(f"min_run must be at least 1, got {min_run!r}")
    M = len(mats)
    firsts, scales, nonempty = [], [], np.ones(n, dtype=bool)
    for D in mats:
        K = np.diff(D.indptr)
        nonempty &= K > 0
        firsts.append(np.where(K > 0, D.indices[np.minimum(D.indptr[:-1], max(D.nnz - 1, 0))], 0).astype(np.int64)
                      if D.nnz else np.zeros(n, dtype=np.int64))
        scales.append(rtol * float(np.abs(D.data).max(initial=0.0)))  # 0: exact equality (the weights' bits)
    coef_bits = coefs.view(np.int64)
    args = (mats, firsts, scales, coef_bits, targets)
    row1, len1, rep1 = _group_runs(*args, nonempty, True, min_run)
    in_run = np.zeros(n, dtype=bool)
    in_run[np.repeat(row1, len1) + _ramp(len1)] = True
    if row_weights:
        # offsets only: each row keeps its weights and coefficients
        row2, len2, rep2 = _group_runs(mats, firsts, scales, coef_bits[:, :0], targets, nonempty & ~in_run, False,
                                       min_run)
        in_run[np.repeat(row2, len2) + _ramp(len2)] = True
    else:
        row2, len2, rep2 = (np.zeros(0, dtype=np.int64),) * 3
    used1, pat1 = np.unique(rep1, return_inverse=True)
    used2, pat2 = np.unique(rep2, return_inverse=True)
    reps = np.concatenate([used1, used2]).astype(np.int64)  # each pattern's representative row
    run_row = np.concatenate([row1, row2])
    run_len = np.concatenate([len1, len2])
    run_pat = np.concatenate([pat1.reshape(-1), pat2.reshape(-1) + len(used1)]).astype(np.int64)
    ptrs, offs, ws, run_w, rws = [], [], [], [], []
    for D, first in zip(mats, firsts):
        K = np.diff(D.indptr).astype(np.int64)
        Kr = K[reps]
        ptr = np.zeros(len(reps) + 1, dtype=np.int64)
        np.cumsum(Kr, out=ptr[1:])
        pos = np.repeat(D.indptr[reps].astype(np.int64), Kr) + _ramp(Kr)
        ptrs.append(ptr)
        offs.append(np.ascontiguousarray(D.indices[pos].astype(np.int64) - np.repeat(first[reps], Kr)))
        ws.append(np.ascontiguousarray(D.data[pos], dtype=np.float64))
        # weighted runs: run q's weights (K, len) by slot, then row: rw[base + s len + k]
        K2 = K[row2]
        size = K2 * len2
        base = np.cumsum(size) - size
        rows = np.repeat(row2, len2) + _ramp(len2)
        k = _ramp(len2)
        Krow = np.repeat(K2, len2)
        s_ = _ramp(Krow)
        dest = np.repeat(np.repeat(base, len2) + k, Krow) + s_ * np.repeat(np.repeat(len2, len2), Krow)
        src = np.repeat(D.indptr[rows].astype(np.int64), Krow) + s_
        rw = np.empty(int(size.sum()), dtype=np.float64)
        rw[dest] = D.data[src]
        rws.append(rw)
        run_w.append(np.concatenate([np.full(len(row1), -1, dtype=np.int64), base.astype(np.int64)]))
    rows2 = np.repeat(row2, len2) + _ramp(len2)
    run_c = np.concatenate([np.full(len(row1), -1, dtype=np.int64), (np.cumsum(len2) - len2).astype(np.int64)])
    order = np.argsort(run_row, kind="stable")
    run_col = np.column_stack([f[run_row] for f in firsts]).reshape(len(run_row), M)
    return StencilRuns(run_row=run_row[order], run_len=run_len[order], run_pat=run_pat[order],
                       run_col=np.ascontiguousarray(run_col[order], dtype=np.int64),
                       run_w=np.ascontiguousarray(np.column_stack(run_w).reshape(len(run_row), M)[order]),
                       run_c=run_c[order], row_coef=np.ascontiguousarray(coefs[rows2]).reshape(len(rows2), coefs.shape[1]),
                       ptr=tuple(ptrs), offsets=tuple(offs), weights=tuple(ws), row_weights=tuple(rws),
                       coef=np.ascontiguousarray(coefs[reps]), rest=np.flatnonzero(~in_run).astype(np.int64),
                       n_rows=n)


def _small(idx):
    """Column indices as int32 when they fit (half the memory and traffic of the CSR rows)."""
    return idx.astype(np.int32) if idx.size == 0 or idx.max() < 2**31 - 1 else idx


def _interleave(parts, shifts, n):
    """CSR rows ``r`` of several operators (``parts``: (indptr, indices, data) of the same ``n`` rows) one
    after the other: row ``r``'s entries of part ``m`` are ``ptr[M r + m]:ptr[M r + m + 1]``, columns + ``shifts[m]``."""
    M = len(parts)
    K = np.column_stack([np.diff(p[0]) for p in parts]).reshape(n, M) if n else np.zeros((0, M), dtype=np.int64)
    ptr = np.zeros(M * n + 1, dtype=np.int64)
    np.cumsum(K.ravel(), out=ptr[1:])
    total = int(ptr[-1])
    idx = np.empty(total, dtype=np.int64)
    dat = np.empty(total, dtype=np.float64)
    for m, ((_, ind, val), shift) in enumerate(zip(parts, shifts)):
        dest = np.repeat(ptr[m:M * n:M], K[:, m]) + _ramp(K[:, m])
        idx[dest] = ind + shift
        dat[dest] = val
    return ptr, idx, dat


def pack_e(runs: StencilRuns, Dx: sp.spmatrix, Dy: sp.spmatrix, free: np.ndarray, coefs: np.ndarray, n_e: int,
           shift_x: int, shift_y: int = 0) -> tuple:
    """The arrays of :func:`manifold_sph.spem.compiled.tmz_e_half` for the E rows (``free``) of ``Dx``, ``Dy`` and their
    runs (``find_runs([Dx, Dy], free, coefs)``); ``Dx`` reads the stacked H at ``column + shift_x``, ``Dy`` at
    ``column + shift_y``.

    Returns
    -------
    tuple
        ``(held, runs, pat, off, w, rw, coef, rc, rrow, rptr, ridx, rdat, rcoef)``.
    """
    free = np.asarray(free, dtype=np.int64)
    held = np.setdiff1d(np.arange(n_e, dtype=np.int64), free)
    wx, wy = runs.run_w[:, 0], runs.run_w[:, 1]
    table = np.column_stack([free[runs.run_row], runs.run_len, runs.run_pat, runs.run_col[:, 0] + shift_x,
                             runs.run_col[:, 1] + shift_y, wx,
                             np.where(wy < 0, -1, wy + len(runs.row_weights[0])), runs.run_c]).reshape(-1, 8)
    table = table.astype(np.int64)
    rw = np.concatenate(runs.row_weights).astype(np.float64)
    nx = len(runs.offsets[0])
    px, py = runs.ptr
    pat = np.column_stack([px[:-1], px[1:], py[:-1] + nx, py[1:] + nx]).reshape(-1, 4).astype(np.int64)
    off = np.concatenate([runs.offsets[0], runs.offsets[1]]).astype(np.int64)
    w = np.concatenate([runs.weights[0], runs.weights[1]]).astype(np.float64)
    rest = runs.rest
    rptr, ridx, rdat = _interleave([runs.rest_csr(Dx), runs.rest_csr(Dy)], (shift_x, shift_y), len(rest))
    ridx = _small(ridx)
    return (held, np.ascontiguousarray(table), np.ascontiguousarray(pat), off, w, rw, np.ascontiguousarray(runs.coef),
            np.ascontiguousarray(runs.row_coef, dtype=np.float64).reshape(-1, 4),
            np.ascontiguousarray(free[rest]), rptr, ridx, rdat, np.ascontiguousarray(coefs[rest], dtype=np.float64))


def pack_h(runs: StencilRuns, D: sp.spmatrix, coefs: np.ndarray) -> tuple:
    """The arrays of :func:`manifold_sph.spem.compiled.tmz_h_half` for the rows of ``D`` and their runs
    (``find_runs([D], arange(n), coefs)``).

    Returns
    -------
    tuple
        ``(runs, pat, off, w, rw, coef, rc, rrow, rptr, ridx, rdat, rcoef)``.
    """
    table = np.column_stack([runs.run_row, runs.run_len, runs.run_pat, runs.run_col[:, 0],
                             runs.run_w[:, 0], runs.run_c]).reshape(-1, 6)
    ptr = runs.ptr[0]
    pat = np.column_stack([ptr[:-1], ptr[1:]]).reshape(-1, 2).astype(np.int64)
    rptr, ridx, rdat = runs.rest_csr(D)
    ridx = _small(ridx)
    return (np.ascontiguousarray(table, dtype=np.int64), np.ascontiguousarray(pat), runs.offsets[0],
            runs.weights[0], runs.row_weights[0], np.ascontiguousarray(runs.coef),
            np.ascontiguousarray(runs.row_coef, dtype=np.float64).reshape(-1, 2), np.ascontiguousarray(runs.rest), rptr, ridx, rdat,
            np.ascontiguousarray(coefs[runs.rest], dtype=np.float64))
