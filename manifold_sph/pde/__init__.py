"""PDEs on point-cloud surfaces (docs/pde.md, docs/method.md section 6): heat, wave, Poisson, Helmholtz-Hodge.

Every solver works with a sparse Laplace-Beltrami matrix, so implicit steps and
Poisson problems are sparse solves, set up once and reused for every step.

- :mod:`~manifold_sph.pde.time_stepping`: :func:`heat`, :func:`wave` (durations in units of
  the cloud: ``reach=`` a fraction of its diameter), :func:`wave_energy`;
- :mod:`~manifold_sph.pde.elliptic`: :func:`poisson`, :func:`screened_poisson`;
- :mod:`~manifold_sph.pde.hodge`: :func:`helmholtz_hodge`;
- :mod:`~manifold_sph.pde.laplacians`: which Laplacian (``laplacian="auto" | "strong" |
  "stable"`` or a matrix) and the explicit schemes' stability limits.

Examples
--------
>>> import numpy as np
>>> from manifold_sph import Surface, pde
>>> from manifold_sph.reference import shapes
>>> s = Surface(shapes.sphere(2000))
>>> hot = np.exp(-50 * ((s.points - [0, 0, 1]) ** 2).sum(axis=1))
>>> sol = pde.heat(s, hot, reach=0.1)                      # spread over a tenth of the diameter
>>> bool(sol.u.max() < hot.max()), sol.laplacian
(True, 'strong')
"""

from __future__ import annotations

from .elliptic import poisson, screened_poisson
from .hodge import HodgeDecomposition, helmholtz_hodge
from .laplacians import (
    AUTO_CHECK_MAX,
    LAPLACIANS,
    choose_laplacian,
    explicit_dt_limit,
    spectral_radius,
    spectrum_right_edge,
    strong_form_decays,
)
from .time_stepping import (
    EXPLICIT_SAFETY,
    HEAT_METHODS,
    MAX_STEPS,
    MIN_STEPS,
    Solution,
    cloud_diameter,
    cloud_spacing,
    heat,
    time_steps,
    wave,
    wave_energy,
)

__all__ = [
    "Solution",
    "heat",
    "wave",
    "wave_energy",
    "cloud_diameter",
    "cloud_spacing",
    "time_steps",
    "poisson",
    "screened_poisson",
    "HodgeDecomposition",
    "helmholtz_hodge",
    "choose_laplacian",
    "strong_form_decays",
    "explicit_dt_limit",
    "spectral_radius",
    "spectrum_right_edge",
    "LAPLACIANS",
    "AUTO_CHECK_MAX",
    "HEAT_METHODS",
    "MIN_STEPS",
    "MAX_STEPS",
    "EXPLICIT_SAFETY",
]
