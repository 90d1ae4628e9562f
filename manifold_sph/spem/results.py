"""Every SPEM result type: what a solver's ``run`` and each validation case return.

Frozen dataclasses with named fields (docs/conventions.md, "Results"); ``to_dict()``
gives the JSON-ready fields (what ``manifold-sph spem --json`` prints: arrays and
picture data left out), the ``repr`` shows arrays by shape. :class:`RunResult` is
what every solver's ``run`` returns; every TMz case result derives from
:class:`CaseResult` (``case``, ``particles``, ``steps``, ``seconds`` (wall time of
the whole call), ``step_seconds`` (the stepping alone), ``error``, ``dt``, ``dr``
and ``fields``, the E field for pictures as a :class:`FieldHistory` when asked for
with ``every=``; the final state always); the scattering and TEz cases have their own.

Examples
--------
>>> r = LineResult(case="line1d", particles=10, steps=5, seconds=0.1, step_seconds=0.05, error=0.01,
...                dt=1e-12, dr=1e-3, h=7e-4, particles_per_wavelength=20.0, courant=0.9)
>>> r.error, sorted(r.to_dict())[:3]
(0.01, ['case', 'certificate_failures', 'consistency'])
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..results import Result

__all__ = ["RunResult", "FieldHistory", "CaseResult", "LineResult", "CavityResult", "PlanewaveResult",
           "WaveguideResult", "PMLResult", "ScatteringResult", "TEzScatteringResult", "TEzCavityResult",
           "TEzPMLResult", "PMLCertificate"]


class Certified:
    """``certified``: the run's ``certificate_failures`` (a field of the result) is empty."""

    certificate_failures: tuple

    @property
    def certified(self) -> bool:
        """True when every certificate the run reports lies in its validated range
        (:func:`~manifold_sph.spem.certify.certificate_failures`; ``certificate_failures`` names the others)."""
        return not self.certificate_failures


@dataclass(frozen=True, repr=False, eq=False)
class RunResult(Result):
    """What every SPEM solver's ``run`` returns (:class:`.stepping.Leapfrog`).

    Attributes
    ----------
    times : ndarray, shape (steps,)
        The time after each step.
    probes : ndarray, shape (steps, P)
        The recorded field (Ez, Ex on the line, Hz for TEz) at the probe particles after each step.
    snapshots : ndarray, shape (S, n_e)
        Copies of the recorded field every ``every`` steps (S = 0 without it).
    snapshot_times : ndarray, shape (S,)
    seconds : float
        Wall time of the steps.
    """

    times: np.ndarray
    probes: np.ndarray
    snapshots: np.ndarray
    snapshot_times: np.ndarray
    seconds: float


