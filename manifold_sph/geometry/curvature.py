"""Curvature from points: the shape operator, mean, Gaussian and principal curvatures, at a scale.

- **Pointwise** (``scale=None``). The shape operator is the tangential gradient of the
  unit normal field, ``W = grad_S n``, written in each particle's tangent frame ``(u, v)``
  and symmetrised; it is positive on a sphere with outward normals. Its eigenvalues are
  the principal curvatures ``k1 >= k2``, its determinant the Gaussian curvature ``K`` and
  half its trace the mean curvature ``H``. ``H`` also comes from the Laplacian of the
  coordinates, ``Lap_S x = -2 H n`` (``method="laplacian"``), which needs no derivative
  of the normals. This is accurate on clean clouds (``docs/geometry.md``) and pure noise on
  a noisy scan: derivatives of noisy normals.
- **At a scale** (``scale=r``, a length). A quadric height function
  ``z = c0 + g . y + y^T A y / 2`` is fitted by weighted least squares to the points within
  a radius ``b`` of each particle (Gaussian weights ``exp(-(2 d / b)^2)``), in the particle's
  tangent frame; ``W = -(I + g g^T)^-1 A / sqrt(1 + |g|^2)`` (the sign so that a sphere with
  outward normals is positive). ``b`` is the largest of ``2.5 h, 2.5 sqrt(2) h, ...`` and ``r``
  (not above ``r``) over which the surface is a height function over the tangent plane: at
  most 2 % of the weight on normals turned more than 60 degrees. Where ``b < r`` the fits of
  radius ``b`` are averaged over the points within ``sqrt(r^2 - b^2)`` on the same side
  (``n_j . n_i > 0``), weights ``exp(-(2 d / r)^2)``, each carried to the particle's tangent
  plane by the rotation between the normals (:func:`average_shape_operators`): the
  curvature of the surface smoothed over about ``r``. One quadric over ``r`` cannot fit a ball
  that holds both sides of a thin part or a bend of radius below ``r``; the average of small
  fits can, but its scatter from noise falls only as ``b / r`` below that of the small fits (the
  curvature's lever arm is ``b``, not ``r``), hence the largest ``b`` that still fits.
- **Automatic scale** (``scale="auto"``): the cloud is first denoised
  (:func:`~manifold_sph.geometry.smooth` with its defaults) if it is noisy: if the median
  residual of the quadric fits over ``2.5 h`` exceeds ``AUTO_NOISE`` spacings (a clean cloud's
  residual is the quadric's misfit, 0.05-0.2 spacings on the coarse test models; Gaussian
  noise of 0.3 spacings gives 0.29-0.41). The estimate at each radius ``r`` of the ladder
  ``2.5 h, 3.5 h, 5 h, 7 h, 10 h, 14 h`` is that of ``scale=r`` on the (denoised) points: the fit over
  the largest ladder radius ``b <= r`` over which the surface is a height function, averaged over
  ``sqrt(r^2 - b^2)``. Its standard deviation is the fit's own (from its weights and the noise of
  the raw points, measured by the residuals of the smallest fit) times ``b / r``, the factor for
  Gaussian-weighted averaging over that reach of errors correlated over ``b``: an upper bound, as
  the errors of curvature fits change sign between neighbours and average out faster
  (docs/geometry.md). Per particle the largest radius is taken whose estimate agrees with every
  smaller one within ``AUTO_WIDTH`` standard deviations (the intersection of confidence intervals
  of Lepski's method), and then the median of those picks over the particle's neighbours within
  ``2.5 h``: a bias that ends the ladder grows smoothly over the surface, while a chance exit from
  the intervals, which leaves a particle with the error of a small fit, does not.
  ``h`` is the mean distance to the 6 nearest points.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from .._validation import check_in, check_positive
from .common import SCALE_RANGE, check_scale, check_surface
from .jets import fit_jets, mean_spacing

_ROWS = 1024  # particles a chunk of the averaging

if TYPE_CHECKING:
    from ..surface import Surface

__all__ = [
    "AUTO_NOISE",
    "AUTO_RADII",
    "BASE_RADIUS",
    "CURVATURE_METHODS",
    "average_shape_operators",
    "curvature_method",
    "curvature_scale",
    "gaussian_curvature",
    "mean_curvature",
    "principal_curvatures",
    "shape_operator",
]

CURVATURE_METHODS = ("auto", "normals", "laplacian")
#: Radii of the automatic scale, in units of the mean spacing ``h`` (mean distance to the 6 nearest points).
AUTO_RADII = (2.5, 3.5, 5.0, 7.0, 10.0, 14.0)
#: Smallest radius of the quadric fits of ``scale=r``, in mean spacings (``r`` itself if smaller).
BASE_RADIUS = 2.5
#: ``scale=r`` fits quadrics over the largest radius where at most this weighted share of the points within it
#: have normals turned more than 60 degrees from the particle's (the surface there is a height function).
GRAPH_TURNED = 0.02
#: Half-width of the confidence intervals of the automatic scale, in standard deviations.
AUTO_WIDTH = 2.0
#: The automatic scale denoises the cloud first when the median residual of the quadric fits over ``2.5 h`` exceeds
#: this many mean spacings ``h``.
AUTO_NOISE = 0.25


def _frames(surface):
    return np.stack([surface.u, surface.v], axis=2)  # (N, 3, 2)


def _pointwise_shape_operator(surface):
    check_scale(surface.points, "curvature", SCALE_RANGE)

    def compute():
        n, N = surface.normals, surface.n_points
        G = surface.gradient_matrix()
        J = np.stack([(G @ n[:, a]).reshape(N, 3) for a in range(3)], axis=1)  # J[i, a, b] = d n_a / d x_b
        E = _frames(surface)
        W = np.einsum("nai,nab,nbj->nij", E, J, E)
        return 0.5 * (W + W.transpose(0, 2, 1))

    return surface.cached("shape_operator", compute)


def _spacing(surface) -> float:
    return surface.cached("mean_spacing", lambda: mean_spacing(surface.points))


def _fit_frame(surface, normals):
    """Tangent vectors (u, v), each (N, 3), of the planes normal to ``normals``: the Surface's u projected on them."""
    u = surface.u - np.einsum("nd,nd->n", surface.u, normals)[:, None] * normals
    u /= np.linalg.norm(u, axis=1)[:, None]
    return u, np.cross(normals, u)


