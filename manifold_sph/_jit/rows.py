"""The weights of the corrected schemes, row by row (:mod:`manifold_sph.assembly`): small dense
inverses and the cspm, msph, ncsph and moment rows."""

from __future__ import annotations

import numpy as np

from .compile import U, inline, njit
from .kernel import quintic

__all__ = ["cspm_rows", "msph_rows", "ncsph_rows", "moment_rows"]


@inline
def _norm1(A, m):
    """1-norm of ``A[:m, :m]``; NaN when an entry is NaN (as numpy's max: a NaN column sum must not
    be skipped, or a singular system, whose inverse holds 0 / 0, would get a finite condition number)."""
    best = 0.0
    for c in range(m):
        s = 0.0
        for r in range(m):
            s += abs(A[r, c])
        if s != s:
            return s
        if s > best:
            best = s
    return best


@njit
def _invert(A, m, inv, work):
    """Inverse of ``A[:m, :m]`` into ``inv`` (Gauss-Jordan, partial pivoting); returns the 1-norm
    condition number, ``inf`` when ``A`` is singular or not finite."""
    for i in range(m):
        for j in range(m):
            a = A[i, j]
            if not np.isfinite(a):
                return np.inf
            work[i, j] = a
            work[i, m + j] = 1.0 if i == j else 0.0
    for col in range(m):
        p = col
        best = abs(work[col, col])
        for r in range(col + 1, m):
            if abs(work[r, col]) > best:
                best = abs(work[r, col])
                p = r
        if best == 0.0:
            return np.inf
        if p != col:
            for j in range(col, 2 * m):
                tmp = work[col, j]
                work[col, j] = work[p, j]
                work[p, j] = tmp
        ip = 1.0 / work[col, col]
        for j in range(col, 2 * m):
            work[col, j] *= ip
        for r in range(m):
            if r != col:
                f = work[r, col]
                if f != 0.0:
                    for j in range(col, 2 * m):
                        work[r, j] -= f * work[col, j]
    for i in range(m):
        for j in range(m):
            inv[i, j] = work[i, m + j]
    cond = _norm1(A, m) * _norm1(inv, m)
    if not np.isfinite(cond):
        return np.inf
    return cond


@inline
def _inverse2(A, inv):
    """Closed-form 2x2 inverse (as ``schemes.base._small_inverse``); returns the 1-norm condition number."""
    a, b, c, d = A[0, 0], A[0, 1], A[1, 0], A[1, 1]
    det = a * d - b * c
    inv[0, 0] = d / det
    inv[0, 1] = -b / det
    inv[1, 0] = -c / det
    inv[1, 1] = a / det
    cond = _norm1(A, 2) * _norm1(inv, 2)
    return cond if np.isfinite(cond) else np.inf


@inline
def _inverse3(A, inv):
    """Closed-form 3x3 inverse (adjugate over determinant); returns the 1-norm condition number."""
    a, b, c = A[0, 0], A[0, 1], A[0, 2]
    d, e, f = A[1, 0], A[1, 1], A[1, 2]
    g, h, k = A[2, 0], A[2, 1], A[2, 2]
    c0 = e * k - f * h
    c1 = f * g - d * k
    c2 = d * h - e * g
    det = a * c0 + b * c1 + c * c2
    inv[0, 0] = c0 / det
    inv[0, 1] = (c * h - b * k) / det
    inv[0, 2] = (b * f - c * e) / det
    inv[1, 0] = c1 / det
    inv[1, 1] = (a * k - c * g) / det
    inv[1, 2] = (c * d - a * f) / det
    inv[2, 0] = c2 / det
    inv[2, 1] = (b * g - a * h) / det
    inv[2, 2] = (a * e - b * d) / det
    cond = _norm1(A, 3) * _norm1(inv, 3)
    return cond if np.isfinite(cond) else np.inf


@njit
def _max_count(lo, hi, indptr):
    k = 0
    for i in range(lo, hi):
        k = max(k, indptr[i + 1] - indptr[i])
    return k


@inline
def _scratch(lo, hi, indptr, width):
    """Per-pair scratch for the particles ``lo:hi``: offsets ``X, Y``, area elements ``D``, kernel
    factors ``W, Q, T``, the weighted rows (K, width) of the local system and the weights ``cx, cy, cl``."""
    K = _max_count(lo, hi, indptr)
    return (np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(K),
            np.empty((K, width)), np.empty(K), np.empty(K), np.empty(K))


