"""Geometry from points: curvature, geodesics, the vector heat method, smoothing, signatures.

Every function takes a :class:`~manifold_sph.Surface` (the ``Surface`` methods of the same
names call them); the geodesic solver and the smoother also take bare points.

- :mod:`~manifold_sph.geometry.curvature`: shape operator, mean, Gaussian and principal
  curvatures, pointwise or at a scale (``scale=r`` or ``"auto"``, for noisy scans).
- :mod:`~manifold_sph.geometry.geodesics`: :class:`GeodesicSolver` (one particle or a set,
  to every particle or a few, all pairs), by wavefront propagation over the local
  Delaunay triangles (:mod:`~manifold_sph.geometry.wavefront`) or by the heat method.
- :mod:`~manifold_sph.geometry.vector_heat`: the connection Laplacian, parallel transport,
  the logarithmic map and Karcher means (the vector heat method).
- :mod:`~manifold_sph.geometry.smoothing`: denoising a cloud (implicit mean-curvature flow
  on the stable Laplacian, optionally feature-preserving).
- :mod:`~manifold_sph.geometry.signatures`: heat and wave kernel signatures.

``docs/geometry.md`` has the methods and the measurements.
"""

from .common import SCALE_RANGE, WAVEFRONT_SCALE_RANGE
from .curvature import (
    AUTO_NOISE,
    AUTO_RADII,
    CURVATURE_METHODS,
    curvature_method,
    curvature_scale,
    gaussian_curvature,
    mean_curvature,
    principal_curvatures,
    shape_operator,
)
from .geodesics import DENOISE_NOISE, GEODESIC_METHODS, GeodesicSolver, geodesic_distance
from .signatures import heat_kernel_signature, wave_kernel_signature
from .smoothing import SMOOTH_METHODS, smooth
from .vector_heat import (
    VectorHeatSolver,
    connection_laplacian,
    karcher_mean,
    log_map,
    transport,
)

__all__ = [
    "AUTO_NOISE",
    "AUTO_RADII",
    "CURVATURE_METHODS",
    "DENOISE_NOISE",
    "GEODESIC_METHODS",
    "SCALE_RANGE",
    "SMOOTH_METHODS",
    "WAVEFRONT_SCALE_RANGE",
    "GeodesicSolver",
    "VectorHeatSolver",
    "connection_laplacian",
    "curvature_method",
    "curvature_scale",
    "gaussian_curvature",
    "geodesic_distance",
    "heat_kernel_signature",
    "karcher_mean",
    "log_map",
    "mean_curvature",
    "principal_curvatures",
    "shape_operator",
    "smooth",
    "transport",
    "wave_kernel_signature",
]
