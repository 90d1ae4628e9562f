"""Compiled per-row kernels (numba) for the hot steps of the pipeline.

numpy does these steps in several passes over the per-pair arrays (gathers,
padding, one temporary per factor), and at a few dozen pairs per particle they are
bound by memory traffic. Each function here does one step for the rows
``lo:hi`` in a single pass, keeping a particle's pairs in registers and cache:

- :func:`filter_count`, :func:`filter_fill`: the radius mask and normal filter of
  :func:`manifold_sph.neighbors.find_neighbors`;
- :func:`frames_rows`: :func:`manifold_sph.frames.tangent_frames`;
- :func:`project_rows`: :func:`manifold_sph.frames.project_neighborhood`;
- :func:`quintic_values`: :func:`manifold_sph.area.kernel_values` (quintic spline);
- :func:`cspm_rows`, :func:`msph_rows`, :func:`ncsph_rows`, :func:`moment_rows`: the
  weights of the schemes of :mod:`manifold_sph.schemes` (quintic spline), with the same
  condition-number test; a particle that fails is only flagged, and the assembly
  recomputes it (with the fallback chain) through the numpy schemes;
- :func:`voronoi_rows`: the tangent-plane Voronoi cells of :mod:`manifold_sph.voronoi`;
- :func:`csr_matvec_dot`, :func:`csr_matvec_dots2`, :func:`bicgstab_direction`,
  :func:`bicgstab_half`, :func:`bicgstab_step`: the passes of
  :func:`manifold_sph._sparse.bicgstab_csr` (the area elements' solve and the implicit
  steps), each a CSR product or vector update fused with the inner products after it.
- :func:`ssor_count`, :func:`ssor_fill`, :func:`ssor_forward`, :func:`ssor_backward`,
  :func:`ssor_upper_times`, :func:`ssor_residual`: the block-SSOR preconditioned area solve
  (:func:`manifold_sph.area.bicgstab_ssor`);

Every function releases the GIL and writes only its rows' slices, so
:func:`manifold_sph.threads.run_chunks` runs chunks on threads. Each has a numpy
twin that defines it; ``tests/test_jit.py`` compares them (to round-off).

``MANIFOLD_SPH_JIT=0`` in the environment, or ``ENABLED = False`` here, selects
the numpy twins everywhere (for debugging: the whole cspm build is then 1.6-2.2x
slower, ``benchmarks/perf.py``). Compiled code is cached on disk (numba
``cache=True``): the first call of each kernel on a machine compiles it (about 7 s
for all of them), later processes load it (about 0.3 s).
"""

from __future__ import annotations

import os

import numpy as np

try:
    import numba
except ImportError:  # pragma: no cover - numba is a dependency; a platform without its wheels still works
    numba = None

__all__ = [
    "ENABLED",
    "bicgstab_direction",
    "bicgstab_half",
    "bicgstab_step",
    "csr_matvec_dot",
    "csr_matvec_dots2",
    "cspm_rows",
    "filter_count",
    "filter_fill",
    "frames_rows",
    "grid_gather",
    "grid_rows",
    "grid_scatter",
    "grid_sort",
    "grid_sort_columns",
    "moment_rows",
    "msph_rows",
    "ncsph_rows",
    "project_rows",
    "quintic_values",
    "ssor_backward",
    "ssor_forward",
    "ssor_count",
    "ssor_fill",
    "ssor_upper_times",
    "ssor_residual",
    "voronoi_rows",
]



def _from_env() -> bool:
    """``MANIFOLD_SPH_JIT`` as a bool (default True). Another value than 0/1, true/false,
    yes/no, on/off gives a ``ManifoldSPHWarning`` and the default: importing never fails on it."""
    raw = os.environ.get("MANIFOLD_SPH_JIT", "1")
    text = raw.strip().lower()
    if text in ("", "1", "true", "yes", "on"):
        return True
    if text in ("0", "false", "no", "off"):
        return False
    import warnings

    from .exceptions import ManifoldSPHWarning

    warnings.warn(
        f"environment variable MANIFOLD_SPH_JIT must be 0 or 1 (or true/false, yes/no, on/off), got {raw!r}; "
        "using the default (1: compiled kernels on)",
        ManifoldSPHWarning,
        stacklevel=2,
    )
    return True


#: Whether the pipeline uses the compiled kernels (``MANIFOLD_SPH_JIT=0`` turns them off; so does
#: a missing numba, e.g. on a Python version it does not support yet: the numpy code then runs).
ENABLED = _from_env() and numba is not None

