"""Compiled (numba) leap-frog half steps of :class:`.TMzSolver`.

- :func:`tmz_e_update`, :func:`tmz_h_update`: the CSR half steps, each row's product and its
  field update in one pass;
- :func:`tmz_e_half`, :func:`tmz_h_half`: the same on the stencil runs of :mod:`.stencil` (rows
  repeating one stencil, or sharing their offsets) and a CSR remainder, one call per half step.

They release the GIL and write only their rows' slices, so chunks of rows run on threads.
``MANIFOLD_SPH_JIT=0`` selects the numpy step of :class:`.TMzSolver` (the same numbers).
Compiled code is cached on disk (numba ``cache=True``).
"""

from __future__ import annotations

import numpy as np

try:
    import numba
except ImportError:  # pragma: no cover - numba is a dependency; without it the numpy step runs
    numba = None

__all__ = ["tmz_e_update", "tmz_h_update", "tmz_e_half", "tmz_h_half", "RUN_BLOCK"]

# error_model="numpy": a division by zero gives inf or nan, as in numpy, instead of raising.
_jit = numba.njit(nogil=True, cache=True, error_model="numpy") if numba is not None else (lambda f: f)
# Unsigned indices: numba then skips the negative-index wrap-around checks.
_u = np.uint64


# ------------------------------------------------------------- SPEM leap-frog (TMz)
# One pass per half step of :meth:`.TMzSolver.step`: each row's CSR product and its
# field update together, no temporaries. The same operations in the same order as the numpy step
# (scipy's row sums, then ``a * f + b * s``): the same numbers.
@_jit
def tmz_e_update(free, xp, xi, xd, yp, yi, yd, hy, hx, cax, cbx, cay, cby, ezx, ezy, ez):
    """Free E rows ``free[r]``: ``ezx = cax ezx + cbx (Dx hy)``, ``ezy = cay ezy - cby (Dy hx)``, ``ez = ezx + ezy``
    (``Dx``, ``Dy``: CSR arrays ``(xp, xi, xd)``, ``(yp, yi, yd)`` of the free rows)."""
    for r in range(free.size):
        i = free[r]
        sx = 0.0
        for q in range(_u(xp[r]), _u(xp[r + 1])):
            sx += xd[q] * hy[_u(xi[q])]
        sy = 0.0
        for q in range(_u(yp[r]), _u(yp[r + 1])):
            sy += yd[q] * hx[_u(yi[q])]
        a = cax[r] * ezx[i] + cbx[r] * sx
        b = cay[r] * ezy[i] - cby[r] * sy
        ezx[i] = a
        ezy[i] = b
        ez[i] = a + b


@_jit
def tmz_h_update(p, idx, dat, ez, h, da, db, sign, out):
    """``out = da h - db (D ez)`` (``sign`` < 0) or ``da h + db (D ez)``, ``D`` the CSR arrays ``(p, idx, dat)``."""
    for i in range(h.size):
        s = 0.0
        for q in range(_u(p[i]), _u(p[i + 1])):
            s += dat[q] * ez[_u(idx[q])]
        if sign < 0:
            out[i] = da[i] * h[i] - db[i] * s
        else:
            out[i] = da[i] * h[i] + db[i] * s


# ------------------------------------------------ TMz stencil runs (spem.stencil)
# The TMz step of spem.TMzSolver with stencil runs, one call per half step (the arrays are packed by
# spem.stencil.pack_e / pack_h). Rows whose operators repeat one stencil are applied run by run: a
# run's rows read columns ``col + k + offsets`` with the pattern's weights and coefficients, so no
# index or weight is streamed per entry. The sums are formed for a block of up to RUN_BLOCK rows at
# once, weight by weight in the pattern's stored order: each row's sum is the same sequence of
# operations as in tmz_e_update / tmz_h_update (the same numbers for the same weights), and the rows
# of a block are independent, so the loop over them runs in SIMD lanes instead of one dependent
# chain of additions per row (the CSR kernels' limit, about 26 ns per E row of 12 entries,
# measured). The other rows follow in CSR form.
RUN_BLOCK = 256


