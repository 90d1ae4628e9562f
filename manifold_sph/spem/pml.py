"""Berenger split-field PML profiles (the thesis [2] eqs. 3.17-3.26; docs/method.md section 7).

``sigma(rho) = sigma_m (rho/delta)^n`` with ``rho`` the depth into a layer of
thickness ``delta``; ``sigma_m = -ln(R0) (n+1) eps0 c / (2 delta)`` gives the
normal-incidence round-trip reflection ``R0`` of the continuous layer. The
magnetic conductivity is matched: ``sigma*/mu0 = sigma/eps0``.

Examples
--------
>>> p = PML(0.1, order=3, reflection=1e-6, interior=(0.0, 1.0, 0.0, 1.0), sides="right")
>>> sx, sy = p.sigma(np.array([[0.5, 0.5], [1.1, 0.5]]))
>>> bool(sx[0] == 0 and np.isclose(sx[1], p.sigma_max)), bool(np.all(sy == 0))
(True, True)
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_int, check_positive
from .constants import C0, EPS0

__all__ = ["PML", "sigma_max"]

_SIDES = ("left", "right", "bottom", "top")


def sigma_max(thickness: float, order: int = 3, reflection: float = 1e-6) -> float:
    """``sigma_m = -ln(R0) (n + 1) eps0 c / (2 delta)`` ([2] eq. 3.26), in S/m."""
    thickness = check_positive("thickness", thickness)
    order = check_int("order", order, minimum=0)
    reflection = check_positive("reflection", reflection)
    if reflection >= 1:
        raise ValueError(f"reflection must be below 1, got {reflection}")
    return -math.log(reflection) * (order + 1) * EPS0 * C0 / (2 * thickness)


class PML:
    """Graded absorbing layers outside the rectangle ``interior``.

    Parameters
    ----------
    thickness : float
        Layer thickness delta (m).
    order : int
        Grading exponent n (3 or 4 usually).
    reflection : float
        Target normal-incidence reflection R0 of the layer.
    interior : (xmin, xmax, ymin, ymax)
        The non-absorbing region; layers lie beyond its selected sides.
    sides : str or sequence
        Any of "left", "right", "bottom", "top", or "all".
    """

    def __init__(self, thickness: float, order: int = 3, reflection: float = 1e-6, *, interior: Sequence[float],
                 sides: str | Sequence[str] = "all") -> None:
        self.thickness = check_positive("thickness", thickness)
        self.order = check_int("order", order, minimum=0)
        self.reflection = float(reflection)
        self.sigma_max = sigma_max(thickness, order, reflection)
        b = np.asarray(interior, dtype=np.float64)
        if b.shape != (4,) or b[1] <= b[0] or b[3] <= b[2]:
            raise ValueError(f"interior must be (xmin, xmax, ymin, ymax), got {interior!r}")
        self.interior = tuple(float(v) for v in b)
        sides = _SIDES if sides == "all" else ((sides,) if isinstance(sides, str) else tuple(sides))
        for s in sides:
            if s not in _SIDES:
                raise ValueError(f"sides must be 'all' or among {_SIDES}, got {s!r}")
        self.sides = sides

    def _profile(self, rho):
        rho = np.clip(rho, 0.0, self.thickness)
        return self.sigma_max * (rho / self.thickness) ** self.order

    def sigma(self, points: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Electric conductivities ``(sigma_x, sigma_y)`` (S/m) at ``points`` (N, 2)."""
        p = np.asarray(points, dtype=np.float64)
        x0, x1, y0, y1 = self.interior
        sx = np.zeros(len(p))
        sy = np.zeros(len(p))
        if "left" in self.sides:
            sx += self._profile(x0 - p[:, 0])
        if "right" in self.sides:
            sx += self._profile(p[:, 0] - x1)
        if "bottom" in self.sides:
            sy += self._profile(y0 - p[:, 1])
        if "top" in self.sides:
            sy += self._profile(p[:, 1] - y1)
        return sx, sy

    def calm_bounds(self) -> tuple[float, float, float, float]:
        """The interior with the sides that carry no layer open (infinite): where a jittered layout may
        move its particles (:func:`.layouts.jitter`'s ``calm``)."""
        x0, x1, y0, y1 = self.interior
        inf = math.inf
        return (x0 if "left" in self.sides else -inf, x1 if "right" in self.sides else inf,
                y0 if "bottom" in self.sides else -inf, y1 if "top" in self.sides else inf)

    def outer_bounds(self) -> tuple[float, float, float, float]:
        """The interior grown by the thickness on the PML sides."""
        x0, x1, y0, y1 = self.interior
        t = self.thickness
        return (x0 - t * ("left" in self.sides), x1 + t * ("right" in self.sides),
                y0 - t * ("bottom" in self.sides), y1 + t * ("top" in self.sides))
