"""Fused CSR products and BiCGSTAB vector updates (:func:`manifold_sph._sparse.bicgstab_csr`)."""

from __future__ import annotations

from .compile import U, njit

__all__ = ["csr_matvec_dot", "csr_matvec_dots2", "bicgstab_direction", "bicgstab_half", "bicgstab_step"]


# Each pass works on the row blocks ``g0:g1`` (rows ``bounds[b]:bounds[b + 1]``) and leaves
# its inner products per block in ``partial[b]``: summed in block order, they do not
# depend on how the blocks are shared among threads.
@njit
def csr_matvec_dot(g0, g1, bounds, indptr, indices, data, x, out, a, partial):
    """``out = A x`` (CSR arrays of ``A``); ``partial[b, 0] = sum a * out`` over block ``b``."""
    for b in range(g0, g1):
        s = 0.0
        for i in range(bounds[b], bounds[b + 1]):
            acc = 0.0
            for p in range(U(indptr[i]), U(indptr[i + 1])):
                acc += data[p] * x[U(indices[p])]
            out[i] = acc
            s += a[i] * acc
        partial[b, 0] = s


@njit
def csr_matvec_dots2(g0, g1, bounds, indptr, indices, data, x, out, a, partial):
    """``out = A x``; ``partial[b] = (sum out * out, sum a * out)`` over block ``b``."""
    for b in range(g0, g1):
        s0 = 0.0
        s1 = 0.0
        for i in range(bounds[b], bounds[b + 1]):
            acc = 0.0
            for p in range(U(indptr[i]), U(indptr[i + 1])):
                acc += data[p] * x[U(indices[p])]
            out[i] = acc
            s0 += acc * acc
            s1 += a[i] * acc
        partial[b, 0] = s0
        partial[b, 1] = s1


@njit
def bicgstab_direction(g0, g1, bounds, r, p, v, dinv, phat, beta, omega, first, partial):
    """BiCGSTAB: ``p = r`` (first step) or ``r + beta (p - omega v)``; ``phat = dinv p``."""
    for i in range(bounds[g0], bounds[g1]):
        pi = r[i] if first else r[i] + beta * (p[i] - omega * v[i])
        p[i] = pi
        phat[i] = dinv[i] * pi


@njit
def bicgstab_half(g0, g1, bounds, r, v, alpha, dinv, shat, partial):
    """BiCGSTAB: ``r = s = r - alpha v``, ``shat = dinv s``; ``partial[b, 0] = s . s`` over block ``b``."""
    for b in range(g0, g1):
        ss = 0.0
        for i in range(bounds[b], bounds[b + 1]):
            s = r[i] - alpha * v[i]
            r[i] = s
            shat[i] = dinv[i] * s
            ss += s * s
        partial[b, 0] = ss


@njit
def bicgstab_step(g0, g1, bounds, x, phat, shat, alpha, omega, r, t, rtilde, partial):
    """BiCGSTAB: ``x += alpha phat + omega shat``, ``r = s - omega t``;
    ``partial[b] = (r . r, rtilde . r)`` over block ``b``."""
    for b in range(g0, g1):
        rr = 0.0
        rho = 0.0
        for i in range(bounds[b], bounds[b + 1]):
            x[i] += alpha * phat[i]
            x[i] += omega * shat[i]
            ri = r[i] - omega * t[i]
            r[i] = ri
            rr += ri * ri
            rho += rtilde[i] * ri
        partial[b, 0] = rr
        partial[b, 1] = rho
