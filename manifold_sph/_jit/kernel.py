"""The quintic spline and its values per pair (:func:`manifold_sph.area.kernel_values`), near pairs of the area solve."""

from __future__ import annotations

import numpy as np

from .compile import U, inline, njit

__all__ = ["quintic", "near_pairs", "quintic_values"]


@inline
def quintic(R):
    """``(w, w'/R, (w'' - w'/R)/R^2)`` of the quintic spline (:meth:`QuinticSpline.radial_terms`)."""
    if R >= 3.0:
        return 0.0, 0.0, 0.0
    a = 3.0 - R
    b = max(2.0 - R, 0.0)
    c = max(1.0 - R, 0.0)
    a3 = a * a * a
    b3 = b * b * b
    c3 = c * c * c
    a4 = a3 * a
    b4 = b3 * b
    w = a4 * a - 6.0 * (b4 * b) + 15.0 * (c3 * c * c)
    if R < 1.0:
        q = -120.0 + R * R * (120.0 - 50.0 * R)
        t = 240.0 - 150.0 * R if R > 0.0 else 0.0
    else:
        q = (30.0 * b4 - 5.0 * a4) / R
        t = (20.0 * a3 - 120.0 * b3 + 300.0 * c3 - q) / (R * R)
    return w, q, t


@njit
def near_pairs(lo, hi, indptr, xy, h, cols, row0, tol, out):
    """``out[p] = 1`` for the pairs of rows ``lo:hi`` with ``|xy_p| < tol h_i`` and column ``!= row0 + i``."""
    for i in range(lo, hi):
        lim = tol * h[i]
        lim2 = lim * lim
        for p in range(U(indptr[i]), U(indptr[i + 1])):
            x = xy[p, 0]
            y = xy[p, 1]
            out[p] = 1 if (x * x + y * y < lim2 and cols[p] != row0 + i) else 0


@njit
def quintic_values(lo, hi, indptr, xy, h, alpha, out):
    """``out[p] = alpha w(|xy_p| / h_i) / h_i^2`` for the pairs of rows ``lo:hi``."""
    for i in range(lo, hi):
        ih = 1.0 / h[i]
        scale = alpha * (ih * ih)
        for p in range(U(indptr[i]), U(indptr[i + 1])):
            x = xy[p, 0]
            y = xy[p, 1]
            R = np.sqrt(x * x + y * y) * ih
            if R >= 3.0:
                out[p] = 0.0
                continue
            a = 3.0 - R
            b = max(2.0 - R, 0.0)
            c = max(1.0 - R, 0.0)
            a2 = a * a
            b2 = b * b
            c2 = c * c
            out[p] = (a2 * a2 * a - 6.0 * (b2 * b2 * b) + 15.0 * (c2 * c2 * c)) * scale
