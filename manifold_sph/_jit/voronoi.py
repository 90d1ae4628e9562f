"""Tangent-plane Voronoi cells of the stable Laplacian (:mod:`manifold_sph.voronoi`)."""

from __future__ import annotations

import numpy as np

from .compile import U, inline, njit

__all__ = ["voronoi_rows"]


@inline
def _hull(px, py, m, order, hx, hy):
    """Convex hull (counter-clockwise, Andrew's monotone chain) of the ``m`` points; returns its size."""
    k = 0
    for t in range(m):  # lower hull
        i = order[t]
        while k >= 2 and (hx[k - 1] - hx[k - 2]) * (py[i] - hy[k - 2]) - (hy[k - 1] - hy[k - 2]) * (px[i] - hx[k - 2]) <= 0.0:
            k -= 1
        hx[k] = px[i]
        hy[k] = py[i]
        k += 1
    low = k + 1
    for t in range(m - 2, -1, -1):  # upper hull
        i = order[t]
        while k >= low and (hx[k - 1] - hx[k - 2]) * (py[i] - hy[k - 2]) - (hy[k - 1] - hy[k - 2]) * (px[i] - hx[k - 2]) <= 0.0:
            k -= 1
        hx[k] = px[i]
        hy[k] = py[i]
        k += 1
    return k - 1  # the last point repeats the first


@njit
def voronoi_rows(lo, hi, indptr, xy, radius, dup_tol, w, area, flags):
    """Tangent-plane Voronoi cell of each particle ``i`` in ``lo:hi`` among its pairs.

    The cell of the origin (the particle) is the convex hull of its neighbourhood
    clipped by the bisector of every neighbour. For each pair, ``w`` receives
    ``|cell edge on the bisector| / |x_ij|`` (0 for a neighbour that bounds no edge),
    ``area[i]`` the cell's area, ``flags[i]`` bit 1 when a neighbour beyond
    ``radius[i]`` could still cut the cell (2 max vertex distance > radius, or the
    cell touches the hull), bit 2 when the cell touches the hull (an open boundary
    or a gap in the neighbourhood), bit 4 when the hull is
    degenerate (collinear or too few neighbours: area 0), bit 8 when a neighbour
    closer than ``dup_tol`` times the cell's size was met (its distance is floored there).
    """
    mmax = 0
    for i in range(lo, hi):
        mmax = max(mmax, indptr[i + 1] - indptr[i])
    cap = 2 * mmax + 8
    px = np.empty(mmax)
    py = np.empty(mmax)
    hx = np.empty(cap)
    hy = np.empty(cap)
    poly = np.empty((cap, 2))
    tmp = np.empty((cap, 2))
    lab = np.empty(cap, dtype=np.int64)
    tlab = np.empty(cap, dtype=np.int64)
    for i in range(lo, hi):
        p0 = indptr[i]
        m = indptr[i + 1] - p0
        fl = 0
        for j in range(m):
            px[j] = xy[U(p0 + j), 0]
            py[j] = xy[U(p0 + j), 1]
            w[U(p0 + j)] = 0.0
        # lexicographic order: a stable argsort by y, then by x
        oy = np.argsort(py[:m], kind="mergesort")
        ox = np.argsort(px[:m][oy], kind="mergesort")
        order = oy[ox]
        n = _hull(px, py, m, order, hx, hy) if m >= 3 else 0
        a2 = 0.0
        for e in range(n):
            b = e + 1 if e + 1 < n else 0
            a2 += hx[e] * hy[b] - hx[b] * hy[e]
        scale2 = 0.0
        for j in range(m):
            scale2 = max(scale2, px[j] * px[j] + py[j] * py[j])
        if n < 3 or a2 <= 1e-12 * scale2:
            area[i] = 0.0
            flags[i] = 4
            continue
        for e in range(n):
            poly[e, 0] = hx[e]
            poly[e, 1] = hy[e]
            lab[e] = -1
        for j in range(m):
            d2 = px[j] * px[j] + py[j] * py[j]
            if d2 == 0.0:
                continue
            rmax2 = 0.0
            for e in range(n):
                rmax2 = max(rmax2, poly[e, 0] * poly[e, 0] + poly[e, 1] * poly[e, 1])
            if d2 >= 4.0 * rmax2:
                continue
            d = np.sqrt(d2)
            nx = px[j] / d
            ny = py[j] / d
            c = 0.5 * d
            k = 0
            for e in range(n):
                b = e + 1 if e + 1 < n else 0
                ax = poly[e, 0]
                ay = poly[e, 1]
                bx = poly[b, 0]
                by = poly[b, 1]
                sa = ax * nx + ay * ny - c
                sb = bx * nx + by * ny - c
                if sa <= 0.0:
                    tmp[k, 0] = ax
                    tmp[k, 1] = ay
                    tlab[k] = lab[e]
                    k += 1
                    if sb > 0.0:
                        t = sa / (sa - sb)
                        tmp[k, 0] = ax + t * (bx - ax)
                        tmp[k, 1] = ay + t * (by - ay)
                        tlab[k] = j
                        k += 1
                elif sb <= 0.0:
                    t = sa / (sa - sb)
                    tmp[k, 0] = ax + t * (bx - ax)
                    tmp[k, 1] = ay + t * (by - ay)
                    tlab[k] = lab[e]
                    k += 1
            n = k
            for e in range(n):
                poly[e, 0] = tmp[e, 0]
                poly[e, 1] = tmp[e, 1]
                lab[e] = tlab[e]
            if n < 3:
                break
        a2 = 0.0
        rmax2 = 0.0
        for e in range(n):
            b = e + 1 if e + 1 < n else 0
            a2 += poly[e, 0] * poly[b, 1] - poly[b, 0] * poly[e, 1]
            rmax2 = max(rmax2, poly[e, 0] * poly[e, 0] + poly[e, 1] * poly[e, 1])
        A = 0.5 * a2 if n >= 3 else 0.0
        area[i] = A
        if A <= 0.0:
            flags[i] = 4
            continue
        floor = dup_tol * np.sqrt(A)
        for e in range(n):
            b = e + 1 if e + 1 < n else 0
            j = lab[e]
            if j < 0:
                fl |= 3  # touches the hull: an open boundary, or a gap a wider search may close
                continue
            L = np.sqrt((poly[b, 0] - poly[e, 0]) ** 2 + (poly[b, 1] - poly[e, 1]) ** 2)
            d = np.sqrt(px[j] * px[j] + py[j] * py[j])
            if d < floor:
                d = floor
                fl |= 8
            w[U(p0 + j)] += L / d
        if 4.0 * rmax2 > radius[i] * radius[i]:
            fl |= 1
        flags[i] = fl
