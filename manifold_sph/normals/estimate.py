"""The entry point: :func:`estimate_normals`, fitted, oriented and outward normals of a bare cloud."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_points
from ..pointcloud import as_cloud, is_point_array
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
    knn,
    n_coefficients,
    refit,
    shape_confidence,
    sharpened_weights,
)
from .orientation import apply_orientation, check_orient
from .poles import pole_signs
from .rows import rows_step, steep_counts
from .visibility import visible_signs


def estimate_normals(points: ArrayLike, k: int | None = None, *, orient: str | ArrayLike = "outward",
                     return_confidence: bool = False, method: str = "jet", degree: int | None = None,
                     refine: bool = True, poles: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Estimate unit normals of a point cloud: fitted, consistently oriented and outward.

    Parameters
    ----------
    points : array_like (N, 3), or anything point-like
        At least 3 distinct points; N >= k. A PointCloud, Surface, file path or Open3D /
        PyVista / trimesh object gives its points (:func:`manifold_sph.as_cloud`; their
        own normals are not used).
    k : int, optional
        Nearest neighbours per particle, itself included. Default: for
        ``method="jet"`` :data:`~manifold_sph.normals.tuning.DEFAULT_JET_K` of the degree (16 for degree 2; at
        least the number of coefficients plus 2), for ``method="pca"`` 16
        (capped at N). Use more on noisy clouds.
    orient : {"outward", "visible", "consistent", "none"} or array_like, shape (3,)
        See :func:`orient_normals`. "outward" (the default) propagates a consistent
        orientation and checks it globally with the winding number, so that every
        component points out. "visible" then corrects the signs by visibility from
        outside (after steps 5-7): for closed surfaces with thin parts; wrong on open
        or nested surfaces seen from inside through an opening (docs/normals.md, step 8).
    return_confidence : bool
        Also return the per-particle confidence (docs/normals.md, confidence).
    method : {"jet", "pca"}
        "jet" (default): local polynomial fits, order ``degree`` on smooth
        surfaces; "pca": the covariance normal (first order).
    degree : int, optional
        Degree of the jet, 1 to 4 (default 2: second order; 3 and 4 for
        high-order schemes). Only with ``method="jet"``.
    refine : bool
        After orientation, refit each particle with only the neighbours whose
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
        On a bad ``points`` array, ``k``, ``orient``, ``method`` or ``degree``.
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
    pts = as_points("points", points if is_point_array(points) else as_cloud(points).points)
    N = pts.shape[0]
    if N < 3:
        raise ValueError(f"points must hold at least 3 points to estimate normals, got {N}")
    if not isinstance(method, str) or method not in tuning.METHODS:
        raise ValueError(f"method must be one of {list(tuning.METHODS)}, got {method!r}")
    for name, flag in (("return_confidence", return_confidence), ("refine", refine), ("poles", poles)):
        if not isinstance(flag, (bool, np.bool_)):
            raise TypeError(f"{name} must be a bool, got {type(flag).__name__} {flag!r}")
    if method == "pca":
        if degree is not None:
            raise ValueError(f"degree applies only to method='jet', got degree={degree!r} with method='pca'")
        k = check_k(min(tuning.DEFAULT_K, N) if k is None else k, N)
    else:
        degree = check_degree(2 if degree is None else degree)
        weighted = k is None  # an explicit k (e.g. a larger one for noise) is fitted with uniform weights
        if k is None:
            k = tuning.DEFAULT_JET_K[degree]
            if k > N:
                raise ValueError(f"points must hold at least {k} points for a degree-{degree} jet fit with the default k, got {N}")
        k = check_k(k, N, degree)
    orient = check_orient(orient)
    consensus = method == "jet" and bool(refine) and not (isinstance(orient, str) and orient == "none")
    k_consensus = max(max(kc for kc, _ in tuning.CONSENSUS_CANDIDATES), tuning.ROW_K) if consensus else 0
    dist, idx = knn(pts, min(max(k, tuning.ORIENT_K, tuning.SCALE_K[-1] if return_confidence else 0, k_consensus), N))
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
