"""What certifies a run with absorbing layers: the PML reflection measured on probes.

A PML is measured by two runs of one pulse: a domain with the layer, and a larger reference domain
without it, large enough that no echo reaches the probes within the window; the reflection is
``max |E - E_ref| / max |E_ref|`` at each probe. The two runs must use the *same operators* in the
domain they share, or their difference is the difference of two discretisations, not the layer's
reflection: on irregular layouts the "sbp" and "mimetic" corrections are global (a change of the
domain changes every weight a little), and two random layouts differ by their discretisation errors
(about 1e-2 at 20 particles per wavelength, read as -40 dB). :func:`restricted` therefore cuts the
test domain out of the reference solver itself: the E particles outside the kept region are held at
zero (a PEC wall behind the layer) and dropped with the H particles no kept E particle sees; every
weight, volume and material value of the kept particles is the reference's. The cut operators are
a principal part of the reference's energy-conserving pair, so the reference's stable step holds.

:func:`certificate_failures` reads the certificates a case result reports (the PML reflection, the interior
consistency residual, the energy drift) against their validated ranges (:data:`PML_REFLECTION_LIMIT_DB`,
:data:`CONSISTENCY_LIMIT`, :data:`ENERGY_DRIFT_LIMIT`); every
TMz case fills its ``certificate_failures`` with it (:func:`certified`), and the command line exits 3 when
one fails.

:func:`pml_probe` runs the pair and returns the reflection per probe in dB;
:func:`pml_certificate` measures the layer a case uses on a small pulse problem with the case's
layout (a jittered one with its layer on lattice particles, ``make_layout(calm=)``, as the cases build it),
support, coupling and layer (cached per configuration): the plane wave and the waveguide
report it as ``pml_reflection_db``, and :func:`.cases.run_pml` is the same measurement at full size.

Examples
--------
>>> from manifold_sph.spem import TMzSolver, yee_layout
>>> s = TMzSolver(yee_layout((0.0, 0.02, 0.0, 0.02), 1e-3))
>>> keep = (s.layout.e[:, 0] < 0.0105)
>>> sub = restricted(s, keep)
>>> sub.dt == s.dt, sub.n_e < s.n_e
(True, True)
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_int, check_positive
from .constants import C0
from .layouts import Layout, make_layout
from .pml import PML
from .results import CaseResult, PMLCertificate
from .sources import GaussianPulse, Source, point_source
from .tmz import TMzSolver

__all__ = ["restricted", "pml_probe", "pml_certificate", "pulse", "pulse_problem", "pulse_source", "inside_box",
           "CERTIFICATE_CELLS", "CERTIFIED_COUPLINGS", "SHARED_SOURCE_WIDTH", "PML_REFLECTION_LIMIT_DB",
           "ENERGY_DRIFT_LIMIT", "CONSISTENCY_LIMIT", "certificate_failures", "certified"]

#: Interior of the certificate's pulse problem, in spacings (the source at its centre, the probes 5
#: spacings in front of the right layer and of the top-right corner).
CERTIFICATE_CELLS = 20

#: The couplings whose cases measure their layer's certificate by default: "mimetic" is left out (its
#: global set-up on the certificate's reference domain costs minutes), "direct" is refused by
#: :func:`restricted` (not energy-conserving).
CERTIFIED_COUPLINGS = ("sbp", "adjoint")

#: Largest PML reflection (dB, the worse of the normal and 45 degree probes) of a certified run: 1 % of the
#: incident amplitude, the accuracy the propagation cases are validated at (plane wave 1e-2). Measured with
#: the default "sbp" coupling: Yee lattice -63.1 dB (5-cell layer) to -90.7 dB (10 cells), staggered lattice
#: -72.8 dB (10 cells); jittered layouts -65 to -70 dB with the layer on lattice particles (the layouts the cases
#: build), -32 to -35 dB with jittered particles in the layer; the lattice at h/dr 1.0 / 1.3 -38.7 / -17.8 dB.
PML_REFLECTION_LIMIT_DB = -40.0

#: Largest interior consistency residual (:meth:`.TMzSolver.interior_consistency_residual`) of a certified
#: run. Measured: round-off for "sbp", "mimetic" and "direct" on the square's layouts (at most 1.4e-8, a 0.1 m
#: Poisson square at 20 spacings) and for "adjoint" on the lattices (2.2e-14); "sbp" on the staggered disk
#: 1.4e-2 / 2.8e-2 / 8.3e-2 at 10 / 20 / 40 spacings per radius (h/dr 0.7; 4.6e-2 / 5.9e-2 / 8.0e-2 at 0.6) with
#: errors 0.57-2.5x the Yee lattice's; "adjoint" 4.45 / 2.0 / 1.71 / 1.62 on the jittered / Poisson / joint /
#: balanced disks, whose cavities measure 47x / 14x / 12x / 11x. The limit sits between the two groups. Next to
#: walls "adjoint" is O(1) on the lattice too (7.0 on the circular cavity) and accurate there (9.0e-3), so the
#: rows within two supports of a wall are not part of this certificate.
CONSISTENCY_LIMIT = 0.5

#: Largest ``|W(end) / W(0) - 1|`` of the discrete energy of a lossless, undriven certified run: leap-frog
#: conserves it to round-off with the energy-conserving couplings (4.4e-16 over one period of the cavity).
ENERGY_DRIFT_LIMIT = 1e-8

#: Width (standard deviation, in spacings) of the probe pulse's source on layouts whose Hx and Hy share
#: particles (the staggered B-grid). A source at one E particle excites the B-grid's checkerboard mode
#: ``(-1)^(i+j) g`` as strongly as the physical wave; for that mode the lattice's x and y differences trade
#: places, so the split-field layer damps the wrong split component and lets it through (measured: -5.3 /
#: -2.8 dB on the 60-cell case). A Gaussian of this width excites it below the layer's own reflection:
#: -72.8 / -72.8 dB (width 1 spacing: -55 / -59 dB on the 20-cell certificate, 1.5: -72 / -79, 2: -71 / -63).
SHARED_SOURCE_WIDTH = 1.5


def restricted(solver: TMzSolver, keep: ArrayLike, *, pml: PML | None = None) -> TMzSolver:
    """The solver's problem on the E particles ``keep``, the others held at zero (a PEC wall), with ``pml``.

    Every kept particle keeps the reference solver's weights, volumes, materials, sources and time
    step; the dropped E particles are held at zero, and the H particles that no kept free E particle
    sees are dropped too (they can no longer reach the field). Couplings "sbp", "mimetic" and
    "adjoint" (energy-conserving: the cut pair is a principal part of the reference's, so its step
    stays stable); "direct" is refused. The H rows that saw a dropped E particle lose that column, so
    the sub-problem's :meth:`~.TMzSolver.consistency_residual` is O(1) at the cut (a PEC wall without
    its closure): its certificate is the reference's.

    Parameters
    ----------
    solver : TMzSolver
        The reference (its fields are not used).
    keep : (n_E,) bool array
        The E particles of the sub-problem (usually those strictly inside a box).
    pml : PML, optional
        Absorbing layers of the sub-problem (their conductivities at the kept particles).
    """
    if not isinstance(solver, TMzSolver):
        raise TypeError(f"solver must be a TMzSolver, got {type(solver).__name__}")
    if solver.coupling == "direct":
        raise ValueError("restricted needs an energy-conserving coupling ('sbp', 'mimetic' or 'adjoint'); the "
                         "'direct' coupling's stability is not inherited by a sub-problem")
    if pml is not None and not isinstance(pml, PML):
        raise TypeError(f"pml must be a PML or None, got {type(pml).__name__}")
    keep = np.asarray(keep)
    if keep.dtype != bool or keep.shape != (solver.n_e,):
        raise ValueError(f"keep must be a bool array of shape ({solver.n_e},), got {keep.dtype} {keep.shape}")
    for src in solver.sources:
        if not keep[src.indices].all():
            raise ValueError("keep must contain every source particle")
    lay = solver.layout
    rows = keep[solver.free]  # kept rows of the E operators
    Dxe, Dye = solver.Dx_e[rows], solver.Dy_e[rows]
    seen_y = np.asarray(abs(Dxe).sum(axis=0)).ravel() > 0
    seen_x = np.asarray(abs(Dye).sum(axis=0)).ravel() > 0
    if lay.shared:
        seen_x = seen_y = seen_x | seen_y
    e_idx, hx_idx, hy_idx = np.flatnonzero(keep), np.flatnonzero(seen_x), np.flatnonzero(seen_y)
    if not len(hx_idx) or not len(hy_idx):
        raise ValueError("keep leaves no free E particle coupled to the H particles")
    new = -np.ones(solver.n_e, dtype=np.int64)
    new[e_idx] = np.arange(len(e_idx))
    hx = lay.hx[hx_idx]
    sub = object.__new__(TMzSolver)
    sub.__dict__.update({k: v for k, v in solver.__dict__.items()
                         if k not in ("_plan", "_fused", "_consistency", "_spectrum", "_pool")})
    sub._pool = None
    sub.layout = Layout(lay.e[e_idx], hx, hx if lay.shared else lay.hy[hy_idx], lay.dr, lay.name,
                        lay.e_fixed[e_idx], lay.bounds, lay.h_ratio)
    sub.pml = pml
    sub.n_e = len(e_idx)
    sub.eps_r, sub.sigma = solver.eps_r[e_idx], solver.sigma[e_idx]
    sub.mu_r_x, sub.mu_r_y = solver.mu_r_x[hx_idx], solver.mu_r_y[hy_idx]
    sub.sources = [Source(new[s.indices], s.waveform, s.kind) for s in solver.sources]
    sub.driven = solver.driven[e_idx]
    sub.free = new[solver.free[rows]]
    sub.Dx_e, sub.Dy_e = Dxe[:, hy_idx].tocsr(), Dye[:, hx_idx].tocsr()
    sub.Dx_hy = solver.Dx_hy[hy_idx][:, e_idx].tocsr()
    sub.Dy_hx = solver.Dy_hx[hx_idx][:, e_idx].tocsr()
    sub.vol_e = solver.vol_e[rows]
    for name, idx in (("vol_hx", hx_idx), ("vol_hy", hy_idx)):
        if getattr(solver, name, None) is not None:
            setattr(sub, name, getattr(solver, name)[idx])
    sub._set_losses()
    sub.reset()
    return sub


def pml_probe(test: TMzSolver, reference: TMzSolver, probes: ArrayLike, steps: int, *,
              progress: bool = False) -> tuple[list, float]:
    """Reflection in dB at each probe point, ``20 log10(max |E - E_ref| / max |E_ref|)`` over ``steps`` steps,
    and the seconds of the two runs.

    ``test`` and ``reference`` run with the test's step from their current state; ``probes`` (P, 2) are
    points (the nearest E particle of each solver). A probe the pulse never reaches in the reference
    (less than 1e-9 of the largest recorded value) gives None.
    """
    pts = np.atleast_2d(np.asarray(probes, dtype=np.float64))
    out, seconds = [], 0.0
    for s in (test, reference):
        if s is reference:
            s.set_dt(test.dt)
        res = s.run(steps, probes=s.probe_indices(pts), progress=progress)
        out.append(res.probes)
        seconds += res.seconds
    diff = np.abs(out[0] - out[1]).max(axis=0)
    ref = np.abs(out[1]).max(axis=0)
    ok = ref > 1e-9 * max(float(ref.max()), 1e-300)
    return [float(20 * np.log10(max(d / r, 1e-300))) if k else None for d, r, k in zip(diff, ref, ok)], seconds


def pulse(dr: float) -> tuple[GaussianPulse, float]:
    """The probe pulse (a modulated Gaussian, about 20 spacings per wavelength at its centre) and its ``tau``."""
    f0 = C0 / (20 * dr)
    tau = 1.5 / (math.pi * f0)
    return GaussianPulse(t0=4 * tau, tau=tau, freq=f0), tau


def pulse_problem(cells: int, pml_cells: int, dr: float, order: int, reflection: float,
                  layout: str = "yee") -> tuple[PML, np.ndarray, tuple[float, float], float, tuple[float, ...]]:
    """Geometry of the pulse problem: ``(pml, probe points, centre, window t_end, reference bounds)``.

    The source sits at the centre of a ``cells`` square, the probes 5 spacings in front of the right
    layer and of the top-right corner. On the staggered layout, whose two E sublattices (i + j even and
    odd) only the walls couple, a probe off the sublattice that holds the source moves one spacing inwards.
    """
    L = cells * dr
    half = cells // 2
    c = (half * dr, half * dr)
    _, tau = pulse(dr)
    probes = np.array([[L - 5 * dr, c[1]], [L - 5 * dr, L - 5 * dr]])
    if layout == "staggered" and (cells - 5 + half) % 2:
        probes[0, 0] -= dr
    far = float(np.hypot(*(probes[1] - c)))
    # window: the pulse passes the farthest probe, plus the round trip through the layer
    t_end = 8 * tau + (far + 2 * (5 + pml_cells + 2) * dr * math.sqrt(2)) / C0
    pml = PML(pml_cells * dr, order=order, reflection=reflection, interior=(0.0, L, 0.0, L))
    # reference: the shortest echo path source -> wall -> probe (>= half + 2 margin cells) exceeds c t_end
    margin = int(math.ceil(max(0.0, C0 * t_end / dr - half) / 2)) + 4
    return pml, probes, c, t_end, (-margin * dr, L + margin * dr, -margin * dr, L + margin * dr)


def certificate_failures(result: CaseResult) -> tuple[str, ...]:
    """The certificates of a case result outside their validated range, one sentence each (empty: certified).

    Reads the fields a result reports: ``pml_reflection_db`` (the plane wave's and the waveguide's layer,
    :func:`pml_certificate`) and the pml case's own ``reflection_normal_db`` / ``reflection_oblique_db``
    against :data:`PML_REFLECTION_LIMIT_DB`; ``consistency_interior`` against :data:`CONSISTENCY_LIMIT`;
    ``energy_drift`` against :data:`ENERGY_DRIFT_LIMIT`.

    Examples
    --------
    >>> from manifold_sph.spem.results import PMLResult
    >>> r = PMLResult(case="pml", particles=1, steps=1, seconds=0.0, step_seconds=0.0, error=1e-2, dt=1.0, dr=1.0,
    ...               reference_particles=1, reflection_normal_db=-40.5, reflection_oblique_db=-35.0, pml_cells=10,
    ...               order=3, target_reflection=1e-6, layout="jittered")
    >>> certificate_failures(r)  # doctest: +ELLIPSIS
    ('the PML reflects -35.0 dB (45 deg), above the validated -40 dB ...',)
    """
    out = []
    d = result.to_dict()
    for key, what in (("pml_reflection_db", "the run's PML reflects {v:.1f} dB (its certificate)"),
                      ("reflection_normal_db", "the PML reflects {v:.1f} dB (normal incidence)"),
                      ("reflection_oblique_db", "the PML reflects {v:.1f} dB (45 deg)")):
        v = d.get(key)
        if v is not None and v > PML_REFLECTION_LIMIT_DB:
            out.append(what.format(v=v) + f", above the validated {PML_REFLECTION_LIMIT_DB:g} dB (1 % of the "
                       "incident wave): the layer does not absorb on this layout and support")
    residual = d.get("consistency_interior")
    if residual is not None and not residual <= CONSISTENCY_LIMIT:
        out.append(f"the operators' interior consistency residual is {residual:.3g}, above the validated "
                   f"{CONSISTENCY_LIMIT:g}: the coupling is not exact for linear fields on this layout")
    drift = d.get("energy_drift")
    if drift is not None and not drift <= ENERGY_DRIFT_LIMIT:
        out.append(f"the discrete energy drifts by {drift:.3g}, above the validated {ENERGY_DRIFT_LIMIT:g}: the "
                   "run is not the energy-conserving scheme")
    return tuple(out)


def certified(result: CaseResult) -> CaseResult:
    """``result`` with its ``certificate_failures`` filled in (:func:`certificate_failures`)."""
    import dataclasses

    return dataclasses.replace(result, certificate_failures=certificate_failures(result))


def pulse_source(layout: Layout, centre: Sequence[float], wave: GaussianPulse) -> Source:
    """The soft source of the probe pulse: the E particle nearest ``centre``, or on layouts with shared H
    particles (the B-grid) a Gaussian of :data:`SHARED_SOURCE_WIDTH` spacings over the E particles around it
    (unit weight at its peak), which leaves the B-grid's checkerboard mode unexcited."""
    if not layout.shared:
        return point_source(layout.e, centre, wave, kind="soft")
    width = SHARED_SOURCE_WIDTH
    r2 = ((layout.e - np.asarray(centre, dtype=np.float64)) ** 2).sum(axis=1) / layout.dr**2
    idx = np.flatnonzero((r2 < (3.5 * width) ** 2) & ~layout.e_fixed)
    weights = np.exp(-r2[idx] / (2 * width**2))
    return Source(idx, _Weighted(weights / weights.max(), wave), "soft")


