"""Open-domain cases with absorbing layers: plane wave, waveguide and the PML reflection (TMz and TEz).

Exact references come from the 1D propagator of the source signal, evaluated
by FFT: a signal ``s(t)`` imposed on the line ``y = y_s`` of a uniform guide
reaches ``y`` as ``IFFT[ S(w) exp(-i k_y(w) (y - y_s)) ]`` with
``k_y = sqrt(w^2 - w_c^2) / c`` (evanescent below the cut-off ``w_c``;
``w_c = 0`` for free space), exact for the semi-infinite line the PML
emulates.

Examples
--------
>>> r = run_planewave(size=0.1, freq=3.6e9, ppw=20, pml_cells=8)
>>> r.case, r.error < 0.05
('planewave', True)
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import j1

from ..._validation import check_in, check_int, check_positive
from ..certify import (
    CERTIFIED_COUPLINGS,
    certified,
    inside_box,
    pml_certificate,
    pml_probe,
    pulse,
    pulse_problem,
    pulse_source,
    restricted,
)
from ..constants import C0
from ..layouts import Layout, jitter, make_layout, tez_layout
from ..operators import COUPLINGS, DEFAULT_COUPLING, DEFAULT_H_RATIO, MIMETIC_H_RATIO
from ..pml import PML
from ..results import PlanewaveResult, PMLResult, TEzPMLResult, WaveguideResult
from ..sources import Sinusoid, Source
from ..tez import DISK_H_RATIO, TEzPMLSolver
from ..tmz import TMzSolver

if TYPE_CHECKING:
    from ...kernels import Kernel

from .common import check_every, field_history, fit_dt, fit_solver_dt, relative_error, timed

__all__ = ["guided_exact", "adjacent_line_difference", "alternating_amplitude", "run_planewave", "run_waveguide",
           "run_pml", "run_tez_pml", "PLANEWAVE_SIDES"]

#: Side walls of :func:`run_planewave`: mirror (PMC) walls or absorbing layers backed by PEC.
PLANEWAVE_SIDES = ("mirror", "pml")


def guided_exact(waveform: Callable[[np.ndarray], ArrayLike], distances: ArrayLike, t: float, *, cutoff: float = 0.0,
                 n_quad: int = 20001) -> np.ndarray:
    """Field at time ``t`` and distances ``d >= 0`` from a line where ``waveform(t)`` is imposed (t >= 0).

    Solves the signalling problem of the Klein-Gordon line
    ``u_tt = c^2 u_yy - w_c^2 u``, ``u(0, t) = s(t)`` (a TM_m mode of a
    parallel-plate guide; ``w_c = 0`` is free space) exactly:

        u(d, t) = s(t - d/c) - w_c (d/c) int_{d/c}^{t} J1(w_c sqrt(tau^2 - d^2/c^2))
                                         / sqrt(tau^2 - d^2/c^2) s(t - tau) dtau

    (the integrand is smooth; composite Simpson with ``n_quad`` nodes).

    Parameters
    ----------
    waveform : callable
        Source signal, zero for ``t < 0``.
    distances : array
        Distances along the propagation direction.
    t : float
    cutoff : float
        Cut-off frequency f_c (Hz) of the guided mode; 0 in free space.

    Examples
    --------
    >>> s = Sinusoid(1e9, ramp=1.0)
    >>> d = np.array([0.0, 0.1])
    >>> np.allclose(guided_exact(s, d, 2e-9), s(2e-9 - d / C0))
    True
    >>> # far behind the front a switched-on mode approaches sin(w t - k d)
    >>> w, wc = 2 * np.pi * 2e9, 2 * np.pi * 1e9
    >>> u = guided_exact(Sinusoid(2e9, ramp=3.0), [0.3], 60e-9, cutoff=1e9)[0]
    >>> bool(abs(u - np.sin(w * 60e-9 - np.sqrt(w**2 - wc**2) / C0 * 0.3)) < 0.02)
    True
    """
    from scipy.integrate import simpson

    d = np.atleast_1d(np.asarray(distances, dtype=np.float64))
    out = np.asarray(waveform(t - d / C0), dtype=np.float64).copy()
    if cutoff == 0.0:
        return out
    wc = 2 * np.pi * check_positive("cutoff", cutoff)
    for k, dk in enumerate(d):
        tau0 = dk / C0
        if dk <= 0 or t <= tau0:
            continue
        tau = np.linspace(tau0, t, n_quad)
        z = np.sqrt(np.clip(tau**2 - tau0**2, 0.0, None))
        with np.errstate(invalid="ignore", divide="ignore"):
            kern = np.where(z > 0, j1(wc * z) / np.where(z > 0, z, 1.0), 0.5 * wc)
        out[k] -= wc * tau0 * simpson(kern * waveform(t - tau), x=tau)
    return out


def adjacent_line_difference(points: ArrayLike, field: ArrayLike, dr: float, axis: int = 0,
                             mask: ArrayLike | None = None) -> float:
    """Largest |field| difference between neighbouring lattice lines, over lines parallel to the other axis.

    Particles are grouped by ``round(coordinate / dr)`` along ``axis`` and by
    the other coordinate; returns ``max |f(line k+1) - f(line k)|`` at equal
    other coordinate (0 for a field constant along ``axis``). The
    free-space failure of [2] (docs/method.md section 7) shows up as an O(1) value here (alternating lines).
    """
    p = np.asarray(points)
    f = np.asarray(field)
    if mask is not None:
        p, f = p[mask], f[mask]
    a = np.round(p[:, axis] / dr).astype(np.int64)
    b = np.round(p[:, 1 - axis] / dr * 2).astype(np.int64)
    key = {(int(i), int(j)): v for i, j, v in zip(a, b, f)}
    diffs = [abs(key[(i + 1, j)] - v) for (i, j), v in key.items() if (i + 1, j) in key]
    return float(max(diffs)) if diffs else float("nan")


def alternating_amplitude(points: ArrayLike, field: ArrayLike, dr: float, mask: ArrayLike | None = None) -> float:
    """Largest grid-scale alternating component across x: ``max |f(i+1) - 2 f(i) + f(i-1)| / 4``.

    A smooth field gives ``O((k dr)^2)``; a pattern alternating from line to
    line (the failure of [2]) gives its amplitude. Lattice layouts only.
    """
    p = np.asarray(points)
    f = np.asarray(field)
    if mask is not None:
        p, f = p[mask], f[mask]
    a = np.round(p[:, 0] / dr).astype(np.int64)
    b = np.round(p[:, 1] / dr * 2).astype(np.int64)
    key = {(int(i), int(j)): v for i, j, v in zip(a, b, f)}
    vals = [abs(key[(i + 1, j)] - 2 * v + key[(i - 1, j)]) / 4 for (i, j), v in key.items()
            if (i + 1, j) in key and (i - 1, j) in key]
    return float(max(vals)) if vals else float("nan")


def _certificate(certify: bool | None, solver: TMzSolver, layout: str, pml_cells: int, *, kernel, form: str,
                 seed) -> float | None:
    """The worst reflection of the run's layer in dB (:func:`.certify.pml_certificate`), or None."""
    if certify is None:
        certify = solver.coupling in CERTIFIED_COUPLINGS
    if not certify:
        return None
    return pml_certificate(layout, pml_cells=pml_cells, h_ratio=solver.h / solver.layout.dr, coupling=solver.coupling,
                           kernel=kernel, form=form, mimetic_fast=bool(getattr(solver, "mimetic_fast", False)),
                           seed=seed if isinstance(seed, (int, type(None))) else 0).worst_db


