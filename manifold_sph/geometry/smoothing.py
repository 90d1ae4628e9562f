"""Smoothing and denoising a point cloud: :func:`smooth`.

``method="jet"`` (default)
    Each particle moves along its normal onto the quadric fitted to the points around it
    (:func:`~manifold_sph.geometry.jets.fit_jets`, Gaussian weights over ``scale``), and
    the normal is refitted from the quadric's slope; ``iterations`` passes. Noise normal to
    the surface is averaged over the fit's points, the surface's own shape is kept to the
    quadric's order (the fit's bias grows like ``curvature' * scale^3``), and particles do not
    drift along the surface. With ``features=True`` (the default) each fit is reweighted twice
    with Cauchy weights of its residuals, so that at a sharp edge or corner it settles on the
    particle's own face instead of rounding the edge, and across a thin part on its own sheet
    (bilateral in the residual; measured on noisy model vertices: cheburashka's ears 0.19
    spacings from the clean mesh against 0.34 without).
``method="flow"``
    Implicit mean-curvature flow on the stable Laplacian of a
    :class:`~manifold_sph.Surface`: ``Y = (M + tau K)^-1 M X`` with ``tau = scale^2 / 4``,
    its displacement ``d = (Y - X) . n`` along the normals (no tangential drift), less its own
    smoothed part ``(M + tau K)^-1 M d`` (the flow's shrinking of curved parts, about
    ``2 tau / R`` on a sphere of radius ``R``, is smooth; the noise is not: a Taubin-style
    correction); ``iterations`` steps with the operator factorised once.

The spacing ``h`` is the mean distance to the 6 nearest points; ``scale`` defaults to
``4 h`` (jet) or ``2 h`` (flow). Measured in ``benchmarks/geometry.py`` (mean distance to the
clean mesh of noisy samples of the test models, beside CGAL's ``jet_smooth_point_set``).
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from .._validation import check_bool, check_in, check_int, check_positive
from ..exceptions import ManifoldSPHWarning
from .common import SCALE_RANGE, as_cloud_points, check_scale, is_surface
from .jets import fit_jets, mean_spacing, tangent_basis
from .wavefront import pca_normals

if TYPE_CHECKING:
    from ..pointcloud import PointCloud
    from ..surface import Surface

__all__ = ["SMOOTH_METHODS", "smooth"]

SMOOTH_METHODS = ("jet", "flow")


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
        Length over which the surface is fitted (``"jet"``) or diffused (``"flow"``):
        noise shorter than it is removed. Default ``4 h`` (jet), ``2 h`` (flow), ``h`` the mean spacing.
    iterations : int
        Passes (``"jet"``) or implicit steps (``"flow"``).
    features : bool
        ``"jet"``: robust fits that keep sharp edges, corners and thin parts (default); ignored by ``"flow"``.

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
        r = 4.0 * h if scale is None else scale / L
        nrm = normals if normals is not None else pca_normals(P, tree.query(P, k=min(16, P.shape[0]), workers=-1)[1])
        out = P.copy()
        for _ in range(iterations):
            u, v = tangent_basis(nrm)
            jets = fit_jets(out, nrm, r, u=u, v=v, spacing=h, robust=2 if features else 0)
            c = jets.coef
            out = out + c[:, :1] * nrm
            new = nrm - c[:, 1:2] * u - c[:, 2:3] * v
            nrm = _orient(new / np.linalg.norm(new, axis=1)[:, None], nrm)
    return PointCloud(out * L + centre, _orient(nrm, normals) if normals is not None else None)


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
