"""Smoothing and denoising a point cloud: :func:`smooth`.

``method="jet"`` (default)
    Each particle moves along its normal onto the quadric fitted to the points around it
    (:func:`jet_heights`, Gaussian weights ``exp(-(2 d / r)^2)`` within the radius ``r``), and
    the normal is refitted from the quadric's slope; ``iterations`` passes. Noise normal to the
    surface is averaged over the fit's points, the surface's own shape is kept to the
    quadric's order, and particles do not drift along the surface.

    *Radius.* With ``scale=None`` and ``features=True`` each particle fits over ``r_i = JET_WIDTH * s_i``, ``s_i`` the
    geometric mean, over its 24 nearest points, of their distance to their own 24th nearest
    point: every fit holds about the same number of points, so densely sampled parts (where
    a model's detail is) get narrow fits and sparse flat parts wide ones. The radii shrink by
    ``min(1, (sigma / (NOISE_REF h))^(1/3))`` on a cloud whose noise ``sigma`` (below) is under
    ``NOISE_REF`` mean spacings ``h``: a quadric's misfit grows with its radius and the noise to
    average falls, so a clean cloud is fitted narrowly and barely moves. A given ``scale`` is
    the radius of every fit; with ``features=False`` it defaults to ``4 h`` (plain fits over
    the narrow radii of densely sampled sharp edges round them; measured in docs/geometry.md).

    *Wider where the surface allows* (``scale=None``, ``features=True``). A fit of a fixed
    number of points removes a fixed share of the noise, whatever the density; where the
    surface is smooth over more than ``r_i`` a wider fit removes more. Each particle takes
    ``WIDER * r_i`` instead where plain fits over both radii say the wider one is the more
    accurate: their heights differ by noise of a known variance plus the difference of their
    biases; averaged over the particle's neighbours (a bias varies slowly, the noise does not),
    that difference may exceed the noise by at most half the variance the wider fit saves.
    Thin parts, bends and the creases of a polyhedral surface keep the narrow fits; a densely
    sampled smooth surface gets the wide ones.

    *Rims* (``scale=None``, ``features=True``). A particle on the boundary of an open surface sees
    its neighbours on one side only: its fit holds half the points and evaluates the quadric at
    the edge of the data, where the height's variance is about five times that at the centre of a
    full disk. :func:`rim_offset` measures how one-sided each neighbourhood is (the offset of the
    weighted centroid of the neighbours in the tangent plane, in fit radii: about 0.05 inside a
    random sample, 0.25 on a rim); from ``RIM_RANGE[0]`` to ``RIM_RANGE[1]`` the radius grows
    linearly to ``RIM_WIDER`` times its value (a half-disk of twice the radius holds four times the
    points, which brings the variance back to within 1.4 times that of an inside fit). The same
    bias test as for the wider fits (below) decides, on the rim particles and pooled along the rim,
    with the break-even bound (the squared bias at most the variance saved): where the rim bends
    within the wider radius the fit keeps its radius. Where another piece of surface continues
    past a boundary, the neighbourhood is not one-sided and nothing changes.

    *Noise level.* Each pass first fits plain quadrics; ``sigma`` is the median of their
    residuals' weighted RMS (at least ``0.02 h``): the noise normal to the surface on a noisy
    cloud, the quadrics' misfit on a clean one.

    *Features* (``features=True``, the default): the fit's weights are bilateral in the normal
    direction, ``exp(-(z / (2 sigma))^2 / 2)`` of the height ``z`` of each point above the
    particle's tangent plane, then twice ``exp(-(e / (2 sigma))^2 / 2)`` of the previous fit's
    residuals ``e``. A point more than a few noise widths off the particle's own sheet (across
    a sharp edge, the other side of a thin part) drops out of the fit, so edges stay sharp and
    thin parts keep their thickness.
``method="flow"``
    Implicit mean-curvature flow on the stable Laplacian of a
    :class:`~manifold_sph.Surface`: ``Y = (M + tau K)^-1 M X`` with ``tau = scale^2 / 4``,
    its displacement ``d = (Y - X) . n`` along the normals (no tangential drift), less its own
    smoothed part ``(M + tau K)^-1 M d`` (the flow's shrinking of curved parts, about
    ``2 tau / R`` on a sphere of radius ``R``, is smooth; the noise is not: a Taubin-style
    correction); ``iterations`` steps with the operator factorised once. ``scale`` defaults to ``2 h``.

The spacing ``h`` is the mean distance to the 6 nearest points. Measured in
``benchmarks/geometry.py`` (mean distance to the clean mesh of noisy samples of the test
models, beside CGAL's ``jet_smooth_point_set``) and in docs/geometry.md.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from .._validation import as_field, as_points, check_bool, check_in, check_int, check_positive
from ..exceptions import ManifoldSPHWarning
from .common import SCALE_RANGE, as_cloud_points, check_scale, is_surface
from .jets import mean_spacing, tangent_basis
from .wavefront import pca_normals

if TYPE_CHECKING:
    from ..pointcloud import PointCloud
    from ..surface import Surface

__all__ = [
    "JET_WIDTH", "NOISE_REF", "RIM_RANGE", "RIM_WIDER", "SMOOTH_METHODS", "WIDER", "jet_heights", "local_spacing", "rim_offset", "smooth",
]

SMOOTH_METHODS = ("jet", "flow")
#: Fit radius of ``smooth(scale=None)`` in units of the local spacing :func:`local_spacing`.
JET_WIDTH = 1.7
#: Noise level (in mean spacings) below which ``smooth(scale=None)`` narrows its fits.
NOISE_REF = 0.4
#: Ratio of the wider fit radius :func:`smooth` takes where the surface allows (``_wider_fits``).
WIDER = float(np.sqrt(2.0))
#: Nearest points that set the local spacing.
_LOCAL_K = 24
_ROWS = 2048  # particles a chunk
_BILATERAL = 2.0  # width of the bilateral weights, in noise levels
_PASSES = 2  # reweighted refits after the bilateral one
_POOL = 2.0  # _wider_fits averages its test over this many fit radii
_BIAS_SHARE = 0.5  # _wider_fits: largest squared bias accepted, as a share of the variance the wider fit saves
#: Radius ratio of the fits of particles on a rim (one-sided neighbourhoods, :func:`rim_offset`).
RIM_WIDER = 2.0
#: :func:`rim_offset` below which a neighbourhood counts as two-sided, and from which as fully one-sided.
RIM_RANGE = (0.1, 0.2)
_RIM_SHARE = 1.0  # _wider_fits on a rim: accepted up to a squared bias equal to the variance saved (break-even)


def local_spacing(points: np.ndarray, tree: cKDTree | None = None, k: int = _LOCAL_K) -> np.ndarray:
    """Local sampling length of each particle, shape (N,).

    The geometric mean, over the particle's ``k`` nearest points (itself included), of their
    distance to their own ``k``-th nearest point: about ``sqrt(k / (pi rho))`` for a surface
    density ``rho``, averaged so that noise in the positions barely moves it.
    """
    points = as_points("points", points)
    k = min(check_int("k", k, minimum=1), points.shape[0] - 1)
    tree = cKDTree(points) if tree is None else tree
    d, idx = tree.query(points, k=k + 1, workers=-1)
    tiny = np.finfo(float).tiny
    return np.exp(np.log(np.maximum(d[:, -1], tiny))[idx].mean(axis=1))


def _fit_inputs(points: ArrayLike, normals: ArrayLike, radius: ArrayLike,
                count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The checked arrays of a local fit: points (N, 3), normals (N, 3), positive radii (N,), count <= N."""
    points = as_points("points", points)
    n = points.shape[0]
    normals = as_field("normals", normals, n, 3)
    radius = as_field("radius", radius, n)
    if np.any(radius <= 0):
        raise ValueError(f"radius must be positive, got minimum {radius.min():g}")
    return points, normals, radius, min(check_int("count", count, minimum=1), n)