@inline
def _begin_row(i, indptr, xy, dvp, h, alpha, use_dv, X, Y, D, Wv, Q, T):
    """Normalised offsets (units of ``h_i``), area elements (``/ h_i^2``; 1 without ``use_dv``) and
    kernel factors of particle ``i``'s pairs; returns ``(p0, m, 1 / h_i, 1 / h_i^2)``."""
    p0 = indptr[i]
    m = indptr[i + 1] - p0
    ih = 1.0 / h[i]
    dsc = ih * ih
    for k in range(m):
        p = U(p0 + k)
        x = xy[p, 0] * ih
        y = xy[p, 1] * ih
        w, q, t = quintic(np.sqrt(x * x + y * y))
        X[k] = x
        Y[k] = y
        D[k] = dvp[p] * dsc if use_dv else 1.0
        Wv[k] = w * alpha
        Q[k] = q * alpha
        T[k] = t * alpha
    return p0, m, ih, dsc


@inline
def _derivative_rows(k, x, y, q, t, dv, rows, c0):
    """``rows[k, c0:c0 + 5] = (W_x, W_y, W_xx, W_xy, W_yy) dV`` of one pair."""
    tx = t * x
    rows[k, c0] = -(x * q) * dv
    rows[k, c0 + 1] = -(y * q) * dv
    rows[k, c0 + 2] = (tx * x + q) * dv
    rows[k, c0 + 3] = (tx * y) * dv
    rows[k, c0 + 4] = (t * y * y + q) * dv


@inline
def _add_taylor_outer(A, rows, k, x, y, n, lead_one):
    """``A[:n, :n] += rows[k, :n] cols^T`` with the Taylor columns ``cols = (x, y, x^2/2, xy, y^2/2)``
    (after a column of ones with ``lead_one``): the columns stay in registers instead of a scratch
    array (the same products and sums: 14 % faster MSPH weights, measured at N = 131072, one thread,
    16 paired runs)."""
    k3 = 0.5 * x * x
    k4 = x * y
    k5 = 0.5 * y * y
    if lead_one:
        for r in range(n):
            s = rows[k, r]
            A[r, 0] += s * 1.0
            A[r, 1] += s * x
            A[r, 2] += s * y
            A[r, 3] += s * k3
            A[r, 4] += s * k4
            A[r, 5] += s * k5
    else:
        for r in range(n):
            s = rows[k, r]
            A[r, 0] += s * x
            A[r, 1] += s * y
            A[r, 2] += s * k3
            A[r, 3] += s * k4
            A[r, 4] += s * k5


@inline
def _add_outer(A, rows, k, cols, n):
    """``A[:n, :n] += rows[k, :n] cols[:n]^T`` (one pair's share of the moment sums)."""
    for r in range(n):
        s = rows[k, r]
        for c in range(n):
            A[r, c] += s * cols[c]


@inline
def _finish_row(Ysel, rows, n, p0, m, ih, dsc, difference, cx, cy, cl, gx, gy, lp):
    """Weights ``(cx, cy, cl)[k] = Ysel[:, :n] rows[k, :n]`` of the ``m`` pairs, stored by :func:`_store`."""
    for k in range(m):
        sx = 0.0
        sy = 0.0
        sl = 0.0
        for r in range(n):
            v = rows[k, r]
            sx += Ysel[0, r] * v
            sy += Ysel[1, r] * v
            sl += Ysel[2, r] * v
        cx[k] = sx
        cy[k] = sy
        cl[k] = sl
    _store(p0, m, cx, cy, cl, ih, dsc, difference, gx, gy, lp)


@inline
def _store(p0, m, cx, cy, cl, ih, dsc, difference, gx, gy, lp):
    """Scale weights to physical units (1/h, 1/h^2) and store them; ``difference``: weights on
    ``f_j - f_i``, so the particle's own slot takes minus the others' sum."""
    if difference:
        sx = 0.0
        sy = 0.0
        sl = 0.0
        for k in range(1, m):
            sx += cx[k]
            sy += cy[k]
            sl += cl[k]
        cx[0] = -sx
        cy[0] = -sy
        cl[0] = -sl
    for k in range(m):
        p = U(p0 + k)
        gx[p] = cx[k] * ih
        gy[p] = cy[k] * ih
        lp[p] = cl[k] * dsc


@inline
def _fail(i, p0, m, failed, gx, gy, lp):
    """Flag particle ``i`` (the assembly redoes it) and zero its weights."""
    failed[i] = True
    for k in range(m):
        p = U(p0 + k)
        gx[p] = 0.0
        gy[p] = 0.0
        lp[p] = 0.0