def _with_pml(interior, pml_cells, dr, sides="all", order=3, reflection=1e-6):
    pml = PML(pml_cells * dr, order=order, reflection=reflection, interior=interior, sides=sides)
    return pml, pml.outer_bounds()


@timed
def run_planewave(*, size: float = 0.5, freq: float = 3.6e9, ppw: float = 40.0, pml_cells: int = 10,
                  layout: str = "yee", form: str = "fpm", kernel: str | Kernel | type[Kernel] = "cubic", h_ratio: float | None = None,
                  courant: float = 0.9, coupling: str = DEFAULT_COUPLING, travel: float = 0.8, ramp: float = 2.0,
                  seed: int | np.random.Generator | None = 0,
                  source_span: str = "full", side: str | None = None, every: int | None = None,
                  certify: bool | None = None, progress: bool = False) -> PlanewaveResult:
    """Free-space plane wave in a ``size`` square, PML at the bottom and top, mirror walls or PML at the sides.

    A hard source (a ramped sinusoid) drives the E particles within dr/2 of
    the line ``y = dr`` and every E particle behind it (the incident region),
    each with the exact plane wave at its own ``y``: on irregular layouts the
    supports reach across a one-row source, and the H rows straddling it
    would see the kink of the two-sided field there (docs/spem.md). It spans
    the whole width including the side layers (``source_span="full"``) or, as
    in the source, only the interior (``"interior"``, whose ends diffract);
    the wave travels +y. A jittered layout keeps the layers' particles on the
    lattice (:func:`.layouts.jitter` with ``calm``). The error is taken over the interior E particles above the
    source at the time the front has crossed ``travel`` of the square.
    ``side="mirror"`` (the default, except on the staggered layout) bounds
    the square at the sides by mirror (perfect magnetic conductor) walls on
    ``x = -dr/2`` and ``x = size + dr/2`` (``TMzSolver(mirror=)``), exact
    for this wave: no side layer, no PEC side wall; a jittered layout keeps
    its particles next to the planes on the lattice, as next to a layer.
    ``side="pml"`` (the staggered layout's default) puts layers on all four
    sides ([2] sec. 4.5), PEC behind them: the grazing wave along those
    walls, which no layer absorbs, dominates the error next to them. The
    staggered layout refuses mirror walls: with its H particles shared at
    the cell centres, the E particles next to a plane between particle
    columns have two H neighbours within the support.
    ``error_centre`` leaves out the 10 % of the width next to each side. ``adjacent_line_difference`` reports the
    largest difference between
    neighbouring lines parallel to the propagation (the failure of [2]:
    O(1) on the staggered layout), relative to the amplitude. ``certify``:
    also measure the layer's reflection on this layout, support and coupling
    (:func:`.certify.pml_certificate`, reported as ``pml_reflection_db``; by
    default for the couplings of :data:`.certify.CERTIFIED_COUPLINGS`).
    """
    every = check_every(every)
    size = check_positive("size", size)
    check_in("source_span", source_span, ("full", "interior"))
    freq = check_positive("freq", freq)
    ppw = check_positive("ppw", ppw)
    pml_cells = check_int("pml_cells", pml_cells, minimum=1)
    dr = C0 / freq / ppw
    n = max(4, int(round(size / dr)))
    dr = size / n
    interior = (0.0, size, 0.0, size)
    if side is None:
        side = "pml" if layout == "staggered" else "mirror"
    check_in("side", side, PLANEWAVE_SIDES)
    if side == "mirror" and layout == "staggered":
        raise ValueError("side='mirror' is not available on the staggered layout (its E particles next to a "
                         "plane between particle columns have too few shared H neighbours); use side='pml'")
    if side == "pml":
        pml, outer = _with_pml(interior, pml_cells, dr)
        mirror = None
        lay = make_layout(layout, outer, dr, seed=seed, calm=pml.calm_bounds())
    else:
        pml = PML(pml_cells * dr, order=3, reflection=1e-6, interior=interior, sides=("bottom", "top"))
        outer = pml.outer_bounds()
        mirror = (-0.5 * dr, size + 0.5 * dr)  # between particle columns: no lattice particle on a plane
        lay = make_layout("yee" if layout == "jittered" else layout, outer, dr, seed=seed)
        tol = 1e-6 * dr  # PEC only behind the bottom and top layers
        fixed = (np.abs(lay.e[:, 1] - outer[2]) < tol) | (np.abs(lay.e[:, 1] - outer[3]) < tol)
        lay = Layout(lay.e, lay.hx, lay.hy, dr, lay.name, fixed, lay.bounds, lay.h_ratio)
        if layout == "jittered":  # lattice next to the mirror planes, as next to side layers (jitter's calm)
            lay = jitter(lay, 0.2, seed, calm=(0.0, size, *pml.calm_bounds()[2:]))
    ys = dr  # one spacing inside the interior
    wave = Sinusoid(freq, ramp=ramp)
    e = lay.e
    band = (e[:, 1] <= ys + 0.5 * dr) & ~lay.e_fixed  # the source line and the incident field behind it
    if source_span == "interior":
        band &= (e[:, 0] > 0) & (e[:, 0] < size)
    idx = np.flatnonzero(band)
    delays = (e[idx, 1] - ys) / C0  # exact plane-wave values on an irregular band

    class _Band:
        def __call__(self, t):
            return wave(t - delays)

    src = Source(idx, _Band())
    t_end = travel * (size - ys) / C0
    s = TMzSolver(lay, h_ratio=h_ratio, kernel=kernel, form=form, coupling=coupling, pml=pml, courant=courant,
                  sources=[src], mirror=mirror)
    dt, steps = fit_solver_dt(s, t_end)
    res = s.run(steps, every=every, progress=progress)
    inside = (e[:, 0] > 0) & (e[:, 0] < size) & (e[:, 1] > ys + 0.5 * dr) & (e[:, 1] < size) & ~lay.e_fixed
    exact = wave(s.t - (e[inside, 1] - ys) / C0)
    # the PEC walls behind the side layers perturb the grazing wave (a layer cannot absorb
    # grazing incidence): also report the error away from the sides
    centre = (e[inside, 0] > 0.1 * size) & (e[inside, 0] < 0.9 * size)
    lattice = layout in ("yee", "staggered")
    return certified(PlanewaveResult(
        case="planewave", particles=lay.n_particles, steps=steps, seconds=res.seconds, step_seconds=res.seconds,
        error=relative_error(s.e_field[inside], exact), dt=dt, dr=dr, layout=lay.name, form=form,
        ppw=C0 / freq / dr, pml_cells=pml_cells, side=side, error_centre=relative_error(s.e_field[inside][centre], exact[centre]),
        adjacent_line_difference=adjacent_line_difference(e, s.e_field, dr, axis=0, mask=inside) if lattice else None,
        alternating_amplitude=alternating_amplitude(e, s.e_field, dr, mask=inside) if lattice else None,
        fields=field_history(e, s.e_field, s.t, res), consistency=s.consistency_residual(),
        consistency_interior=s.interior_consistency_residual(),
        pml_reflection_db=_certificate(certify, s, layout, pml_cells, kernel=kernel, form=form, seed=seed)))


