"""SPEM: smoothed-particle electromagnetics, time-domain Maxwell on particles (docs/method.md section 7, docs/spem.md).

Modules, in the order they build on each other: :mod:`.constants`; :mod:`.layouts`
(TMz E / H sets: staggered, Yee-style, jittered, Poisson, disk, line; TEz Hz / Ex /
Ey sets with wall particles); :mod:`.operators` (cross-set CSPM derivative matrices,
the SBP correction with its PEC closure, the couplings) and :mod:`.mimetic` (the
second-order energy-conserving "mimetic" coupling); :mod:`.pml`, :mod:`.sources`;
:mod:`.stability` (CFL rule, spectral radius bound, leap-frog growth);
:mod:`.stepping` (the ``run`` contract every solver shares); :mod:`.steady` (driven runs
until their phasor is steady); :mod:`.tmz`
(:class:`TMzSolver`; compiled steps in :mod:`.compiled` and
:mod:`.stencil`); :mod:`.line` (:class:`Line1DSolver`); :mod:`.tez` (:class:`TEzSolver`, :class:`TEzPMLSolver`);
:mod:`.mie` (the exact cylinder series of both polarisations); :mod:`.interfaces`
(dielectric interface permittivities); :mod:`.cases` (the validation cases with
exact references); :mod:`.results` (every result type); :mod:`.analysis` (null
modes and dispersion); :mod:`.dirichlet` (the Kronecker-delta system); :mod:`.cli`
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

from .cases import (
    CASES,
    run_case,
    run_cavity,
    run_line1d,
    run_planewave,
    run_pml,
    run_scattering,
    run_tez_cavity,
    run_tez_circular_cavity,
    run_tez_pml,
    run_tez_scattering,
    run_waveguide,
    scattering_layout,
    tez_cavity_frequency,
    tez_disk_frequency,
    tez_disk_mode,
    tez_scattering_layout,
)
from .certify import certificate_failures, pml_certificate, restricted
from .constants import C0, EPS0, ETA0, MU0
from .dirichlet import KroneckerSystem
from .interfaces import (
    EPS_AVERAGES,
    INTERFACES,
    TEZ_INTERFACES,
    cell_fraction,
    jump_permittivity,
    particle_permittivity,
    tez_jump_permittivity,
)
from .layouts import (
    LAYOUTS,
    POISSON_H_RATIO,
    TEZ_LAYOUT_KINDS,
    Layout,
    TEzLayout,
    disk_layout,
    jitter,
    line_layout,
    make_layout,
    poisson_layout,
    staggered_layout,
    tez_disk_layout,
    tez_layout,
    wall_closure_layout,
    yee_layout,
)
from .line import Line1DSolver
from .mie import (
    SCATTERERS,
    TEZ_SCATTERERS,
    mie_coefficients,
    scattered_field,
    tez_mie_coefficients,
    tez_scattered_field,
    tez_total_field,
    total_field,
    wavenumber,
)
from .operators import COUPLINGS, DEFAULT_COUPLING, DEFAULT_H_RATIO, FORMS, cross_gradient, cross_pairs, sbp_pair
from .pml import PML, sigma_max
from .results import (
    CaseResult,
    CavityResult,
    FieldHistory,
    LineResult,
    PlanewaveResult,
    PMLCertificate,
    PMLResult,
    RunResult,
    ScatteringResult,
    TEzCavityResult,
    TEzPMLResult,
    TEzScatteringResult,
    WaveguideResult,
)
from .sources import GaussianPulse, Sinusoid, Source, line_source, point_source
from .stability import cfl_number, leapfrog_growth, spectral_radius_bound
from .steady import PeriodPhasors, run_driven
from .tez import DISK_H_RATIO, CircularInterface, TEzPMLSolver, TEzSolver
from .tmz import TMzSolver

__all__ = [
    "C0", "EPS0", "ETA0", "MU0",
    "LAYOUTS", "Layout", "disk_layout", "jitter", "line_layout", "make_layout", "poisson_layout", "staggered_layout",
    "yee_layout", "POISSON_H_RATIO", "TEZ_LAYOUT_KINDS", "TEzLayout", "tez_layout", "tez_disk_layout",
    "wall_closure_layout",
    "FORMS", "COUPLINGS", "DEFAULT_COUPLING", "DEFAULT_H_RATIO", "cross_gradient", "cross_pairs", "sbp_pair",
    "PML", "sigma_max",
    "GaussianPulse", "Sinusoid", "Source", "line_source", "point_source",
    "cfl_number", "leapfrog_growth", "spectral_radius_bound", "PeriodPhasors", "run_driven",
    "TMzSolver", "Line1DSolver", "TEzSolver", "TEzPMLSolver", "CircularInterface", "DISK_H_RATIO",
    "SCATTERERS", "TEZ_SCATTERERS", "wavenumber", "mie_coefficients", "scattered_field", "total_field",
    "tez_mie_coefficients", "tez_scattered_field", "tez_total_field",
    "INTERFACES", "EPS_AVERAGES", "TEZ_INTERFACES", "cell_fraction", "jump_permittivity", "particle_permittivity",
    "tez_jump_permittivity",
    "CASES", "run_case", "run_line1d", "run_cavity", "run_waveguide", "run_planewave", "run_pml", "run_tez_pml",
    "run_tez_cavity", "run_tez_circular_cavity", "tez_cavity_frequency", "tez_disk_frequency", "tez_disk_mode",
    "scattering_layout", "tez_scattering_layout", "run_scattering", "run_tez_scattering",
    "RunResult", "FieldHistory", "CaseResult", "LineResult", "CavityResult", "PlanewaveResult", "WaveguideResult",
    "PMLResult", "ScatteringResult", "TEzScatteringResult", "TEzCavityResult", "TEzPMLResult",
    "KroneckerSystem", "restricted", "pml_certificate", "PMLCertificate", "certificate_failures",
]
