"""Local fits of the normal direction: PCA and jet (polynomial height-function) fits.

- :func:`pca_normals`: the eigenvector of the smallest eigenvalue of each particle's
  neighbourhood covariance (first order);
- :func:`jet_normals` and :func:`jet_fit`: in the tangent frame of a first normal, the
  neighbours are fitted by a height function ``z = sum c_ab x^a y^b`` of total degree ``d``
  (weighted least squares, all small systems solved at once; Cazals & Pouget 2005); the normal
  is that of the fitted surface at the particle, with error ``O(h^d)`` on a smooth surface;
- :func:`refit`: the feature-aware refit (only neighbours whose oriented normal agrees), and
  :func:`sharpened_weights`, sharper weights where the fit residual is bias rather than noise;
- :func:`high_order`: degree-3/4 fits started from oriented degree-2 normals, guarded.
"""

from __future__ import annotations

from typing import overload

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from .. import _jit
from .._jit.compile import njit
from .._validation import as_points, check_int
from ..pointcloud import as_cloud, is_point_array
from ..threads import get_num_threads, run_chunks
from . import tuning


def point_array(points: object) -> np.ndarray:
    """The (N, 3) points of an array or of anything point-like (PointCloud, Surface, path, Open3D /
    PyVista / trimesh object; :func:`manifold_sph.as_cloud`), validated."""
    return as_points("points", points if is_point_array(points) else as_cloud(points).points)


def unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def tangents(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.where(np.abs(n[:, :1]) < 0.6, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    t1 = unit(np.cross(n, a))
    return t1, np.cross(n, t1)


def knn(points: np.ndarray, k: int, tree: cKDTree | None = None) -> tuple[np.ndarray, np.ndarray]:
    tree = cKDTree(points) if tree is None else tree
    dist, idx = tree.query(points, k=k, workers=get_num_threads())
    return dist, idx


def covariance(pts: np.ndarray, neighbors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    nbr = pts[neighbors]  # (N, k, 3)
    # centre on the particle's own mean; subtract the particle first for conditioning
    local = nbr - pts[:, None, :]
    local -= local.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", local, local) / neighbors.shape[1]
    return np.linalg.eigh(cov)  # ascending eigenvalues


def shape_confidence(w: np.ndarray) -> np.ndarray:
    w = np.maximum(w, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(w[:, 1] > 0, w[:, 0] / w[:, 1], 1.0)
    return np.clip(1.0 - ratio, 0.0, 1.0)


def pca_rows(pts: np.ndarray, neighbors: np.ndarray) -> np.ndarray:
    """PCA normals of the rows of ``neighbors`` (their own first column is the particle)."""
    local = pts[neighbors] - pts[neighbors[:, :1]]
    local -= local.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", local, local)
    return np.linalg.eigh(cov)[1][:, :, 0]


def _monomials(degree: int) -> list:
    return [(a, d - a) for d in range(degree + 1) for a in range(d, -1, -1)]


@overload
def n_coefficients(degree: int) -> int: ...


@overload
def n_coefficients(degree: np.ndarray) -> np.ndarray: ...


def n_coefficients(degree: int | np.ndarray) -> int | np.ndarray:
    """Coefficients of a bivariate polynomial of degree ``degree`` (per row for an array of degrees)."""
    return (degree + 1) * (degree + 2) // 2


def jet_fit(pts: np.ndarray, neighbors: np.ndarray, frame: np.ndarray, degree: int | np.ndarray, weights: np.ndarray | None = None,
            residual: np.ndarray | None = None, centers: np.ndarray | None = None, kurtosis: np.ndarray | None = None) -> np.ndarray:
    """Normals of degree-``degree`` height-function fits in the tangent frames of ``frame``.

    ``degree`` is an int or a per-particle int array (0 keeps the frame normal);
    ``weights`` (N, k) zero out neighbours. Row ``r`` is centred on ``pts[r]``, or on
    ``centers[r]`` when given (fits of a subset of rows). ``residual`` (N,) receives the
    weighted RMS residual over the fit radius, ``kurtosis`` (N,) the weighted
    ``mean(r^4) / mean(r^2)^2`` of the residuals (3 for Gaussian noise, near 1 for two layers:
    the two sides of a part thinner than the neighbourhood). Compiled (:func:`jet_rows`, on
    threads) unless the kernels are off; the numpy twin is :func:`jet_fit_numpy`.
    """
    if not _jit.ENABLED:
        return jet_fit_numpy(pts, neighbors, frame, degree, weights, residual, centers, kurtosis)
    centers = pts if centers is None else centers
    N = frame.shape[0]
    out = np.ascontiguousarray(frame, dtype=np.float64).copy()
    if N == 0:
        return out
    degs = np.ascontiguousarray(np.broadcast_to(np.asarray(degree, dtype=np.int64), (N,)))
    t1, t2 = tangents(out)
    use_w = weights is not None
    W = np.ascontiguousarray(weights, dtype=np.float64) if use_w else np.zeros((1, 1))
    res = np.zeros(N)
    kurt = np.full(N, 3.0)
    args = (np.ascontiguousarray(pts, dtype=np.float64), np.ascontiguousarray(neighbors, dtype=np.int64),
            np.ascontiguousarray(centers, dtype=np.float64), out.copy(), t1, t2, degs, W, use_w, _EXP_A, _EXP_B, out, res, kurt)
    n_chunks = max(1, min(64, N // 256))
    bounds = np.linspace(0, N, n_chunks + 1).astype(np.int64)
    run_chunks(lambda c: jet_rows(bounds[c], bounds[c + 1], *args), n_chunks)
    if residual is not None:
        fitted = degs > 0
        residual[fitted] = res[fitted]
    if kurtosis is not None:
        fitted = degs > 0
        kurtosis[fitted] = kurt[fitted]
    return out


_MONOMIALS = [(a, d - a) for d in range(5) for a in range(d, -1, -1)]
_EXP_A = np.array([a for a, _ in _MONOMIALS], dtype=np.int64)
_EXP_B = np.array([b for _, b in _MONOMIALS], dtype=np.int64)


@njit
def jet_rows(lo: int, hi: int, pts: np.ndarray, nbr: np.ndarray, centers: np.ndarray, frame: np.ndarray, t1: np.ndarray, t2: np.ndarray,
             degs: np.ndarray, weights: np.ndarray, use_w: bool, ea: np.ndarray, eb: np.ndarray, out: np.ndarray, residual: np.ndarray,
             kurtosis: np.ndarray) -> None:  # pragma: no cover - compiled
    """Rows ``lo:hi`` of :func:`jet_fit`: the normal equations of each height fit, solved by Gaussian
    elimination with partial pivoting (the same regularisation as the numpy twin).

    ``frame`` holds the input normals, ``out`` (N, 3) receives the fitted ones (a row whose system
    is singular keeps its input normal), ``residual`` and ``kurtosis`` (N,) the residual statistics;
    ``ea``, ``eb`` are the exponents of the monomials ``u^a v^b`` up to degree 4, ``weights`` is
    read only with ``use_w``. Writes only rows ``lo:hi`` (chunks run on threads)."""
    K = nbr.shape[1]
    A = np.empty((15, 15))
    b = np.empty(15)
    vals = np.empty(15)
    zs = np.empty(K)
    us = np.empty(K)
    vs = np.empty(K)
    for i in range(lo, hi):
        d = degs[i]
        if d <= 0:
            continue
        m = (d + 1) * (d + 2) // 2
        cx, cy, cz = centers[i, 0], centers[i, 1], centers[i, 2]
        s2 = 0.0
        for j in range(K):
            q = nbr[i, j]
            px, py, pz = pts[q, 0] - cx, pts[q, 1] - cy, pts[q, 2] - cz
            x = px * t1[i, 0] + py * t1[i, 1] + pz * t1[i, 2]
            y = px * t2[i, 0] + py * t2[i, 1] + pz * t2[i, 2]
            us[j] = x
            vs[j] = y
            zs[j] = px * frame[i, 0] + py * frame[i, 1] + pz * frame[i, 2]
            if x * x + y * y > s2:
                s2 = x * x + y * y
        s = np.sqrt(s2)
        if not s > 0:
            s = 1.0
        for p in range(m):
            b[p] = 0.0
            for r in range(m):
                A[p, r] = 0.0
        for j in range(K):
            u = us[j] / s
            v = vs[j] / s
            for p in range(m):
                vals[p] = u ** ea[p] * v ** eb[p]
            w = weights[i, j] if use_w else 1.0
            for p in range(m):
                wp = w * vals[p]
                b[p] += wp * zs[j]
                for r in range(p, m):
                    A[p, r] += wp * vals[r]
        tr = 0.0
        for p in range(m):
            tr += A[p, p]
            for r in range(p):
                A[p, r] = A[r, p]
        for p in range(m):
            A[p, p] += 1e-10 * tr + 1e-300
        # Gaussian elimination with partial pivoting
        singular = False
        for c in range(m):
            piv = c
            big = abs(A[c, c])
            for r in range(c + 1, m):
                if abs(A[r, c]) > big:
                    big = abs(A[r, c])
                    piv = r
            if not big > 0:
                singular = True
                break
            if piv != c:
                for r in range(m):
                    A[c, r], A[piv, r] = A[piv, r], A[c, r]
                b[c], b[piv] = b[piv], b[c]
            for r in range(c + 1, m):
                f = A[r, c] / A[c, c]
                if f != 0.0:
                    for t in range(c, m):
                        A[r, t] -= f * A[c, t]
                    b[r] -= f * b[c]
        if singular:
            continue
        for c in range(m - 1, -1, -1):
            acc = b[c]
            for t in range(c + 1, m):
                acc -= A[c, t] * b[t]
            b[c] = acc / A[c, c]
        gx = b[1] / s
        gy = b[2] / s
        nx = frame[i, 0] - gx * t1[i, 0] - gy * t2[i, 0]
        ny = frame[i, 1] - gx * t1[i, 1] - gy * t2[i, 1]
        nz = frame[i, 2] - gx * t1[i, 2] - gy * t2[i, 2]
        norm = np.sqrt(nx * nx + ny * ny + nz * nz)
        if np.isfinite(norm) and norm > 0:
            out[i, 0] = nx / norm
            out[i, 1] = ny / norm
            out[i, 2] = nz / norm
        m2 = 0.0
        m4 = 0.0
        sw = 0.0
        for j in range(K):
            u = us[j] / s
            v = vs[j] / s
            fit = 0.0
            for p in range(m):
                fit += b[p] * u ** ea[p] * v ** eb[p]
            e = zs[j] - fit
            w = weights[i, j] if use_w else 1.0
            m2 += w * e * e
            m4 += w * e * e * e * e
            sw += w
        residual[i] = np.sqrt(m2 / max(sw, 1e-300)) / s
        kurtosis[i] = m4 * sw / max(m2 * m2, 1e-300) if m2 > 0 else 3.0


def jet_fit_numpy(pts: np.ndarray, neighbors: np.ndarray, frame: np.ndarray, degree: int | np.ndarray, weights: np.ndarray | None = None,
                  residual: np.ndarray | None = None, centers: np.ndarray | None = None, kurtosis: np.ndarray | None = None) -> np.ndarray:
    """The numpy twin of :func:`jet_fit` (batched solves), also used when the kernels are off.

    ``degree`` is an int or a per-particle int array (0 keeps the frame normal);
    ``weights`` (N, k) zero out neighbours. Rows are batched by degree. Row ``r`` is
    centred on ``pts[r]``, or on ``centers[r]`` when given (fits of a subset of rows).
    ``residual`` (N,) receives the weighted RMS residual over the fit radius, ``kurtosis`` (N,)
    the weighted ``mean(r^4) / mean(r^2)^2`` of the residuals (3 for Gaussian noise, near 1 for
    two layers: the two sides of a part thinner than the neighbourhood).
    """
    centers = pts if centers is None else centers
    N = frame.shape[0]
    degs = np.broadcast_to(np.asarray(degree, dtype=np.int64), (N,))
    out = frame.copy()
    t1, t2 = tangents(frame)
    for d in np.unique(degs):
        if d <= 0:
            continue
        rows = np.flatnonzero(degs == d)
        for lo in range(0, rows.size, 20000):  # bound the (rows, k, m) temporaries
            r = rows[lo : lo + 20000]
            local = pts[neighbors[r]] - centers[r, None, :]
            x = np.einsum("nki,ni->nk", local, t1[r])
            y = np.einsum("nki,ni->nk", local, t2[r])
            z = np.einsum("nki,ni->nk", local, frame[r])
            s = np.sqrt((x * x + y * y).max(axis=1, keepdims=True))
            s = np.where(s > 0, s, 1.0)
            u, v = x / s, y / s
            mons = _monomials(int(d))
            V = np.stack([u**a * v**b for a, b in mons], axis=2)
            w = np.ones_like(u) if weights is None else weights[r]
            Vw = V * w[..., None]
            A = np.matmul(Vw.transpose(0, 2, 1), V)
            rhs = np.matmul(Vw.transpose(0, 2, 1), z[..., None])[..., 0]
            tr = np.trace(A, axis1=1, axis2=2)
            A += (1e-10 * tr + 1e-300)[:, None, None] * np.eye(len(mons))
            c = np.linalg.solve(A, rhs[..., None])[..., 0]
            gx = c[:, mons.index((1, 0))] / s[:, 0]
            gy = c[:, mons.index((0, 1))] / s[:, 0]
            n = frame[r] - gx[:, None] * t1[r] - gy[:, None] * t2[r]
            ok = np.all(np.isfinite(n), axis=1)
            out[r[ok]] = unit(n[ok])
            if residual is not None or kurtosis is not None:
                res = z - np.matmul(V, c[..., None])[..., 0]
            if residual is not None:
                residual[r] = np.sqrt((w * res * res).sum(axis=1) / np.maximum(w.sum(axis=1), 1e-300)) / s[:, 0]
            if kurtosis is not None:
                m2 = (w * res**2).sum(axis=1)
                m4 = (w * res**4).sum(axis=1) * w.sum(axis=1)
                kurtosis[r] = np.where(m2 > 0, m4 / np.maximum(m2 * m2, 1e-300), 3.0)
    return out


def distance_weights(pts: np.ndarray, neighbors: np.ndarray, alpha: float | np.ndarray | None = None) -> np.ndarray:
    """Gaussian weights ``exp(-alpha (r_j / r_max)^2)`` of the neighbours of every row (scale-free).

    ``alpha``: a number, or one per row (shape (N,))."""
    alpha = tuning.JET_WEIGHT if alpha is None else alpha
    r2 = np.einsum("nki,nki->nk", pts[neighbors] - pts[neighbors[:, :1]], pts[neighbors] - pts[neighbors[:, :1]])
    rmax = r2.max(axis=1, keepdims=True)
    return np.exp(-np.reshape(alpha, (-1, 1)) * r2 / np.where(rmax > 0, rmax, 1.0))


def sharpened_weights(pts: np.ndarray, neighbors: np.ndarray, frame: np.ndarray, weights: np.ndarray, residual2: np.ndarray) -> np.ndarray:
    """Weights of the step-5 refit: sharper where the base fit's residual is bias, not noise.

    ``residual2``: the relative residual of the degree-2 fit with ``weights`` in the frames of
    ``frame``; the same neighbours are fitted at degree 3 in the same frames. Where the residual
    ratio ``rho = res3 / res2`` (median over the row's neighbours) is small, the residual is
    structure that a higher degree explains (a coarsely sampled, strongly curved part, where the
    neighbourhood is too wide: bias), and the Gaussian exponent rises from ``tuning.JET_WEIGHT``
    (``rho`` above ``tuning.SHARP_RHO[1]``) to ``tuning.SHARP_WEIGHT`` (below ``tuning.SHARP_RHO[0]``), linearly
    between. Noise leaves ``rho`` near 0.8 (0.80-0.82 median, 0.68-0.76 at the 10th
    percentile, on spheres with noise of 0.01-0.3 spacings), so noisy clouds keep the wide
    weights. Where the sharply weighted neighbours spread like a line (``tuning.SHARP_LINE``: the
    rows of a ring- or scan-line-sampled cloud) the base weights stay. Scale-free, so the
    order on smooth surfaces is kept (docs/normals.md, step 5).
    """
    res3 = np.zeros(pts.shape[0])
    jet_fit(pts, neighbors, frame, 3, weights=weights, residual=res3)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(residual2 > 0, res3 / residual2, 1.0)
    rho = np.median(rho[neighbors], axis=1)
    lo, hi = tuning.SHARP_RHO
    alpha = tuning.JET_WEIGHT + (tuning.SHARP_WEIGHT - tuning.JET_WEIGHT) * np.clip((hi - rho) / (hi - lo), 0.0, 1.0)
    sharp = distance_weights(pts, neighbors, alpha)
    # rows (scan lines, meridian circles): the sharper weights fall on the particle's own row,
    # whose plane the fit would return; keep the base weights where their spread is line-like
    L = pts[neighbors] - pts[:, None, :]
    L -= np.einsum("nk,nki->ni", sharp, L)[:, None, :] / sharp.sum(axis=1)[:, None, None]
    ev = np.linalg.eigvalsh(np.einsum("nk,nki,nkj->nij", sharp, L, L))
    with np.errstate(divide="ignore", invalid="ignore"):
        line = ~(ev[:, 1] >= tuning.SHARP_LINE * ev[:, 2])
    return np.where(line[:, None], weights, sharp)


def refit(pts: np.ndarray, neighbors: np.ndarray, normals: np.ndarray, degree: int | np.ndarray, iterations: int | None = None,
          threshold: float | None = None, residual: np.ndarray | None = None, weights: np.ndarray | None = None) -> np.ndarray:
    """Refit with only the neighbours whose oriented normal agrees (``n_i . n_j > threshold``)."""
    iterations = tuning.REFIT_ITERATIONS if iterations is None else iterations
    threshold = tuning.REFIT_DOT if threshold is None else threshold
    need = n_coefficients(degree) + 2
    n = normals
    for _ in range(iterations):
        dots = np.einsum("nkj,nj->nk", n[neighbors], n)
        w = (dots > threshold).astype(np.float64)
        w[:, 0] = 1.0  # the particle itself (first neighbour)
        count = w.sum(axis=1)
        deg = np.where(count >= need, degree, np.where(count >= 5, 1, 0))
        n = jet_fit(pts, neighbors, n, deg, w if weights is None else w * weights, residual=residual)
    return n


def high_order(pts: np.ndarray, neighbors: np.ndarray, base: np.ndarray, base_residual: np.ndarray, degree: int | np.ndarray,
               refine: bool) -> tuple[np.ndarray, np.ndarray]:
    """Degree-``degree`` fits started from the oriented ``base`` (degree-2) normals, guarded.

    The high-degree normal replaces the base one where the two agree within
    ``tuning.GUARD_DEGREES`` (smooth, well-resolved parts: the error drops from ``O(h^2)``
    to ``O(h^degree)``) or where its fit residual is below ``tuning.GUARD_RESIDUAL`` times the
    base fit's (one face of a crease found by the wider neighbourhood). Elsewhere, on
    thin or coarsely sampled parts where the wider neighbourhood of a high-degree fit
    reaches across, the base normal is kept (docs/normals.md, step 6).
    """
    res = np.zeros(pts.shape[0])
    if refine:
        hi = refit(pts, neighbors, base, degree, residual=res)
    else:
        hi = jet_fit(pts, neighbors, base, degree, residual=res)
    dot = np.einsum("ij,ij->i", hi, base)
    close = np.abs(dot) > np.cos(np.radians(tuning.GUARD_DEGREES))
    one_sided = ~close & (res < tuning.GUARD_RESIDUAL * base_residual)
    return np.where((close | one_sided)[:, None], hi, base), one_sided


def check_degree(degree: int | np.ndarray) -> int:
    if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)):
        raise TypeError(f"degree must be an integer from 1 to 4, got {type(degree).__name__} {degree!r}")
    if not 1 <= int(degree) <= 4:
        raise ValueError(f"degree must be an integer from 1 to 4, got {degree!r}")
    return int(degree)


def check_k(k: int, N: int, degree: int | np.ndarray | None = None) -> int:
    k = check_int("k", k, minimum=3)
    if degree is not None and k < n_coefficients(degree) + 2:
        raise ValueError(f"k must be at least {n_coefficients(degree) + 2} for a degree-{degree} jet fit, got {k}")
    if k > N:
        raise ValueError(f"k must be at most the number of points {N}, got {k}")
    return k


def pca_normals(points: ArrayLike, k: int = tuning.DEFAULT_K, *, neighbors: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Unoriented PCA normals and their confidence.

    Parameters
    ----------
    points : array_like (N, 3), or anything point-like (a PointCloud, Surface, path, ...)
    k : int
        Neighbours per particle, itself included (at least 3, below N).
    neighbors : ndarray of int, shape (N, k), optional
        Precomputed neighbour indices (overrides ``k``).

    Returns
    -------
    normals : ndarray, shape (N, 3)
        Unit normals with the sign convention of ``numpy.linalg.eigh`` (arbitrary).
    confidence : ndarray, shape (N,)
        ``1 - lambda_0 / lambda_1`` in [0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> p = np.c_[rng.uniform(size=(200, 2)), np.zeros(200)]     # the plane z = 0
    >>> n, c = pca_normals(p, k=10)
    >>> float(np.abs(n[:, 2]).min().round(6)), float(c.min().round(6))
    (1.0, 1.0)
    """
    pts = point_array(points)
    if neighbors is None:
        k = check_int("k", k, minimum=3)
        if k > pts.shape[0]:
            raise ValueError(f"k must be at most the number of points {pts.shape[0]}, got {k}")
        _, neighbors = knn(pts, k)
    neighbors = np.asarray(neighbors)
    w, v = covariance(pts, neighbors)
    return v[:, :, 0], shape_confidence(w)


def jet_normals(points: ArrayLike, k: int | None = None, *, degree: int = 2, neighbors: ArrayLike | None = None) -> np.ndarray:
    """Unoriented normals of local polynomial (jet) fits.

    Parameters
    ----------
    points : array_like (N, 3), or anything point-like (a PointCloud, Surface, path, ...)
    k : int, optional
        Neighbours per particle, itself included (default :data:`tuning.DEFAULT_JET_K`
        of the degree; at least the number of coefficients plus 2).
    degree : int
        Total degree of the height function, 1 to 4.
    neighbors : ndarray of int, shape (N, k), optional
        Precomputed neighbour indices, itself first (overrides ``k``).

    Returns
    -------
    ndarray, shape (N, 3)
        Unit normals (signs arbitrary); error ``O(h^degree)`` on smooth surfaces.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph.reference import shapes
    >>> c = shapes.sphere(2000)
    >>> n = jet_normals(c.points, degree=2)
    >>> bool(np.abs(np.einsum("ij,ij->i", n, c.normals)).min() > np.cos(np.radians(0.05)))
    True
    """
    pts = point_array(points)
    degree = check_degree(degree)
    if neighbors is None:
        k = tuning.DEFAULT_JET_K[degree] if k is None else k
        k = check_k(k, pts.shape[0], degree)
        _, neighbors = knn(pts, k)
    neighbors = np.asarray(neighbors)
    _, v = covariance(pts, neighbors[:, : min(tuning.PCA_K, neighbors.shape[1])])
    return jet_fit(pts, neighbors, v[:, :, 0], degree)


def jet_fit_per_row(pts: np.ndarray, neighbors: np.ndarray, frame: np.ndarray, ks: np.ndarray, degree: int = 2,
                    residual: np.ndarray | None = None) -> np.ndarray:
    """Degree-``degree`` jet normals with a neighbourhood size of its own for every row (uniform weights).

    ``ks`` (N,) holds each row's ``k`` (at most ``neighbors.shape[1]``); rows sharing a ``k`` are
    fitted together, each on its own ``k`` nearest, in the tangent frame of ``frame``.
    """
    out = frame.copy()
    for k in np.unique(ks):
        rows = np.flatnonzero(ks == k)
        res = None if residual is None else np.zeros(rows.size)
        out[rows] = jet_fit(pts, neighbors[rows, : int(k)], frame[rows], degree, residual=res, centers=pts[rows])
        if residual is not None:
            residual[rows] = res
    return out


def smooth_normals(pts: np.ndarray, neighbors: np.ndarray, normals: np.ndarray, strength: np.ndarray,
                   degrees: float | None = None) -> np.ndarray:
    """Normals averaged over their neighbours with a similar normal line (bilateral, sign-free).

    Neighbour ``j`` of particle ``i`` weighs ``exp(-2 (r_ij / r_k)^2) exp(-((1 - |n_i . n_j|) /
    (1 - cos degrees))^2)``, its normal taken with the sign of ``n_i``: noise averages out while
    creases (normals turning by more than ``degrees``) are kept. ``strength`` (N,) in [0, 1] blends
    each particle's own normal (0) with the average (1).
    """
    degrees = tuning.SMOOTH_DEGREES if degrees is None else degrees
    nb = normals[neighbors]
    d = np.einsum("nkj,nj->nk", nb, normals)
    nb = nb * np.where(d < 0, -1.0, 1.0)[..., None]
    L = pts[neighbors] - pts[:, None, :]
    r2 = np.einsum("nkj,nkj->nk", L, L)
    rmax = r2.max(axis=1, keepdims=True)
    ws = np.exp(-2.0 * r2 / np.where(rmax > 0, rmax, 1.0))
    wn = np.exp(-(((1.0 - np.abs(d)) / (1.0 - np.cos(np.radians(degrees)))) ** 2))
    avg = unit(np.einsum("nk,nkj->nj", ws * wn, nb))
    return unit((1.0 - strength)[:, None] * normals + strength[:, None] * avg)
