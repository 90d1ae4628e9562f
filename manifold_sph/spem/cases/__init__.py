"""The validation cases with exact references (the thesis [2], chapter 4; docs/method.md section 7; docs/spem.md).

:mod:`.line` (the 1D line), :mod:`.cavity` (the TMz dielectric disk, the TEz PEC
rectangle and disk), :mod:`.propagation` (plane wave, waveguide, PML reflection),
:mod:`.scattering` (plane-wave scattering by PEC, dielectric and coated
cylinders, TMz and TEz); :mod:`.common` holds their error measures. Every
``run_*`` returns a result dataclass of :mod:`..results`; ``to_dict()`` is its
JSON-ready form. :func:`run_case` runs the TMz cases by name (:data:`CASES`).

Examples
--------
>>> r = run_case("cavity", n_radial=10, periods=1.0)
>>> r.case, r.error < 0.02  # measured 1.2e-2 (sbp, 10 spacings per radius)
('cavity', True)
"""

from __future__ import annotations

from typing import Any

from ..._validation import check_in
from ..results import CaseResult
from .cavity import (
    cavity_exact,
    cavity_frequency,
    peak_frequency,
    run_cavity,
    run_tez_cavity,
    run_tez_circular_cavity,
    tez_cavity_frequency,
    tez_disk_frequency,
    tez_disk_mode,
)
from .common import dft_phasor, l2_error, relative_error
from .line import run_line1d
from .propagation import (
    adjacent_line_difference,
    alternating_amplitude,
    guided_exact,
    run_planewave,
    run_pml,
    run_tez_pml,
    run_waveguide,
)
from .scattering import run_scattering, run_tez_scattering, scattering_layout, tez_scattering_layout

__all__ = ["CASES", "run_case", "relative_error", "l2_error", "dft_phasor", "run_line1d", "cavity_exact",
           "cavity_frequency", "peak_frequency", "run_cavity", "tez_cavity_frequency", "run_tez_cavity",
           "tez_disk_frequency", "tez_disk_mode", "run_tez_circular_cavity", "guided_exact", "adjacent_line_difference",
           "alternating_amplitude", "run_planewave", "run_waveguide", "run_pml", "run_tez_pml", "scattering_layout",
           "tez_scattering_layout", "run_scattering", "run_tez_scattering"]

#: The TMz cases of :func:`run_case` (``manifold-sph spem CASE``).
CASES = ("line1d", "cavity", "waveguide", "planewave", "pml")


def run_case(case: str, **kwargs: Any) -> CaseResult:
    """Run a TMz case by name (see :data:`CASES`) with the keyword arguments of its ``run_*`` function."""
    check_in("case", case, CASES)
    fn = {"line1d": run_line1d, "cavity": run_cavity, "waveguide": run_waveguide, "planewave": run_planewave,
          "pml": run_pml}[case]
    return fn(**kwargs)
