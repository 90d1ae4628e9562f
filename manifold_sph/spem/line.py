"""The leap-frog SPEM solver on a line: Ex on E particles, Hy on H particles ([2] sec. 4.2).

Examples
--------
>>> from manifold_sph.spem import line_layout
>>> e, h = line_layout(0.0, 1.0, 0.01)
>>> Line1DSolver(e, h, h=0.018).run(5).times.shape
(5,)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_positive
from .constants import C0, EPS0, MU0
from .operators import cross_gradient
from .sources import Source
from .stability import cfl_number, check_dt, per_particle
from .stepping import Leapfrog

if TYPE_CHECKING:
    from ..kernels import Kernel

__all__ = ["Line1DSolver"]


class Line1DSolver(Leapfrog):
    """SPEM on a line: Ex on E particles, Hy on H particles ([2] sec. 4.2).

    ``dEx/dt = -(1/eps) dHy/dz``, ``dHy/dt = -(1/mu) dEx/dz``; the end E
    particles are held at zero (PEC) unless ``fixed_ends=False``.

    Examples
    --------
    >>> from manifold_sph.spem import line_layout
    >>> e, h = line_layout(0.0, 1.0, 0.01)
    >>> s = Line1DSolver(e, h, h=0.018)
    >>> s.n_e, len(s.h_points)
    (101, 100)
    >>> round(Line1DSolver(e, h, h=0.018, eps_r=0.25).dt / s.dt, 12)  # the fastest speed sets dt
    0.5
    """

    def __init__(self, e_points: ArrayLike, h_points: ArrayLike, *, h: float, kernel: str | Kernel | type[Kernel] = "cubic",
                 form: str = "fpm", eps_r: float | ArrayLike | Callable[[np.ndarray], ArrayLike] = 1.0,
                 mu_r: float | ArrayLike | Callable[[np.ndarray], ArrayLike] = 1.0, dt: float | None = None,
                 courant: float = 0.9, sources: Sequence[Source] = (), fixed_ends: bool = True) -> None:
        self.e_points = np.asarray(e_points, dtype=np.float64).reshape(-1, 1)
        self.h_points = np.asarray(h_points, dtype=np.float64).reshape(-1, 1)
        self.h = check_positive("h", h)
        self.n_e = len(self.e_points)
        fixed = np.zeros(self.n_e, bool)
        if fixed_ends and self.n_e:
            fixed[np.argmin(self.e_points[:, 0])] = fixed[np.argmax(self.e_points[:, 0])] = True
        self.fixed = fixed
        self.free = np.flatnonzero(~fixed)
        self.D_e = cross_gradient(self.e_points[self.free], self.h_points, self.h, kernel=kernel, form=form,
                                  row_name="E particles", col_name="H particles")[0]
        self.D_h = cross_gradient(self.h_points, self.e_points, self.h, kernel=kernel, form=form,
                                  row_name="H particles", col_name="E particles")[0]
        self.eps = EPS0 * per_particle("eps_r", eps_r, self.e_points)
        self.mu = MU0 * per_particle("mu_r", mu_r, self.h_points)
        self.c_max = C0 / math.sqrt(float(self.eps.min() / EPS0) * float(self.mu.min() / MU0))
        self.dt = check_dt(dt, self.h, courant, self.c_max)
        self.courant = cfl_number(self.dt, self.h, self.c_max)
        self.sources = list(sources)
        self.ex = np.zeros(self.n_e)
        self.hy = np.zeros(len(self.h_points))
        self.t = 0.0
        self.n = 0

    @property
    def e_field(self) -> np.ndarray:
        """Ex at the E particles."""
        return self.ex

    @property
    def field(self) -> np.ndarray:
        """What ``run`` records: Ex (:attr:`e_field`)."""
        return self.ex

    def step(self) -> None:
        """One leap-frog step."""
        fr = self.free
        self.ex[fr] -= self.dt / self.eps[fr] * (self.D_e @ self.hy)
        self.n += 1
        self.t = self.n * self.dt
        for s in self.sources:
            v = s.waveform(self.t)
            if s.kind == "hard":
                self.ex[s.indices] = v
            else:
                self.ex[s.indices] += v
        self.hy -= self.dt / self.mu * (self.D_h @ self.ex)
