"""Physical constants in SI units (CODATA 2018)."""

from __future__ import annotations

import math

__all__ = ["EPS0", "MU0", "C0", "ETA0"]

#: Vacuum permittivity, F/m.
EPS0 = 8.8541878128e-12
#: Vacuum permeability, H/m.
MU0 = 1.25663706212e-6
#: Speed of light in vacuum, m/s.
C0 = 1.0 / math.sqrt(EPS0 * MU0)
#: Impedance of free space, ohm.
ETA0 = math.sqrt(MU0 / EPS0)
