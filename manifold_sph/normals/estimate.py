"""The entry point: :func:`estimate_normals`, fitted, oriented and outward normals of a bare cloud.

With the default ``k="auto"`` the noise level of every region is measured first
(:func:`~manifold_sph.normals.scale.noise_level`). A clean cloud (mesh vertices, analytic
samples) takes the weighted jet fits on ``tuning.DEFAULT_JET_K`` neighbours, the propagation of
:mod:`.orientation` and the refinements of ``docs/normals.md`` (steps 1-9). A noisy cloud (a scan)
takes fits whose neighbourhood grows with the local noise (:func:`~manifold_sph.normals.scale.auto_k`),
normals averaged over neighbours with a similar normal line, and the global orientation of
:mod:`.patches`. Last, every closed part is turned outward on its own (:mod:`.shells`).
"""


from __future__ import annotations

from typing import Literal, overload

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_spread
from . import tuning
from .confidence import scale_confidence, thin_confidence
from .consensus import consensus_normals
from .fitting import (
    check_degree,
    check_k,
    covariance,
    distance_weights,
    high_order,
    jet_fit,
    jet_fit_per_row,
    knn,
    n_coefficients,
    point_array,
    refit,
    shape_confidence,
    sharpened_weights,
    smooth_normals,
)
from .orientation import apply_orientation, check_orient, orient_to_view
from .patches import attach_agreement, correct_parts, global_orientation
from .poles import pole_signs
from .rows import rows_step, steep_counts
from .scale import auto_k, noise_level
from .shells import separate_parts
from .visibility import visible_signs


@overload
def estimate_normals(points: ArrayLike, k: int | str | None = "auto", *, orient: str | ArrayLike = "outward",
                     nested: str = "separate", return_confidence: Literal[False] = False, method: str = "jet",
                     degree: int | None = None, refine: bool = True, poles: bool = False) -> np.ndarray: ...


@overload
def estimate_normals(points: ArrayLike, k: int | str | None = "auto", *, orient: str | ArrayLike = "outward",
                     nested: str = "separate", return_confidence: Literal[True], method: str = "jet",
                     degree: int | None = None, refine: bool = True, poles: bool = False) -> tuple[np.ndarray, np.ndarray]: ...


@overload
def estimate_normals(points: ArrayLike, k: int | str | None = "auto", *, orient: str | ArrayLike = "outward",
                     nested: str = "separate", return_confidence: bool = False, method: str = "jet",
                     degree: int | None = None, refine: bool = True,
                     poles: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]: ...