@_jit
def tmz_e_half(q0, q1, r0, r1, held, runs, pat, off, w, rw, coef, rc, rrow, rptr, ridx, rdat, rcoef, h, ezx, ezy,
               ez):
    """E half step: ``ezx = cax ezx + cbx (Dx h)``, ``ezy = cay ezy - cby (Dy h)``, ``ez = ezx + ezy``.

    ``h`` is the stacked ``[hx, hy]``. Runs ``q0:q1``: ``runs[q]`` = (first E index, rows, pattern, first
    column of Dx, of Dy, Dx row weights, Dy row weights), pattern ``p``'s Dx entries ``pat[p, 0]:pat[p, 1]``
    and Dy entries ``pat[p, 2]:pat[p, 3]`` of ``(off, w)``, coefficients ``coef[p]`` = (cax, cbx, cay, cby);
    row weights -1: the pattern's ``w``, else row ``k``'s weight ``s`` (of ``n`` rows) is
    ``rw[start + s n + k]`` (a weighted run), whose coefficients are ``rc[runs[q, 7] + k]`` (the
    pattern's when ``runs[q, 7]`` is -1). CSR rows
    ``r0:r1``: E index ``rrow[r]``, Dx entries ``rptr[2 r]:rptr[2 r + 1]``, Dy entries ``rptr[2 r + 1]:
    rptr[2 r + 2]`` of ``(ridx, rdat)``, coefficients ``rcoef[r]``. ``held`` (the E particles not updated):
    ``ez = ezx + ezy`` only (with ``q0 == 0``)."""
    if q0 == 0:
        for t in range(held.size):
            i = _u(held[t])
            ez[i] = ezx[i] + ezy[i]
    sx = np.empty(RUN_BLOCK)
    sy = np.empty(RUN_BLOCK)
    for q in range(q0, q1):
        p = runs[q, 2]
        cax = coef[p, 0]
        cbx = coef[p, 1]
        cay = coef[p, 2]
        cby = coef[p, 3]
        n = runs[q, 1]
        for k0 in range(0, n, RUN_BLOCK):
            m = min(RUN_BLOCK, n - k0)
            i0 = runs[q, 0] + k0
            cx = runs[q, 3] + k0
            cy = runs[q, 4] + k0
            for k in range(m):
                sx[k] = 0.0
                sy[k] = 0.0
            wx = runs[q, 5]
            wy = runs[q, 6]
            for s in range(pat[p, 0], pat[p, 1]):
                c = _u(cx + off[s])
                if wx < 0:
                    wt = w[s]
                    for k in range(m):
                        sx[k] += wt * h[c + _u(k)]
                else:
                    b = _u(wx + (s - pat[p, 0]) * n + k0)
                    for k in range(m):
                        sx[k] += rw[b + _u(k)] * h[c + _u(k)]
            for s in range(pat[p, 2], pat[p, 3]):
                c = _u(cy + off[s])
                if wy < 0:
                    wt = w[s]
                    for k in range(m):
                        sy[k] += wt * h[c + _u(k)]
                else:
                    b = _u(wy + (s - pat[p, 2]) * n + k0)
                    for k in range(m):
                        sy[k] += rw[b + _u(k)] * h[c + _u(k)]
            c0 = runs[q, 7]
            if c0 < 0:
                for k in range(m):
                    i = _u(i0 + k)
                    a = cax * ezx[i] + cbx * sx[k]
                    b = cay * ezy[i] - cby * sy[k]
                    ezx[i] = a
                    ezy[i] = b
                    ez[i] = a + b
            else:
                for k in range(m):
                    i = _u(i0 + k)
                    j = _u(c0 + k0 + k)
                    a = rc[j, 0] * ezx[i] + rc[j, 1] * sx[k]
                    b = rc[j, 2] * ezy[i] - rc[j, 3] * sy[k]
                    ezx[i] = a
                    ezy[i] = b
                    ez[i] = a + b
    for r in range(r0, r1):
        i = _u(rrow[r])
        x = 0.0
        for t in range(_u(rptr[2 * r]), _u(rptr[2 * r + 1])):
            x += rdat[t] * h[_u(ridx[t])]
        y = 0.0
        for t in range(_u(rptr[2 * r + 1]), _u(rptr[2 * r + 2])):
            y += rdat[t] * h[_u(ridx[t])]
        a = rcoef[r, 0] * ezx[i] + rcoef[r, 1] * x
        b = rcoef[r, 2] * ezy[i] - rcoef[r, 3] * y
        ezx[i] = a
        ezy[i] = b
        ez[i] = a + b


@_jit
def tmz_h_half(q0, q1, r0, r1, runs, pat, off, w, rw, coef, rc, rrow, rptr, ridx, rdat, rcoef, ez, h, out):
    """H half step on the stacked ``h = [hx, hy]``: ``out = da h + dbs (D ez)``, ``dbs`` = -db for Hx, +db for Hy.

    Runs ``q0:q1``: ``runs[q]`` = (first row, rows, pattern, first column, row weights, row coefficients),
    pattern ``p``'s entries ``pat[p, 0]:pat[p, 1]`` of ``(off, w)``, ``coef[p]`` = (da, dbs), row weights
    and coefficients (``rc``) as in :func:`tmz_e_half`. CSR rows ``r0:r1``: row ``rrow[r]``,
    entries ``rptr[r]:rptr[r + 1]`` of ``(ridx, rdat)``, ``rcoef[r]``. ``out`` may be ``h`` (each row reads
    only its own ``h``)."""
    acc = np.empty(RUN_BLOCK)
    for q in range(q0, q1):
        p = runs[q, 2]
        da = coef[p, 0]
        db = coef[p, 1]
        n = runs[q, 1]
        for k0 in range(0, n, RUN_BLOCK):
            m = min(RUN_BLOCK, n - k0)
            i0 = runs[q, 0] + k0
            c0 = runs[q, 3] + k0
            for k in range(m):
                acc[k] = 0.0
            wr = runs[q, 4]
            for t in range(pat[p, 0], pat[p, 1]):
                c = _u(c0 + off[t])
                if wr < 0:
                    wt = w[t]
                    for k in range(m):
                        acc[k] += wt * ez[c + _u(k)]
                else:
                    b = _u(wr + (t - pat[p, 0]) * n + k0)
                    for k in range(m):
                        acc[k] += rw[b + _u(k)] * ez[c + _u(k)]
            c1 = runs[q, 5]
            if c1 < 0:
                for k in range(m):
                    i = _u(i0 + k)
                    out[i] = da * h[i] + db * acc[k]
            else:
                for k in range(m):
                    i = _u(i0 + k)
                    j = _u(c1 + k0 + k)
                    out[i] = rc[j, 0] * h[i] + rc[j, 1] * acc[k]
    for r in range(r0, r1):
        i = _u(rrow[r])
        x = 0.0
        for t in range(_u(rptr[r]), _u(rptr[r + 1])):
            x += rdat[t] * ez[_u(ridx[t])]
        out[i] = rcoef[r, 0] * h[i] + rcoef[r, 1] * x
