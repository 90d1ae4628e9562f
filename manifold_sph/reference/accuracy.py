"""Accuracy studies: operator errors against the exact references, and convergence.

These are the measurements behind the README's figures and the CLI's
``operators`` and ``convergence`` commands.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..pointcloud import PointCloud
from ..schemes import SCHEMES
from ..surface import Surface
from . import functions, shapes
from .errors import ConvergenceTable, convergence_study, error_summary
from .functions import ScalarFunction

__all__ = [
    "SHAPES", "SCALAR_FUNCTIONS", "make_cloud", "get_function", "operator_errors", "curvature_errors", "convergence",
    "format_rows",
]

#: Built-in shapes: name -> sampler returning a PointCloud with its exact shape.
SHAPES: dict[str, Callable[..., PointCloud]] = {
    "sphere": shapes.sphere,
    "torus": shapes.torus,
    "double_torus": shapes.double_torus,
    "sausage": shapes.sausage,
}

#: Scalar test functions with exact ambient derivatives.
SCALAR_FUNCTIONS = ("cos_xz_sin_y", "xyz", "linear", "z_cos_xy")


def make_cloud(shape: str, n: int, sampling: str | None = None, seed: int = 0) -> PointCloud:
    """Sample a built-in shape (``sampling=None``: the shape's near-uniform default)."""
    if shape not in SHAPES:
        raise ValueError(f"shape must be one of {sorted(SHAPES)}, got {shape!r}")
    kwargs = {} if sampling is None else {"sampling": sampling}
    return SHAPES[shape](n, seed=seed, **kwargs)


def get_function(name: str) -> ScalarFunction:
    """A scalar test function from :mod:`manifold_sph.reference.functions` by name."""
    if name not in SCALAR_FUNCTIONS:
        raise ValueError(f"function must be one of {list(SCALAR_FUNCTIONS)}, got {name!r}")
    return getattr(functions, name)


def exact_operators(cloud: PointCloud, function: ScalarFunction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(f, grad_S f, Lap_S f)`` at the cloud's points from its exact shape."""
    if cloud.geometry is None:
        raise ValueError("the cloud has no exact shape: exact references need a cloud from manifold_sph.reference.shapes")
    x = cloud.points
    g, H = function.gradient(x), function.hessian(x)
    return function.value(x), cloud.geometry.surface_gradient(x, g), cloud.geometry.laplace_beltrami(x, g, H)


def operator_errors(
    cloud: PointCloud,
    function: str | ScalarFunction = "cos_xz_sin_y",
    schemes: Sequence[str] | None = None,
    **surface_kwargs: Any,
) -> list[dict[str, Any]]:
    """Relative L2 and Linf errors of the Laplace-Beltrami and gradient of each scheme.

    Parameters
    ----------
    cloud : PointCloud
        With an exact shape (from :mod:`manifold_sph.reference.shapes`).
    function : str or scalar test function
    schemes : sequence of str, optional
        Default: all registered schemes.
    **surface_kwargs
        Passed to :class:`~manifold_sph.Surface`.

    Returns
    -------
    list of dict
        One row per scheme: ``scheme, n, lap_l2, lap_linf, lap_worst, grad_l2, grad_linf,
        build_s, fallback, negative_area`` (errors relative, ``lap_worst`` the index of the
        largest Laplacian error).

    Examples
    --------
    >>> from manifold_sph.reference import shapes
    >>> rows = operator_errors(shapes.sphere(1002), "xyz", schemes=["cspm"])
    >>> rows[0]["scheme"], bool(rows[0]["lap_l2"] < 0.05)
    ('cspm', True)
    """
    fn = get_function(function) if isinstance(function, str) else function
    f, grad, lap = exact_operators(cloud, fn)
    rows = []
    for name in schemes or list(SCHEMES):
        t0 = time.perf_counter()
        s = Surface(cloud, scheme=name, **surface_kwargs)
        build = time.perf_counter() - t0
        el = error_summary(s.laplacian(f, form="strong"), lap)
        eg = error_summary(s.gradient(f), grad)
        rows.append(
            {
                "scheme": name,
                "n": len(cloud),
                "lap_l2": el["l2_rel"],
                "lap_linf": el["linf_rel"],
                "lap_worst": int(el["argmax"]),
                "grad_l2": eg["l2_rel"],
                "grad_linf": eg["linf_rel"],
                "build_s": build,
                "fallback": int(sum(v.size for v in s.fallback.values())),
                "negative_area": s.area.n_negative,
            }
        )
    return rows


def curvature_errors(
    cloud: PointCloud, schemes: Sequence[str] = ("msph", "msph4"), *, estimated_normals: bool = False
) -> list[dict[str, Any]]:
    """Relative L2 errors of the mean and Gaussian curvature against the shape's exact ones.

    Parameters
    ----------
    cloud : PointCloud
        With its exact shape (from :mod:`manifold_sph.reference.shapes`).
    schemes : sequence of str
    estimated_normals : bool
        Build from the bare points (normals estimated) instead of the exact normals.

    Returns
    -------
    list of dict
        One row per scheme: ``scheme, n, H_l2, K_l2, seconds``.

    Examples
    --------
    >>> from manifold_sph.reference import shapes
    >>> row = curvature_errors(shapes.torus(4000), ["msph"])[0]
    >>> bool(row["H_l2"] < 5e-3 and row["K_l2"] < 2e-2)
    True
    """
    if cloud.geometry is None:
        raise ValueError("cloud must carry its exact shape (a cloud from manifold_sph.reference.shapes)")
    x = cloud.points
    H = 0.5 * cloud.geometry.mean_curvature(x)
    K = cloud.geometry.gaussian_curvature(x)
    rows = []
    for scheme in schemes:
        t = time.perf_counter()
        s = Surface(x, scheme=scheme) if estimated_normals else Surface(cloud, scheme=scheme)
        h, k = s.mean_curvature(), s.gaussian_curvature()
        rows.append({
            "scheme": scheme, "n": len(x),
            "H_l2": float(np.linalg.norm(h - H) / np.linalg.norm(H)),
            "K_l2": float(np.linalg.norm(k - K) / np.linalg.norm(K)),
            "seconds": time.perf_counter() - t,
        })
    return rows


def convergence(
    shape: str,
    sizes: Sequence[int] | np.ndarray,
    scheme: str = "cspm",
    function: str = "cos_xz_sin_y",
    *,
    sampling: str | None = None,
    seed: int = 0,
    progress: Callable[[], object] | None = None,
    **surface_kwargs: Any,
) -> ConvergenceTable:
    """Convergence of one scheme on a built-in shape over the cloud sizes ``sizes``.

    Errors are relative L2 and Linf of the Laplace-Beltrami and the gradient;
    orders are fitted against ``h ~ N^(-1/2)``. ``progress`` is an optional
    callable invoked after each size (e.g. a tqdm ``update``).
    """

    def run(n):
        row = operator_errors(make_cloud(shape, int(n), sampling, seed), function, [scheme], **surface_kwargs)[0]
        if progress is not None:
            progress()
        return {k: row[k] for k in ("lap_l2", "lap_linf", "grad_l2", "grad_linf")}

    return convergence_study(sizes, run, kind="N", dim=2)


def format_rows(rows: list[dict[str, Any]]) -> str:
    """Plain-text table of :func:`operator_errors` rows."""
    head = f"{'scheme':<9} {'N':>7} {'lap L2':>10} {'lap Linf':>10} {'grad L2':>10} {'grad Linf':>10} {'build s':>8} {'fallback':>8}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['scheme']:<9} {r['n']:>7d} {r['lap_l2']:>10.3e} {r['lap_linf']:>10.3e} "
            f"{r['grad_l2']:>10.3e} {r['grad_linf']:>10.3e} {r['build_s']:>8.2f} {r['fallback']:>8d}"
        )
    return "\n".join(lines)


def planar_errors(
    points: ArrayLike,
    schemes: Sequence[str] | None = None,
    *,
    bounds: Sequence[float] = (-1.0, 1.0, -1.0, 1.0),
    mirror: bool = False,
    **domain_kwargs: Any,
) -> list[dict[str, Any]]:
    """The chapter-2 cases of [1] (docs/method.md) in a planar domain, relative L2 and Linf errors per scheme.

    Gradient of ``xy``, divergence of ``(sin pi x, sin pi y)``, Laplacian of
    ``sin(pi x) cos(pi y)``.

    Returns
    -------
    list of dict
        ``scheme, n, mirror, grad_l2, grad_linf, div_l2, div_linf, lap_l2, lap_linf``.
    """
    from ..domain import Domain2D

    p = np.asarray(points, dtype=np.float64)
    g_ex = functions.xy_2d.gradient(p)
    f = functions.sin_pi_x_cos_pi_y
    lap_ex = np.trace(f.hessian(p), axis1=1, axis2=2)
    fld = functions.sin_pi_field_2d
    rows = []
    for name in schemes or list(SCHEMES):
        d = Domain2D(p, scheme=name, bounds=bounds, mirror=mirror, **domain_kwargs)
        eg = error_summary(d.gradient(functions.xy_2d.value(p)), g_ex)
        ed = error_summary(d.divergence(fld.value(p)), fld.divergence(p))
        el = error_summary(d.laplacian(f.value(p), form="strong"), lap_ex)
        rows.append(
            {
                "scheme": name, "n": len(p), "mirror": mirror,
                "grad_l2": eg["l2_rel"], "grad_linf": eg["linf_rel"],
                "div_l2": ed["l2_rel"], "div_linf": ed["linf_rel"],
                "lap_l2": el["l2_rel"], "lap_linf": el["linf_rel"],
            }
        )
    return rows