@timed
def run_waveguide(*, width: float = 0.5, length: float = 0.4, pml_thickness: float = 0.1, ppw: float = 80.0,
                  f_ratio: float = 1.2, t_end: float = 4.1e-9, line_x: float = 0.244, amplitude: float = 0.2,
                  layout: str = "yee", form: str = "fpm", kernel: str | Kernel | type[Kernel] = "cubic",
                  h_ratio: float | None = None,
                  courant: float = 0.9, coupling: str = DEFAULT_COUPLING, ramp: float = 0.0, every: int | None = None,
                  certify: bool | None = None, progress: bool = False) -> WaveguideResult:
    """Parallel-plate waveguide ([2] sec. 4.4): PEC plates x = 0 and x = ``width``, TM1 source at y = 0.

    The E particles of the row y = 0 are driven with
    ``amplitude sin(pi x / width) sin(2 pi f t)``, ``f = f_ratio * f_c``,
    ``f_c = c / (2 width)``; a PML of ``pml_thickness`` ends the guide at
    ``y = length``. The exact field is the TM1 profile times the 1D
    propagator of the source signal (:func:`guided_exact`). Error along the
    line of E particles nearest ``x = line_x``, excluding the PML, at ``t_end``.
    ``certify``: the layer's reflection, as in :func:`run_planewave`.
    """
    every = check_every(every)
    width = check_positive("width", width)
    ppw = check_positive("ppw", ppw)
    fc = C0 / (2 * width)
    freq = f_ratio * fc
    dr = C0 / freq / ppw
    n = max(4, int(round(width / dr)))
    dr = width / n
    nl = max(2, int(round(length / dr)))
    length = nl * dr
    npml = max(1, int(round(pml_thickness / dr)))
    interior = (0.0, width, 0.0, length)
    pml = PML(npml * dr, order=3, reflection=1e-6, interior=interior, sides=("top",))
    lay = make_layout(layout, pml.outer_bounds(), dr, calm=pml.calm_bounds())
    # PEC only on the plates and the far end; the source row carries the signal
    e = lay.e
    tol = 1e-6 * dr
    fixed = (np.abs(e[:, 0]) < tol) | (np.abs(e[:, 0] - width) < tol) | (np.abs(e[:, 1] - pml.outer_bounds()[3]) < tol)
    row0 = np.flatnonzero((np.abs(e[:, 1]) < tol) & ~fixed)
    lay = Layout(lay.e, lay.hx, lay.hy, dr, lay.name, fixed, lay.bounds, lay.h_ratio)
    wave = Sinusoid(freq, amplitude=amplitude, ramp=ramp)
    profile = np.sin(np.pi * e[row0, 0] / width)

    class _Profiled:
        def __call__(self, t):
            return profile * wave(t)

    src = Source(row0, _Profiled())
    s = TMzSolver(lay, h_ratio=h_ratio, kernel=kernel, form=form, coupling=coupling, pml=pml, courant=courant,
                  sources=[src])
    dt, steps = fit_solver_dt(s, t_end)
    res = s.run(steps, every=every, progress=progress)
    xs = e[np.argmin(np.abs(e[:, 0] - line_x)), 0]
    column = np.abs(e[:, 0] - xs) < tol
    if column.sum() < 3:  # irregular layouts: the band of E particles within dr/2 of the line
        xs = line_x
        column = np.abs(e[:, 0] - xs) <= 0.5 * dr
    on_line = column & (e[:, 1] <= length + tol) & ~fixed
    exact = np.sin(np.pi * e[on_line, 0] / width) * guided_exact(wave, e[on_line, 1], s.t, cutoff=fc)
    return certified(WaveguideResult(case="waveguide", particles=lay.n_particles, steps=steps, seconds=res.seconds,
                           step_seconds=res.seconds, error=relative_error(s.e_field[on_line], exact), dt=dt, dr=dr,
                           layout=layout, form=form, freq=freq, f_cutoff=fc, line_x=float(xs), ppw=C0 / freq / dr,
                           pml_cells=npml, fields=field_history(e, s.e_field, s.t, res),
                           consistency=s.consistency_residual(),
                           consistency_interior=s.interior_consistency_residual(),
                           pml_reflection_db=_certificate(certify, s, layout, npml, kernel=kernel, form=form,
                                                          seed=0)))