def _jet_fits(surface, radii, points=None, normals=None):
    """Quadric fits at each radius (:func:`~manifold_sph.geometry.jets.fit_jets`) in frames close to the
    Surface's (of ``normals`` if given): shape operators (R, N, 2, 2), the standard deviation of their H per
    unit noise (R, N), and the noise of each particle from the smallest fit (N,)."""
    check_scale(surface.points, "curvature at a scale", SCALE_RANGE)
    P = surface.points if points is None else points
    nrm = surface.normals if normals is None else normals
    u, v = _fit_frame(surface, nrm)
    h = _spacing(surface)
    fits = [fit_jets(P, nrm, r, u=u, v=v, spacing=h) for r in radii]
    return (np.stack([f.shape_operator() for f in fits]), np.stack([f.mean_sd for f in fits]), fits[0].noise)


def _scaled_shape_operator(surface, scale):
    if isinstance(scale, str):
        check_in("scale", scale, ("auto",))
        return surface.cached(("shape_operator", "auto"), lambda: _auto_fits(surface))[0]
    r = check_positive("scale", scale)
    return surface.cached(("shape_operator", r), lambda: _at_scale(surface, r))


def _at_scale(surface, r):
    """``scale=r``: at each particle the quadric fit of the largest radius ``b`` of ``2.5 h * sqrt(2)^k`` (and ``r``)
    over which the surface is a height function, averaged over the same side within ``sqrt(r^2 - b^2)``
    (module notes)."""
    h = _spacing(surface)
    radii = [min(r, BASE_RADIUS * h)]
    while radii[-1] * np.sqrt(2.0) < r:
        radii.append(radii[-1] * np.sqrt(2.0))
    if radii[-1] < r:
        radii.append(r)
    Ws = _jet_fits(surface, radii)[0]
    pick = np.zeros(surface.n_points, dtype=np.int64)
    for k in range(1, len(radii)):
        graph = _turned(surface.points, surface.normals, radii[k], h) <= GRAPH_TURNED
        pick[graph & (pick == k - 1)] = k
    out = Ws[pick, np.arange(surface.n_points)]
    for k in range(len(radii) - 1):
        rows = np.flatnonzero(pick == k)
        if rows.size:
            a = np.sqrt(r * r - radii[k] ** 2)
            out[rows] = _average(surface.points, surface.normals, _frames(surface), Ws[k], a, h, rows)[0][rows]
    return out