class _Weighted:
    """``weights * wave(t)``: one waveform over several particles."""

    def __init__(self, weights: np.ndarray, wave: GaussianPulse) -> None:
        self.weights, self.wave = weights, wave

    def __call__(self, t: float) -> np.ndarray:
        return self.weights * self.wave(t)


def inside_box(points: np.ndarray, bounds: Sequence[float], tol: float) -> np.ndarray:
    """Points strictly inside the box ``bounds`` (by more than ``tol``)."""
    x0, x1, y0, y1 = bounds
    return (points[:, 0] > x0 + tol) & (points[:, 0] < x1 - tol) & (points[:, 1] > y0 + tol) & (points[:, 1] < y1 - tol)


@functools.lru_cache(maxsize=32)
def _certificate(layout: str, h_ratio: float | None, coupling: str, pml_cells: int, order: int, reflection: float,
                 kernel: str, form: str, mimetic_fast: bool, seed: int | None) -> PMLCertificate:
    dr = 1e-3
    pml, probes, c, t_end, ref_bounds = pulse_problem(CERTIFICATE_CELLS, pml_cells, dr, order, reflection, layout)
    wave, _ = pulse(dr)
    lay = make_layout(layout, ref_bounds, dr, seed=seed, calm=pml.calm_bounds())
    kw = {"mimetic_fast": True} if mimetic_fast else {}
    ref = TMzSolver(lay, h_ratio=h_ratio, kernel=kernel, form=form, coupling=coupling,
                    sources=[pulse_source(lay, c, wave)], **kw)
    test = restricted(ref, inside_box(lay.e, pml.outer_bounds(), 1e-6 * dr), pml=pml)
    steps = int(math.ceil(t_end / ref.dt - 1e-9))
    db, seconds = pml_probe(test, ref, probes, steps)
    return PMLCertificate(normal_db=db[0], oblique_db=db[1], layout=layout, pml_cells=pml_cells,
                          h_ratio=float(ref.h / dr), coupling=coupling, seconds=seconds)


