"""The radius search of :func:`manifold_sph.neighbors.find_neighbors`: k-NN filtering and the grid (cell list) search."""

from __future__ import annotations

import numpy as np

from .compile import U, njit

__all__ = ["filter_count", "filter_fill", "grid_sort", "grid_sort_columns", "grid_gather", "grid_rows", "grid_scatter"]


@njit
def filter_count(lo, hi, dist, idx, radii, normals, cand_normals, threshold, use_normals, keep, counts, n_filtered):
    """Rows ``lo:hi`` of a k-NN result (dist, idx (n, k)): mark the kept slots in ``keep`` (uint8, (n, k))
    (inside ``radii`` and, with ``use_normals``, ``n_i . n_j > threshold``); count them and the filtered ones."""
    k = dist.shape[1]
    for i in range(lo, hi):
        r = radii[i]
        c = 0
        f = 0
        for s in range(k):
            ok = dist[i, s] < r
            if ok and use_normals:
                j = U(idx[i, s])
                dot = normals[i, 0] * cand_normals[j, 0] + normals[i, 1] * cand_normals[j, 1]
                if normals.shape[1] == 3:
                    dot += normals[i, 2] * cand_normals[j, 2]
                if not dot > threshold:
                    ok = False
                    f += 1
            keep[i, s] = ok
            c += ok
        counts[i] = c
        n_filtered[i] = f


@njit
def filter_fill(lo, hi, idx, keep, indptr, indices):
    """Write the kept columns of rows ``lo:hi`` (in k-NN order) at ``indices[indptr[i]:indptr[i + 1]]``."""
    k = idx.shape[1]
    for i in range(lo, hi):
        p = indptr[i]
        for s in range(k):
            if keep[i, s]:
                indices[U(p)] = idx[i, s]
                p += 1


# ------------------------------------------------- grid (cell list) radius search
@njit
def grid_sort(pts, lo, cell, ax_a, ax_b, ax_z, n_a, n_b, max_column, colptr, order):
    """Counting sort of the points by their column of cells (``ax_a``, ``ax_b``: cells of ``cell`` from
    ``lo``): ``order`` the point indices column by column (each column in index order; sort them along
    ``ax_z`` with :func:`grid_sort_columns`), ``colptr`` (n_a n_b + 1) the columns' bounds in it.
    Returns the largest column's size; above ``max_column`` nothing is placed."""
    n = pts.shape[0]
    ncols = n_a * n_b
    col = np.empty(n, dtype=np.int64)
    colptr[:] = 0
    for i in range(n):
        a = min(int((pts[i, ax_a] - lo[ax_a]) / cell), n_a - 1)
        b = min(int((pts[i, ax_b] - lo[ax_b]) / cell), n_b - 1)
        c = a * n_b + b
        col[i] = c
        colptr[c + 1] += 1
    biggest = 0
    for c in range(ncols):
        biggest = max(biggest, colptr[c + 1])
        colptr[c + 1] += colptr[c]
    if biggest > max_column:
        return biggest
    pos = colptr[:-1].copy()
    for i in range(n):
        c = col[i]
        order[pos[c]] = i
        pos[c] += 1
    return biggest


@njit
def grid_sort_columns(c0, c1, pts, ax_z, colptr, order):
    """Sort the columns ``c0:c1`` of :func:`grid_sort` along ``ax_z`` (insertion sort, stable)."""
    for c in range(c0, c1):
        first = colptr[c]
        for s in range(first + 1, colptr[c + 1]):
            i = order[s]
            zi = pts[i, ax_z]
            t = s
            while t > first and pts[order[t - 1], ax_z] > zi:
                order[t] = order[t - 1]
                t -= 1
            order[t] = i


@njit
def grid_gather(s0, s1, order, pts, normals, use_normals, lo, cell, ax_a, ax_b, ax_z, n_a, n_b, ps, ns, zs, ca, cb):
    """The points, normals, sort coordinate and column coordinates at the sorted positions ``s0:s1``
    (the order of :func:`grid_sort`)."""
    for s in range(s0, s1):
        i = order[s]
        for d in range(3):
            ps[s, d] = pts[i, d]
            if use_normals:
                ns[s, d] = normals[i, d]
        zs[s] = pts[i, ax_z]
        ca[s] = min(int((pts[i, ax_a] - lo[ax_a]) / cell), n_a - 1)
        cb[s] = min(int((pts[i, ax_b] - lo[ax_b]) / cell), n_b - 1)