# ----------------------------------------------------------------- schemes
# Every scheme fills, per particle, the weighted rows of its local system (K, n) and
# the moment matrix A = sum_k rows[k] cols[k]^T, inverts A with the condition test,
# and turns three rows ``Ysel`` of A^-1 (f_x, f_y and f_xx + f_yy) into weights.
@inline
def _first_derivative_rows(A, M1i, Ysel):
    """CSPM's gradient: ``Ysel[:2, :2] = M1^-1`` for ``M1 = A[:2, :2]`` (the ``W_x, W_y`` rows
    against ``x, y``), the rest of those two rows zero; returns the condition number of ``M1``."""
    c1 = _inverse2(A[:2, :2], M1i)
    Ysel[:2, :] = 0.0
    Ysel[0, 0] = M1i[0, 0]
    Ysel[0, 1] = M1i[0, 1]
    Ysel[1, 0] = M1i[1, 0]
    Ysel[1, 1] = M1i[1, 1]
    return c1


@njit
def cspm_rows(lo, hi, indptr, xy, dvp, h, alpha, max_condition, gx, gy, lp, cond, failed):
    """CSPM weights (:class:`manifold_sph.schemes.CSPM`) of rows ``lo:hi`` into the pair arrays
    ``gx, gy, lp`` (physical units), with each row's condition number and failure flag.

    ``A`` is the 5x5 moment matrix of the rows ``W_x, W_y, W_xx, W_xy, W_yy`` against the
    columns ``x, y, x^2/2, xy, y^2/2``: ``M1 = A[:2, :2]``, ``N1 = A[2:, :2]``, ``N2 = A[2:, 2:]``.
    """
    X, Y, D, Wv, Q, T, rows, cx, cy, cl = _scratch(lo, hi, indptr, 5)
    A = np.empty((5, 5))
    M1i = np.empty((2, 2))
    N2i = np.empty((3, 3))
    Ysel = np.empty((3, 5))
    for i in range(lo, hi):
        p0, m, ih, dsc = _begin_row(i, indptr, xy, dvp, h, alpha, True, X, Y, D, Wv, Q, T)
        A[:] = 0.0
        for k in range(m):
            _derivative_rows(k, X[k], Y[k], Q[k], T[k], D[k], rows, 0)
            _add_taylor_outer(A, rows, k, X[k], Y[k], 5, False)
        c1 = _first_derivative_rows(A, M1i, Ysel)
        c2 = _inverse3(A[2:, 2:], N2i)
        cond[i] = max(c1, c2)
        if not (c1 <= max_condition and c2 <= max_condition):
            _fail(i, p0, m, failed, gx, gy, lp)
            continue
        failed[i] = False
        # Laplacian: y = N2^-T e (e picks H_xx + H_yy), weights y . rows2 - (N1^T y) . M1^-1 rows1
        for c in range(3):
            Ysel[2, 2 + c] = N2i[0, c] + N2i[2, c]
        z0 = Ysel[2, 2] * A[2, 0] + Ysel[2, 3] * A[3, 0] + Ysel[2, 4] * A[4, 0]  # z = N1^T y
        z1 = Ysel[2, 2] * A[2, 1] + Ysel[2, 3] * A[3, 1] + Ysel[2, 4] * A[4, 1]
        Ysel[2, 0] = -(z0 * M1i[0, 0] + z1 * M1i[1, 0])
        Ysel[2, 1] = -(z0 * M1i[0, 1] + z1 * M1i[1, 1])
        _finish_row(Ysel, rows, 5, p0, m, ih, dsc, True, cx, cy, cl, gx, gy, lp)


@njit
def msph_rows(lo, hi, indptr, xy, dvp, h, alpha, max_condition, gx, gy, lp, cond, failed):
    """MSPH weights (:class:`manifold_sph.schemes.MSPH`, the 6x6 system) of rows ``lo:hi``."""
    X, Y, D, Wv, Q, T, rows, cx, cy, cl = _scratch(lo, hi, indptr, 6)
    A = np.empty((6, 6))
    Ai = np.empty((6, 6))
    work = np.empty((6, 12))
    Ysel = np.empty((3, 6))
    for i in range(lo, hi):
        p0, m, ih, dsc = _begin_row(i, indptr, xy, dvp, h, alpha, True, X, Y, D, Wv, Q, T)
        A[:] = 0.0
        for k in range(m):
            rows[k, 0] = Wv[k] * D[k]
            _derivative_rows(k, X[k], Y[k], Q[k], T[k], D[k], rows, 1)
            _add_taylor_outer(A, rows, k, X[k], Y[k], 6, True)
        c = _invert(A, 6, Ai, work)
        cond[i] = c
        if not c <= max_condition:
            _fail(i, p0, m, failed, gx, gy, lp)
            continue
        failed[i] = False
        for r in range(6):
            Ysel[0, r] = Ai[1, r]
            Ysel[1, r] = Ai[2, r]
            Ysel[2, r] = Ai[3, r] + Ai[5, r]
        _finish_row(Ysel, rows, 6, p0, m, ih, dsc, False, cx, cy, cl, gx, gy, lp)