# error_model="numpy": a division by zero gives inf or nan (then caught by the
# condition test), as in numpy, instead of raising.
_jit = numba.njit(nogil=True, cache=True, error_model="numpy") if numba is not None else (lambda f: f)
# Small helpers of the scheme kernels, inlined into them at numba's level (as separate
# functions the shared helpers cost up to 1.7x in the cspm kernel, measured).
_inline = numba.njit(nogil=True, cache=True, error_model="numpy", inline="always") if numba is not None else (lambda f: f)

# Indices into the pair and point arrays are cast to unsigned: numba then skips the
# wrap-around test of negative indices. It made a CSR product 1.5x slower than scipy's
# (measured, 3.5 million entries: 5.8 ms signed, 2.4 ms unsigned, scipy 4.0 ms).
_u = np.uint64


# ----------------------------------------------------------------- neighbours
@_jit
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
                j = _u(idx[i, s])
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


@_jit
def filter_fill(lo, hi, idx, keep, indptr, indices):
    """Write the kept columns of rows ``lo:hi`` (in k-NN order) at ``indices[indptr[i]:indptr[i + 1]]``."""
    k = idx.shape[1]
    for i in range(lo, hi):
        p = indptr[i]
        for s in range(k):
            if keep[i, s]:
                indices[_u(p)] = idx[i, s]
                p += 1


# ------------------------------------------------- grid (cell list) radius search
@_jit
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


@_jit
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


@_jit
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


@_jit
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


@_jit
def grid_scatter(s0, s1, order, offsets, found, indptr, indices):
    """Copy the neighbours of the points at sorted positions ``s0:s1`` (from :func:`grid_rows`) to their rows."""
    for s in range(s0, s1):
        i = order[s]
        k = s - s0
        p = indptr[i]
        for u in range(offsets[k], offsets[k + 1]):
            indices[p] = found[u]
            p += 1


# ----------------------------------------------------------------- frames
@_jit
def frames_rows(lo, hi, normals, parallel_tol, u, v):
    """:func:`manifold_sph.frames.tangent_frames` for rows ``lo:hi``: ``u`` the unit tangent in the
    plane ``y = y_i`` (or ``x = x_i`` when the normal is almost along y), ``v = n x u``."""
    for i in range(lo, hi):
        nx, ny, nz = normals[i, 0], normals[i, 1], normals[i, 2]
        if np.hypot(nx, nz) < parallel_tol:
            a, b, c = 0.0, nz, -ny
        else:
            a, b, c = nz, 0.0, -nx
        norm = np.sqrt(a * a + b * b + c * c)
        a /= norm
        b /= norm
        c /= norm
        u[i, 0] = a
        u[i, 1] = b
        u[i, 2] = c
        v[i, 0] = ny * c - nz * b
        v[i, 1] = nz * a - nx * c
        v[i, 2] = nx * b - ny * a


# ----------------------------------------------------------------- projection
@_jit
def project_rows(lo, hi, points, cand, u, v, indptr, indices, out):
    """``out[p] = ((c_j - p_i) . u_i, (c_j - p_i) . v_i)`` for the pairs ``p`` of rows ``lo:hi``."""
    for i in range(lo, hi):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        ux, uy, uz = u[i, 0], u[i, 1], u[i, 2]
        vx, vy, vz = v[i, 0], v[i, 1], v[i, 2]
        for p in range(_u(indptr[i]), _u(indptr[i + 1])):
            j = _u(indices[p])
            dx = cand[j, 0] - px
            dy = cand[j, 1] - py
            dz = cand[j, 2] - pz
            out[p, 0] = dx * ux + dy * uy + dz * uz
            out[p, 1] = dx * vx + dy * vy + dz * vz


# ----------------------------------------------------------------- kernel
@_inline
def _quintic(R):
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


@_jit
def near_pairs(lo, hi, indptr, xy, h, cols, row0, tol, out):
    """``out[p] = 1`` for the pairs of rows ``lo:hi`` with ``|xy_p| < tol h_i`` and column ``!= row0 + i``."""
    for i in range(lo, hi):
        lim = tol * h[i]
        lim2 = lim * lim
        for p in range(_u(indptr[i]), _u(indptr[i + 1])):
            x = xy[p, 0]
            y = xy[p, 1]
            out[p] = 1 if (x * x + y * y < lim2 and cols[p] != row0 + i) else 0


@_jit
def quintic_values(lo, hi, indptr, xy, h, alpha, out):
    """``out[p] = alpha w(|xy_p| / h_i) / h_i^2`` for the pairs of rows ``lo:hi``."""
    for i in range(lo, hi):
        ih = 1.0 / h[i]
        scale = alpha * (ih * ih)
        for p in range(_u(indptr[i]), _u(indptr[i + 1])):
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


# ----------------------------------------------------------------- small systems
@_inline
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


@_jit
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


@_inline
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


@_inline
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


@_jit
def _max_count(lo, hi, indptr):
    k = 0
    for i in range(lo, hi):
        k = max(k, indptr[i + 1] - indptr[i])
    return k


