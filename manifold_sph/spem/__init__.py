"""SPEM: smoothed-particle electromagnetics, time-domain Maxwell on particles (docs/method.md section 7).

Modules: :mod:`.layouts` (E / H particle sets: staggered, Yee-style, jittered,
Poisson, disk, line), :mod:`.operators` (cross-set CSPM derivative matrices,
the SBP correction with its PEC closure), :mod:`.mimetic` (the second-order, energy-conserving
"mimetic" coupling: cubic-exact gradient, adjoint divergence, fitted volumes), :mod:`.solver` (leap-frog TMz and 1D
solvers, energy-conserving "sbp" coupling by default, the CFL and spectral
limits, the measured-spectrum check that refuses a growing "direct" coupling,
PEC, materials, split-field PML), :mod:`.pml`, :mod:`.sources` (sinusoid,
Gaussian pulse, hard/soft point and line sources), :mod:`.dirichlet` (the
Kronecker-delta system), :mod:`.scattering` (plane-wave scattering by PEC, dielectric and
coated cylinders: exact Bessel series and SPEM cases), :mod:`.tez` (TEz: Hz, Ex, Ey), :mod:`.tez_scattering` (TEz
scattering by PEC and dielectric cylinders: exact Hz series, split-field PML),
:mod:`.cases` / :mod:`.cases2d` (helpers in
:mod:`._casekit`; :mod:`.cases` imports :mod:`.cases2d`, not the reverse) (the
validation cases of the thesis [2] with exact references), :mod:`.results` (what ``run`` and
the cases return: :class:`RunResult`, :class:`CaseResult` and one subclass per case, frozen
dataclasses with named fields), :mod:`.analysis` (null modes and dispersion), :mod:`.cli`
(``manifold-sph spem CASE``).

Examples
--------
>>> from manifold_sph.spem import TMzSolver, yee_layout
>>> import numpy as np
>>> lay = yee_layout((0.0, 0.1, 0.0, 0.1), 0.005)
>>> s = TMzSolver(lay)
>>> a = 0.1
>>> s.set_initial(np.sin(np.pi * lay.e[:, 0] / a) * np.sin(np.pi * lay.e[:, 1] / a))
>>> out = s.run(100, probes=[0, 5])
>>> out.probes.shape, bool(np.abs(s.e_field).max() <= 1.0)
((100, 2), True)
"""

from .constants import C0, EPS0, ETA0, MU0
from .dirichlet import KroneckerSystem
from .layouts import (LAYOUTS, Layout, disk_layout, jitter, line_layout, make_layout, poisson_layout,
                      staggered_layout, yee_layout)
from .operators import FORMS, cross_gradient, cross_pairs, sbp_pair
from .pml import PML, sigma_max
from .scattering import (INTERFACES, SCATTERERS, ScatteringResult, jump_permittivity, mie_coefficients, run_scattering,
                         scattered_field, scattering_layout, total_field)
from .tez import (POISSON_H_RATIO, TEZ_LAYOUT_KINDS, TEzCavityResult, TEzLayout, TEzSolver, run_tez_cavity, run_tez_circular_cavity, tez_cavity_frequency,
                  tez_disk_frequency, tez_disk_layout, tez_disk_mode, tez_layout, wall_closure_layout)
from .tez_scattering import (EPS_AVERAGES, TEZ_INTERFACES, TEZ_SCATTERERS, TEzPMLResult, TEzPMLSolver, TEzScatteringResult,
                             particle_permittivity, run_tez_pml, run_tez_scattering, tez_jump_permittivity,
                             tez_mie_coefficients,
                             tez_scattered_field, tez_scattering_layout, tez_total_field)
from .results import (CaseResult, CavityResult, FieldHistory, LineResult, PlanewaveResult, PMLResult, RunResult,
                      WaveguideResult)
from .solver import COUPLINGS, DEFAULT_COUPLING, DEFAULT_H_RATIO, Line1DSolver, TMzSolver, cfl_number, leapfrog_growth
from .sources import GaussianPulse, Sinusoid, Source, line_source, point_source

__all__ = [
    "C0", "EPS0", "ETA0", "MU0",
    "KroneckerSystem",
    "LAYOUTS", "Layout", "disk_layout", "jitter", "line_layout", "make_layout", "poisson_layout",
    "staggered_layout", "yee_layout",
    "FORMS", "cross_gradient", "cross_pairs", "sbp_pair",
    "PML", "sigma_max",
    "INTERFACES", "SCATTERERS", "ScatteringResult", "jump_permittivity", "mie_coefficients", "run_scattering", "scattered_field", "scattering_layout",
    "total_field", "POISSON_H_RATIO", "TEZ_LAYOUT_KINDS", "TEzCavityResult", "TEzLayout", "TEzSolver", "run_tez_cavity", "tez_cavity_frequency",
    "tez_layout", "run_tez_circular_cavity", "tez_disk_frequency", "tez_disk_layout", "tez_disk_mode",
    "wall_closure_layout",
    "EPS_AVERAGES", "TEZ_INTERFACES", "TEZ_SCATTERERS", "tez_jump_permittivity", "TEzPMLResult", "TEzPMLSolver", "TEzScatteringResult", "particle_permittivity",
    "run_tez_pml", "run_tez_scattering", "tez_mie_coefficients", "tez_scattered_field", "tez_scattering_layout",
    "tez_total_field",
    "RunResult", "CaseResult", "LineResult", "CavityResult", "PlanewaveResult", "WaveguideResult", "PMLResult",
    "FieldHistory",
    "COUPLINGS", "DEFAULT_COUPLING", "DEFAULT_H_RATIO", "Line1DSolver", "TMzSolver", "cfl_number", "leapfrog_growth",
    "GaussianPulse", "Sinusoid", "Source", "line_source", "point_source",
]