def estimate_normals(points: ArrayLike, k: int | str | None = "auto", *, orient: str | ArrayLike = "outward",
                     nested: str = "separate", return_confidence: bool = False, method: str = "jet",
                     degree: int | None = None, refine: bool = True,
                     poles: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Estimate unit normals of a point cloud: fitted, consistently oriented and outward.

    Parameters
    ----------
    points : array_like (N, 3), or anything point-like
        At least 3 distinct points; N >= k. A PointCloud, Surface, file path or Open3D /
        PyVista / trimesh object gives its points (:func:`manifold_sph.as_cloud`; their
        own normals are not used).
    k : int or "auto"
        Nearest neighbours per particle, itself included. "auto" (the default, also ``None``):
        the scale follows the noise, region by region (module notes): clean clouds take
        :data:`~manifold_sph.normals.tuning.DEFAULT_JET_K` of the degree (16 for degree 2),
        noisy ones up to 96. An int is honoured as given (uniform weights; at least the number
        of coefficients plus 2). For ``method="pca"``, "auto" is 16 (capped at N).
    orient : {"outward", "visible", "consistent", "none"} or array_like, shape (3,)
        See :func:`orient_normals`. "outward" (the default) orients the whole cloud
        consistently and checks it with the winding number, so that every part points out.
        "visible" then corrects the signs by visibility from outside: for closed surfaces
        with thin parts; wrong on open or nested surfaces seen from inside through an opening
        (docs/normals.md, step 8). A point (3,): every normal towards that viewpoint.
    nested : {"separate", "cavity"}
        A closed part inside another: "separate" (the default) reads it as a part of its own,
        normals out of it; "cavity" as the inner wall of a hollow body, normals into the
        cavity. Only with ``orient="outward"`` or ``"visible"``.
    return_confidence : bool
        Also return the per-particle confidence (docs/normals.md, confidence).
    method : {"jet", "pca"}
        "jet" (default): local polynomial fits, order ``degree`` on smooth
        surfaces; "pca": the covariance normal (first order).
    degree : int, optional
        Degree of the jet, 1 to 4 (default 2: second order; 3 and 4 for
        high-order schemes; noisy clouds are fitted at degree 2). Only with ``method="jet"``.
    refine : bool
        On clean clouds, after orientation, refit each particle with only the neighbours whose
        normal agrees with its own (no averaging across creases or thin parts),
        then choose the direction of undetermined normals (thin or anisotropically
        sampled parts) among fits on several neighbourhoods by agreement with the
        neighbours (docs/normals.md, steps 5 and 7; at least 24 points).
        Only with ``method="jet"``; ignored when ``orient="none"``.
    poles : bool
        Also use the Voronoi poles of the cloud (one 3D Delaunay triangulation,
        :func:`~manifold_sph.normals.voronoi_poles`): the pole line and a fit in its
        frame as further candidates of step 7, and a last sign check by the winding
        number at each particle's two poles (docs/normals.md, step 9). Fewer wrong
        orientations at thin parts of coarse models sampled at their vertices, smaller and
        mixed gains on random samples, worse on noisy clouds, at the cost of the
        triangulation (about 2.5 times the default's time); not the default. Only with
        ``orient="outward"`` or ``"visible"`` (ignored otherwise) and at least 5
        points spanning a volume (ignored on planar clouds).

    Returns
    -------
    normals : ndarray, shape (N, 3)
    confidence : ndarray, shape (N,), only if ``return_confidence``
        In [0, 1]; below about 0.5 the normal or its sign is poorly determined.

    Raises
    ------
    ValueError
        On a bad ``points`` array, ``k``, ``orient``, ``nested``, ``method`` or ``degree``.
    TypeError
        On a ``k`` or ``degree`` that is not an integer, or a non-bool flag.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(1000)
    >>> n, conf = estimate_normals(cloud.points, return_confidence=True)
    >>> float(np.einsum("ij,ij->i", n, cloud.normals).min().round(3)), bool(conf.min() > 0.9)
    (1.0, True)
    """
    pts = point_array(points)
    N = pts.shape[0]
    if N < 3:
        raise ValueError(f"points must hold at least 3 points to estimate normals, got {N}")
    check_spread("points", pts)
    if not isinstance(method, str) or method not in tuning.METHODS:
        raise ValueError(f"method must be one of {list(tuning.METHODS)}, got {method!r}")
    if not isinstance(nested, str) or nested not in tuning.NESTED:
        raise ValueError(f"nested must be one of {list(tuning.NESTED)}, got {nested!r}")
    for name, flag in (("return_confidence", return_confidence), ("refine", refine), ("poles", poles)):
        if not isinstance(flag, (bool, np.bool_)):
            raise TypeError(f"{name} must be a bool, got {type(flag).__name__} {flag!r}")
    if isinstance(k, str) and k != "auto":
        raise ValueError(f"k must be a positive integer or 'auto', got {k!r}")
    given = None if k is None or isinstance(k, str) else k  # an explicit k (check_k checks it); None: "auto"
    orient = check_orient(orient)
    if method == "pca":
        if degree is not None:
            raise ValueError(f"degree applies only to method='jet', got degree={degree!r} with method='pca'")
        k = check_k(min(tuning.DEFAULT_K, N) if given is None else given, N)
        return _clean(pts, k, orient, nested, return_confidence, method, None, refine, poles, True)
    degree = check_degree(2 if degree is None else degree)
    if given is not None:  # an explicit k (e.g. a larger one for noise) is fitted with uniform weights
        return _clean(pts, check_k(given, N, degree), orient, nested, return_confidence, method, degree, refine, poles, False)
    k = tuning.DEFAULT_JET_K[degree]
    if k > N:
        raise ValueError(f"points must hold at least {k} points for a degree-{degree} jet fit with the default k, got {N}")
    if N < max(2 * tuning.NOISE_K, tuning.NOISE_REGION, tuning.ATTACH_K):  # too few to read the noise
        return _clean(pts, k, orient, nested, return_confidence, method, degree, refine, poles, True)
    dist, idx = knn(pts, max(tuning.NOISE_REGION, 2 * tuning.NOISE_K, tuning.ATTACH_K, tuning.ROW_K))
    _, v = covariance(pts, idx[:, : tuning.PCA_K])
    sigma, spacing = noise_level(pts, idx, dist, v[:, :, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = np.where(spacing > 0, sigma / spacing, 0.0)
    if np.mean(nu >= tuning.NOISE_CLEAN) < tuning.NOISY_SHARE:
        return _clean(pts, k, orient, nested, return_confidence, method, degree, refine, poles, True, (dist, idx))
    return _noisy(pts, dist, idx, sigma, spacing, nu, orient, nested, return_confidence)


def _noisy(pts, dist, idx, sigma, spacing, nu, orient, nested, return_confidence):
    """Scale that follows the noise, smoothing of similar normal lines, global orientation (module notes)."""
    N = pts.shape[0]
    ks = auto_k(sigma, spacing, N)
    if ks.max() > idx.shape[1]:
        dist, idx = knn(pts, int(ks.max()))
    w, v = covariance(pts, idx[:, : tuning.NOISY_FRAME_K])
    res = np.zeros(N)
    nrm = jet_fit_per_row(pts, idx, v[:, :, 0], ks, 2, residual=res)
    res = res * dist[np.arange(N), ks - 1]  # a length
    strength = np.clip((nu - tuning.NOISE_CLEAN) / tuning.NOISE_CLEAN, 0.0, 1.0)
    nrm = smooth_normals(pts, idx[:, : tuning.SMOOTH_K], nrm, strength)
    good = np.ones(N, dtype=bool)
    if not isinstance(orient, str):
        nrm = orient_to_view(pts, nrm, orient)
    elif orient != "none":
        nrm, good = global_orientation(pts, nrm, idx, dist, sigma, res)
        if orient in ("outward", "visible"):
            nrm = separate_parts(pts, nrm, idx, dist, nested, sigma)
        if orient == "visible":
            nrm, _ = visible_signs(pts, nrm)
    if not return_confidence:
        return nrm
    noise = float(np.median(sigma / np.maximum(dist[:, tuning.THIN_K - 1], 1e-300)))
    oconf = np.where(good, 1.0, attach_agreement(pts, nrm, idx[:, : tuning.ATTACH_K], sigma))
    return nrm, shape_confidence(w) * oconf * thin_confidence(pts, idx[:, : tuning.THIN_K], dist[:, : tuning.THIN_K], nrm, noise)


def _clean(pts, k, orient, nested, return_confidence, method, degree, refine, poles, weighted, knn_result=None):
    """Jet (or PCA) fits on ``k`` neighbours, propagation and the refinements of docs/normals.md (steps 1-9)."""
    N = pts.shape[0]
    consensus = method == "jet" and bool(refine) and not (isinstance(orient, str) and orient == "none")
    k_consensus = max(max(kc for kc, _ in tuning.CONSENSUS_CANDIDATES), tuning.ROW_K) if consensus else 0
    kq = min(max(k, tuning.ORIENT_K, tuning.SCALE_K[-1] if return_confidence else 0, k_consensus), N)
    if knn_result is not None and knn_result[1].shape[1] >= kq:
        dist, idx = knn_result[0][:, :kq], knn_result[1][:, :kq]
    else:
        dist, idx = knn(pts, kq)
    refine = bool(refine) and not (isinstance(orient, str) and orient == "none")
    vor = None
    if poles and isinstance(orient, str) and orient in ("outward", "visible"):
        from .poles import voronoi_poles

        try:
            vor = voronoi_poles(pts)
        except ValueError:  # a planar cloud: no volume, no poles
            vor = None
    if method == "pca":
        w, v = covariance(pts, idx[:, :k])
        nrm = v[:, :, 0]
    else:
        # degree 3/4: fit and orient at degree 2 first (its smaller neighbourhood is
        # the robust one on thin parts), then refit at the full degree (step 6)
        base_deg, kb = (degree, k) if degree <= 2 else (2, min(k, tuning.DEFAULT_JET_K[2]))
        w, v = covariance(pts, idx[:, : min(k, tuning.PCA_K)])
        base_res = np.zeros(N)
        base_w = distance_weights(pts, idx[:, :kb]) if tuning.JET_WEIGHT and weighted else None
        nrm = jet_fit(pts, idx[:, :kb], v[:, :, 0], base_deg, weights=base_w, residual=base_res)
        refit_w = base_w  # step 5: sharper where the residual is bias, not noise (sharpened_weights)
        if refine and base_w is not None and tuning.SHARP_WEIGHT != tuning.JET_WEIGHT and base_deg == 2 and kb >= n_coefficients(3) + 2:
            refit_w = sharpened_weights(pts, idx[:, :kb], v[:, :, 0], base_w, base_res)
        across = np.zeros(N, dtype=bool)
        if refine and tuning.ROW_STEEP and idx.shape[1] >= tuning.ROW_K:
            nrm, across = rows_step(pts, idx, nrm, w)
    conf = shape_confidence(w)
    before = None
    noise = float(np.median(base_res)) if method == "jet" else 0.0  # the cloud's relative fit residual
    nrm, _, oconf = apply_orientation(pts, nrm, idx, dist, orient, noise)
    if method == "jet":
        if refine:  # the normals of step 2b are kept (their neighbours lie on their own row)
            nrm = np.where(across[:, None], nrm, refit(pts, idx[:, :kb], nrm, base_deg, residual=base_res, weights=refit_w))
        one_sided = None
        if degree > 2:
            hi, one_sided = high_order(pts, idx[:, :k], nrm, base_res, degree, refine)
            nrm = np.where(across[:, None], nrm, hi)
        if consensus:
            if vor is None:
                nrm, before = consensus_normals(pts, idx, nrm, one_sided)
            else:
                nrm, before = consensus_normals(pts, idx, nrm, one_sided, pole=vor[0])
    if vor is not None:  # step 9: signs from the winding number at the Voronoi poles
        nrm, _ = pole_signs(pts, nrm, dist, vor)
    if isinstance(orient, str) and orient in ("outward", "visible"):
        if tuning.CORRECT_PARTS and idx.shape[1] >= tuning.ATTACH_K:
            nrm = correct_parts(pts, nrm, idx, dist)
        nrm = separate_parts(pts, nrm, idx, dist, nested)
    if isinstance(orient, str) and orient == "visible":
        nrm, _ = visible_signs(pts, nrm)
    if not return_confidence:
        return nrm
    scale = scale_confidence(pts, idx, nrm, before)
    if method == "jet" and across.any():  # step 2b: the row normals disagree with the nearest points'
        rows = np.flatnonzero(across)  # fits by construction; trusted where no point lies steeply on both sides
        up, down, *_ = steep_counts(pts, idx[rows, :tuning.ROW_K], nrm, rows)
        scale[rows[np.minimum(up, down) == 0]] = 1.0
    return nrm, conf * oconf * scale * thin_confidence(pts, idx[:, :tuning.THIN_K], dist[:, :tuning.THIN_K], nrm, noise)