def _ball_search(points: np.ndarray, radius: float, spacing: float) -> tuple[np.ndarray, float, cKDTree, int]:
    """Points in units of the cloud's extent (scale-free), the radius in those units, their KD-tree, and
    the neighbour count that covers a ball of ``radius`` at this ``spacing``."""
    n = points.shape[0]
    lo, hi = points.min(axis=0), points.max(axis=0)
    L = float(np.max(hi - lo))
    P = (points - (lo + 0.5 * (hi - lo))) / L
    r, h = radius / L, spacing / L
    return P, r, cKDTree(P), int(min(n, max(12, np.ceil(1.2 * np.pi * r * r / (0.9 * h * h)))))


def _turned(points, normals, radius, spacing):
    """Weighted share (N,) of each particle's neighbours within ``radius`` whose normals turn past 60 degrees."""
    n = points.shape[0]
    P, r, tree, k = _ball_search(points, radius, spacing)
    out = np.empty(n)
    for lo_ in range(0, n, _ROWS):
        rows = np.arange(lo_, min(n, lo_ + _ROWS))
        dist, idx = tree.query(P[rows], k=k, workers=-1)
        w = np.exp(-((2.0 * dist / r) ** 2)) * (dist <= r)
        out[rows] = np.einsum("rk,rk->r", w, np.einsum("rkd,rd->rk", normals[idx], normals[rows]) < 0.5) / w.sum(axis=1)
    return out


def average_shape_operators(
    points: np.ndarray, normals: np.ndarray, tangents: np.ndarray, W: np.ndarray, radius: float, *, spacing: float
) -> np.ndarray:
    """Shape operators (N, 2, 2) averaged over each particle's neighbours on the same side of the surface.

    Neighbour ``j`` of particle ``i`` counts if ``|x_j - x_i| <= radius`` and ``n_j . n_i > 0``
    (a thin part's far side and a misoriented normal are left out), with the weight
    ``exp(-(2 |x_j - x_i| / radius)^2)``. Its operator, written in ambient coordinates
    ``E_j W_j E_j^T`` (``tangents`` ``E = [u, v]``, shape (N, 3, 2)), is carried to ``i``'s tangent plane by the
    smallest rotation taking ``n_j`` to ``n_i`` before the weighted mean, which is written back in
    ``E_i``: a sphere's ``I / R`` is kept exactly.
    """
    return _average(points, normals, tangents, W, radius, spacing, np.arange(points.shape[0]))[0]


def _average(points, normals, frames, W, radius, spacing, subset):
    """:func:`average_shape_operators`, and the weighted share of each particle's neighbours within ``radius``
    whose normals turn more than 60 degrees from its own (N,)."""
    n = points.shape[0]
    P, r, tree, k = _ball_search(points, radius, spacing)
    S = np.einsum("nai,nij,nbj->nab", frames, W, frames)  # (N, 3, 3)
    out = np.zeros_like(W)
    turned = np.zeros(n)
    for lo_ in range(0, subset.size, _ROWS):
        rows = subset[lo_:lo_ + _ROWS]
        dist, idx = tree.query(P[rows], k=k, workers=-1)
        if k == 1:
            dist, idx = dist[:, None], idx[:, None]
        ni, nj = normals[rows][:, None, :], normals[idx]
        c = np.einsum("rkd,rkd->rk", nj, ni)
        w = np.exp(-((2.0 * dist / r) ** 2)) * (dist <= r)
        turned[rows] = np.einsum("rk,rk->r", w, c < 0.5) / w.sum(axis=1)
        w = w * (c > 0)
        # R = I + [a]x + [a]x^2 / (1 + c), a = n_j x n_i: the rotation about a taking n_j to n_i
        a = np.cross(nj, np.broadcast_to(ni, nj.shape))
        ax = np.zeros(a.shape + (3,))
        ax[..., 0, 1], ax[..., 0, 2], ax[..., 1, 2] = -a[..., 2], a[..., 1], -a[..., 0]
        ax -= np.swapaxes(ax, -1, -2)
        R = np.eye(3) + ax + (ax @ ax) / np.maximum(1.0 + c, 1e-12)[..., None, None]
        Sr = R @ S[idx] @ np.swapaxes(R, -1, -2)
        sw = w.sum(axis=1)
        mean = np.einsum("rk,rkab->rab", w, Sr) / sw[:, None, None]
        E = frames[rows]
        out[rows] = np.einsum("rai,rab,rbj->rij", E, mean, E)
    return 0.5 * (out + out.transpose(0, 2, 1)), turned