def pml_certificate(layout: str, *, pml_cells: int, order: int = 3, reflection: float = 1e-6,
                    h_ratio: float | None = None, coupling: str = "sbp", kernel: str = "cubic", form: str = "fpm",
                    mimetic_fast: bool = False, seed: int | None = 0) -> PMLCertificate:
    """The reflection of a split-field PML with these settings, measured on probes (cached per configuration).

    A soft pulse (about 20 spacings per wavelength at its centre; :func:`pulse_source`) at the centre of a
    :data:`CERTIFICATE_CELLS` square with the layer on every side, against the reference without it
    (:func:`pml_probe`, the test domain cut out of the reference solver by :func:`restricted`), on the
    layout ``layout`` (:func:`.layouts.make_layout`, ``seed``) with the support, coupling and layer of
    the case: ``pml_cells`` spacings thick, profile ``order``, normal reflection target ``reflection``.

    Examples
    --------
    >>> cert = pml_certificate("yee", pml_cells=6)
    >>> cert.normal_db < -60, cert.oblique_db < -60
    (True, True)
    """
    pml_cells = check_int("pml_cells", pml_cells, minimum=1)
    order = check_int("order", order, minimum=0)
    reflection = check_positive("reflection", reflection)
    if h_ratio is not None:
        h_ratio = float(check_positive("h_ratio", h_ratio))
    kname = kernel if isinstance(kernel, str) else getattr(kernel, "name", str(kernel))
    return _certificate(layout, h_ratio, coupling, pml_cells, order, float(reflection), kname, form,
                        bool(mimetic_fast), seed)
