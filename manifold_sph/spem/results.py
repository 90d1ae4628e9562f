"""SPEM results: :class:`RunResult` of a solver's ``run``, the ``*Result`` of each validation case.

Frozen dataclasses with named fields (the package's convention, README
"Results"); ``to_dict()`` gives the JSON-ready numbers (what ``manifold-sph spem
--json`` prints). Every case result has ``case``, ``particles``, ``steps``,
``seconds`` (wall time of the whole call), ``step_seconds`` (the stepping
alone), ``error``, ``dt``, ``dr`` and ``fields`` (the E field for pictures,
:class:`FieldHistory`, when asked for with ``frames=``), plus its own
quantities.

Examples
--------
>>> r = LineResult(case="line1d", particles=10, steps=5, seconds=0.1, step_seconds=0.05, error=0.01,
...                dt=1e-12, dr=1e-3, h=7e-4, particles_per_wavelength=20.0, courant=0.9)
>>> r.error, sorted(r.to_dict())[:3]
(0.01, ['case', 'courant', 'dr'])
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..results import Result

__all__ = ["RunResult", "FieldHistory", "CaseResult", "LineResult", "CavityResult", "PlanewaveResult",
           "WaveguideResult", "PMLResult"]


@dataclass(frozen=True, repr=False, eq=False)
class RunResult(Result):
    """What :meth:`TMzSolver.run <manifold_sph.spem.TMzSolver.run>` and ``Line1DSolver.run`` return.

    Attributes
    ----------
    times : ndarray, shape (steps,)
        The time after each step.
    probes : ndarray, shape (steps, P)
        The E field at the probe particles after each step.
    snapshots : ndarray, shape (S, n_e)
        Copies of the E field every ``snapshot_every`` steps (S = 0 without it).
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
class CaseResult(Result):
    """The fields every validation case reports (:mod:`manifold_sph.spem.cases`).

    ``error`` is mean |numerical - exact| / max |exact| over the case's
    evaluation points (the PML case: the relative reflection at normal
    incidence, None where the pulse never reaches the probe).
    """

    case: str
    particles: int
    steps: int
    seconds: float
    step_seconds: float
    error: float | None
    dt: float
    dr: float
    fields: FieldHistory | None = dataclasses.field(default=None, repr=False)

    _dict_skip = ("fields",)


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class LineResult(CaseResult):
    """:func:`~manifold_sph.spem.cases.run_line1d`: smoothing length, resolution and Courant number."""

    h: float
    particles_per_wavelength: float
    courant: float


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class CavityResult(CaseResult):
    """:func:`~manifold_sph.spem.cases.run_cavity`; ``f1_measured``/``f1_error`` with ``spectrum_periods`` > 0."""

    layout: str
    form: str
    r0: float
    eps_r: float
    f1_exact: float
    f1_measured: float | None = None
    f1_error: float | None = None


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class PlanewaveResult(CaseResult):
    """:func:`~manifold_sph.spem.cases2d.run_planewave`; the line measures on lattice layouts only."""

    layout: str
    form: str
    ppw: float
    pml_cells: int
    error_centre: float
    adjacent_line_difference: float | None = None
    alternating_amplitude: float | None = None


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class WaveguideResult(CaseResult):
    """:func:`~manifold_sph.spem.cases2d.run_waveguide`: frequency, cut-off and the evaluation line."""

    layout: str
    form: str
    freq: float
    f_cutoff: float
    line_x: float
    ppw: float
    pml_cells: int


@dataclass(frozen=True, repr=False, eq=False, kw_only=True)
class PMLResult(CaseResult):
    """:func:`~manifold_sph.spem.cases2d.run_pml`: reflections in dB (None where undefined), the reference run."""

    reference_particles: int
    reflection_normal_db: float | None
    reflection_oblique_db: float | None
    pml_cells: int
    order: int
    target_reflection: float
    layout: str