@_inline
def _scratch(lo, hi, indptr, width):
    """Per-pair scratch for the particles ``lo:hi``: offsets ``X, Y``, area elements ``D``, kernel
    factors ``W, Q, T``, the weighted rows (K, width) of the local system and the weights ``cx, cy, cl``."""
    K = _max_count(lo, hi, indptr)
    return (np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(K),
            np.empty((K, width)), np.empty(K), np.empty(K), np.empty(K))


@_inline
def _begin_row(i, indptr, xy, dvp, h, alpha, use_dv, X, Y, D, Wv, Q, T):
    """Normalised offsets (units of ``h_i``), area elements (``/ h_i^2``; 1 without ``use_dv``) and
    kernel factors of particle ``i``'s pairs; returns ``(p0, m, 1 / h_i, 1 / h_i^2)``."""
    p0 = indptr[i]
    m = indptr[i + 1] - p0
    ih = 1.0 / h[i]
    dsc = ih * ih
    for k in range(m):
        p = _u(p0 + k)
        x = xy[p, 0] * ih
        y = xy[p, 1] * ih
        w, q, t = _quintic(np.sqrt(x * x + y * y))
        X[k] = x
        Y[k] = y
        D[k] = dvp[p] * dsc if use_dv else 1.0
        Wv[k] = w * alpha
        Q[k] = q * alpha
        T[k] = t * alpha
    return p0, m, ih, dsc


@_inline
def _derivative_rows(k, x, y, q, t, dv, rows, c0):
    """``rows[k, c0:c0 + 5] = (W_x, W_y, W_xx, W_xy, W_yy) dV`` of one pair."""
    tx = t * x
    rows[k, c0] = -(x * q) * dv
    rows[k, c0 + 1] = -(y * q) * dv
    rows[k, c0 + 2] = (tx * x + q) * dv
    rows[k, c0 + 3] = (tx * y) * dv
    rows[k, c0 + 4] = (t * y * y + q) * dv


@_inline
def _add_taylor_outer(A, rows, k, x, y, n, lead_one):
    """``A[:n, :n] += rows[k, :n] cols^T`` with the Taylor columns ``cols = (x, y, x^2/2, xy, y^2/2)``
    (after a column of ones with ``lead_one``): the columns stay in registers instead of a scratch array (the same products and sums: 14 % faster
    MSPH weights, measured at N = 131072, one thread, 16 paired runs)."""
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


@_inline
def _add_outer(A, rows, k, cols, n):
    """``A[:n, :n] += rows[k, :n] cols[:n]^T`` (one pair's share of the moment sums)."""
    for r in range(n):
        s = rows[k, r]
        for c in range(n):
            A[r, c] += s * cols[c]


@_inline
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


@_inline
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
        p = _u(p0 + k)
        gx[p] = cx[k] * ih
        gy[p] = cy[k] * ih
        lp[p] = cl[k] * dsc


@_inline
def _fail(i, p0, m, failed, gx, gy, lp):
    """Flag particle ``i`` (the assembly redoes it) and zero its weights."""
    failed[i] = True
    for k in range(m):
        p = _u(p0 + k)
        gx[p] = 0.0
        gy[p] = 0.0
        lp[p] = 0.0


# ----------------------------------------------------------------- schemes
# Every scheme fills, per particle, the weighted rows of its local system (K, n) and
# the moment matrix A = sum_k rows[k] cols[k]^T, inverts A with the condition test,
# and turns three rows ``Ysel`` of A^-1 (f_x, f_y and f_xx + f_yy) into weights.
@_inline
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


@_jit
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


@_jit
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


@_jit
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


@_jit
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


# ----------------------------------------------------------------- Krylov solves
# Each pass works on the row blocks ``g0:g1`` (rows ``bounds[b]:bounds[b + 1]``) and leaves
# its inner products per block in ``partial[b]``: summed in block order, they do not
# depend on how the blocks are shared among threads.
@_jit
def csr_matvec_dot(g0, g1, bounds, indptr, indices, data, x, out, a, partial):
    """``out = A x`` (CSR arrays of ``A``); ``partial[b, 0] = sum a * out`` over block ``b``."""
    for b in range(g0, g1):
        s = 0.0
        for i in range(bounds[b], bounds[b + 1]):
            acc = 0.0
            for p in range(_u(indptr[i]), _u(indptr[i + 1])):
                acc += data[p] * x[_u(indices[p])]
            out[i] = acc
            s += a[i] * acc
        partial[b, 0] = s