@njit
def ncsph_rows(lo, hi, indptr, xy, dvp, h, alpha, max_condition, gx, gy, lp, cond, failed):
    """NCSPH weights (:class:`manifold_sph.schemes.NCSPH`: CSPM's gradient, the 5x5 block system's
    Laplacian) of rows ``lo:hi``."""
    X, Y, D, Wv, Q, T, rows, cx, cy, cl = _scratch(lo, hi, indptr, 5)
    A = np.empty((5, 5))
    Ai = np.empty((5, 5))
    work = np.empty((5, 10))
    M1i = np.empty((2, 2))
    Ysel = np.empty((3, 5))
    for i in range(lo, hi):
        p0, m, ih, dsc = _begin_row(i, indptr, xy, dvp, h, alpha, True, X, Y, D, Wv, Q, T)
        A[:] = 0.0
        for k in range(m):
            _derivative_rows(k, X[k], Y[k], Q[k], T[k], D[k], rows, 0)
            _add_taylor_outer(A, rows, k, X[k], Y[k], 5, False)
        c1 = _first_derivative_rows(A, M1i, Ysel)
        c2 = _invert(A, 5, Ai, work)
        cond[i] = max(c1, c2)
        if not (c1 <= max_condition and c2 <= max_condition):
            _fail(i, p0, m, failed, gx, gy, lp)
            continue
        failed[i] = False
        for r in range(5):
            Ysel[2, r] = Ai[2, r] + Ai[4, r]
        _finish_row(Ysel, rows, 5, p0, m, ih, dsc, True, cx, cy, cl, gx, gy, lp)


@njit
def moment_rows(lo, hi, indptr, xy, h, alpha, px, py, scale, sel, max_condition, gx, gy, lp, cond, failed):
    """Weights of the moment-form schemes (:class:`manifold_sph.schemes.msph4.HighOrderCorrected`:
    monomials ``x^px y^py * scale``, ``U = px.size`` unknowns; ``sel`` the positions of
    ``f_x, f_y, f_xx, f_yy``) of rows ``lo:hi``, with the Jacobi-equilibrated condition test."""
    U = px.size
    top = 0
    for a in range(U):
        top = max(top, px[a], py[a])
    X, Y, D, Wv, Q, T, mw, cx, cy, cl = _scratch(lo, hi, indptr, U)
    mono = np.empty(U)
    powx = np.empty(top + 1)
    powy = np.empty(top + 1)
    A = np.empty((U, U))
    As = np.empty((U, U))
    Ai = np.empty((U, U))
    work = np.empty((U, 2 * U))
    d = np.empty(U)
    Ysel = np.empty((3, U))
    for i in range(lo, hi):
        p0, m, ih, dsc = _begin_row(i, indptr, xy, xy[:, 0], h, alpha, False, X, Y, D, Wv, Q, T)
        A[:] = 0.0
        for k in range(m):
            powx[0] = 1.0
            powy[0] = 1.0
            for e in range(1, top + 1):
                powx[e] = powx[e - 1] * X[k]
                powy[e] = powy[e - 1] * Y[k]
            for a in range(U):
                v = powx[px[a]] * powy[py[a]] * scale[a]
                mono[a] = v
                mw[k, a] = v * Wv[k]
            _add_outer(A, mw, k, mono, U)
        ok = True
        for a in range(U):
            if not (np.isfinite(A[a, a]) and A[a, a] > 0.0):
                ok = False
                break
            d[a] = 1.0 / np.sqrt(A[a, a])
        c = np.inf
        if ok:
            for a in range(U):
                for b in range(U):
                    As[a, b] = A[a, b] * d[a] * d[b]
            c = _invert(As, U, Ai, work)
        cond[i] = c
        if not c <= max_condition:
            _fail(i, p0, m, failed, gx, gy, lp)
            continue
        failed[i] = False
        for b in range(U):  # rows of A^-1 = D As^-1 D picked by sel
            Ysel[0, b] = d[sel[0]] * Ai[sel[0], b] * d[b]
            Ysel[1, b] = d[sel[1]] * Ai[sel[1], b] * d[b]
            Ysel[2, b] = d[sel[2]] * Ai[sel[2], b] * d[b] + d[sel[3]] * Ai[sel[3], b] * d[b]
        _finish_row(Ysel, mw, U, p0, m, ih, dsc, True, cx, cy, cl, gx, gy, lp)