@timed
def run_pml(*, cells: int = 60, pml_cells: int = 10, order: int = 3, reflection: float = 1e-6,
            layout: str = "yee", form: str = "fpm", kernel: str | Kernel | type[Kernel] = "cubic", h_ratio: float | None = None,
            courant: float = 0.9, coupling: str = DEFAULT_COUPLING, dr: float = 1e-3, seed: int | None = 0,
            pml_check: bool = True, progress: bool = False) -> PMLResult:
    """PML reflection: a pulse in a ``cells`` square with PML, against a reference run without echo.

    A soft point source (differentiated-Gaussian-like modulated pulse, about
    20 spacings per wavelength at its centre frequency; on the staggered
    layout a Gaussian over a few particles, :func:`.certify.pulse_source`) sits at the centre;
    probes lie 5 spacings in front of the right layer (normal incidence) and
    in front of the top-right corner along the diagonal (oblique, 45 deg).
    The reference domain is large enough that no echo reaches the probes
    within the window; the test domain is cut out of the reference solver
    (:func:`.certify.restricted`: the same weights in the shared domain, so
    that on irregular layouts the difference is the layer's reflection, not a
    difference of discretisations). Reflection = max |E - E_ref| / max |E_ref|
    at each probe, in dB; ``consistency`` is the reference's (the cut
    operators are its rows, inconsistent only at the cut behind the layer).
    ``pml_check``: refuse a support outside the layer's validated range
    (:data:`.tmz.PML_H_RATIO_MAX`), as :class:`.TMzSolver` does.
    """
    cells = check_int("cells", cells, minimum=10)
    pml_cells = check_int("pml_cells", pml_cells, minimum=1)
    dr = check_positive("dr", dr)
    pml, probes_xy, c, t_end, ref_bounds = pulse_problem(cells, pml_cells, dr, order, reflection, layout)
    wave, _ = pulse(dr)
    lay = make_layout(layout, ref_bounds, dr, seed=seed, calm=pml.calm_bounds())
    if pml_check:  # the layer's validated support (the reference has no layer: checked here, before its set-up)
        check_in("coupling", coupling, COUPLINGS)
        support = MIMETIC_H_RATIO if coupling == "mimetic" else (lay.h_ratio or DEFAULT_H_RATIO)
        TMzSolver.check_pml_support(check_positive("h_ratio", h_ratio) if h_ratio is not None else support, coupling)
    ref = TMzSolver(lay, h_ratio=h_ratio, kernel=kernel, form=form, coupling=coupling, courant=courant,
                    sources=[pulse_source(lay, c, wave)])
    test = restricted(ref, inside_box(lay.e, pml.outer_bounds(), 1e-6 * dr), pml=pml)
    dt, steps = fit_dt(t_end, ref.dt)
    ref.set_dt(dt)
    test.set_dt(dt)
    db, seconds = pml_probe(test, ref, probes_xy, steps, progress=progress)
    rel = [None if v is None else 10 ** (v / 20) for v in db]
    return certified(PMLResult(case="pml", particles=test.layout.n_particles, steps=2 * steps, seconds=seconds,
                     step_seconds=seconds, error=rel[0], dt=dt, dr=dr, reference_particles=lay.n_particles,
                     reflection_normal_db=db[0], reflection_oblique_db=db[1], pml_cells=pml_cells, order=order,
                     target_reflection=reflection, layout=layout, consistency=ref.consistency_residual(),
                     consistency_interior=ref.interior_consistency_residual()))