@njit
def grid_rows(s0, s1, order, ps, ns, zs, ca, cb, n_a, n_b, colptr, cell, radii, threshold, use_normals, width,
              counts, n_filtered, like):
    """Radius search (``|p_i - p_j| < radii[i]``, distances as scipy's KD-tree computes them) with the
    normal filter, for the points at sorted positions ``s0:s1`` (``order[s]`` the point; ``ps``, ``ns``,
    ``zs``, ``ca``, ``cb`` the points, normals, sort coordinate and column coordinates in sorted
    order; the candidates lie in the 3 x 3 neighbouring columns, within ``cell`` in ``z``).
    Fills ``counts`` and ``n_filtered`` per point and returns ``(offsets, neighbours)``: the neighbours
    of the point at ``s0 + k`` at ``offsets[k]:offsets[k + 1]``, sorted by squared distance (the point
    itself first, ties by index; of the integer type of ``like``); ``width`` the first guess of
    neighbours per point (the buffer grows by half when full and is trimmed at the end)."""
    m_rows = s1 - s0
    offsets = np.zeros(m_rows + 1, dtype=np.int64)
    cap = max(m_rows * width, 16)
    out = np.empty(cap, dtype=like.dtype)
    dbuf = np.empty(64)
    jbuf = np.empty(64, dtype=np.int64)
    for s in range(s0, s1):
        i = order[s]
        r = radii[i]
        r2 = r * r
        r2_in = r2 * (1.0 - 1e-15)  # below: sqrt(d2) < r for sure; above r2_out: not
        r2_out = r2 * (1.0 + 1e-15)
        q0 = ps[s, 0]
        q1 = ps[s, 1]
        q2 = ps[s, 2]
        zq = zs[s]
        a = ca[s]
        b = cb[s]
        m = 0
        f = 0
        zlo = zq - cell
        zhi = zq + cell
        for da in range(-1, 2):
            aa = a + da
            if aa < 0 or aa >= n_a:
                continue
            for db in range(-1, 2):
                bb = b + db
                if bb < 0 or bb >= n_b:
                    continue
                c = aa * n_b + bb
                lo = colptr[c]
                end = colptr[c + 1]
                hi = end
                while lo < hi:  # first position with z >= zq - cell
                    mid = (lo + hi) >> 1
                    if zs[mid] < zlo:
                        lo = mid + 1
                    else:
                        hi = mid
                for t in range(lo, end):
                    if zs[t] > zhi:
                        break
                    d0 = q0 - ps[t, 0]
                    d1 = q1 - ps[t, 1]
                    d2 = q2 - ps[t, 2]
                    acc = 0.0
                    acc += d0 * d0
                    acc += d1 * d1
                    acc += d2 * d2
                    if acc >= r2_out:
                        continue
                    if acc > r2_in and not np.sqrt(acc) < r:
                        continue
                    if use_normals:
                        dot = ns[s, 0] * ns[t, 0] + ns[s, 1] * ns[t, 1]
                        dot += ns[s, 2] * ns[t, 2]
                        if not dot > threshold:
                            f += 1
                            continue
                    j = order[t]
                    if m == dbuf.size:
                        dnew = np.empty(2 * m)
                        jnew = np.empty(2 * m, dtype=np.int64)
                        dnew[:m] = dbuf
                        jnew[:m] = jbuf
                        dbuf = dnew
                        jbuf = jnew
                    # insertion by (not itself, squared distance, index)
                    key = -1.0 if j == i else acc
                    u = m
                    while u > 0 and (dbuf[u - 1] > key or (dbuf[u - 1] == key and jbuf[u - 1] > j)):
                        dbuf[u] = dbuf[u - 1]
                        jbuf[u] = jbuf[u - 1]
                        u -= 1
                    dbuf[u] = key
                    jbuf[u] = j
                    m += 1
        k = s - s0
        p = offsets[k]
        if p + m > cap:
            cap = max(cap + cap // 2, p + m)
            grown = np.empty(cap, dtype=like.dtype)
            grown[:p] = out[:p]
            out = grown
        for u in range(m):
            out[p + u] = jbuf[u]
        offsets[k + 1] = p + m
        counts[i] = m
        n_filtered[i] = f
    used = offsets[m_rows]
    if used < cap - cap // 8:
        return offsets, out[:used].copy()
    return offsets, out


@njit
def grid_scatter(s0, s1, order, offsets, found, indptr, indices):
    """Copy the neighbours of the points at sorted positions ``s0:s1`` (from :func:`grid_rows`) to their rows."""
    for s in range(s0, s1):
        i = order[s]
        k = s - s0
        p = indptr[i]
        for u in range(offsets[k], offsets[k + 1]):
            indices[p] = found[u]
            p += 1