@_jit
def csr_matvec_dots2(g0, g1, bounds, indptr, indices, data, x, out, a, partial):
    """``out = A x``; ``partial[b] = (sum out * out, sum a * out)`` over block ``b``."""
    for b in range(g0, g1):
        s0 = 0.0
        s1 = 0.0
        for i in range(bounds[b], bounds[b + 1]):
            acc = 0.0
            for p in range(_u(indptr[i]), _u(indptr[i + 1])):
                acc += data[p] * x[_u(indices[p])]
            out[i] = acc
            s0 += acc * acc
            s1 += a[i] * acc
        partial[b, 0] = s0
        partial[b, 1] = s1


@_jit
def bicgstab_direction(g0, g1, bounds, r, p, v, dinv, phat, beta, omega, first, partial):
    """BiCGSTAB: ``p = r`` (first step) or ``r + beta (p - omega v)``; ``phat = dinv p``."""
    for i in range(bounds[g0], bounds[g1]):
        pi = r[i] if first else r[i] + beta * (p[i] - omega * v[i])
        p[i] = pi
        phat[i] = dinv[i] * pi


@_jit
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


@_jit
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


# ------------------------------------------------ block SSOR (Eisenstat) for the area solve
# The matrix ``A = D + L + U + B`` is cut into row blocks ``bounds[b]:bounds[b + 1]``; ``L`` and
# ``U`` are the strictly lower and upper parts inside the blocks, ``B`` the couplings between
# blocks. :func:`ssor_count` and :func:`ssor_fill` copy ``U`` and ``L + B`` of the matrix with
# its unknowns permuted (a sweep order) into two CSR arrays and ``D`` into a vector; the split-preconditioned operator ``(D + L)^-1 A (D + U)^-1`` is
# then applied in two passes that read each entry once (Eisenstat's trick): ``t = (D + U)^-1 x``
# backward over ``U``, then ``out = t + (D + L)^-1 (x - D t + B t)`` forward over ``L + B``.
# Blocks are independent inside a pass.
@_jit
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
            for p in range(_u(indptr[i]), _u(indptr[i + 1])):
                c = iperm[_u(indices[p])]
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


@_jit
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
            for p in range(_u(indptr[i]), _u(indptr[i + 1])):
                c = iperm[_u(indices[p])]
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


@_jit
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
            for q in range(_u(ptr_u[i]), _u(ptr_u[i + 1])):
                acc -= dat_u[q] * t[_u(i + idx_u[q])]
            t[i] = acc / diag[i]
        partial[b, 0] = ss


@_jit
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
            for q in range(_u(ptr_r[i]), _u(ptr_r[i + 1])):
                j = i + idx_r[q]
                if lo <= j < i:
                    acc -= dat_r[q] * w[_u(j)]
                else:
                    acc += dat_r[q] * t[_u(j)]
            wi = acc / diag[i]
            w[i] = wi
            o = t[i] + wi
            out[i] = o
            s0 += o * o
            s1 += a[i] * o
        partial[b, 0] = s0
        partial[b, 1] = s1


@_jit
def ssor_upper_times(g0, g1, bounds, ptr_u, idx_u, dat_u, diag, x, out, partial):
    """``out = (D + U) x`` on blocks ``g0:g1``."""
    for b in range(g0, g1):
        for i in range(bounds[b], bounds[b + 1]):
            acc = diag[i] * x[i]
            for q in range(_u(ptr_u[i]), _u(ptr_u[i + 1])):
                acc += dat_u[q] * x[_u(i + idx_u[q])]
            out[i] = acc


@_jit
def ssor_residual(g0, g1, bounds, ptr_u, idx_u, dat_u, ptr_r, idx_r, dat_r, diag, b, x, out, partial):
    """``out = b - A x`` from the split (``A = D + U + L + B``, all in the sweep order) on blocks
    ``g0:g1``; ``partial[k] = (out . out, max |out|)`` over block ``k``."""
    for k in range(g0, g1):
        ss = 0.0
        mx = 0.0
        for i in range(bounds[k], bounds[k + 1]):
            acc = diag[i] * x[i]
            for q in range(_u(ptr_u[i]), _u(ptr_u[i + 1])):
                acc += dat_u[q] * x[_u(i + idx_u[q])]
            for q in range(_u(ptr_r[i]), _u(ptr_r[i + 1])):
                acc += dat_r[q] * x[_u(i + idx_r[q])]
            o = b[i] - acc
            out[i] = o
            ss += o * o
            mx = max(mx, abs(o))
        partial[k, 0] = ss
        partial[k, 1] = mx


# ------------------------------------------------------------- Voronoi cells
@_inline
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


@_jit
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
            px[j] = xy[_u(p0 + j), 0]
            py[j] = xy[_u(p0 + j), 1]
            w[_u(p0 + j)] = 0.0
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
            w[_u(p0 + j)] += L / d
        if 4.0 * rmax2 > radius[i] * radius[i]:
            fl |= 1
        flags[i] = fl
