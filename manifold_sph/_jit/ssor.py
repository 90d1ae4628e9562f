"""Block SSOR (Eisenstat) preconditioning of the area solve (:func:`manifold_sph.area.bicgstab_ssor`)."""

from __future__ import annotations

from .compile import U, njit

__all__ = ["ssor_count", "ssor_fill", "ssor_backward", "ssor_forward", "ssor_upper_times", "ssor_residual"]


# The matrix ``A = D + L + U + B`` is cut into row blocks ``bounds[b]:bounds[b + 1]``; ``L`` and
# ``U`` are the strictly lower and upper parts inside the blocks, ``B`` the couplings between
# blocks. :func:`ssor_count` and :func:`ssor_fill` copy ``U`` and ``L + B`` of the matrix with
# its unknowns permuted (a sweep order) into two CSR arrays and ``D`` into a vector; the
# split-preconditioned operator ``(D + L)^-1 A (D + U)^-1`` is then applied in two passes that
# read each entry once (Eisenstat's trick): ``t = (D + U)^-1 x`` backward over ``U``, then
# ``out = t + (D + L)^-1 (x - D t + B t)`` forward over ``L + B``.
# Blocks are independent inside a pass.
@njit
def ssor_count(g0, g1, bounds, perm, iperm, indptr, indices, data, n_upper, n_rest, diag, partial):
    """Per row ``r`` of blocks ``g0:g1`` of the permuted matrix ``A[perm][:, perm]`` (``iperm`` the
    inverse permutation): entries of ``U`` and of ``L + B``, and the diagonal (summed if repeated);
    ``partial[b, 0]`` the rows of block ``b`` whose diagonal is not positive, ``partial[b, 1]`` the
    largest ``|c - r|`` of its off-diagonal entries (the width of :func:`ssor_fill`'s offsets)."""
    for b in range(g0, g1):
        hi = bounds[b + 1]
        bad = 0.0
        width = 0
        for r in range(bounds[b], hi):
            i = perm[r]
            nu = 0
            nr = 0
            d = 0.0
            for p in range(U(indptr[i]), U(indptr[i + 1])):
                c = iperm[U(indices[p])]
                width = max(width, abs(c - r))
                if c == r:
                    d += data[p]
                elif r < c < hi:
                    nu += 1
                else:
                    nr += 1
            n_upper[r] = nu
            n_rest[r] = nr
            diag[r] = d
            if not d > 0.0:
                bad += 1.0
        partial[b, 0] = bad
        partial[b, 1] = width


@njit
def ssor_fill(g0, g1, bounds, perm, iperm, indptr, indices, data, ptr_u, idx_u, dat_u, ptr_r, idx_r, dat_r, partial):
    """Copy the entries of ``U`` and of ``L + B`` of blocks ``g0:g1`` of ``A[perm][:, perm]`` (row offsets
    from :func:`ssor_count`), each row's in their order; the columns as offsets ``c - r`` from the row
    (int16 when they fit: 10 bytes an entry instead of 12, read twice an iteration)."""
    for b in range(g0, g1):
        hi = bounds[b + 1]
        for r in range(bounds[b], hi):
            i = perm[r]
            qu = ptr_u[r]
            qr = ptr_r[r]
            for p in range(U(indptr[i]), U(indptr[i + 1])):
                c = iperm[U(indices[p])]
                if c == r:
                    continue
                if r < c < hi:
                    idx_u[qu] = c - r
                    dat_u[qu] = data[p]
                    qu += 1
                else:
                    idx_r[qr] = c - r
                    dat_r[qr] = data[p]
                    qr += 1


@njit
def ssor_backward(g0, g1, bounds, ptr_u, idx_u, dat_u, diag, mode, r, p, v, c1, c2, t, partial):
    """``t = (D + U)^-1 x`` on blocks ``g0:g1`` (rows in reverse order), ``x`` formed on the fly:
    ``mode`` 0: ``x = r``; 1: ``x = p = r + c1 (p - c2 v)`` (BiCGSTAB's direction, stored in ``p``);
    2: ``x = s = r - c1 v`` (stored in ``r``; ``partial[b, 0] = s . s``)."""
    for b in range(g0, g1):
        lo = bounds[b]
        ss = 0.0
        for i in range(bounds[b + 1] - 1, lo - 1, -1):
            if mode == 0:
                x = r[i]
            elif mode == 1:
                x = r[i] + c1 * (p[i] - c2 * v[i])
                p[i] = x
            else:
                x = r[i] - c1 * v[i]
                r[i] = x
                ss += x * x
            acc = x
            for q in range(U(ptr_u[i]), U(ptr_u[i + 1])):
                acc -= dat_u[q] * t[U(i + idx_u[q])]
            t[i] = acc / diag[i]
        partial[b, 0] = ss


@njit
def ssor_forward(g0, g1, bounds, ptr_r, idx_r, dat_r, diag, x, t, w, out, a, partial):
    """``out = t + w``, ``w = (D + L)^-1 (x - D t + B t)`` on blocks ``g0:g1`` (``t`` of every block
    from :func:`ssor_backward`; ``t = 0`` gives ``out = (D + L)^-1 x``);
    ``partial[b] = (out . out, a . out)``."""
    for b in range(g0, g1):
        lo = bounds[b]
        s0 = 0.0
        s1 = 0.0
        for i in range(lo, bounds[b + 1]):
            acc = x[i] - diag[i] * t[i]
            for q in range(U(ptr_r[i]), U(ptr_r[i + 1])):
                j = i + idx_r[q]
                if lo <= j < i:
                    acc -= dat_r[q] * w[U(j)]
                else:
                    acc += dat_r[q] * t[U(j)]
            wi = acc / diag[i]
            w[i] = wi
            o = t[i] + wi
            out[i] = o
            s0 += o * o
            s1 += a[i] * o
        partial[b, 0] = s0
        partial[b, 1] = s1


@njit
def ssor_upper_times(g0, g1, bounds, ptr_u, idx_u, dat_u, diag, x, out, partial):
    """``out = (D + U) x`` on blocks ``g0:g1``."""
    for b in range(g0, g1):
        for i in range(bounds[b], bounds[b + 1]):
            acc = diag[i] * x[i]
            for q in range(U(ptr_u[i]), U(ptr_u[i + 1])):
                acc += dat_u[q] * x[U(i + idx_u[q])]
            out[i] = acc


@njit
def ssor_residual(g0, g1, bounds, ptr_u, idx_u, dat_u, ptr_r, idx_r, dat_r, diag, b, x, out, partial):
    """``out = b - A x`` from the split (``A = D + U + L + B``, all in the sweep order) on blocks
    ``g0:g1``; ``partial[k] = (out . out, max |out|)`` over block ``k``."""
    for k in range(g0, g1):
        ss = 0.0
        mx = 0.0
        for i in range(bounds[k], bounds[k + 1]):
            acc = diag[i] * x[i]
            for q in range(U(ptr_u[i]), U(ptr_u[i + 1])):
                acc += dat_u[q] * x[U(i + idx_u[q])]
            for q in range(U(ptr_r[i]), U(ptr_r[i + 1])):
                acc += dat_r[q] * x[U(i + idx_r[q])]
            o = b[i] - acc
            out[i] = o
            ss += o * o
            mx = max(mx, abs(o))
        partial[k, 0] = ss
        partial[k, 1] = mx
