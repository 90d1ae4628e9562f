"""TEz polarisation (Hz, Ex, Ey) on particles, beside the TMz solver (issue 21 item 4).

The fields of TEz waves in the plane:

    mu dHz/dt = dEx/dy - dEy/dx,   eps dEx/dt = dHz/dy,   eps dEy/dt = -dHz/dx,

leap-frog with Hz at integer and E at half steps. The layout is the Yee
lattice of TEz (:func:`tez_layout`): Hz at the cell centres, Ex at
``(i + 1/2, j) dr`` and Ey at ``(i, j + 1/2) dr``; on a PEC wall the
tangential E particles (Ex on the walls ``y = const``, Ey on ``x = const``)
are held at zero and Hz needs no boundary particle (its condition,
``dHz/dn = 0``, is natural).

Couplings, as in :class:`.TMzSolver`:

``"sbp"`` (default)
    The Hz rows ``D`` (CSPM derivatives of the free E particles; the wall
    particles carry zero) are corrected by :func:`.operators.sbp_pair` so
    that the E rows ``-V_E^-1 D^T V_Hz`` are exact for linear fields: a
    skew-adjoint pair, so leap-frog conserves the discrete energy.
``"adjoint"``
    The E rows are ``-D^T`` without the correction (energy-conserving, not
    consistent next to walls).
``"direct"``
    Each set by its own CSPM derivatives; the spectrum of the Hz -> Hz
    operator is computed and a growing layout refused (ValueError).

Examples
--------
>>> r = run_tez_cavity(n=6, modes=((1, 0),))
>>> r.case, r.frequency_error < 0.02
('tez-cavity', True)
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from .._validation import check_in, check_int, check_positive
from .constants import C0, EPS0, MU0
from .operators import SBP_LAYERS, cross_gradient, sbp_pair
from .solver import COUPLINGS, DEFAULT_COUPLING, DEFAULT_H_RATIO, STABILITY_MARGIN, leapfrog_growth, spectral_radius_bound

#: Couplings of :class:`TEzSolver` (those of :class:`.TMzSolver` but "mimetic").
TEZ_COUPLINGS = tuple(c for c in COUPLINGS if c != "mimetic")

__all__ = ["TEzLayout", "tez_layout", "TEzSolver", "TEzCavityResult", "tez_cavity_frequency", "run_tez_cavity"]


@dataclass(frozen=True)
class TEzLayout:
    """Particles of a TEz problem.

    Attributes
    ----------
    hz, ex, ey : (N, 2) arrays
        Hz, Ex and Ey particles.
    ex_fixed, ey_fixed : bool arrays
        E particles held at zero (tangential E on a PEC wall).
    dr : float
        Spacing.
    bounds : tuple
        ``(xmin, xmax, ymin, ymax)``.
    """

    hz: np.ndarray
    ex: np.ndarray
    ey: np.ndarray
    ex_fixed: np.ndarray
    ey_fixed: np.ndarray
    dr: float
    bounds: tuple

    @property
    def n_particles(self) -> int:
        """Hz + Ex + Ey particles."""
        return len(self.hz) + len(self.ex) + len(self.ey)


def tez_layout(bounds: Sequence[float], dr: float, *, amplitude: float = 0.0, seed: int | None = 0) -> TEzLayout:
    """The TEz Yee lattice in a PEC rectangle (the sides multiples of ``dr``), optionally jittered.

    ``amplitude`` > 0 moves every Hz particle and every free E particle by a
    uniform random offset of at most ``amplitude * dr`` per coordinate
    (clipped into the rectangle); the wall E particles stay on the walls.

    >>> lay = tez_layout((0.0, 1.0, 0.0, 0.5), 0.25)
    >>> len(lay.hz), len(lay.ex), int(lay.ex_fixed.sum()), len(lay.ey), int(lay.ey_fixed.sum())
    (8, 12, 8, 10, 4)
    """
    dr = check_positive("dr", dr)
    b = np.asarray(bounds, dtype=np.float64)
    if b.shape != (4,) or not np.all(np.isfinite(b)) or b[1] <= b[0] or b[3] <= b[2]:
        raise ValueError(f"bounds must be (xmin, xmax, ymin, ymax) with xmin < xmax and ymin < ymax, got {bounds!r}")
    nx = int(round((b[1] - b[0]) / dr))
    ny = int(round((b[3] - b[2]) / dr))
    if nx < 2 or ny < 2 or abs(nx * dr - (b[1] - b[0])) > 1e-6 * dr or abs(ny * dr - (b[3] - b[2])) > 1e-6 * dr:
        raise ValueError(f"the sides of bounds {tuple(b.tolist())} must be multiples (>= 2) of dr = {dr}")

    def grid(mx, my, ox, oy):
        X, Y = np.meshgrid(b[0] + (np.arange(mx) + ox) * dr, b[2] + (np.arange(my) + oy) * dr, indexing="ij")
        return np.column_stack([X.ravel(), Y.ravel()])

    hz = grid(nx, ny, 0.5, 0.5)
    ex = grid(nx, ny + 1, 0.5, 0.0)
    ey = grid(nx + 1, ny, 0.0, 0.5)
    tol = 1e-6 * dr
    ex_fixed = (np.abs(ex[:, 1] - b[2]) < tol) | (np.abs(ex[:, 1] - b[3]) < tol)
    ey_fixed = (np.abs(ey[:, 0] - b[0]) < tol) | (np.abs(ey[:, 0] - b[1]) < tol)
    amplitude = check_positive("amplitude", amplitude, allow_zero=True)
    if amplitude >= 0.5:
        raise ValueError(f"amplitude must be below 0.5 (particles would cross), got {amplitude}")
    if amplitude:
        rng = np.random.default_rng(seed)
        lo, hi = np.array([b[0], b[2]]), np.array([b[1], b[3]])

        def move(p, frozen):
            q = p + amplitude * dr * rng.uniform(-1.0, 1.0, p.shape)
            q[frozen] = p[frozen]
            return np.clip(q, lo, hi)

        hz = move(hz, np.zeros(len(hz), bool))
        ex = move(ex, ex_fixed)
        ey = move(ey, ey_fixed)
    return TEzLayout(hz, ex, ey, ex_fixed, ey_fixed, dr, tuple(float(v) for v in b))


class TEzSolver:
    """Leap-frog SPEM for TEz waves (module docstring) in a PEC rectangle.

    Parameters
    ----------
    layout : TEzLayout
    h_ratio : float
        ``h / dr`` (default 0.7, cubic kernel).
    eps_r, mu_r : float
        Relative permittivity (E particles) and permeability (Hz particles), finite and > 0.
    coupling : {"sbp", "adjoint", "direct"}
    courant : float
        Fraction of the smaller of the CFL step ``h / (sqrt(2) c_max)`` and
        the spectral limit ``2 / sqrt(rho)`` (default 0.9).
    kernel, form : str
        As :func:`.operators.cross_gradient`.
    sbp_layers : int or None
        As :class:`.TMzSolver`.

    Examples
    --------
    >>> s = TEzSolver(tez_layout((0.0, 0.1, 0.0, 0.1), 0.01))
    >>> s.set_initial(np.cos(np.pi * s.layout.hz[:, 0] / 0.1))
    >>> _ = s.run(50)
    >>> bool(abs(s.energy() / s.energy0 - 1) < 1e-12)  # "sbp": the discrete energy is conserved
    True
    """

    def __init__(self, layout: TEzLayout, *, h_ratio: float = DEFAULT_H_RATIO, eps_r: float = 1.0, mu_r: float = 1.0,
                 coupling: str = DEFAULT_COUPLING, courant: float = 0.9, kernel: str = "cubic", form: str = "fpm",
                 sbp_layers: int | None = SBP_LAYERS) -> None:
        if not isinstance(layout, TEzLayout):
            raise TypeError(f"layout must be a TEzLayout, got {type(layout).__name__}")
        self.layout = layout
        self.h = check_positive("h_ratio", h_ratio) * layout.dr
        if coupling == "mimetic":  # not built for TEz (its wall particles are the vector set's): never run another
            raise ValueError("coupling 'mimetic' is available for TMz only (TMzSolver); TEzSolver offers "
                             f"{', '.join(repr(c) for c in TEZ_COUPLINGS)}")
        self.coupling = check_in("coupling", coupling, TEZ_COUPLINGS)
        courant = check_positive("courant", courant)
        if courant > 1:
            raise ValueError(f"courant must be at most 1, got {courant}")
        self.eps = EPS0 * check_positive("eps_r", eps_r)
        self.mu = MU0 * check_positive("mu_r", mu_r)
        self.c_max = 1.0 / math.sqrt(self.eps * self.mu)
        lay = layout
        self.fx = np.flatnonzero(~lay.ex_fixed)
        self.fy = np.flatnonzero(~lay.ey_fixed)
        kw = {"kernel": kernel, "form": form}
        # Hz rows: d/dx of Ey and d/dy of Ex (the wall E particles carry zero: their columns are dropped)
        Dx = cross_gradient(lay.hz, lay.ey, self.h, row_name="Hz particles", col_name="Ey particles", **kw)[0]
        Dy = cross_gradient(lay.hz, lay.ex, self.h, row_name="Hz particles", col_name="Ex particles", **kw)[1]
        Dx, Dy = sp.csr_matrix(Dx)[:, self.fy], sp.csr_matrix(Dy)[:, self.fx]
        if self.coupling == "sbp":
            vol_h = np.ones(len(lay.hz))
            Dx, _ = sbp_pair(Dx, lay.hz, lay.ey[self.fy], 0, vol_h, np.ones(len(self.fy)), scale=lay.dr,
                             layers=sbp_layers)
            Dy, _ = sbp_pair(Dy, lay.hz, lay.ex[self.fx], 1, vol_h, np.ones(len(self.fx)), scale=lay.dr,
                             layers=sbp_layers)
        if self.coupling == "direct":
            Gx = cross_gradient(lay.ey[self.fy], lay.hz, self.h, row_name="Ey particles", col_name="Hz particles",
                                **kw)[0]
            Gy = cross_gradient(lay.ex[self.fx], lay.hz, self.h, row_name="Ex particles", col_name="Hz particles",
                                **kw)[1]
        else:
            Gx, Gy = -Dx.T, -Dy.T
        self.Dx, self.Dy, self.Gx, self.Gy = (sp.csr_matrix(M) for M in (Dx, Dy, Gx, Gy))
        L = (self.Dx @ self.Gx + self.Dy @ self.Gy) / (self.eps * self.mu)  # Hz'' = L Hz
        self._check_spectrum(L.tocsr(), courant)
        self.reset()

    def _check_spectrum(self, L, courant):
        from scipy.sparse.linalg import eigs

        if self.coupling == "direct":
            lam = np.linalg.eigvals(L.toarray()) if L.shape[0] <= 900 else np.concatenate(
                [eigs(L, k=8, which="LM", return_eigenvectors=False), eigs(L, k=8, which="LI",
                                                                        return_eigenvectors=False)])
            rho = float(np.abs(lam).max())
        else:
            lam = None
            theta, bound = spectral_radius_bound(0.5 * (L + L.T))  # -D D^T: negative semi-definite
            rho = max(bound, theta * (1.0 + STABILITY_MARGIN)) / (1.0 + STABILITY_MARGIN)  # as TMzSolver's
        self.dt_stable = 2.0 / math.sqrt(rho * (1.0 + STABILITY_MARGIN))  # the margin: at least 0.5 %
        self.dt = courant * min(self.dt_stable, self.h / (math.sqrt(2.0) * self.c_max))
        if lam is not None:
            g = float(leapfrog_growth(lam, self.dt).max())
            if g > 1.0 + 1e-12:
                raise ValueError(f"the direct coupling is unstable on this layout: a leap-frog mode grows by {g:.6g} "
                                 f"per step; use coupling='sbp' (energy-conserving)")

    @property
    def n_particles(self) -> int:
        """Hz + Ex + Ey particles."""
        return self.layout.n_particles

    def reset(self) -> None:
        """Zero the fields, t = 0."""
        self.hz = np.zeros(len(self.layout.hz))
        self.ex = np.zeros(len(self.fx))
        self.ey = np.zeros(len(self.fy))
        self.t, self.n = 0.0, 0
        self.energy0 = 0.0

    def set_dt(self, dt: float) -> None:
        """Change the step (below the CFL and spectral limits); call before :meth:`set_initial`."""
        dt = check_positive("dt", dt)
        limit = min(self.dt_stable, self.h / (math.sqrt(2.0) * self.c_max))
        if dt >= limit:
            raise ValueError(f"dt = {dt:.4g} s exceeds the stability limit {limit:.4g} s")
        self.dt = dt

    def set_initial(self, hz0: ArrayLike) -> None:
        """Hz(0) = hz0 with E(0) = 0, E advanced half a step (second order for fields even in time)."""
        from .._validation import as_field

        self.reset()
        self.hz = as_field("hz0", hz0, len(self.layout.hz)).copy()
        self.ex = 0.5 * self.dt / self.eps * (self.Gy @ self.hz)
        self.ey = -0.5 * self.dt / self.eps * (self.Gx @ self.hz)
        self.energy0 = self.energy()

    def energy(self) -> float:
        """``mu Hz^n . Hz^n + eps E^{n+1/2} . E^{n-1/2}``, conserved by leap-frog when ``G = -D^T`` ("sbp", "adjoint").

        ``E^{n-1/2}`` is reconstructed from the last update.
        """
        ex_prev = self.ex - self.dt / self.eps * (self.Gy @ self.hz)
        ey_prev = self.ey + self.dt / self.eps * (self.Gx @ self.hz)
        return float(self.mu * self.hz @ self.hz + self.eps * (self.ex @ ex_prev + self.ey @ ey_prev))

    def step(self) -> None:
        """Hz to t + dt, then E to t + 3 dt / 2."""
        self.hz += self.dt / self.mu * (self.Dy @ self.ex - self.Dx @ self.ey)
        self.n += 1
        self.t = self.n * self.dt
        self.ex += self.dt / self.eps * (self.Gy @ self.hz)
        self.ey -= self.dt / self.eps * (self.Gx @ self.hz)

    def run(self, steps: int, probe: int | None = None) -> np.ndarray:
        """Advance ``steps`` steps; the Hz series at particle ``probe`` (empty without)."""
        steps = check_int("steps", steps, minimum=0)
        out = np.empty(steps if probe is not None else 0)
        for k in range(steps):
            self.step()
            if probe is not None:
                out[k] = self.hz[probe]
        return out


def tez_cavity_frequency(a: float, b: float, m: int, n: int, eps_r: float = 1.0, mu_r: float = 1.0) -> float:
    """Exact TE_mn resonance ``c / (2 sqrt(eps_r mu_r)) sqrt((m/a)^2 + (n/b)^2)`` of a PEC rectangle a x b (Hz).

    >>> round(tez_cavity_frequency(0.1, 0.05, 1, 0) / 1e9, 6)
    1.498962
    """
    a, b = check_positive("a", a), check_positive("b", b)
    m, n = check_int("m", m, minimum=0), check_int("n", n, minimum=0)
    if m == n == 0:
        raise ValueError("m and n must not both be 0 (TE_00 is not a mode)")
    return C0 / (2 * math.sqrt(eps_r * mu_r)) * math.hypot(m / a, n / b)


@dataclass(frozen=True)
class TEzCavityResult:
    """What :func:`run_tez_cavity` measured.

    ``error``: relative L2 error of Hz after ``periods`` periods of the first
    mode (its initial field evolved exactly); ``frequency_error``: relative
    error of that mode's resonance, fitted to the projection of Hz onto the mode.
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

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict."""
        return dict(self.__dict__)


def run_tez_cavity(*, a: float = 0.1, b: float = 0.06, n: int = 12, modes: Sequence[tuple[int, int]] = ((1, 0), (1, 1)),
                   eps_r: float = 1.0, layout: str = "yee", amplitude: float = 0.2, seed: int | None = 0,
                   coupling: str = DEFAULT_COUPLING, h_ratio: float = DEFAULT_H_RATIO,
                   courant: float = 0.9, periods: float = 1.0, spectrum_periods: float = 5.0,
                   sbp_layers: int | None = SBP_LAYERS) -> TEzCavityResult:
    """TEz modes of a PEC rectangle ``a x b``: ``Hz = sum cos(m pi x/a) cos(n pi y/b) cos(w_mn t)``.

    ``n`` spacings along ``b`` (``dr = b / n``; ``a`` must be a multiple of
    ``dr``). The field starts as the sum of the ``modes`` (each ``(m, n)``),
    runs ``periods`` periods of the first, and is compared with the exact
    evolution (``error``; on ``layout="jittered"`` particles the particles
    move by up to ``amplitude * dr``); the run continues ``spectrum_periods``
    periods and the first mode's resonance is fitted to the projection of Hz
    onto it (``frequency_error``).

    Examples
    --------
    >>> r = run_tez_cavity(n=6)
    >>> r.error < 0.05, r.frequency_error < 0.005  # measured 4.2e-2 and 3.3e-3
    (True, True)
    """
    t0 = time.perf_counter()
    n = check_int("n", n, minimum=2)
    periods = check_positive("periods", periods)
    spectrum_periods = check_positive("spectrum_periods", spectrum_periods)
    try:
        modes = [(int(m), int(k)) for m, k in modes]
    except (TypeError, ValueError):
        raise ValueError(f"modes must be a sequence of (m, n) integer pairs, got {modes!r}") from None
    if not modes:
        raise ValueError("modes must name at least one (m, n) mode")
    dr = check_positive("b", b) / n
    check_in("layout", layout, ("yee", "jittered"))
    lay = tez_layout((0.0, check_positive("a", a), 0.0, b), dr, amplitude=amplitude if layout == "jittered" else 0.0,
                     seed=seed)
    s = TEzSolver(lay, h_ratio=h_ratio, eps_r=eps_r, coupling=coupling, courant=courant, sbp_layers=sbp_layers)
    x, y = lay.hz.T
    shapes = [np.cos(m * np.pi * x / a) * np.cos(k * np.pi * y / b) for m, k in modes]
    freqs = [tez_cavity_frequency(a, b, m, k, eps_r) for m, k in modes]
    T = periods / freqs[0]
    steps = int(math.ceil(T / s.dt - 1e-9))
    s.set_dt(T / steps)
    s.set_initial(sum(shapes))
    s.run(steps)
    exact = sum(f * math.cos(2 * math.pi * fr * s.t) for f, fr in zip(shapes, freqs))
    err = float(np.linalg.norm(s.hz - exact) / np.linalg.norm(exact))
    # the first mode's resonance: its amplitude a(t) = q.Hz over ``spectrum_periods`` more periods, fitted by
    # A cos(w t) + B sin(w t) (least squares over w)
    q = shapes[0] / (shapes[0] @ shapes[0])
    more = int(round(spectrum_periods / freqs[0] / s.dt))
    amp = np.empty(more)
    for k in range(more):
        s.step()
        amp[k] = q @ s.hz
    fm = _fit_frequency(amp, s.dt * (steps + 1 + np.arange(more)), freqs[0])
    return TEzCavityResult("tez-cavity", err, abs(fm - freqs[0]) / freqs[0], fm, freqs[0], lay.n_particles, s.n,
                           time.perf_counter() - t0, dr, s.dt, coupling, layout)


def _fit_frequency(signal, times, f0):
    """The frequency ``f`` near ``f0`` (within 10 %) of the best fit ``A cos(2 pi f t) + B sin(2 pi f t)``."""
    from scipy.optimize import minimize_scalar

    def residual(f):
        M = np.column_stack([np.cos(2 * np.pi * f * times), np.sin(2 * np.pi * f * times)])
        coef = np.linalg.lstsq(M, signal, rcond=None)[0]
        return float(np.sum((M @ coef - signal) ** 2))

    grid = f0 * np.linspace(0.9, 1.1, 81)
    k = int(np.argmin([residual(f) for f in grid]))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    return float(minimize_scalar(residual, bounds=(lo, hi), method="bounded", options={"xatol": 1e-9 * f0}).x)