def _auto_fits(surface) -> tuple[np.ndarray, np.ndarray]:
    """``scale="auto"``: the shape operators (N, 2, 2) at the radius each particle picks, and those radii (N,)."""
    from .smoothing import smooth

    h = _spacing(surface)
    radii = [f * h for f in AUTO_RADII]
    # the noise of the raw points sets the intervals: what smoothing leaves is correlated over its
    # own scale, which the residuals of a small fit cannot see
    noise = _jet_fits(surface, radii[:1])[2]
    if np.median(noise) > AUTO_NOISE * h:  # noise normal to the surface removed first: the fits' scatter falls with it
        den = smooth(surface)
        P, nrm = den.points, den.normals
        Ws, unit_sd, _ = _jet_fits(surface, radii, P, nrm)
    else:  # a clean cloud: its residuals are the quadrics' misfit, which smoothing would add to
        P, nrm = surface.points, surface.normals
        Ws, unit_sd, _ = _jet_fits(surface, radii)
    n = P.shape[0]
    # the estimate at each radius is that of scale=radius: the fit over the largest radius b that is a height
    # function, averaged over sqrt(radius^2 - b^2); its standard deviation is taken as the fit's times b / radius
    # (fits correlated over b under Gaussian weights), an upper bound (module notes)
    frames = np.stack(_fit_frame(surface, nrm), axis=2)
    Es, sd = Ws.copy(), unit_sd * noise[None, :]
    base = np.zeros(n, dtype=np.int64)
    for k in range(1, len(radii)):
        base[(_turned(P, nrm, radii[k], h) <= GRAPH_TURNED) & (base == k - 1)] = k
        for b in np.unique(base[base < k]):
            rows = np.flatnonzero(base == b)
            Es[k, rows] = _average(P, nrm, frames, Ws[b], np.sqrt(radii[k] ** 2 - radii[b] ** 2), h, rows)[0][rows]
            sd[k, rows] = sd[b, rows] * radii[b] / radii[k]
    H = 0.5 * (Es[:, :, 0, 0] + Es[:, :, 1, 1])
    sd *= AUTO_WIDTH
    lo, hi = H[0] - sd[0], H[0] + sd[0]
    pick = np.zeros(n, dtype=np.int64)
    alive = np.ones(n, dtype=bool)
    for k in range(1, len(radii)):
        lo, hi = np.maximum(lo, H[k] - sd[k]), np.minimum(hi, H[k] + sd[k])
        alive &= lo <= hi
        pick[alive] = k
    # a bias grows smoothly over the surface, a chance exit from the intervals does not: each particle takes
    # the median of the picks within the smallest radius
    Pn, _, tree, kk = _ball_search(P, radii[0], h)
    pick = np.sort(pick[tree.query(Pn, k=kk, workers=-1)[1]], axis=1)[:, (kk - 1) // 2]
    return Es[pick, np.arange(n)], np.asarray(AUTO_RADII)[pick] * h


def curvature_scale(surface: Surface) -> np.ndarray:
    """Radius each particle's curvature was fitted over by ``scale="auto"``, shape (N,)."""
    check_surface(surface)
    return surface.cached(("shape_operator", "auto"), lambda: _auto_fits(surface))[1]


def shape_operator(surface: Surface, *, scale: float | str | None = None) -> np.ndarray:
    """Shape operator (Weingarten map) in each particle's tangent frame, shape (N, 2, 2).

    Parameters
    ----------
    surface : Surface
    scale : None, float or "auto"
        ``None``: ``W[i] = E_i^T (grad_S n)_i E_i`` symmetrised, with ``E_i = [u_i, v_i]``
        (the frames :attr:`Surface.u`, :attr:`Surface.v`) and ``(grad_S n)_ab = d n_a / d x_b``
        from :meth:`Surface.gradient_matrix`. A length: from a quadric fitted to the points
        within that radius; ``"auto"``: a radius chosen per particle (module notes).
        Positive definite on a convex surface with outward normals. Cached on the surface.
    """
    check_surface(surface)
    if scale is None:
        return _pointwise_shape_operator(surface)
    return _scaled_shape_operator(surface, scale)


def curvature_method(surface: Surface, method: str = "auto") -> str:
    """The method :func:`mean_curvature` uses for ``method``: ``"normals"`` or ``"laplacian"``."""
    check_in("method", method, CURVATURE_METHODS)
    return "normals" if method == "auto" else method


def mean_curvature(surface: Surface, method: str = "auto", *, scale: float | str | None = None) -> np.ndarray:
    """Mean curvature ``H = (k1 + k2) / 2``, shape (N,): ``1 / r`` on a sphere of radius ``r`` with outward normals.

    Parameters
    ----------
    surface : Surface
    method : {"auto", "normals", "laplacian"}
        Pointwise (``scale=None``) only. ``"normals"``: half the trace of
        :func:`shape_operator`; ``"laplacian"``: ``H = -(Lap_S x) . n / 2`` (no derivative of
        the normals). ``"auto"`` is ``"normals"``, the more accurate of the two with exact
        normals and with the normals a ``Surface`` estimates.
    scale : None, float or "auto"
        ``None``: pointwise, from derivatives (clean clouds). A length ``r``: the curvature
        of the surface at that scale, from quadrics fitted over radius ``r`` (noisy scans).
        ``"auto"``: the radius chosen per particle (module notes; :func:`curvature_scale`).

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import Surface
    >>> from manifold_sph.reference import shapes
    >>> s = Surface(shapes.sphere(4000, radius=2.0), scheme="msph")
    >>> bool(np.allclose(mean_curvature(s), 0.5, rtol=1e-3))
    True
    >>> bool(np.allclose(mean_curvature(s, scale=0.3), 0.5, rtol=1e-2))
    True
    """
    check_surface(surface)
    if scale is not None:
        if method not in ("auto", "normals"):
            raise ValueError(f"method={method!r} applies to scale=None only (a scale fits quadrics)")
        W = _scaled_shape_operator(surface, scale)
        return 0.5 * (W[:, 0, 0] + W[:, 1, 1])
    if curvature_method(surface, method) == "normals":
        W = _pointwise_shape_operator(surface)
        return 0.5 * (W[:, 0, 0] + W[:, 1, 1])
    check_scale(surface.points, "curvature", SCALE_RANGE)
    return surface.cached(("mean_curvature", "laplacian"), lambda: -0.5 * np.einsum(
        "ij,ij->i", surface.laplacian_matrix(form="strong") @ surface.points, surface.normals))


def gaussian_curvature(surface: Surface, *, scale: float | str | None = None) -> np.ndarray:
    """Gaussian curvature ``K = k1 k2``, shape (N,): the determinant of :func:`shape_operator` (same ``scale``)."""
    W = shape_operator(surface, scale=scale)
    return W[:, 0, 0] * W[:, 1, 1] - W[:, 0, 1] * W[:, 1, 0]


def principal_curvatures(
    surface: Surface, *, scale: float | str | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Principal curvatures and directions from :func:`shape_operator` (same ``scale``).

    Returns
    -------
    k1, k2 : ndarray, shape (N,)
        ``k1 >= k2``, signed like :func:`mean_curvature`.
    d1, d2 : ndarray, shape (N, 3)
        Unit tangent principal directions (each up to sign), ``d1 . d2 = 0``.
        Undefined at umbilic points (``k1 == k2``), where any tangent direction is principal.
    """
    W = shape_operator(surface, scale=scale)
    lam, vec = np.linalg.eigh(W)  # ascending
    d = np.einsum("nai,nij->naj", _frames(surface), vec)  # (N, 3, 2)
    return lam[:, 1], lam[:, 0], d[:, :, 1], d[:, :, 0]