class FieldHistory(NamedTuple):
    """The E field of a case for pictures: ``snapshots[i]`` at ``times[i]`` on ``points``; ``exact`` or None."""

    points: np.ndarray
    times: np.ndarray
    snapshots: np.ndarray
    exact: np.ndarray | None = None


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class CaseResult(Certified, Result):
    """The fields every validation case reports (:mod:`manifold_sph.spem.cases`).

    ``consistency`` is the largest error of the run's derivative matrices on linear fields
    (:meth:`.TMzSolver.consistency_residual`: round-off for a consistent coupling, O(1) for an
    inconsistent one); ``consistency_interior`` the same over the rows two kernel supports and more
    from the walls and driven particles (:meth:`.TMzSolver.interior_consistency_residual`); None where
    not computed. ``error`` is mean |numerical - exact| / max |exact|
    over the case's evaluation points (the PML case: the relative reflection at normal
    incidence, None where the pulse never reaches the probe). ``certificate_failures``: one sentence per
    certificate outside its validated range (:func:`~manifold_sph.spem.certify.certificate_failures`), empty
    when the run is certified (``certified``).
    """

    _dict_skip = ('fields',)

    case: str
    particles: int
    steps: int
    seconds: float
    step_seconds: float
    error: float | None
    dt: float
    dr: float
    fields: FieldHistory | None = dataclasses.field(default=None, repr=False)
    consistency: float | None = None
    consistency_interior: float | None = None
    certificate_failures: tuple = ()


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class LineResult(CaseResult):
    """:func:`~manifold_sph.spem.cases.run_line1d`: smoothing length, resolution and Courant number."""

    h: float
    particles_per_wavelength: float
    courant: float


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class CavityResult(CaseResult):
    """:func:`~manifold_sph.spem.cases.run_cavity`; ``f1_measured``/``f1_error`` with ``spectrum_periods`` > 0;
    ``energy_drift``: ``|W(end) / W(0) - 1|`` of the discrete energy (:meth:`.TMzSolver.energy`) over the periods."""

    layout: str
    form: str
    r0: float
    eps_r: float
    f1_exact: float
    f1_measured: float | None = None
    f1_error: float | None = None
    energy_drift: float | None = None


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class PMLCertificate(Result):
    """:func:`~manifold_sph.spem.certify.pml_certificate`: a layer's reflection measured on probes, in dB.

    ``normal_db`` and ``oblique_db`` (45 degrees) are ``20 log10(max |E - E_ref| / max |E_ref|)`` at each
    probe (None where the pulse never reaches it), for the layout, support ``h_ratio`` (h / dr) and
    coupling of the run it certifies; ``seconds`` is the wall time of its two runs.
    """

    normal_db: float | None
    oblique_db: float | None
    layout: str
    pml_cells: int
    h_ratio: float
    coupling: str
    seconds: float

    @property
    def worst_db(self) -> float | None:
        """The larger of the two reflections (None when neither is defined)."""
        vals = [v for v in (self.normal_db, self.oblique_db) if v is not None]
        return max(vals) if vals else None


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class PlanewaveResult(CaseResult):
    """:func:`~manifold_sph.spem.cases.run_planewave`; the line measures on lattice layouts only.

    ``pml_reflection_db``: the worst reflection of the run's layer measured by
    :func:`~manifold_sph.spem.certify.pml_certificate` (None where not measured: ``certify=False``, or
    the "mimetic" and "direct" couplings by default). ``side``: "mirror" (PMC side walls) or "pml"."""

    layout: str
    form: str
    ppw: float
    pml_cells: int
    error_centre: float
    side: str = "pml"
    adjacent_line_difference: float | None = None
    alternating_amplitude: float | None = None
    pml_reflection_db: float | None = None


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class WaveguideResult(CaseResult):
    """:func:`~manifold_sph.spem.cases.run_waveguide`: frequency, cut-off and the evaluation line;
    ``pml_reflection_db`` as :class:`PlanewaveResult`'s."""

    layout: str
    form: str
    freq: float
    f_cutoff: float
    line_x: float
    ppw: float
    pml_cells: int
    pml_reflection_db: float | None = None


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class PMLResult(CaseResult):
    """:func:`~manifold_sph.spem.cases.run_pml`: reflections in dB (None where undefined), the reference run."""

    reference_particles: int
    reflection_normal_db: float | None
    reflection_oblique_db: float | None
    pml_cells: int
    order: int
    target_reflection: float
    layout: str


@dataclass(frozen=True, repr=False, eq=False)
class ScatteringResult(Certified, Result):
    """What :func:`run_scattering` measured.

    Attributes
    ----------
    case : str
        The scatterer ("pec", "dielectric", "coated").
    error : float
        Relative L2 error of the complex scattered field on the evaluation particles.
    ring_error : float
        The same on the E particles of the annulus ``radius < r <= 2 radius`` (the near field).
    particles, steps : int
        Particles (E + Hx + Hy, PML included) and leap-frog steps.
    seconds, setup_seconds : float
        Wall time of the whole case and of the set-up (layout, operators, stability limit).
    dr, dt : float
    layout, coupling : str
    points : (P, 2) array
        The evaluation E particles (outside the PML, not on a conductor).
    phasor, exact : (P,) complex arrays
        Measured (the steady phasor extrapolated from the periods run, with ``periods="auto"``:
        :mod:`~manifold_sph.spem.steady`) and exact scattered phasors there.
    interface : str
        The interface treatment used ("average" or "jump"; "average" for the PEC cylinder).
    periods : float
        Drive periods run (``steps`` over the steps per period).
    transient : float
        Estimated transient left in ``phasor``, relative to its L2 norm
        (:class:`~manifold_sph.spem.steady.PeriodPhasors`).
    gain : float
        The extrapolation's gain (1 for a fixed number of periods; above
        :data:`~manifold_sph.spem.steady.GAIN_MAX` a mode resonates near the drive frequency).
    certificate_failures : tuple of str
        One sentence per certificate outside its validated range: the phasor not steady or resonant
        (:func:`~manifold_sph.spem.steady.steady_failures`), the interior consistency
        (:func:`~manifold_sph.spem.certify.certificate_failures`).
    consistency, consistency_interior : float
        The operators' error on linear fields, everywhere and away from the conductors and
        driven particles (as :class:`CaseResult`).
    """

    _dict_skip = ('points', 'phasor', 'exact')

    case: str
    error: float
    ring_error: float
    particles: int
    steps: int
    seconds: float
    setup_seconds: float
    dr: float
    dt: float
    layout: str
    coupling: str
    n_radial: int
    points: np.ndarray = dataclasses.field(repr=False)
    phasor: np.ndarray = dataclasses.field(repr=False)
    exact: np.ndarray = dataclasses.field(repr=False)
    interface: str = "average"
    periods: float = 0.0
    transient: float = 0.0
    certificate_failures: tuple = ()
    consistency: float | None = None
    consistency_interior: float | None = None
    gain: float = 1.0


