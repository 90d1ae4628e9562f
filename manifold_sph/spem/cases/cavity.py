"""Cavity cases with exact modes: the TMz dielectric disk of [2] and the TEz PEC rectangle and disk.

Examples
--------
>>> r = run_cavity(n_radial=10, periods=1.0)
>>> r.case, r.error < 0.02  # measured 1.2e-2 (sbp, 10 spacings per radius)
('cavity', True)
>>> r = run_tez_cavity(n=6, modes=((1, 0),))
>>> r.case, r.frequency_error < 0.02
('tez-cavity', True)
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import j0, j1, jn_zeros

from ..._validation import as_points, check_in, check_int, check_positive
from ..certify import certificate_failures, certified
from ..constants import C0, EPS0, MU0
from ..layouts import POISSON_H_RATIO, disk_layout, tez_disk_layout, tez_layout, wall_closure_layout
from ..operators import DEFAULT_COUPLING, DEFAULT_H_RATIO, SBP_LAYERS
from ..results import CavityResult, TEzCavityResult
from ..tez import DISK_H_RATIO, TEzSolver
from ..tmz import TMzSolver

if TYPE_CHECKING:
    from ...kernels import Kernel

from .common import check_every, field_history, fit_solver_dt, relative_error, timed

__all__ = ["cavity_exact", "cavity_frequency", "peak_frequency", "run_cavity", "tez_cavity_frequency", "run_tez_cavity",
           "TEZ_RECTANGLE_H_RATIO_MAX", "check_tez_rectangle_support", "TEZ_DISK_H_RATIO_MAX",
           "CAVITY_H_RATIO_MAX", "CAVITY_POISSON_N_RADIAL_MAX", "check_cavity_support",
           "tez_disk_frequency", "tez_disk_mode", "run_tez_circular_cavity"]


#: Largest ``h / dr`` validated for the TEz rectangle (:func:`run_tez_cavity`) per layout; None: no support
#: validated. Measured at 12 spacings (modes (1, 0) + (1, 1), one period, "sbp"; the lattice's default 9.1e-3):
#: lattice with closure walls 6.5e-3 / 1.5e-2 / 5.3e-2 / 6.2e-2 / 5.0e-2 / 1.3e-1 at h/dr 0.8 / 1.0 / 1.1 / 1.2 /
#: 1.3 / 1.5 (plain walls at 1.3: 0.32, the frequency 4.4 % off); jittered (closure walls) 1.9e-2 / 2.4e-2 /
#: 4.6e-2 - 7.8e-2 (seeds 0-2) / 1.0e-1 / 1.4e-1 at 0.8 / 0.9 / 1.0 / 1.1 / 1.2; Poisson (closure walls) 4.4e-2 -
#: 4.7e-2 or refused (seeds 0-2) / 5.2e-2 - 9.5e-2 / 1.1e-1 / 1.5e-1 / 1.8e-1 at 0.9 / 1.0 / 1.1 / 1.2 / 1.5:
#: its Hz operator's spurious modes (docs/spem.md) keep it above 5x the lattice at every support.
TEZ_RECTANGLE_H_RATIO_MAX = {"yee": 1.3, "jittered": 1.0, "poisson": None, "poisson-shared": None}


def check_tez_rectangle_support(layout: str, h_ratio: float) -> None:
    """Refuse (ValueError) a layout and support of the TEz rectangle outside :data:`TEZ_RECTANGLE_H_RATIO_MAX`."""
    top = TEZ_RECTANGLE_H_RATIO_MAX[layout]
    lattice = TEZ_RECTANGLE_H_RATIO_MAX["yee"]
    if top is None:
        raise ValueError(
            f"layout = {layout!r} is outside the validated range of the TEz rectangle: its Hz operator has spurious "
            f"modes below the fundamental and the error is 5-20x the lattice's at every h_ratio 0.9-1.5 (1.5e-1 at 12 "
            f"spacings, h_ratio 1.2); use layout 'yee' (h_ratio <= {lattice}) or 'jittered' (h_ratio <= "
            f"{TEZ_RECTANGLE_H_RATIO_MAX['jittered']}), or support_check=False to run anyway")
    if h_ratio > top * (1 + 1e-9):
        raise ValueError(
            f"h_ratio = {h_ratio:.3g} is outside the validated range of the TEz rectangle on layout {layout!r} "
            f"(h_ratio <= {top}: beyond it the error exceeds 10x the lattice's); use h_ratio <= {top}, or "
            f"support_check=False to run anyway")


#: Largest ``h / dr`` validated for the TEz disk (:func:`run_tez_circular_cavity`) per layout. Measured at 10
#: spacings per radius (TE11 + TE21, one period; the lattice's default, h/dr 0.8: 2.52e-2): lattice 4.3e-2 /
#: 6.2e-2 / 1.3e-1 / 1.5e-1 / 2.8e-1 at h/dr 0.6 / 1.0 / 1.3 / 1.5 / 2.0 (11x at 2.0); jittered 8.3e-2 / 1.1e-1 /
#: 1.7e-1 / 3.5e-1 at 1.0 / 1.3 / 1.5 / 2.0 (14x at 2.0); Poisson 1.2e-1 / 1.8e-1 / 1.8e-1 / 3.6e-1 / 6.0e-1 at
#: 1.0 / 1.2 / 1.3 / 1.5 / 2.0 (14x at 1.5). "poisson-shared" takes the Poisson value (not measured apart).
TEZ_DISK_H_RATIO_MAX = {"yee": 1.5, "jittered": 1.5, "poisson": 1.3, "poisson-shared": 1.3}


#: Largest ``h / dr`` validated for the TMz cavity (:func:`run_cavity`, couplings other than "mimetic"). Measured
#: (error over the lattice's at the default support, the same spacing): lattice / jittered / Poisson at h/dr 2.0
#: 3.4x / 3.0x / 3.7x at 10 spacings per radius, 6.8x / 6.7x / 7.6x at 20, 6.3x / 7.1x / 19x at 40; at 10 spacings
#: per radius 5.6x / 5.5x / 5.1x at 2.5 and 25x / 24x / 20x at 4.0; Poisson (and joint) at 40: 8.5x / 7.4x / 11x
#: at h/dr 1.2 / 1.3 / 1.5.
CAVITY_H_RATIO_MAX = {"yee": 2.0, "staggered": 2.0, "jittered": 2.0, "poisson": 1.3, "poisson-joint": 1.3,
                      "poisson-balanced": 1.3}
#: Finest Poisson disk (spacings per radius) validated for the cavity with the "sbp", "adjoint" and "direct"
#: couplings: "sbp" is not convergent on independently sampled sets (error over the lattice's 2.8x / 8.5x / 16x
#: at 10 / 40 / 80 spacings per radius: 3.4e-2, 7.0e-3, 5.2e-3 against 1.2e-2, 8.2e-4, 3.3e-4).
CAVITY_POISSON_N_RADIAL_MAX = 40


def check_cavity_support(layout: str, n_radial: int, h_ratio: float | None) -> None:
    """Refuse (ValueError) a TMz cavity outside :data:`CAVITY_H_RATIO_MAX` / :data:`CAVITY_POISSON_N_RADIAL_MAX`."""
    top = CAVITY_H_RATIO_MAX[layout]
    if h_ratio is not None and h_ratio > top * (1 + 1e-9):
        raise ValueError(f"h_ratio = {h_ratio:.3g} is outside the validated range of the cavity on layout {layout!r} "
                         f"(h_ratio <= {top}: beyond it the error exceeds 10x the lattice's); use h_ratio <= {top}, "
                         f"coupling='mimetic', or support_check=False to run anyway")
    if layout.startswith("poisson") and n_radial > CAVITY_POISSON_N_RADIAL_MAX:
        raise ValueError(f"n_radial = {n_radial} is outside the validated range of the cavity on layout {layout!r} "
                         f"(n_radial <= {CAVITY_POISSON_N_RADIAL_MAX}: the 'sbp' coupling is not convergent on Poisson "
                         f"layouts, 16x the lattice at 80); use n_radial <= {CAVITY_POISSON_N_RADIAL_MAX}, "
                         f"coupling='mimetic' (second order there), or support_check=False to run anyway")


# ----------------------------------------------------------------------------- cavity
def cavity_exact(r: ArrayLike, t: float, r0: float = 0.1, eps_r: float = 10.0, n_terms: int = 200) -> np.ndarray:
    """Bessel series of the cavity ([2] eq. 4.5) for ``Ez(0) = 1 - r^2/r0^2``.

    ``Ez = 8 sum_n J0(b_n r/r0) / (b_n^3 J1(b_n)) cos(b_n t / (r0 sqrt(eps_r eps0 mu0)))``.

    >>> float(np.round(cavity_exact(np.array([0.0, 0.05]), 0.0), 4)[1])
    0.75
    """
    b = jn_zeros(0, n_terms)
    w = b / (r0 * math.sqrt(eps_r * EPS0 * MU0))
    r = np.asarray(r, dtype=np.float64)
    return 8.0 * (j0(np.outer(r, b) / r0) / (b**3 * j1(b)) * np.cos(w * t)).sum(axis=1)


def cavity_frequency(r0: float = 0.1, eps_r: float = 10.0) -> float:
    """Fundamental TM01 resonance ``b_1 c / (2 pi r0 sqrt(eps_r))`` (362.85 MHz for the defaults)."""
    return float(jn_zeros(0, 1)[0] / (2 * math.pi * r0 * math.sqrt(eps_r * EPS0 * MU0)))


def peak_frequency(signal: ArrayLike, dt: float, fmin: float = 0.0) -> float:
    """Frequency of the largest spectral peak above ``fmin``.

    Hann window, 16x zero padding, then a parabola through the log-magnitude
    of the three bins around the peak.
    """
    x = np.asarray(signal, dtype=np.float64)
    x = (x - x.mean()) * np.hanning(len(x))
    nfft = 16 * int(2 ** math.ceil(math.log2(len(x))))
    spec = np.abs(np.fft.rfft(x, nfft))
    f = np.fft.rfftfreq(nfft, dt)
    spec[f < fmin] = 0.0
    k = int(np.argmax(spec[1:-1])) + 1
    a, b, c = np.log(spec[k - 1 : k + 2] + 1e-300)
    shift = 0.5 * (a - c) / (a - 2 * b + c)
    return float(f[k] + shift * (f[1] - f[0]))


@timed
def run_cavity(*, r0: float = 0.1, eps_r: float = 10.0, n_radial: int = 40, periods: float = 1.0,
               layout: str = "yee", form: str = "fpm", kernel: str | Kernel | type[Kernel] = "cubic",
               h_ratio: float | None = None,
               courant: float = 0.9, coupling: str = DEFAULT_COUPLING, spectrum_periods: float = 0.0, every: int | None = None,
               sbp_layers: int | None = None, seed: int | np.random.Generator | None = 0,
               progress: bool = False, mimetic_fast: bool = False, support_check: bool = True) -> CavityResult:
    """Circular PEC cavity ([2] sec. 4.3), ``Ez(0) = 1 - r^2/r0^2``, compared with the Bessel series.

    ``dr = r0 / n_radial``. The error is taken over every E particle after
    ``periods`` periods of the fundamental mode. With ``spectrum_periods`` > 0
    the run continues and the fundamental resonance is read from the
    spectrum of a probe at the centre (``"f1_measured"``, relative error
    ``"f1_error"`` against the exact 362.8 MHz). ``sbp_layers`` defaults to
    None here (the whole operator is corrected: next to the curved wall it
    keeps converging where a local band stalls; :data:`.operators.SBP_LAYERS`). ``layout`` "jittered" and
    "poisson" are seeded random disks (:func:`.layouts.disk_layout`; "poisson-joint": the Poisson E set with
    its H set relaxed into the E gaps, for the "mimetic" coupling; "poisson-balanced": also H particles added
    where E outnumbers H, no spurious localised modes measured; validated with the "mimetic" coupling only,
    refused with the others: "sbp" measures 2.2e-2 at 40 spacings per radius, 27x the lattice's 8.2e-4);
    ``h_ratio`` defaults to the coupling's.
    ``mimetic_fast``: as :class:`.TMzSolver` (``coupling="mimetic"`` only). ``support_check``: refuse, with the
    couplings other than "mimetic", a support or a Poisson resolution outside :data:`CAVITY_H_RATIO_MAX` and
    :data:`CAVITY_POISSON_N_RADIAL_MAX` (:func:`check_cavity_support`).
    """
    every = check_every(every)
    r0 = check_positive("r0", r0)
    eps_r = check_positive("eps_r", eps_r)
    n_radial = check_int("n_radial", n_radial, minimum=4)
    check_in("layout", layout, ("yee", "staggered", "jittered", "poisson", "poisson-joint", "poisson-balanced"))
    if support_check and coupling != "mimetic":
        check_cavity_support(layout, n_radial, h_ratio)
    if layout == "poisson-balanced" and coupling != "mimetic":
        raise ValueError(f"layout = 'poisson-balanced' is validated with coupling='mimetic' only, got coupling = "
                         f"{coupling!r} (the 'sbp' cavity on it: 2.2e-2 at 40 spacings per radius, 27x the lattice's "
                         f"8.2e-4); use coupling='mimetic' or layout 'poisson' / 'poisson-joint'")
    dr = r0 / n_radial
    c = (r0, r0)
    lay = disk_layout(c, r0, dr, kind=layout, seed=seed)
    f1 = cavity_frequency(r0, eps_r)
    T1 = 1.0 / f1
    s = TMzSolver(lay, h_ratio=h_ratio, kernel=kernel, form=form, coupling=coupling, eps_r=eps_r, courant=courant,
                  sbp_layers=sbp_layers, mimetic_fast=mimetic_fast)
    dt, steps = fit_solver_dt(s, periods * T1)
    r = np.hypot(lay.e[:, 0] - c[0], lay.e[:, 1] - c[1])
    s.set_initial(np.clip(1.0 - r**2 / r0**2, 0.0, None))
    centre = int(np.argmin(r))
    energy0 = s.energy()
    res = s.run(steps, probes=[centre], every=every, progress=progress)
    # the energy leap-frog conserves (not defined for the "direct" coupling, which conserves none)
    energy_drift = None if coupling == "direct" else abs(s.energy() / energy0 - 1.0)
    exact = cavity_exact(r, s.t, r0, eps_r)
    out = CavityResult(case="cavity", particles=lay.n_particles, steps=steps, seconds=res.seconds,
                       step_seconds=res.seconds, error=relative_error(s.e_field, exact), dt=dt, dr=dr, layout=layout,
                       form=form, r0=r0, eps_r=eps_r, f1_exact=f1,
                       fields=field_history(lay.e, s.e_field, s.t, res, exact),
                       consistency=s.consistency_residual(),
                       consistency_interior=s.interior_consistency_residual(), energy_drift=energy_drift)
    if spectrum_periods > 0:
        more = int(round(spectrum_periods * T1 / dt))
        res2 = s.run(more, probes=[centre], progress=progress)
        sig = np.r_[res.probes[:, 0], res2.probes[:, 0]]
        fm = peak_frequency(sig, dt, fmin=0.3 * f1)
        out = dataclasses.replace(out, f1_measured=fm, f1_error=abs(fm - f1) / f1, steps=steps + more,
                                  seconds=res.seconds + res2.seconds, step_seconds=res.seconds + res2.seconds)
    return certified(out)


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


def _check_modes(modes) -> list[tuple[int, int]]:
    """``modes`` as a non-empty list of ``(m, n)`` integer pairs (ValueError otherwise)."""
    try:
        modes = [(int(m), int(k)) for m, k in modes]
    except (TypeError, ValueError):
        raise ValueError(f"modes must be a sequence of (m, n) integer pairs, got {modes!r}") from None
    if not modes:
        raise ValueError("modes must name at least one (m, n) mode")
    return modes


def run_tez_cavity(*, a: float = 0.1, b: float = 0.06, n: int = 12, modes: Sequence[tuple[int, int]] = ((1, 0), (1, 1)),
                   eps_r: float = 1.0, layout: str = "yee", amplitude: float = 0.2, seed: int | None = 0,
                   coupling: str = DEFAULT_COUPLING, h_ratio: float | None = None,
                   courant: float = 0.9, periods: float = 1.0, spectrum_periods: float = 5.0,
                   sbp_layers: int | None = SBP_LAYERS, wall_closure: bool | None = None,
                   support_check: bool = True) -> TEzCavityResult:
    """TEz modes of a PEC rectangle ``a x b``: ``Hz = sum cos(m pi x/a) cos(n pi y/b) cos(w_mn t)``.

    ``n`` spacings along ``b`` (``dr = b / n``; ``a`` must be a multiple of
    ``dr``). The field starts as the sum of the ``modes`` (each ``(m, n)``),
    runs ``periods`` periods of the first, and is compared with the exact
    evolution (``error``; on ``layout="jittered"`` particles the particles
    move by up to ``amplitude * dr``); the run continues ``spectrum_periods``
    periods and the first mode's resonance is fitted to the projection of Hz
    onto it (``frequency_error``). ``wall_closure=True``: the walls as closure
    columns with fitted volumes (:func:`wall_closure_layout`; couplings "sbp"
    and "adjoint"), which converges on jittered layouts too; None (default):
    on the jittered and Poisson layouts, and on the lattice with ``h_ratio``
    above 0.7 (on irregular layouts the plain walls' corrected rows collapse
    the step and lose the mode; on the lattice at h/dr 1.3 the plain walls
    are 0.32 off, the closure walls 5.0e-2; docs/spem.md has the numbers). ``h_ratio``
    defaults to 0.7, with ``wall_closure`` to :data:`DISK_H_RATIO` (at 0.7 an Hz
    volume of the lattice rectangle's correction turns negative and the layout is refused).
    ``support_check``: refuse a layout and support outside
    :data:`TEZ_RECTANGLE_H_RATIO_MAX` (:func:`check_tez_rectangle_support`).

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
    modes = _check_modes(modes)
    dr = check_positive("b", b) / n
    check_in("layout", layout, ("yee", "jittered", "poisson", "poisson-shared"))
    if h_ratio is not None:
        h_ratio = check_positive("h_ratio", h_ratio)
    if wall_closure is None:
        wall_closure = layout != "yee" or (h_ratio is not None and h_ratio > DEFAULT_H_RATIO * (1 + 1e-9))
    if not isinstance(wall_closure, bool):
        raise TypeError(f"wall_closure must be True, False or None, got {wall_closure!r}")
    lay = tez_layout((0.0, check_positive("a", a), 0.0, b), dr, amplitude=amplitude if layout == "jittered" else 0.0,
                     seed=seed, kind=layout if layout.startswith("poisson") else "lattice")
    if wall_closure:
        lay = wall_closure_layout(lay)
    if h_ratio is None:
        h_ratio = (POISSON_H_RATIO if layout.startswith("poisson") else DISK_H_RATIO) if wall_closure \
            else DEFAULT_H_RATIO
    if support_check:
        check_tez_rectangle_support(layout, h_ratio)
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
    result = TEzCavityResult("tez-cavity", err, abs(fm - freqs[0]) / freqs[0], fm, freqs[0], lay.n_particles, s.n,
                             time.perf_counter() - t0, dr, s.dt, coupling, layout, h_ratio=float(h_ratio),
                             wall_closure=wall_closure, consistency_interior=s.interior_consistency_residual())
    return dataclasses.replace(result, certificate_failures=certificate_failures(result))


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


def tez_disk_frequency(radius: float, m: int, n: int, eps_r: float = 1.0, mu_r: float = 1.0) -> float:
    """Exact TE_mn resonance ``c j'_mn / (2 pi a sqrt(eps_r mu_r))`` of a circular PEC cavity of radius ``a`` (Hz).

    ``j'_mn`` is the n-th positive zero of ``J_m'`` (TE11: 1.8412, TE21: 3.0542, TE01: 3.8317).

    >>> [round(tez_disk_frequency(0.1, m, 1) * 2 * np.pi * 0.1 / C0, 4) for m in (1, 0)]
    [1.8412, 3.8317]
    """
    from scipy.special import jnp_zeros

    radius = check_positive("radius", radius)
    m, n = check_int("m", m, minimum=0), check_int("n", n, minimum=1)
    eps_r, mu_r = check_positive("eps_r", eps_r), check_positive("mu_r", mu_r)
    return float(C0 * jnp_zeros(m, n)[-1] / (2 * math.pi * radius * math.sqrt(eps_r * mu_r)))


def tez_disk_mode(points: ArrayLike, center: ArrayLike, radius: float, m: int, n: int) -> np.ndarray:
    """The TE_mn mode ``Hz = J_m(j'_mn r / a) cos(m phi)`` of a circular PEC cavity at ``points`` ((N, 2)).

    >>> float(tez_disk_mode([[0.0, 0.0]], (0.0, 0.0), 0.1, 0, 1)[0])
    1.0
    """
    from scipy.special import jnp_zeros, jv


    p = as_points("points", points, dim=2) - np.asarray(center, dtype=np.float64).reshape(2)
    radius = check_positive("radius", radius)
    m, n = check_int("m", m, minimum=0), check_int("n", n, minimum=1)
    r = np.hypot(p[:, 0], p[:, 1])
    return jv(m, jnp_zeros(m, n)[-1] * r / radius) * np.cos(m * np.arctan2(p[:, 1], p[:, 0]))


def run_tez_circular_cavity(*, radius: float = 0.1, n_radial: int = 20,
                            modes: Sequence[tuple[int, int]] = ((1, 1), (2, 1)), eps_r: float = 1.0,
                            coupling: str = DEFAULT_COUPLING, h_ratio: float | None = None, courant: float = 0.9,
                            periods: float = 1.0, spectrum_periods: float = 10.0, wall_spacing: float = 0.5,
                            wall_margin: float = 0.3, layout: str = "yee", amplitude: float = 0.2,
                            seed: int | None = 0, support_check: bool = True) -> TEzCavityResult:
    """TE modes of a circular PEC cavity (curved walls, :func:`tez_disk_layout`) against the exact Bessel modes.

    ``Hz(0) = sum_(m, n) J_m(j'_mn r / a) cos(m phi)`` over ``modes`` (E = 0), ``dr = radius / n_radial``.
    After ``periods`` periods of the first mode Hz is compared with the exact
    evolution (``error``: relative L2 error in the Hz volumes); the run continues
    ``spectrum_periods`` periods and the first mode's resonance is fitted to the
    projection of Hz onto it (``frequency_error``) and read from the spectrum of
    Hz at the particle where that mode is largest (``probe_frequency_error``:
    Hann window, zero padding, parabolic peak). ``layout="jittered"``: every
    particle moved by up to ``amplitude * dr`` (seeded; the wall correction then
    covers the whole operator); ``"poisson"`` / ``"poisson-shared"``: the Poisson
    layouts of :func:`tez_disk_layout` (seeded). ``h_ratio`` defaults to
    :data:`DISK_H_RATIO` on the lattice, :data:`POISSON_H_RATIO` on Poisson layouts.
    ``support_check``: refuse an ``h_ratio`` above :data:`TEZ_DISK_H_RATIO_MAX` for the layout.

    Examples
    --------
    >>> r = run_tez_circular_cavity(n_radial=6, spectrum_periods=3.0)
    >>> r.case, r.frequency_error < 0.005, r.error < 0.05  # measured 1.4e-3 and 3.3e-2
    ('tez-disk', True, True)
    """
    t0 = time.perf_counter()
    radius = check_positive("radius", radius)
    n_radial = check_int("n_radial", n_radial, minimum=3)
    periods = check_positive("periods", periods)
    spectrum_periods = check_positive("spectrum_periods", spectrum_periods)
    eps_r = check_positive("eps_r", eps_r)
    modes = _check_modes(modes)
    if any(m < 0 or k < 1 for m, k in modes):
        raise ValueError(f"modes must be (m, n) with m >= 0 and n >= 1 (TE_mn), got {modes!r}")
    if coupling == "direct":
        raise ValueError("coupling must be 'sbp' or 'adjoint' for the circular cavity ('direct' is not available "
                         "with curved walls)")
    check_in("coupling", coupling, ("sbp", "adjoint"))
    check_in("layout", layout, ("yee", "jittered", "poisson", "poisson-shared"))
    poisson = layout.startswith("poisson")
    if h_ratio is None:
        h_ratio = POISSON_H_RATIO if poisson else DISK_H_RATIO
    h_ratio = check_positive("h_ratio", h_ratio)
    top = TEZ_DISK_H_RATIO_MAX[layout]
    if support_check and h_ratio > top * (1 + 1e-9):
        raise ValueError(f"h_ratio = {h_ratio:.3g} is outside the validated range of the TEz disk on layout {layout!r} "
                         f"(h_ratio <= {top}: beyond it the error exceeds 10x the lattice's); use h_ratio <= {top}, "
                         f"or support_check=False to run anyway")
    dr = radius / n_radial
    c = (radius, radius)
    lay = tez_disk_layout(c, radius, dr, wall_spacing=wall_spacing, wall_margin=wall_margin,
                          amplitude=amplitude if layout == "jittered" else 0.0, seed=seed,
                          kind=layout if poisson else "lattice")
    s = TEzSolver(lay, h_ratio=h_ratio, eps_r=eps_r, coupling=coupling, courant=courant)
    shapes = [tez_disk_mode(lay.hz, c, radius, m, k) for m, k in modes]
    freqs = [tez_disk_frequency(radius, m, k, eps_r) for m, k in modes]
    T = periods / freqs[0]
    steps = int(math.ceil(T / s.dt - 1e-9))
    s.set_dt(T / steps)
    s.set_initial(sum(shapes))
    s.run(steps)
    exact = sum(f * math.cos(2 * math.pi * fr * s.t) for f, fr in zip(shapes, freqs))
    v = s.vol_hz
    err = float(math.sqrt(((s.hz - exact) ** 2 @ v) / (exact**2 @ v)))
    q = shapes[0] * v / ((shapes[0] * v) @ shapes[0])
    probe = int(np.argmax(np.abs(shapes[0])))
    more = int(round(spectrum_periods / freqs[0] / s.dt))
    amp, sig = np.empty(more), np.empty(more)
    for k in range(more):
        s.step()
        amp[k] = q @ s.hz
        sig[k] = s.hz[probe]
    fm = _fit_frequency(amp, s.dt * (steps + 1 + np.arange(more)), freqs[0])
    fp = _probe_peak(sig, s.dt, freqs[0])
    cfl = s.h / (math.sqrt(2.0) * s.c_max)
    result = TEzCavityResult("tez-disk", err, abs(fm - freqs[0]) / freqs[0], fm, freqs[0], lay.n_particles, s.n,
                             time.perf_counter() - t0, dr, s.dt, coupling, f"disk-{layout}",
                             probe_frequency_error=abs(fp - freqs[0]) / freqs[0], stable_fraction=s.dt / cfl,
                             h_ratio=float(h_ratio), consistency_interior=s.interior_consistency_residual())
    return dataclasses.replace(result, certificate_failures=certificate_failures(result))


def _probe_peak(signal, dt, f0):
    """The largest spectral peak of ``signal`` within 25 % of ``f0`` (Hann window, 16x zero padding, parabola)."""
    x = np.asarray(signal, dtype=np.float64)
    x = (x - x.mean()) * np.hanning(len(x))
    nfft = 16 * int(2 ** math.ceil(math.log2(len(x))))
    spec = np.abs(np.fft.rfft(x, nfft))
    f = np.fft.rfftfreq(nfft, dt)
    spec[(f < 0.75 * f0) | (f > 1.25 * f0)] = 0.0
    k = min(max(int(np.argmax(spec)), 1), len(spec) - 2)
    a, b, c = np.log(spec[k - 1 : k + 2] + 1e-300)
    den = a - 2 * b + c
    return float(f[k] + (0.5 * (a - c) / den if den != 0 else 0.0) * (f[1] - f[0]))