def run_tez_pml(*, cells: int = 60, pml_cells: int = 10, order: int = 3, reflection: float = 1e-6,
                angles: tuple = (0.0, 30.0, 45.0), h_ratio: float = DISK_H_RATIO, courant: float = 0.9,
                dr: float = 1e-3, pml_check: bool = True) -> TEzPMLResult:
    """Reflection of the TEz split-field PML: a pulse in a ``cells`` square with PML, against a run without echo.

    As :func:`.run_pml` (TMz): a soft Hz point source (modulated Gaussian,
    about 20 spacings per wavelength at its centre frequency) at the centre;
    probes on the line 5 spacings in front of the right layer, at ``angles``
    (degrees from the normal) seen from the source (45: in front of the
    corner). The layouts are the lattice with closure walls on the PEC box
    behind the PML (:func:`.wall_closure_layout`); the reference domain is
    large enough that no echo reaches the probes within the window, run with
    the same step. Reflection = max |Hz - Hz_ref| / max |Hz_ref| per probe, in dB.
    ``pml_check``: refuse a support outside the layer's validated range
    (:data:`.tez.TEZ_PML_H_RATIO_MAX`), as :class:`.TEzPMLSolver` does.

    Examples
    --------
    >>> r = run_tez_pml(cells=30, pml_cells=6, angles=(0.0,))  # doctest: +SKIP
    >>> round(r.reflection_db[0])  # doctest: +SKIP
    -43
    """
    from ..layouts import wall_closure_layout
    from ..sources import GaussianPulse

    t0 = time.perf_counter()
    cells = check_int("cells", cells, minimum=12)
    pml_cells = check_int("pml_cells", pml_cells, minimum=1)
    dr = check_positive("dr", dr)
    try:
        ang = np.asarray(angles, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"angles must be a sequence of degrees, got {angles!r}") from None
    if not len(ang) or not np.all((ang >= 0) & (ang <= 45)):
        raise ValueError(f"angles must be between 0 and 45 degrees, got {angles!r}")
    L = cells * dr
    half = cells // 2
    c = np.array([half + 0.5, half + 0.5]) * dr  # an Hz site (a cell centre: no tie between nearest particles)
    f0 = C0 / (20 * dr)
    tau = 1.5 / (math.pi * f0)
    wave = GaussianPulse(t0=4 * tau, tau=tau, freq=f0)
    px = L - 5.5 * dr
    py = (np.round((px - c[0]) * np.tan(np.radians(ang)) / dr) + half + 0.5) * dr
    probes = np.column_stack([np.full(len(ang), px), np.minimum(py, px)])
    far = float(np.hypot(*(probes - c).T).max())
    t_end = 8 * tau + (far + 2 * (5 + pml_cells + 2) * dr * math.sqrt(2)) / C0
    pml = PML(pml_cells * dr, order, reflection, interior=(0.0, L, 0.0, L))
    margin = int(math.ceil(max(0.0, C0 * t_end / dr - half) / 2)) + 4
    solvers = []
    for bounds, p in ((pml.outer_bounds(), pml), ((-margin * dr, L + margin * dr, -margin * dr, L + margin * dr), None)):
        lay = wall_closure_layout(tez_layout(bounds, dr))
        solvers.append(TEzPMLSolver(lay, pml=p, h_ratio=h_ratio, courant=courant, pml_check=pml_check))
    dt = min(s.dt for s in solvers)
    steps = int(math.ceil(t_end / dt))
    out = []
    for s in solvers:
        s.set_dt(dt)
        hz = s.layout.hz
        src = int(np.argmin(((hz - c) ** 2).sum(axis=1)))
        idx = [int(np.argmin(((hz - q) ** 2).sum(axis=1))) for q in probes]
        rec = np.empty((steps, len(idx)))
        for n in range(steps):
            s.step()
            s.hzx[src] += wave(s.t)
            rec[n] = s.hz[idx]
        out.append(rec)
    diff = np.abs(out[0] - out[1]).max(axis=0)
    ref = np.abs(out[1]).max(axis=0)
    db = tuple(float(20 * np.log10(d / r)) for d, r in zip(diff, ref))
    return TEzPMLResult(tuple(float(a) for a in ang), db, solvers[0].layout.n_particles,
                        solvers[1].layout.n_particles, steps, time.perf_counter() - t0, dr, dt, pml_cells, order,
                        float(reflection))