@dataclass(frozen=True, repr=False, eq=False)
class TEzScatteringResult(Certified, Result):
    """What :func:`run_tez_scattering` measured (the fields of :class:`.ScatteringResult`, for Hz, and more).

    Attributes
    ----------
    case : str
        The scatterer ("pec", "dielectric").
    error : float
        Relative L2 error of the complex scattered Hz on the evaluation Hz particles.
    ring_error : float
        The same on those in the annulus ``radius < r <= 2 radius`` (the near field).
    particles, steps : int
        Particles (Hz + Ex + Ey + wall, PML included) and leap-frog steps.
    seconds, setup_seconds : float
        Wall time of the whole case and of the set-up (layout, operators, stability limit).
    dr, dt : float
    layout, coupling, average : str
        ``average``: the permittivity average of the E particles ("dielectric").
    n_radial : int
    stable_fraction : float
        ``dt`` over the lossless pair's stability limit ``2 / sqrt(rho)``.
    field_growth : float
        Largest ``|Hz|`` over the last period divided by the largest over the
        period before (about 1 at steady state; silent growth shows as > 1).
    points : (P, 2) array
        The evaluation Hz particles (outside the PML, outside a conductor).
    phasor, exact : (P,) complex arrays
        Measured and exact scattered phasors there.
    periods, transient, gain, certificate_failures
        As :class:`ScatteringResult`.
    consistency_interior : float
        :meth:`~manifold_sph.spem.tez.TEzSolver.interior_consistency_residual` of the run's operators.
    """

    _dict_skip = ('points', 'phasor', 'exact')

    case: str
    error: float
    ring_error: float
    particles: int
    steps: int
    seconds: float
    setup_seconds: float
    dr: float
    dt: float
    layout: str
    coupling: str
    average: str
    n_radial: int
    stable_fraction: float
    field_growth: float
    points: np.ndarray = dataclasses.field(repr=False)
    phasor: np.ndarray = dataclasses.field(repr=False)
    exact: np.ndarray = dataclasses.field(repr=False)
    periods: float = 0.0
    transient: float = 0.0
    certificate_failures: tuple = ()
    consistency_interior: float | None = None
    gain: float = 1.0


@dataclass(frozen=True, repr=False, eq=False)
class TEzCavityResult(Certified, Result):
    """What :func:`run_tez_cavity` measured.

    ``error``: relative L2 error of Hz after ``periods`` periods of the first
    mode (its initial field evolved exactly); ``frequency_error``: relative
    error of that mode's resonance, fitted to the projection of Hz onto the mode.
    :func:`run_tez_circular_cavity` also gives ``probe_frequency_error`` (the
    peak of the spectrum of Hz at one particle) and ``stable_fraction`` (the
    time step over the CFL step ``h / (sqrt(2) c)``). ``h_ratio`` is the support the run used and
    ``wall_closure`` whether the rectangle's walls were closure columns (None for the disk).
    ``consistency_interior``: :meth:`~manifold_sph.spem.tez.TEzSolver.interior_consistency_residual`;
    ``certificate_failures`` names it when above its validated range (``certified``: none).
    """

    case: str
    error: float
    frequency_error: float
    frequency: float
    exact_frequency: float
    particles: int
    steps: int
    seconds: float
    dr: float
    dt: float
    coupling: str
    layout: str
    probe_frequency_error: float | None = None
    stable_fraction: float | None = None
    h_ratio: float | None = None
    wall_closure: bool | None = None
    consistency_interior: float | None = None
    certificate_failures: tuple = ()


# ----------------------------------------------------------------------------- PML reflection
@dataclass(frozen=True, repr=False, eq=False)
class TEzPMLResult(Result):
    """What :func:`run_tez_pml` measured: the reflection (dB) at each probe angle, and the cost."""

    angles: tuple
    reflection_db: tuple
    particles: int
    reference_particles: int
    steps: int
    seconds: float
    dr: float
    dt: float
    pml_cells: int
    order: int
    target_reflection: float
