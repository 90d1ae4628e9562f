"""TEz: the circular PEC cavity (curved walls) beside the rectangle, with fitted orders.

Run: .venv/bin/python benchmarks/spem_tez.py            (about 1 min)
     .venv/bin/python benchmarks/spem_tez.py --sweep    (also h_ratio 0.6-2 and eps_r on the disk: 10^4 steps each)
     .venv/bin/python benchmarks/spem_tez.py --scattering   (only the TEz scattering table, about 10 min: see
     :func:`scattering_main`)
     .venv/bin/python benchmarks/spem_tez.py --jump   (the fitted dielectric interface, about 5 min: :func:`jump_table`)

Disk: ``run_tez_circular_cavity`` (radius 0.1 m, TE11 + TE21; error after one TE11 period; the TE11
resonance fitted to the projection of Hz onto the mode and read from a probe spectrum, 10 periods).
Rectangle: ``run_tez_cavity`` (0.1 x 0.06 m, TE10 + TE11). ``k dr``: the first mode's wavenumber times
the spacing (the disk's TE11 at n spacings per radius has k dr = 1.84 / n; the rectangle's TE10 at n
spacings along 0.06 m has k dr = 0.6 pi / n), so rows with equal k dr have equal particles per wavelength.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import manifold_sph.spem as ts
from manifold_sph import spem as tez
from manifold_sph.spem.cases import l2_error
from manifold_sph.spem.cases.scattering import scattering_domain
from manifold_sph.spem.constants import C0, EPS0, MU0
from manifold_sph.spem.pml import PML
from manifold_sph.spem.steady import STEADY_TOL, run_driven


def order(ns, values):
    """Least-squares slope of log(value) against log(n) (the convergence order)."""
    return float(-np.polyfit(np.log(ns), np.log(values), 1)[0])


def table(title, runs, kdr):
    print(f"\n{title}")
    print(f"{'n':>4} {'particles':>9} {'k dr':>6} {'error':>9} {'f error':>9} {'probe f':>9} {'dt/CFL':>7} "
          f"{'steps':>6} {'s':>6}")
    for n, r in runs:
        probe = f"{r.probe_frequency_error:9.2e}" if r.probe_frequency_error is not None else f"{'':>9}"
        frac = f"{r.stable_fraction:7.3f}" if r.stable_fraction is not None else f"{'':>7}"
        print(f"{n:4d} {r.particles:9d} {kdr(n):6.3f} {r.error:9.2e} {r.frequency_error:9.2e} {probe} {frac} "
              f"{r.steps:6d} {r.seconds:6.2f}")
    ns = [n for n, _ in runs]
    print(f"fitted order: error {order(ns, [r.error for _, r in runs]):.2f}, frequency "
          f"{order(ns, [r.frequency_error for _, r in runs]):.2f}")


def sweep():
    print("\nDisk, 10 spacings per radius, random Hz(0), 10^4 steps: relative change of the discrete energy")
    rng = np.random.default_rng(0)
    for coupling in ("sbp", "adjoint"):
        for hr in (0.6, 0.8, 1.0, 1.5, 2.0):
            for eps_r in (1.0, 0.25):
                lay = tez.tez_disk_layout((0.0, 0.0), 0.1, 0.01)
                try:
                    s = tez.TEzSolver(lay, h_ratio=hr, eps_r=eps_r, coupling=coupling)
                except ValueError as exc:
                    print(f"  {coupling:7s} h/dr {hr:3.1f} eps_r {eps_r:4.2f}: refused ({exc})")
                    continue
                s.set_initial(rng.standard_normal(len(lay.hz)))
                s.run(10_000)
                cfl = s.h / (math.sqrt(2) * s.c_max)
                print(f"  {coupling:7s} h/dr {hr:3.1f} eps_r {eps_r:4.2f}: drift {s.energy() / s.energy0 - 1:+.1e}, "
                      f"dt/CFL {s.dt / cfl:.3f}, wall residual {s.sbp_residual:.0e}")


class YeeTEz:
    """A staircased TEz Yee FDTD (numpy) on the lattice of :func:`.tez_layout` in ``[-L, L]^2``, split-field PML.

    Hz at the cell centres, Ex at ``(i + 1/2, j) d``, Ey at ``(i, j + 1/2) d``
    (the positions of SPEM's lattice), the tangential E on the box held at 0;
    ``eps_x``, ``eps_y`` per edge; Hz split ``Hzx + Hzy`` with the same
    semi-implicit coefficients as :class:`.TEzPMLSolver`; Courant number
    ``c dt / d = 0.99 / sqrt(2)``.
    """

    def __init__(self, L, d, pml, eps_x=1.0, eps_y=1.0, courant=0.99 / math.sqrt(2)):
        self.N = N = int(round(2 * L / d))
        self.d = d
        c = -L + (np.arange(N) + 0.5) * d
        e = -L + np.arange(N + 1) * d
        self.hz_xy = np.meshgrid(c, c, indexing="ij")
        self.ex_xy = np.meshgrid(c, e, indexing="ij")
        self.ey_xy = np.meshgrid(e, c, indexing="ij")
        self.eps_x = EPS0 * np.broadcast_to(eps_x, (N, N + 1))
        self.eps_y = EPS0 * np.broadcast_to(eps_y, (N + 1, N))
        self.dt = courant * d / C0
        self.pml = pml
        self.set_dt(self.dt)

    def set_dt(self, dt):
        self.dt = dt

        def coef(s, m):
            a = s * dt / (2.0 * m)
            return (1.0 - a) / (1.0 + a), (dt / m) / (1.0 + a)

        def sig(xy):
            return self.pml.sigma(np.column_stack([xy[0].ravel(), xy[1].ravel()]))

        sx, sy = (v.reshape(self.hz_xy[0].shape) for v in sig(self.hz_xy))
        self.dax, self.dbx = coef(sx * MU0 / EPS0, MU0)
        self.day, self.dby = coef(sy * MU0 / EPS0, MU0)
        self.cax, self.cbx = coef(sig(self.ex_xy)[1].reshape(self.ex_xy[0].shape), self.eps_x)
        self.cay, self.cby = coef(sig(self.ey_xy)[0].reshape(self.ey_xy[0].shape), self.eps_y)
        N = self.N
        self.hzx, self.hzy = np.zeros((N, N)), np.zeros((N, N))
        self.ex, self.ey = np.zeros((N, N + 1)), np.zeros((N + 1, N))

    def step(self):
        d = self.d
        self.hzx = self.dax * self.hzx - self.dbx * (self.ey[1:, :] - self.ey[:-1, :]) / d
        self.hzy = self.day * self.hzy + self.dby * (self.ex[:, 1:] - self.ex[:, :-1]) / d
        hz = self.hzx + self.hzy
        self.ex[:, 1:-1] = self.cax[:, 1:-1] * self.ex[:, 1:-1] + self.cbx[:, 1:-1] * (hz[:, 1:] - hz[:, :-1]) / d
        self.ey[1:-1, :] = self.cay[1:-1, :] * self.ey[1:-1, :] - self.cby[1:-1, :] * (hz[1:, :] - hz[:-1, :]) / d
        return hz


def run_yee_tez_scattering(kind, n_radial, *, average="staircase", radius=0.1, ka=2.0, eps_r=4.0, periods="auto",
                           ramp=3.0, dft_periods=2.0, margin=0.5, pml_thickness=0.5):
    """The case of :func:`.run_tez_scattering` on the staircased Yee grid (same domain, PML, drive and DFT;
    ``periods="auto"``: until the phasor is steady, :func:`manifold_sph.spem.steady.run_driven`).

    PEC: the Ey edges whose midpoint is inside the cylinder are held at the scattered
    ``-Ey_inc`` and the Ex edges there at 0 (``Ex_inc = 0``). Dielectric: ``eps`` per
    edge by ``average`` (:func:`.particle_permittivity`: "staircase" is eps_r at the
    edge midpoint) and the volume source on Ey.
    """
    from manifold_sph.spem.cases.scattering import SwitchedWave

    t0 = time.perf_counter()
    freq, dr, inner, outer = scattering_domain(radius, ka, n_radial, margin, pml_thickness)
    L = dr * math.ceil(outer / dr - 1e-9)
    pml = PML(outer - inner, 3, 1e-6, interior=(-inner, inner, -inner, inner))
    probe = YeeTEz(L, dr, pml)
    ex_p = np.column_stack([probe.ex_xy[0].ravel(), probe.ex_xy[1].ravel()])
    ey_p = np.column_stack([probe.ey_xy[0].ravel(), probe.ey_xy[1].ravel()])
    eps_x = eps_y = 1.0
    if kind == "dielectric":
        eps_x = ts.particle_permittivity(ex_p, 0, dr, radius, eps_r, average).reshape(probe.ex_xy[0].shape)
        eps_y = ts.particle_permittivity(ey_p, 1, dr, radius, eps_r, average).reshape(probe.ey_xy[0].shape)
    s = YeeTEz(L, dr, pml, eps_x, eps_y)
    T = 1.0 / freq
    per = int(math.ceil(T / s.dt - 1e-9))
    s.set_dt(T / per)
    k0 = 2 * math.pi * freq / C0
    eta0 = math.sqrt(MU0 / EPS0)
    hz_p = np.column_stack([s.hz_xy[0].ravel(), s.hz_xy[1].ravel()])
    r_h = np.hypot(hz_p[:, 0], hz_p[:, 1])
    if kind == "pec":
        pec_x = (np.hypot(*s.ex_xy) < radius)
        pec_y = (np.hypot(*s.ey_xy) < radius)
        inc = SwitchedWave(s.ey_xy[0][pec_y], freq, -radius, ramp, k0)
        fixed = int(pec_x.sum() + pec_y.sum())
        keep_h = r_h > radius
    else:
        diel = np.asarray(s.eps_y) > EPS0 * (1 + 1e-12)
        inc = SwitchedWave(s.ey_xy[0][diel], freq, -radius, ramp, k0)
        fac = eta0 * (1.0 - EPS0 / np.asarray(s.eps_y)[diel])
        fixed = 0
        keep_h = np.ones(len(hz_p), bool)
    N = s.N
    unknowns = int(keep_h.sum()) + N * (N - 1) * 2 - fixed
    ev = np.flatnonzero(keep_h & (np.abs(hz_p[:, 0]) <= inner) & (np.abs(hz_p[:, 1]) <= inner))
    w = 2 * math.pi * freq
    setup = time.perf_counter() - t0

    def advance(n):
        hz = s.step()
        t_next = (n + 1.5) * s.dt
        if kind == "pec":
            s.ex[pec_x] = 0.0
            s.ey[pec_y] = -eta0 * inc(t_next)
        else:
            s.ey[diel] -= fac * (inc(t_next) - inc(t_next - s.dt))
        return hz.ravel()[ev], (n + 1) * s.dt

    run = run_driven(advance, per, w, periods=periods, ramp=ramp, window=dft_periods)
    phasor, steps = run.phasor, run.steps
    pts = hz_p[ev]
    exact = ts.tez_scattered_field(pts, kind, freq=freq, radius=radius, eps_r=eps_r)
    r = np.hypot(pts[:, 0], pts[:, 1])
    ring = (r > radius) & (r <= 2 * radius)
    total = time.perf_counter() - t0
    return {"method": "Yee " + ("staircased" if kind == "pec" or average == "staircase" else average),
            "case": kind, "n_radial": n_radial, "unknowns": unknowns, "error": l2_error(phasor, exact),
            "ring": l2_error(phasor[ring], exact[ring]), "setup": setup, "run": total - setup, "steps": steps,
            "periods": run.periods, "transient": run.transient}


def run_spem_tez(kind, n_radial, **kw):
    r = ts.run_tez_scattering(kind, n_radial=n_radial, **kw)
    label = f"SPEM {r.layout}" + (f" seed={kw['seed']}" if "seed" in kw else "") \
        + (f" {r.average}" if kind == "dielectric" else "")
    return {"method": label, "case": kind, "n_radial": n_radial, "unknowns": r.particles, "error": r.error,
            "ring": r.ring_error, "setup": r.setup_seconds, "run": r.seconds - r.setup_seconds, "steps": r.steps,
            "growth": r.field_growth, "dt_frac": r.stable_fraction, "periods": r.periods, "transient": r.transient}


def scattering_main():
    """TEz plane-wave scattering (ka = 2, radius 0.1 m, eps_r = 4) and the TEz PML, in one run.

    1. The split-field PML's reflection (:func:`.run_tez_pml`, 60-cell square, pulse at 20 spacings
       per wavelength; 10 and 20 cells of cubic grading, R0 = 1e-6) at 0 / 30 / 45 degrees.
    2. SPEM (:func:`.run_tez_scattering`; lattice and jittered 0.2 dr interior, seed=0 and for the PEC
       also seed=1) and the
       staircased Yee grid (:func:`run_yee_tez_scattering`; for the dielectric also with the same
       anisotropic cell average as SPEM), at 4 / 8 / 16 spacings per radius (Yee also 32), with the
       error of the scattered Hz against the series (all Hz points in the interior box; ``ring``:
       radius < r <= 2 radius), set-up and run seconds, and the fitted order.
    3. Yee's error at SPEM's unknowns and the Yee CPU for SPEM's error (log-log interpolation on
       Yee's own curves).
    4. Other cylinders (PEC at ka = 1 and 3; dielectric eps_r = 2 at ka = 2 and eps_r = 9 at ka = 1),
       SPEM on the lattice against Yee with the same anisotropic average, 8 and 16 spacings per radius.
    """
    print("TEz split-field PML (h/dr 0.8): reflection in dB at 0 / 30 / 45 degrees")
    for cells in (10, 20):
        r = ts.run_tez_pml(pml_cells=cells)
        print(f"  {cells:2d} cells: " + " / ".join(f"{v:6.1f}" for v in r.reflection_db)
              + f"   ({r.particles} particles, {r.steps} steps, {r.seconds:.1f} s)")
    head = (f"{'method':<28s} {'case':<10s} {'n_r':>4s} {'unknowns':>8s} {'error':>9s} {'ring':>9s} {'setup s':>8s} "
            f"{'run s':>7s} {'steps':>6s}")
    rows = {}
    print("\nTEz scattering, ka = 2, eps_r = 4 (dielectric); error of the scattered Hz against the series")
    print(head)
    plan = [("pec", "SPEM yee", lambda n: run_spem_tez("pec", n), (4, 8, 16)),
            ("pec", "SPEM jittered", lambda n: run_spem_tez("pec", n, layout="jittered"), (4, 8, 16)),
            ("pec", "SPEM jittered seed=1", lambda n: run_spem_tez("pec", n, layout="jittered", seed=1), (4, 8, 16)),
            ("pec", "Yee staircased", lambda n: run_yee_tez_scattering("pec", n), (4, 8, 16, 32)),
            ("dielectric", "SPEM yee auto", lambda n: run_spem_tez("dielectric", n, average="auto"), (4, 8, 16)),
            ("dielectric", "SPEM yee", lambda n: run_spem_tez("dielectric", n), (4, 8, 16)),
            ("dielectric", "SPEM jittered", lambda n: run_spem_tez("dielectric", n, layout="jittered"), (4, 8, 16)),
            ("dielectric", "SPEM yee arithmetic", lambda n: run_spem_tez("dielectric", n, average="arithmetic"),
             (4, 8, 16)),
            ("dielectric", "SPEM yee harmonic", lambda n: run_spem_tez("dielectric", n, average="harmonic"),
             (4, 8, 16)),
            ("dielectric", "Yee staircased", lambda n: run_yee_tez_scattering("dielectric", n), (4, 8, 16, 32)),
            ("dielectric", "Yee anisotropic", lambda n: run_yee_tez_scattering("dielectric", n, average="anisotropic"),
             (4, 8, 16, 32))]
    for kind, name, fn, ns in plan:
        out = []
        for n in ns:
            r = fn(n)
            out.append(r)
            print(f"{r['method']:<28s} {kind:<10s} {n:>4d} {r['unknowns']:>8d} {r['error']:>9.2e} {r['ring']:>9.2e} "
                  f"{r['setup']:>8.2f} {r['run']:>7.2f} {r['steps']:>6d}", flush=True)
        print(f"{'':<28s} fitted order {order(list(ns), [r['error'] for r in out]):.2f}")
        rows[(kind, name)] = out
    print("\nYee interpolated (log-log) on its own curves: error at SPEM's unknowns, CPU for SPEM's error")
    for kind, yee_name in (("pec", "Yee staircased"), ("dielectric", "Yee staircased"),
                           ("dielectric", "Yee anisotropic")):
        yee = rows[(kind, yee_name)]
        lu = np.log([r["unknowns"] for r in yee])
        le = np.log([r["error"] for r in yee])
        lc = np.log([r["setup"] + r["run"] for r in yee])
        for (k2, name), spem in rows.items():
            if k2 != kind or not name.startswith("SPEM") or ("arith" in name or "harm" in name):
                continue
            for r in spem:
                e = math.exp(np.interp(math.log(r["unknowns"]), lu, le))
                le_r = math.log(r["error"])
                if le_r < le.min():  # beyond Yee's finest grid: the line through its two finest points
                    slope = (lc[-1] - lc[-2]) / (le[-1] - le[-2])
                    cpu, note = math.exp(lc[-1] + slope * (le_r - le[-1])), " (extrapolated)"
                elif le_r > le.max():
                    cpu, note = math.exp(lc[0]), " (Yee's coarsest grid is already more accurate)"
                else:
                    order_e = np.argsort(le)
                    cpu, note = math.exp(np.interp(le_r, le[order_e], lc[order_e])), ""
                print(f"  {kind:<10s} {name:<22s} n_r={r['n_radial']:<3d} ({r['unknowns']:>6d} unknowns): SPEM "
                      f"{r['error']:.2e} in {r['setup'] + r['run']:6.1f} s; {yee_name} at equal unknowns {e:.2e} "
                      f"({e / r['error']:.1f}x), Yee CPU for SPEM's error {cpu:.3g} s{note}")


def other_cylinders():
    print("\nOther cylinders: error of the scattered Hz at 8 / 16 spacings per radius (order)")
    for kind, kw in (("pec", dict(ka=1.0)), ("pec", dict(ka=3.0)), ("dielectric", dict(eps_r=2.0)),
                     ("dielectric", dict(eps_r=9.0, ka=1.0))):
        spem = [ts.run_tez_scattering(kind, n_radial=n, **kw).error for n in (8, 16)]
        yee = [run_yee_tez_scattering(kind, n, average="anisotropic", **kw)["error"] for n in (8, 16)]
        label = ", ".join(f"{k} {v:g}" for k, v in kw.items())
        print(f"  {kind:<10s} {label:<18s} SPEM {spem[0]:.2e} / {spem[1]:.2e} ({math.log2(spem[0] / spem[1]):.2f})   "
              f"Yee {'staircased' if kind == 'pec' else 'anisotropic'} {yee[0]:.2e} / {yee[1]:.2e} "
              f"({math.log2(yee[0] / yee[1]):.2f})", flush=True)


def jump_table():
    """The fitted interface (``average="jump"``, :func:`.tez_jump_permittivity`) against the anisotropic average.

    Dielectric cylinders on the lattice (ka = 2 and eps_r = 4 unless given), 4 / 8 / 16 spacings per
    radius: SPEM with the anisotropic average, SPEM "jump" (and "jump held": ``jump_energy_weight=0.01``,
    the start's energy of the test fields kept), and the Yee grid with the same anisotropic
    average (:func:`run_yee_tez_scattering`); the error of the scattered Hz (``growth``: the field's
    last-period growth, about 1 at a steady state).
    """
    print("\nTEz dielectric cylinders: error of the scattered Hz at 4 / 8 / 16 spacings per radius")
    for kw in (dict(), dict(eps_r=2.0), dict(eps_r=9.0), dict(ka=1.0), dict(ka=3.0)):
        label = ", ".join(f"{k} {v:g}" for k, v in kw.items()) or "ka 2, eps_r 4"
        for name, fn in (("SPEM anisotropic", lambda n: ts.run_tez_scattering("dielectric", n_radial=n, **kw)),
                         ("SPEM jump", lambda n: ts.run_tez_scattering("dielectric", n_radial=n, average="jump",
                                                                       **kw)),
                         ("SPEM jump held", lambda n: ts.run_tez_scattering("dielectric", n_radial=n, average="jump",
                                                                            jump_energy_weight=0.01, **kw)),
                         ("Yee anisotropic", lambda n: run_yee_tez_scattering("dielectric", n, average="anisotropic",
                                                                              **kw))):
            res = [fn(n) for n in (4, 8, 16)]
            err = [r.error if hasattr(r, "error") else r["error"] for r in res]
            growth = [r.field_growth if hasattr(r, "field_growth") else r.get("growth", float("nan")) for r in res]
            print(f"  {label:<14s} {name:<17s} " + " / ".join(f"{e:.2e}" for e in err)
                  + "   growth " + " / ".join(f"{g:.3f}" for g in growth), flush=True)


def dielectric_table(ns=(4, 8, 16)):
    """TEz dielectric cylinders: SPEM with the corrected interface against the Yee grid, at 4 / 8 / 16 spacings.

    SPEM ``average="auto"`` (lattice: the jump-corrected curl pair, :class:`.CircularInterface`, with the
    fourth-order bulk rows; jittered: the anisotropic cell average), SPEM with the anisotropic cell average
    (second-order bulk: the previous default), and the Yee grid with the same anisotropic average and
    staircased (:func:`run_yee_tez_scattering`), ka = 2 and eps_r = 4 unless given. Every run lasts until its
    phasor is steady (``periods="auto"``; the periods it took in brackets, ``*`` where it stopped unsteady).
    ``ratio``: the averaged Yee's error at SPEM's unknowns (log-log interpolation on Yee's own curve) over
    SPEM "auto"'s.
    """
    print("\nTEz dielectric cylinders: error of the scattered Hz at " + " / ".join(map(str, ns))
          + " spacings per radius (unknowns, periods run until steady)")
    cases = [dict(), dict(ka=1.0), dict(ka=3.0), dict(eps_r=2.0), dict(eps_r=8.0), dict(layout="jittered")]
    for kw in cases:
        label = ", ".join(f"{k} {v}" for k, v in kw.items()) or "ka 2, eps_r 4"
        yee_kw = {k: v for k, v in kw.items() if k != "layout"}
        rows = {}
        for name, fn in (("SPEM auto", lambda n: ts.run_tez_scattering("dielectric", n_radial=n, average="auto", **kw)),
                         ("SPEM anisotropic", lambda n: ts.run_tez_scattering("dielectric", n_radial=n, **kw)),
                         ("Yee anisotropic", lambda n: run_yee_tez_scattering("dielectric", n, average="anisotropic",
                                                                              **yee_kw)),
                         ("Yee staircased", lambda n: run_yee_tez_scattering("dielectric", n, **yee_kw))):
            out = []
            for n in ns:
                try:
                    r = fn(n)
                except (ValueError, MemoryError) as e:
                    out.append((n, None, None, "", type(e).__name__, ""))
                    continue
                if isinstance(r, dict):
                    steady = "" if r["transient"] <= STEADY_TOL else "*"
                    out.append((n, r["error"], r["unknowns"], "", "", f"{r['periods']:g}{steady}"))
                else:
                    steady = "" if not r.certificate_failures else "*"
                    out.append((n, r.error, r.particles, r.average, "", f"{r.periods:g}{steady}"))
            rows[name] = out
            cells = [f"{e:.2e} ({u}, {p})" if e is not None else f"failed: {why}" for _, e, u, _, why, p in out]
            used = sorted({a for _, _, _, a, _, _ in out if a})
            print(f"  {label:<16s} {name:<17s} " + " / ".join(cells) + (f"   [{', '.join(used)}]" if used else ""),
                  flush=True)
        yee = [(u, e) for _, e, u, _, _, _ in rows["Yee anisotropic"] if e is not None]
        lu, le = np.log([u for u, _ in yee]), np.log([e for _, e in yee])
        ratios = []
        for _, e, u, _, _, _ in rows["SPEM auto"]:
            ratios.append(f"{math.exp(np.interp(math.log(u), lu, le)) / e:.1f}x" if e is not None else "-")
        print(f"  {label:<16s} {'ratio':<17s} " + " / ".join(ratios) + "   (averaged Yee at SPEM's unknowns / SPEM auto)",
              flush=True)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--sweep", action="store_true")
    p.add_argument("--scattering", action="store_true", help="only the TEz scattering table (scattering_main)")
    p.add_argument("--jump", action="store_true", help="only the fitted-interface table (jump_table)")
    p.add_argument("--dielectric", action="store_true",
                   help="only the dielectric table: the corrected interface against Yee (dielectric_table)")
    args = p.parse_args()
    if args.dielectric:
        dielectric_table()
        return
    if args.jump:
        jump_table()
        return
    if args.scattering:
        scattering_main()
        other_cylinders()
        return
    disk_kdr = lambda n: 1.8412 / n  # noqa: E731
    rect_kdr = lambda n: 0.6 * math.pi / n  # noqa: E731
    table("Circular TEz cavity, sbp (h/dr 0.8)",
          [(n, tez.run_tez_circular_cavity(n_radial=n)) for n in (10, 20, 40)], disk_kdr)
    table("Circular TEz cavity, sbp, h/dr 0.7",
          [(n, tez.run_tez_circular_cavity(n_radial=n, h_ratio=0.7)) for n in (10, 20, 40)], disk_kdr)
    for seed in (0, 1):
        table(f"Circular TEz cavity, jittered 0.2 dr (seed={seed}), sbp (h/dr 0.8; whole operator corrected)",
              [(n, tez.run_tez_circular_cavity(n_radial=n, layout="jittered", seed=seed)) for n in (10, 20, 40)],
              disk_kdr)
    table("Circular TEz cavity, adjoint (no wall correction; energy-conserving, inconsistent)",
          [(n, tez.run_tez_circular_cavity(n_radial=n, coupling="adjoint")) for n in (10, 20, 40)], disk_kdr)
    table("PEC rectangle 0.1 x 0.06 m, sbp (h/dr 0.7)", [(n, tez.run_tez_cavity(n=n)) for n in (6, 12, 24)], rect_kdr)
    table("PEC rectangle, walls as closure columns with fitted volumes (wall_closure=True, h/dr 0.8)",
          [(n, tez.run_tez_cavity(n=n, wall_closure=True)) for n in (6, 12, 24)], rect_kdr)
    table("PEC rectangle jittered 0.2 dr (seed=0), unit-volume sbp (h/dr 0.8)",
          [(n, tez.run_tez_cavity(n=n, layout="jittered", h_ratio=0.8, wall_closure=False)) for n in (6, 12, 24)], rect_kdr)
    table("PEC rectangle jittered 0.2 dr (seed=0), wall_closure=True (h/dr 0.8)",
          [(n, tez.run_tez_cavity(n=n, layout="jittered", wall_closure=True)) for n in (6, 12, 24)], rect_kdr)
    if args.sweep:
        sweep()


if __name__ == "__main__":
    main()