def jet_heights(
    points: np.ndarray,
    normals: np.ndarray,
    radius: np.ndarray,
    *,
    count: int,
    sigma: float | None = None,
    tree: cKDTree | None = None,
    rows: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quadric fits of the heights of each particle's neighbours, in its frame ``(u, v, n)``.

    The heights ``z = n_i . (x_j - x_i)`` of the ``count`` nearest points within ``radius[i]``
    are fitted by weighted least squares as ``c0 + c1 y1 + c2 y2 + (c3 y1^2 + 2 c4 y1 y2 + c5 y2^2) / 2``
    in the tangent coordinates ``y`` divided by the radius, with weights
    ``exp(-(2 |x_j - x_i| / radius[i])^2)``; with ``sigma`` given, times bilateral weights in the
    height and then in the residuals (module notes).

    Parameters
    ----------
    points, normals : ndarray, shape (N, 3)
        Unit normals.
    radius : ndarray, shape (N,)
        Fit radius of each particle.
    count : int
        Nearest points searched per particle.
    sigma : float, optional
        Noise level for the bilateral weights (plain fits without).
    tree : cKDTree, optional
        Of ``points``.
    rows : ndarray of int, optional
        The particles to fit (default all); the others get zeros.

    Returns
    -------
    height : ndarray, shape (N,)
        ``c0``, the fitted surface's height above the particle.
    slope : ndarray, shape (N, 2)
        ``(c1, c2)`` per unit length, along ``u`` and ``v`` of :func:`~manifold_sph.geometry.jets.tangent_basis`.
    rms : ndarray, shape (N,)
        Weighted RMS of the fit's residuals (a length).
    """
    points, normals, radius, count = _fit_inputs(points, normals, radius, count)
    n = points.shape[0]
    if sigma is not None:
        sigma = check_positive("sigma", sigma)
    tree = cKDTree(points) if tree is None else tree
    which = np.arange(n) if rows is None else np.asarray(rows, dtype=np.int64).reshape(-1)
    if which.size and (which.min() < 0 or which.max() >= n):
        raise ValueError(f"rows must index the {n} points, got indices from {which.min()} to {which.max()}")
    u, v = tangent_basis(normals)
    height, rms, slope = np.zeros(n), np.zeros(n), np.zeros((n, 2))
    chunk = max(1, min(_ROWS, 2_000_000 // count))  # (chunk, count, 6) arrays of at most 100 MB
    for lo in range(0, which.size, chunk):
        rows = which[lo : lo + chunk]
        dist, idx = tree.query(points[rows], k=count, workers=-1)
        dist, idx = dist.reshape(len(rows), count), idx.reshape(len(rows), count)
        r = radius[rows][:, None]
        off = points[idx] - points[rows][:, None, :]
        y1 = np.einsum("rkd,rd->rk", off, u[rows]) / r
        y2 = np.einsum("rkd,rd->rk", off, v[rows]) / r
        z = np.einsum("rkd,rd->rk", off, normals[rows])
        A = np.stack([np.ones_like(y1), y1, y2, 0.5 * y1 * y1, y1 * y2, 0.5 * y2 * y2], axis=-1)
        w0 = np.exp(-((2.0 * dist / r) ** 2)) * (dist <= r)
        res = z  # the bilateral weights of the first fit: the heights above the particle's tangent plane
        for it in range(1 + (0 if sigma is None else _PASSES)):
            w = w0 if sigma is None else w0 * np.exp(-0.5 * (res / (_BILATERAL * sigma)) ** 2)
            AtW = A * w[..., None]
            G = np.einsum("rki,rkj->rij", AtW, A)
            G += (1e-10 * np.trace(G, axis1=1, axis2=2) + 1e-300)[:, None, None] * np.eye(6)
            c = np.linalg.solve(G, np.einsum("rki,rk->ri", AtW, z)[..., None])[..., 0]
            res = z - np.einsum("rki,ri->rk", A, c)
        sw = w.sum(axis=1)
        ok = (sw > 1e-6) & np.all(np.isfinite(c), axis=1)  # a fit with (almost) no weight leaves its particle in place
        height[rows] = np.where(ok, c[:, 0], 0.0)
        slope[rows] = np.where(ok[:, None], c[:, 1:3] / r, 0.0)
        rms[rows] = np.where(ok, np.sqrt(np.einsum("rk,rk->r", w, res * res) / np.maximum(sw, 1e-300)), 0.0)
    return height, slope, rms


def rim_offset(
    points: np.ndarray, normals: np.ndarray, radius: np.ndarray, *, count: int, tree: cKDTree | None = None
) -> np.ndarray:
    """How one-sided each particle's neighbourhood is, shape (N,): the offset of its neighbours'
    weighted centroid in the tangent plane, in units of the radius.

    The weights are those of :func:`jet_heights` (``exp(-(2 d / r)^2)`` over the ``count`` nearest
    points within ``r = radius[i]``). Inside a surface the centroid sits on the particle up to the
    sampling's scatter (median 0.05, 95th percentile 0.10 on uniformly random samples at the default
    radius); a particle on a rim sees a half-disk, whose centroid lies about a quarter of the radius
    inward. The ratio does not depend on the units, the density or the orientation.
    """
    points, normals, radius, count = _fit_inputs(points, normals, radius, count)
    n = points.shape[0]
    tree = cKDTree(points) if tree is None else tree
    u, v = tangent_basis(normals)
    m = np.zeros(n)
    chunk = max(1, min(_ROWS, 2_000_000 // count))
    for lo in range(0, n, chunk):
        rows = np.arange(lo, min(n, lo + chunk))
        dist, idx = tree.query(points[rows], k=count, workers=-1)
        dist, idx = dist.reshape(len(rows), count), idx.reshape(len(rows), count)
        r = radius[rows][:, None]
        off = points[idx] - points[rows][:, None, :]
        w = np.exp(-((2.0 * dist / r) ** 2)) * (dist <= r)
        sw = np.maximum(w.sum(axis=1), 1e-300)
        c1 = np.einsum("rk,rkd,rd->r", w, off, u[rows]) / sw
        c2 = np.einsum("rk,rkd,rd->r", w, off, v[rows]) / sw
        m[rows] = np.hypot(c1, c2) / radius[rows]
    return m


def _wider_fits(
    points: np.ndarray,
    normals: np.ndarray,
    radius: np.ndarray,
    *,
    factor: float | np.ndarray,
    count: int,
    tree: cKDTree | None = None,
    rows: np.ndarray | None = None,
    share: float = _BIAS_SHARE,
) -> np.ndarray:
    """Where a plain quadric fit over ``factor * radius`` is as accurate as one over ``radius``, shape (N,) bool.

    Both fits are computed on the same neighbours. Their heights ``c0`` differ by
    ``D = (a_w - a_n) . z``, ``a_n`` and ``a_w`` the fits' influence vectors (``c0 = a . z``): pure
    noise of variance ``sigma^2 |a_w - a_n|^2`` plus the difference of their biases. ``D^2`` and that
    variance are averaged over the particle's neighbours within ``2 radius`` (Gaussian weights
    ``exp(-(d / radius)^2)``): a bias varies slowly along the surface, the noise does not, so the
    average sees biases well below one fit's scatter (the neighbours' ``D`` share most of their
    points: the ball of twice the radius holds about four independent ones). The wider fit is
    kept where the averaged ``D^2`` is at most 1.5 times the averaged noise variance: its squared
    bias is then at most half the variance it saves, ``|a_n|^2 - |a_w|^2 ~ |a_w - a_n|^2``, so it
    is more accurate with a margin for the scatter of the test itself (at twice the variance the
    two fits would break even). ``sigma`` is the median residual noise of the narrow fits
    (degrees of freedom taken off). ``factor`` may differ per particle; with ``rows`` only those
    particles are tested (the others are False), pooling over their neighbours among ``rows``.
    """
    n = points.shape[0]
    count = min(count, n)
    tree = cKDTree(points) if tree is None else tree
    fac = np.broadcast_to(np.asarray(factor, dtype=float), (n,))
    which = np.arange(n) if rows is None else np.asarray(rows, dtype=np.int64)
    tested = np.zeros(n, dtype=bool)
    tested[which] = True
    if not which.size:
        return tested
    u, v = tangent_basis(normals)
    D = np.zeros(n)
    var = np.zeros(n)
    noise = np.zeros(n)
    chunk = max(1, min(_ROWS, 2_000_000 // count))
    for lo in range(0, which.size, chunk):
        rows = which[lo : lo + chunk]
        dist, idx = tree.query(points[rows], k=count, workers=-1)
        dist, idx = dist.reshape(len(rows), count), idx.reshape(len(rows), count)
        r = (fac[rows] * radius[rows])[:, None]
        off = points[idx] - points[rows][:, None, :]
        y1 = np.einsum("rkd,rd->rk", off, u[rows]) / r
        y2 = np.einsum("rkd,rd->rk", off, v[rows]) / r
        z = np.einsum("rkd,rd->rk", off, normals[rows])
        A = np.stack([np.ones_like(y1), y1, y2, 0.5 * y1 * y1, y1 * y2, 0.5 * y2 * y2], axis=-1)
        infl = []
        for rr in (r / fac[rows][:, None], r):
            w = np.exp(-((2.0 * dist / rr) ** 2)) * (dist <= rr)
            AtW = A * w[..., None]
            G = np.einsum("rki,rkj->rij", AtW, A)
            G += (1e-10 * np.trace(G, axis1=1, axis2=2) + 1e-300)[:, None, None] * np.eye(6)
            x = np.linalg.solve(G, np.broadcast_to(np.eye(6)[:, :1], G.shape[:1] + (6, 1)))[..., 0]  # G^-1 e0
            a = w * np.einsum("rki,ri->rk", A, x)  # c0 = a . z
            infl.append(a)
            if len(infl) == 1:
                c = np.linalg.solve(G, np.einsum("rki,rk->ri", AtW, z)[..., None])[..., 0]
                res = z - np.einsum("rki,ri->rk", A, c)
                sw = np.maximum(w.sum(axis=1), 1e-300)
                dof = np.maximum(sw - np.einsum("rk,rk->r", w, w) / sw * 6.0, 1.0)
                noise[rows] = np.einsum("rk,rk->r", w, res * res) / dof
        diff = infl[1] - infl[0]
        D[rows] = np.einsum("rk,rk->r", diff, z)
        var[rows] = np.einsum("rk,rk->r", diff, diff)
    sigma2 = float(np.median(noise[which]))
    T = np.zeros(n)
    E = np.zeros(n)
    k_n = min(n, max(12, int(np.ceil(count * _POOL**2 / float(fac[which].min()) ** 2))))
    chunk = max(1, min(_ROWS, 2_000_000 // k_n))
    for lo in range(0, which.size, chunk):
        rows = which[lo : lo + chunk]
        dist, idx = tree.query(points[rows], k=k_n, workers=-1)
        dist, idx = dist.reshape(len(rows), k_n), idx.reshape(len(rows), k_n)
        rr = _POOL * radius[rows][:, None]
        w = np.exp(-((2.0 * dist / rr) ** 2)) * (dist <= rr) * tested[idx]
        sw = np.maximum(w.sum(axis=1), 1e-300)
        T[rows] = np.einsum("rk,rk->r", w, D[idx] ** 2) / sw
        E[rows] = np.einsum("rk,rk->r", w, var[idx]) / sw
    return tested & (T <= (1.0 + share) * sigma2 * E)


def _orient(new: np.ndarray, like: np.ndarray | None) -> np.ndarray:
    if like is None:
        return new
    return new * np.where(np.einsum("nd,nd->n", new, like) < 0, -1.0, 1.0)[:, None]


def smooth(
    cloud: Surface | PointCloud | ArrayLike,
    *,
    method: str = "jet",
    scale: float | None = None,
    iterations: int = 3,
    features: bool = True,
) -> PointCloud:
    """A smoothed (denoised) copy of a cloud, as a :class:`~manifold_sph.PointCloud` (module notes).

    Parameters
    ----------
    cloud : Surface, PointCloud or array_like of shape (N, 3)
    method : {"jet", "flow"}
    scale : float, optional
        Length over which the surface is fitted (``"jet"``: the radius of every fit) or diffused
        (``"flow"``): noise shorter than it is removed. Default: ``"jet"`` a radius per particle
        from its local spacing and the cloud's noise level (module notes; ``4 h`` with
        ``features=False``), ``"flow"`` ``2 h``, ``h`` the mean spacing.
    iterations : int
        Passes (``"jet"``) or implicit steps (``"flow"``).
    features : bool
        ``"jet"``: fits bilateral in the normal direction, which keep sharp edges, corners and thin
        parts (default); ignored by ``"flow"``.

    Returns
    -------
    PointCloud
        The moved points; normals refitted (oriented like the input's) when the input had normals.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph.reference import shapes
    >>> c = shapes.sphere(4000)
    >>> h = np.sqrt(4 * np.pi / 4000)
    >>> noisy = c.points + 0.5 * h * np.random.default_rng(0).standard_normal((4000, 3))
    >>> out = smooth(noisy)
    >>> before = np.abs(np.linalg.norm(noisy, axis=1) - 1).mean()
    >>> after = np.abs(np.linalg.norm(out.points, axis=1) - 1).mean()
    >>> bool(after < before / 3)
    True
    """
    from ..pointcloud import PointCloud

    method = check_in("method", method, SMOOTH_METHODS)
    iterations = check_int("iterations", iterations, minimum=1)
    features = check_bool("features", features)
    if scale is not None:
        scale = check_positive("scale", scale)
    points, normals = as_cloud_points(cloud)
    if points.shape[0] < 12:
        raise ValueError(f"cloud must hold at least 12 points to be smoothed, got {points.shape[0]}")
    centre, L = check_scale(points, "smooth", SCALE_RANGE)
    P = (points - centre) / L  # unit extent: the result does not depend on the units
    tree = cKDTree(P)
    h = mean_spacing(P, tree)
    if method == "flow":
        out, nrm = _flow(cloud if is_surface(cloud) else None, P, normals, (2.0 * h if scale is None else scale / L), iterations)
    else:
        out, nrm = _jets(P, normals, tree, h, None if scale is None else scale / L, iterations, features)
    return PointCloud(out * L + centre, _orient(nrm, normals) if normals is not None else None)


def _jets(P, normals, tree, h, scale, iterations, features):
    """``method="jet"`` on the cloud ``P`` of unit extent (module notes): moved points and normals."""
    n = P.shape[0]
    nrm = normals if normals is not None else pca_normals(P, tree.query(P, k=min(16, n), workers=-1)[1])
    if scale is None and not features:
        scale = 4.0 * h
    if scale is None:
        radius = JET_WIDTH * local_spacing(P, tree)
        count = int(min(n, np.ceil(1.6 * (_LOCAL_K + 1) * JET_WIDTH**2)))
        wide_count = int(min(n, np.ceil(count * WIDER**2)))
    else:
        radius = np.full(n, scale)
        count = int(min(n, max(12, np.ceil(1.2 * np.pi * scale * scale / (0.9 * h * h)))))
    out = P.copy()
    groups: list[tuple[np.ndarray | None, int]] = [(None, count)]  # particles fitted together, and their neighbour count

    def fits(t, sigma):
        d, g, rms = np.zeros(n), np.zeros((n, 2)), np.zeros(n)
        for rows, k in groups:
            if rows is None or rows.size:
                dd, gg, ee = jet_heights(out, nrm, radius, count=k, sigma=sigma, tree=t, rows=rows)
                sel = slice(None) if rows is None else rows
                d[sel], g[sel], rms[sel] = dd[sel], gg[sel], ee[sel]
        return d, g, rms

    for it in range(iterations):
        t = cKDTree(out)
        sigma = None
        if features or (it == 0 and scale is None):
            sigma = max(float(np.median(fits(t, None)[2])), 0.02 * h)
            if it == 0 and scale is None:
                radius = radius * min(1.0, (sigma / (NOISE_REF * h)) ** (1.0 / 3.0))
                if WIDER > 1.0:
                    wide = _wider_fits(out, nrm, radius, factor=WIDER, count=wide_count, tree=t)
                    radius = np.where(wide, WIDER * radius, radius)
                    if wide.any():
                        count = wide_count
                groups = [(None, count)]
                if RIM_WIDER > 1.0:  # one-sided neighbourhoods: wider fits, which hold the points a full disk would
                    lo, hi = RIM_RANGE
                    side = np.clip((rim_offset(out, nrm, radius, count=count, tree=t) - lo) / (hi - lo), 0.0, 1.0)
                    grow = 1.0 + (RIM_WIDER - 1.0) * side
                    rim_count = int(min(n, np.ceil(count * max(1.0, 0.5 * RIM_WIDER**2))))  # a half-disk of RIM_WIDER r
                    tested = np.flatnonzero(side > 0)
                    ok = _wider_fits(out, nrm, radius, factor=grow, count=rim_count, tree=t, rows=tested, share=_RIM_SHARE)
                    grow = np.where(ok, grow, 1.0)
                    radius = radius * grow
                    rim = grow > 1.0
                    if rim.any():
                        groups = [(np.flatnonzero(~rim), count), (np.flatnonzero(rim), rim_count)]
        d, g, _ = fits(t, sigma if features else None)
        u, v = tangent_basis(nrm)
        out = out + d[:, None] * nrm
        new = nrm - g[:, :1] * u - g[:, 1:2] * v
        nrm = _orient(new / np.linalg.norm(new, axis=1)[:, None], nrm)
    return out, nrm


def _flow(surface, P, normals, scale, iterations):
    from ..solvers import spd_solver
    from ..surface import Surface

    if surface is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ManifoldSPHWarning)
            surface = Surface(P, normals)
        K, m, nrm = surface.stiffness_matrix(), np.asarray(surface.mass_matrix().diagonal()), surface.normals
    else:  # the Surface's own operator, in units of the cloud's extent
        L = float(np.max(np.ptp(surface.points, axis=0)))
        K, m, nrm = surface.stiffness_matrix(), np.asarray(surface.mass_matrix().diagonal()) / L**2, surface.normals
    import scipy.sparse as sp

    tau = 0.25 * scale * scale
    solve = spd_solver((sp.diags(m) + tau * K).tocsr()).solve
    X = P.copy()
    for _ in range(iterations):
        Y = np.stack([solve(m * X[:, a]) for a in range(3)], axis=1)
        d = np.einsum("nd,nd->n", Y - X, nrm)
        d -= solve(m * d)  # the smooth part of the displacement is the flow's shrinking, not noise
        X = X + d[:, None] * nrm
    return X, nrm
