"""SPEM against a staircased Yee FDTD on the circular PEC cavity (TMz, [2] sec. 4.3) and cylinder scattering.

Run: .venv/bin/python benchmarks/spem_vs_yee.py [--full]
     .venv/bin/python benchmarks/spem_vs_yee.py --scattering [--full]   (plane wave on PEC, dielectric and
     coated cylinders, :mod:`manifold_sph.spem.cases.scattering`, against the same scattered-field formulation,
     PML and DFT on the Yee grid; staircased, and for the dielectric also cell-averaged like SPEM's particles)
     .venv/bin/python benchmarks/spem_vs_yee.py --dielectric   (the dielectric cylinder table of issue 21
     item 3 in one run: Yee staircased / cell-averaged against SPEM with and without ``time_correction``,
     and with ``interface="jump"``)
     .venv/bin/python benchmarks/spem_vs_yee.py --dielectric-checks   (the jump-corrected interface against the
     cell average on other cylinders: eps_r 2 and 8, ka 1 and 3, at 8 and 16 spacings per radius, beside the
     staircased Yee grid; periods long enough for the high-Q cases to ring down)
     .venv/bin/python benchmarks/spem_vs_yee.py --cost [--sizes 1e4 9e4 1e6] [--repeat 7]   (ns per unknown
     and step on lattices, in one run: the numpy Yee, SPEM's CSR step (``stencil=False``) and its stencil
     runs (the default), on a PEC square cavity and on a plane wave with PML; see :func:`cost_main`)

The cavity: radius r0 = 0.1 m, eps_r = 10, Ez(0) = 1 - r^2/r0^2, exact Bessel series
(:func:`manifold_sph.spem.cases.cavity_exact`). Both methods report

- ``error``: mean |Ez - exact| / max |exact| over their E points after one period of TM010,
- ``f1_error``: relative error of the TM010 resonance read from 10 periods of a centre probe,
- ``unknowns``: Ez + Hx + Hy values updated (inside the cavity), ``setup`` and ``run`` seconds.

The Yee grid is a small numpy FDTD written for this benchmark: square cells of side d, Ez at
(i, j) d, Hx at (i, j + 1/2) d, Hy at (i + 1/2, j) d, Ez held at 0 on every node with r >= r0
(the staircased wall), Courant number c dt / d = 0.99 / sqrt(2). It is checked against the
exact TM_11 frequency of a square PEC cavity (printed first). Then a table at equal resolution,
and the Yee cost needed to reach each SPEM error (log-log interpolation of Yee's error against
its CPU time).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from manifold_sph.spem.cases import cavity_exact, cavity_frequency, peak_frequency, relative_error, run_cavity
from manifold_sph.spem.constants import C0, EPS0, MU0
from manifold_sph.spem.steady import run_driven


class YeeTMz:
    """2D TMz Yee FDTD on an (n + 1) x (n + 1) node grid of spacing d, PEC where ``pec`` (bool, Ez nodes)."""

    def __init__(self, n, d, pec, eps_r=1.0, courant=0.99 / math.sqrt(2)):
        self.n, self.d = n, d
        self.dt = courant * d / (C0 / math.sqrt(eps_r))
        self.ce = self.dt / (EPS0 * eps_r * d)
        self.ch = self.dt / (MU0 * d)
        self.pec = pec
        self.ez = np.zeros((n + 1, n + 1))  # [i, j] at (i d, j d)
        self.hx = np.zeros((n + 1, n))  # (i d, (j + 1/2) d)
        self.hy = np.zeros((n, n + 1))  # ((i + 1/2) d, j d)
        self.t = 0.0

    def set_initial(self, ez0):
        self.ez[:] = np.where(self.pec, 0.0, ez0)
        self._h(0.5)

    def _h(self, frac=1.0):
        self.hx -= frac * self.ch * (self.ez[:, 1:] - self.ez[:, :-1])
        self.hy += frac * self.ch * (self.ez[1:, :] - self.ez[:-1, :])

    def step(self):
        ez = self.ez
        ez[1:-1, 1:-1] += self.ce * ((self.hy[1:, 1:-1] - self.hy[:-1, 1:-1]) - (self.hx[1:-1, 1:] - self.hx[1:-1, :-1]))
        ez[self.pec] = 0.0
        self.t += self.dt
        self._h()


def yee_square_check(n=40):
    """Relative error of the TM_11 resonance of a unit-free square PEC cavity (exact c / (sqrt 2 a))."""
    a = 1.0
    d = a / n
    x = np.arange(n + 1) * d
    X, Y = np.meshgrid(x, x, indexing="ij")
    pec = (X <= 0) | (X >= a) | (Y <= 0) | (Y >= a)
    s = YeeTMz(n, d, pec)
    s.set_initial(np.sin(np.pi * X / a) * np.sin(np.pi * Y / a) + 0.3 * np.sin(2 * np.pi * X / a) * np.sin(np.pi * Y / a))
    sig = []
    for _ in range(4000):
        s.step()
        sig.append(s.ez[n // 3, n // 3])
    f = peak_frequency(np.array(sig), s.dt, fmin=0.5 * C0 / (math.sqrt(2) * a))
    exact = C0 / (math.sqrt(2) * a)
    # the discrete Yee frequency: sin(w dt / 2) = c dt / d * sqrt(2) sin(pi d / (2 a))
    w = 2 / s.dt * math.asin(C0 * s.dt / d * math.sqrt(2) * math.sin(math.pi * d / (2 * a)))
    return abs(f - exact) / exact, abs(f - w / (2 * math.pi)) / exact


def run_yee_cavity(n_radial, r0=0.1, eps_r=10.0, spectrum_periods=10.0):
    t0 = time.perf_counter()
    d = r0 / n_radial
    n = 2 * n_radial + 2
    x = (np.arange(n + 1) - n / 2) * d
    X, Y = np.meshgrid(x, x, indexing="ij")
    R = np.hypot(X, Y)
    pec = R >= r0
    s = YeeTMz(n, d, pec, eps_r)
    s.set_initial(np.clip(1 - R**2 / r0**2, 0, None))
    f1 = cavity_frequency(r0, eps_r)
    T = 1 / f1
    steps = int(math.ceil(T / s.dt))
    s.dt = T / steps  # end exactly at one period (Courant slightly below 0.99/sqrt 2)
    s.ce, s.ch = s.dt / (EPS0 * eps_r * d), s.dt / (MU0 * d)
    s.set_initial(np.clip(1 - R**2 / r0**2, 0, None))
    inside = ~pec
    hx_in = np.hypot(X[:, :-1], Y[:, :-1] + d / 2) < r0
    hy_in = np.hypot(X[:-1, :] + d / 2, Y[:-1, :]) < r0
    unknowns = int(inside.sum() + hx_in.sum() + hy_in.sum())
    setup = time.perf_counter() - t0
    c = n // 2
    probe = []
    t1 = time.perf_counter()
    for _ in range(steps):
        s.step()
        probe.append(s.ez[c, c])
    run1 = time.perf_counter() - t1
    err = relative_error(s.ez[inside], cavity_exact(R[inside], s.t, r0, eps_r))
    more = int(round(spectrum_periods * T / s.dt))
    for _ in range(more):
        s.step()
        probe.append(s.ez[c, c])
    fm = peak_frequency(np.array(probe), s.dt, fmin=0.3 * f1)
    return {"method": "Yee FDTD (staircased)", "n_radial": n_radial, "unknowns": unknowns, "error": err,
            "f1_error": abs(fm - f1) / f1, "setup": setup, "run": run1, "steps": steps,
            "ns_per_unknown_step": 1e9 * run1 / (steps * unknowns)}


def run_spem_cavity(n_radial, coupling="sbp"):
    r = run_cavity(n_radial=n_radial, coupling=coupling, spectrum_periods=10.0)
    r1 = run_cavity(n_radial=n_radial, coupling=coupling)  # one period only: the run time comparable with Yee's
    unknowns = r1.particles  # E (free and wall) + Hx + Hy; the wall E are held at 0
    return {"method": f"SPEM {coupling}", "n_radial": n_radial, "unknowns": unknowns, "error": r1.error,
            "f1_error": r.f1_error, "setup": r1.seconds - r1.step_seconds, "run": r1.step_seconds,
            "steps": r1.steps, "ns_per_unknown_step": 1e9 * r1.step_seconds / (r1.steps * unknowns)}


def row(r):
    return (f"{r['method']:<24s} {r['n_radial']:>4d} {r['unknowns']:>8d} {r['error']:>10.3e} {r['f1_error']:>10.3e} "
            f"{r['setup']:>8.2f} {r['run']:>8.3f} {r['steps']:>6d} {r['ns_per_unknown_step']:>8.1f}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--full", action="store_true", help="add SPEM at 80 spacings per radius (set-up ~40 s); "
                    "with --scattering, jittered particles at 16 spacings per radius too")
    ap.add_argument("--scattering", action="store_true", help="the cylinder scattering cases instead of the cavity")
    ap.add_argument("--dielectric", action="store_true", help="the dielectric cylinder table (issue 21 item 3): "
                    "Yee staircased / cell-averaged against SPEM mimetic (fast band, h/dr 1.2) and sbp, with and "
                    "without time_correction, and the jump-corrected interface; one run, ~12 min")
    ap.add_argument("--dielectric-checks", action="store_true", help="interface='jump' against the cell average "
                    "on eps_r 2 / 8 and ka 1 / 3 cylinders (~10 min)")
    ap.add_argument("--cost", action="store_true", help="the cost per unknown and step table (lattices)")
    ap.add_argument("--sizes", type=float, nargs="+", default=[1e4, 9e4, 1e6], help="--cost: unknowns (about)")
    ap.add_argument("--repeat", type=int, default=7, help="--cost: timed repeats (the median is printed)")
    a = ap.parse_args()
    if a.cost:
        cost_main(a.sizes, a.repeat)
        return
    if a.scattering:
        scattering_main(a.full)
        return
    if a.dielectric:
        dielectric_main()
        return
    if a.dielectric_checks:
        dielectric_checks()
        return
    e1, e2 = yee_square_check()
    print(f"Yee check, square PEC cavity TM11 at 40 cells: frequency error {e1:.2e} against the exact mode, "
          f"{e2:.1e} against the Yee dispersion relation")
    head = (f"{'method':<24s} {'n_r':>4s} {'unknowns':>8s} {'error':>10s} {'f1_error':>10s} {'setup s':>8s} {'run s':>8s} "
            f"{'steps':>6s} {'ns/u/st':>8s}")
    print(head)
    yee = [run_yee_cavity(n) for n in (10, 20, 40, 80, 160)]
    for r in yee:
        print(row(r))
    spem = [run_spem_cavity(n) for n in ((10, 20, 40, 80) if a.full else (10, 20, 40))]
    for r in spem:
        print(row(r))
    # Yee's CPU (set-up + run, one period) to reach each SPEM error, by log-log interpolation
    le = np.log([r["error"] for r in yee])
    lt = np.log([r["setup"] + r["run"] for r in yee])
    lu = np.log([r["unknowns"] for r in yee])
    order = np.argsort(le)
    print("\nat equal error (Yee interpolated on its own error/cost curve):")
    for r in spem:
        x = math.log(r["error"])
        if x < le.min():
            print(f"  SPEM n_r={r['n_radial']}: error {r['error']:.2e} is below every Yee run (best {math.exp(le.min()):.2e})")
            continue
        t = math.exp(np.interp(x, le[order], lt[order]))
        u = math.exp(np.interp(x, le[order], lu[order]))
        cpu = r["setup"] + r["run"]
        print(f"  SPEM n_r={r['n_radial']}: error {r['error']:.2e} in {cpu:.2f} s (set-up incl.) with {r['unknowns']} "
              f"unknowns; Yee needs ~{u:.0f} unknowns and ~{t:.3f} s: SPEM/Yee CPU = {cpu / t:.1f}")
    # equal unknowns
    print("\nat equal unknowns (Yee interpolated on its own unknowns/error curve):")
    for r in spem:
        e = math.exp(np.interp(math.log(r["unknowns"]), lu, le))
        print(f"  SPEM n_r={r['n_radial']} ({r['unknowns']} unknowns): error {r['error']:.2e}, Yee {e:.2e}: "
              f"Yee/SPEM = {e / r['error']:.1f}")


def run_spem_scattering(kind, n_radial, **kw):
    from manifold_sph.spem.cases import run_scattering

    r = run_scattering(kind, n_radial=n_radial, **kw)
    return {"method": f"SPEM {r.coupling} {r.layout}", "case": kind, "n_radial": n_radial, "unknowns": r.particles,
            "error": r.error, "ring_error": r.ring_error, "setup": r.setup_seconds,
            "run": r.seconds - r.setup_seconds, "steps": r.steps,
            "ns_per_unknown_step": 1e9 * (r.seconds - r.setup_seconds) / (r.steps * r.particles)}


def _compare(spem, yee, label):
    """Yee interpolated (log-log) on its own unknowns/error and error/CPU curves."""
    le = np.log([r["error"] for r in yee])
    lt = np.log([r["setup"] + r["run"] for r in yee])
    lu = np.log([r["unknowns"] for r in yee])
    order = np.argsort(le)
    for r in spem:
        e = math.exp(np.interp(math.log(r["unknowns"]), lu, le))
        cpu = r["setup"] + r["run"]
        x = math.log(r["error"])
        if x < le.min():
            # extrapolated along the last two runs (error ~ n^-p, CPU ~ n^q)
            k = np.argsort(lu)[-2:]
            slope = (lt[k[1]] - lt[k[0]]) / (le[k[1]] - le[k[0]])
            t = math.exp(lt[k[1]] + slope * (x - le[k[1]]))
            eq = (f"below every {label} run (best {math.exp(le.min()):.2e}); extrapolated, {label} needs ~{t:.0f} s: "
                  f"SPEM/{label} CPU = {cpu / t:.2g}")
        elif x > le.max():
            eq = f"above every {label} run"
        else:
            t = math.exp(np.interp(x, le[order], lt[order]))
            eq = f"{label} reaches it in ~{t:.2f} s: SPEM/{label} CPU = {cpu / t:.1f}"
        print(f"  {r['case']:<10s} n_r={r['n_radial']:<3d} ({r['unknowns']} unknowns): SPEM {r['error']:.2e} in "
              f"{cpu:.2f} s; {label} at equal unknowns {e:.2e} ({label}/SPEM = {e / r['error']:.1f}); "
              f"equal error: {eq}")


def scattering_main(full=False, kinds=("pec", "dielectric", "coated"), layouts=("yee", "jittered")):
    """Plane-wave scattering by PEC, dielectric (eps_r 4) and coated cylinders, ka = 2 (issue 21 item 3)."""
    head = (f"{'method':<34s} {'case':<10s} {'n_r':>4s} {'unknowns':>8s} {'error':>10s} {'ring':>10s} {'setup s':>8s} "
            f"{'run s':>8s} {'steps':>6s} {'ns/u/st':>8s}")

    def line(r):
        return (f"{r['method']:<34s} {r['case']:<10s} {r['n_radial']:>4d} {r['unknowns']:>8d} {r['error']:>10.3e} "
                f"{r['ring_error']:>10.3e} {r['setup']:>8.2f} {r['run']:>8.2f} {r['steps']:>6d} "
                f"{r['ns_per_unknown_step']:>8.1f}")

    print("relative L2 error of the complex scattered field (DFT at the drive frequency) on the particles/nodes "
          "outside the PML; 'ring': the annulus a < r <= 2a")
    print(head)
    for kind in kinds:
        periods = 12.0 if kind == "pec" else 20.0
        yee = [run_yee_scattering(kind, n, periods=periods) for n in ((4, 8, 16, 32, 64) if kind == "pec"
                                                                        else (4, 8, 16, 32))]
        avg = [] if kind == "pec" else [run_yee_scattering(kind, n, periods=periods, eps_mode="average")
                                        for n in (4, 8, 16, 32)]
        for r in yee + avg:
            print(line(r), flush=True)
        spem = {}
        # (layout, sbp_layers, h_ratio, sizes); "auto": the whole operator corrected with a conductor, a band of
        # 2 rings for the dielectric
        configs = [("yee", "auto", 0.7, (4, 8, 16))]
        if kind == "pec":
            configs.append(("yee", 2, 0.7, (8, 16, 24)))
        if kind == "dielectric":
            configs.append(("yee", "auto", 0.6, (4, 8, 16)))
        if "jittered" in layouts:
            configs.append(("jittered", "auto", 0.7, (4, 8, 16) if full else (4, 8)))
        for layout, layers, h_ratio, sizes in configs:
            rows = [run_spem_scattering(kind, n, periods=periods, layout=layout, sbp_layers=layers, h_ratio=h_ratio,
                                        interface="average")
                    for n in sizes]
            for r in rows:
                r["method"] += ("" if layers == "auto" else f" {layers} rings") + ("" if h_ratio == 0.7
                                                                                  else f" h/dr {h_ratio}")
                print(line(r), flush=True)
            spem[layout, layers, h_ratio] = rows
        for (layout, layers, h_ratio), rows in spem.items():
            what = f"SPEM {layout}" + ("" if layers == "auto" else f" ({layers} rings)") + (
                "" if h_ratio == 0.7 else f" (h/dr {h_ratio})")
            print(f"{kind}, {what} against the staircased Yee:")
            _compare(rows, yee, "Yee")
            if avg:
                print(f"{kind}, {what} against Yee with the same cell-averaged eps:")
                _compare(rows, avg, "Yee-avg")


def dielectric_main(periods=20.0):
    """The dielectric cylinder (eps_r 4, ka = 2, 20 periods) in one run: the issue's Yee baselines (staircased,
    cell-averaged), Yee with the time correction (for reference), SPEM mimetic (fast band, h/dr 1.2) with and
    without ``time_correction`` (with it at 32 spacings per radius too), the same with ``interface="jump"``
    (4-32; and with 40 periods: at 20 the slow ring-down of the cylinder's modes leaves about 2e-4), and sbp
    with the time correction, with and without the jump; then each SPEM row against the staircased Yee at
    equal unknowns and at equal error (CPU)."""
    head = (f"{'method':<40s} {'n_r':>4s} {'unknowns':>8s} {'error':>10s} {'ring':>10s} {'setup s':>8s} "
            f"{'run s':>8s} {'steps':>6s}")
    print("dielectric cylinder eps_r 4, ka = 2, 20 periods: relative L2 error of the scattered phasor")
    print(head)

    def line(r):
        print(f"{r['method']:<40s} {r['n_radial']:>4d} {r['unknowns']:>8d} {r['error']:>10.3e} "
              f"{r['ring_error']:>10.3e} {r['setup']:>8.2f} {r['run']:>8.2f} {r['steps']:>6d}", flush=True)

    yee = [run_yee_scattering("dielectric", n, periods=periods) for n in (4, 8, 16, 32, 64)]
    for r in yee:
        line(r)
    avg = [run_yee_scattering("dielectric", n, periods=periods, eps_mode="average") for n in (4, 8, 16, 32)]
    for r in avg:
        line(r)
    for n in (4, 8, 16, 32):
        line(run_yee_scattering("dielectric", n, periods=periods, eps_mode="average", time_correction=True))
    spem = {"mimetic-fast h/dr 1.2": dict(coupling="mimetic", mimetic_fast=True, h_ratio=1.2, interface="average"),
            "mimetic-fast h/dr 1.2 time-corr.": dict(coupling="mimetic", mimetic_fast=True, h_ratio=1.2,
                                                      time_correction=True, interface="average"),
            "mimetic-fast h/dr 1.2 time-corr. jump": dict(coupling="mimetic", mimetic_fast=True, h_ratio=1.2,
                                                           time_correction=True, interface="jump"),
            "mimetic-fast h/dr 1.2 time-corr. jump 40 periods": dict(coupling="mimetic", mimetic_fast=True,
                                                                      h_ratio=1.2, time_correction=True,
                                                                      interface="jump", periods=40.0),
            "sbp time-corr.": dict(coupling="sbp", time_correction=True, interface="average"),
            "sbp jump": dict(coupling="sbp", interface="jump")}
    rows = {}
    for name, kw in spem.items():
        sizes = (4, 8, 16, 32) if name.startswith("mimetic-fast h/dr 1.2 time-corr.") else (4, 8, 16)
        kw = {"periods": periods, **kw}
        rows[name] = [run_spem_scattering("dielectric", n, **kw) for n in sizes]
        for r in rows[name]:
            r["method"] = f"SPEM {name}"
            line(r)
    for name, rr in rows.items():
        print(f"SPEM {name} against the staircased Yee:")
        _compare(rr, yee, "Yee")
        print(f"SPEM {name} against the cell-averaged Yee:")
        _compare(rr, avg, "Yee-avg")


def dielectric_checks():
    """``interface="jump"`` against the cell average (SPEM mimetic, fast band, h/dr 1.2, time correction) on
    cylinders other than the issue's: eps_r 2 and 8 (ka 2), ka 1 and 3 (eps_r 4), at 8 and 16 spacings per
    radius, with the staircased Yee grid at equal resolution. eps_r 8 and ka = 3 have high-Q modes that ring
    down slowly (20 periods leave 5e-2 there), so they run 150 and 120 periods."""
    head = (f"{'case':<16s} {'method':<34s} {'n_r':>4s} {'unknowns':>8s} {'error':>10s} {'ring':>10s} "
            f"{'setup s':>8s} {'run s':>8s}")
    print("dielectric cylinders: relative L2 error of the scattered phasor (SPEM mimetic fast, h/dr 1.2, "
          "time correction)")
    print(head)
    cases = [("eps_r 2", dict(eps_r=2.0), 20.0), ("eps_r 8", dict(eps_r=8.0), 150.0),
             ("ka 1", dict(ka=1.0), 20.0), ("ka 3", dict(ka=3.0), 120.0)]
    for label, kw, periods in cases:
        for n in (8, 16):
            rows = [run_yee_scattering("dielectric", n, periods=periods, **kw)]
            for interface in ("average", "jump"):
                r = run_spem_scattering("dielectric", n, periods=periods, coupling="mimetic", mimetic_fast=True,
                                        h_ratio=1.2, time_correction=True, interface=interface, **kw)
                r["method"] = f"SPEM {interface}"
                rows.append(r)
            for r in rows:
                print(f"{label + f' ({periods:g} per.)':<16s} {r['method']:<34s} {n:>4d} {r['unknowns']:>8d} "
                      f"{r['error']:>10.3e} {r['ring_error']:>10.3e} {r['setup']:>8.2f} {r['run']:>8.2f}",
                      flush=True)
    centre = (0.013, -0.021)
    for n in (8, 16):
        for interface in ("average", "jump"):
            err, setup, run = run_offcentre_dielectric(n, centre, interface)
            print(f"{'off-centre':<16s} {'SPEM ' + interface + f' centre {centre}':<34s} {n:>4d} {'':>8s} "
                  f"{err:>10.3e} {'':>10s} {setup:>8.2f} {run:>8.2f}", flush=True)


def run_offcentre_dielectric(n_radial, centre, interface, *, radius=0.1, ka=2.0, eps_r=4.0, periods=20.0):
    """The dielectric cylinder (eps_r 4, ka = 2) centred at ``centre``, off the lattice's symmetry, with the
    public pieces of :mod:`manifold_sph.spem.cases.scattering` (``run_scattering`` keeps the cylinder at the
    origin): cell-averaged eps or :func:`~manifold_sph.spem.cases.jump_permittivity` with the circle's
    curvature, mimetic fast band, h/dr 1.2, time correction, the same PML and DFT. Returns (error, set-up s,
    run s); the exact field is the centred series shifted (the incident phase ``exp(i k cx)``)."""
    from manifold_sph.spem.cases import l2_error
    from manifold_sph.spem.cases.scattering import SwitchedWave, VolumeDrive, interior_particles, scattering_layout
    from manifold_sph.spem.interfaces import cell_fraction, jump_permittivity
    from manifold_sph.spem.mie import scattered_field
    from manifold_sph.spem.pml import PML
    from manifold_sph.spem.sources import Source
    from manifold_sph.spem.tmz import TMzSolver

    t0 = time.perf_counter()
    cx, cy = centre
    freq = ka * C0 / (2 * math.pi * radius)
    lam = C0 / freq
    dr = radius / n_radial
    inner = dr * math.ceil((radius + math.hypot(cx, cy) + 0.5 * lam) / dr - 1e-9)
    outer = inner + dr * math.ceil(0.5 * lam / dr - 1e-9)
    lay = scattering_layout("dielectric", radius, dr, outer)
    e = lay.e
    phi = np.hypot(e[:, 0] - cx, e[:, 1] - cy) - radius
    eps = 1.0 + (eps_r - 1.0) * cell_fraction(e, dr, lambda x, y: np.hypot(x - cx, y - cy) < radius)
    cand = np.flatnonzero((phi < 6 * dr) & ~lay.e_fixed)  # every particle the jump can change (checked below)
    k0 = 2 * math.pi * freq / C0
    inc = SwitchedWave(e[cand, 0], freq, cx - radius, 3.0, k0)
    drive = VolumeDrive(inc, np.zeros(len(cand)))
    pml = PML(outer - inner, 3, 1e-6, interior=(-inner, inner, -inner, inner))
    s = TMzSolver(lay, h_ratio=1.2, eps_r=eps, pml=pml, sources=[Source(cand, drive, "soft")], coupling="mimetic",
                  mimetic_fast=True, sbp_layers=2)
    if interface == "jump":
        fr = s.free
        L = s.Dx_e @ s.Dx_hy[:, fr] + s.Dy_e @ s.Dy_hx[:, fr]
        eps = np.ones(len(e))
        eps[fr] = jump_permittivity(L, phi[fr], eps_r, curvature=1.0 / radius)
        s._set_materials(eps, 1.0, 0.0)
        s._set_time_step(None, 0.9)
        s._set_losses()
        outside = np.ones(len(e), bool)
        outside[cand] = False
        assert (eps[outside] == 1.0).all(), "the jump changed eps beyond the driven particles"
    drive.factor = (eps[cand] - 1.0) / eps[cand]
    per = int(math.ceil(1.0 / freq / s.dt - 1e-9))
    w = 2 * math.pi * freq
    dt = 2.0 * math.sin(math.pi / per) / w  # the time correction
    w = 2 * math.pi / (per * dt)
    inc.freq = w / (2 * math.pi)
    s.set_dt(dt)
    drive.dt = s.dt
    ev = interior_particles(s, e, inner)
    setup = time.perf_counter() - t0

    def advance(n):
        s.step()
        return s.e_field[ev], s.t

    phasor = run_driven(advance, per, w, periods=periods, ramp=3.0, window=2.0).phasor
    exact = scattered_field(e[ev] - [cx, cy], "dielectric", freq=freq, radius=radius, eps_r=eps_r)
    exact = exact * np.exp(1j * k0 * cx)
    return l2_error(phasor, exact), setup, time.perf_counter() - t0 - setup


# ----------------------------------------------------------------------------- scattering (issue 21 item 3)
def run_yee_scattering(kind, n_radial, *, radius=0.1, ka=2.0, eps_r=4.0, core_radius=None, margin=0.5,
                       pml_thickness=0.5, periods=12.0, ramp=3.0, dft_periods=2.0, courant=0.99 / math.sqrt(2),
                       eps_mode="staircase", time_correction=False):
    """The scattering cases of :func:`manifold_sph.spem.cases.run_scattering` on a numpy Yee grid.

    Same scattered-field formulation, incident switch-on, split-field PML (the same
    :class:`~manifold_sph.spem.pml.PML` profile, same thickness in metres), periods and DFT. Cells of
    side d = radius / n_radial with an Ez node at the centre; the conductor is staircased (Ez_s = -Ez_inc
    on every node with r <= b), the dielectric too (``eps_mode="staircase"``: eps_r on the nodes with
    r < a) or cell-averaged like SPEM's particles (``"average"``). ``time_correction``: as in
    :func:`~manifold_sph.spem.cases.run_scattering` (the leap-frog's time dispersion removed at the
    drive frequency; not the issue's baseline, which is without it).
    """
    from manifold_sph.spem.cases import l2_error
    from manifold_sph.spem.cases.scattering import SwitchedWave
    from manifold_sph.spem.interfaces import cell_fraction
    from manifold_sph.spem.mie import scattered_field
    from manifold_sph.spem.pml import PML

    t_start = time.perf_counter()
    if kind == "coated" and core_radius is None:
        core_radius = 0.5 * radius
    freq = ka * C0 / (2 * math.pi * radius)
    lam = C0 / freq
    d = radius / n_radial
    inner = d * math.ceil((radius + margin * lam) / d - 1e-9)
    outer = inner + d * math.ceil(pml_thickness * lam / d - 1e-9)
    n = int(round(2 * outer / d))
    x = np.arange(n + 1) * d - outer
    X, Y = np.meshgrid(x, x, indexing="ij")
    R = np.hypot(X, Y)
    pml = PML(outer - inner, 3, 1e-6, interior=(-inner, inner, -inner, inner))
    pts = np.column_stack([X.ravel(), Y.ravel()])
    sx, sy = (v.reshape(X.shape) for v in pml.sigma(pts))
    hxp = np.column_stack([X[:, :-1].ravel(), (Y[:, :-1] + d / 2).ravel()])
    hyp = np.column_stack([(X[:-1, :] + d / 2).ravel(), Y[:-1, :].ravel()])
    sy_hx = pml.sigma(hxp)[1].reshape(n + 1, n)
    sx_hy = pml.sigma(hyp)[0].reshape(n, n + 1)
    eps = np.ones_like(X)
    wall_r = {"pec": radius, "coated": core_radius}.get(kind)
    pec = np.zeros(X.shape, bool) if wall_r is None else R <= wall_r
    if kind != "pec":
        b = core_radius if kind == "coated" else 0.0
        if eps_mode == "staircase":
            eps = np.where((R < radius) & ~pec, eps_r, 1.0)
        else:
            frac = cell_fraction(pts, d, lambda u, v: (np.hypot(u, v) < radius) & (np.hypot(u, v) >= b))
            frac = frac.reshape(X.shape)
            eps = 1.0 + (eps_r - 1.0) * frac
    dt_max = courant * d / C0
    T = 1.0 / freq
    per = int(math.ceil(T / dt_max - 1e-9))
    dt = T / per
    w = 2 * math.pi * freq
    f_drive = freq
    if time_correction:
        dt = 2.0 * math.sin(math.pi / per) / w
        f_drive = 1.0 / (per * dt)

    def coef(s, m):
        a = s * dt / (2 * m)
        return (1 - a) / (1 + a), (dt / m) / (1 + a) / d

    cax, cbx = coef(sx, EPS0 * eps)
    cay, cby = coef(sy, EPS0 * eps)
    dax, dbx = coef(sy_hx * MU0 / EPS0, MU0)
    day, dby = coef(sx_hy * MU0 / EPS0, MU0)
    cax, cbx, cay, cby = (v[1:-1, 1:-1] for v in (cax, cbx, cay, cby))
    x0 = -radius
    pec_i = np.nonzero(pec)
    k0 = w / C0
    drive_pec = SwitchedWave(X[pec_i], f_drive, x0, ramp, k0)
    diel = np.nonzero((eps > 1.0) & ~pec)
    drive_d = SwitchedWave(X[diel], f_drive, x0, ramp, k0)
    fac = (eps[diel] - 1.0) / eps[diel]
    ezx = np.zeros(X.shape)
    ezy = np.zeros(X.shape)
    hx = np.zeros((n + 1, n))
    hy = np.zeros((n, n + 1))
    steps = int(round(periods * per))
    n_dft = int(round(dft_periods * per))
    ev = (np.abs(X) <= inner + 1e-9 * d) & (np.abs(Y) <= inner + 1e-9 * d) & ~pec
    ev[0, :] = ev[-1, :] = ev[:, 0] = ev[:, -1] = False
    acc = np.zeros(int(ev.sum()), dtype=complex)
    w = 2 * math.pi * f_drive
    unknowns = int((~pec[1:-1, 1:-1]).sum() + hx.size + hy.size)
    setup = time.perf_counter() - t_start
    t1 = time.perf_counter()
    t = 0.0
    for k in range(steps):
        ezx[1:-1, 1:-1] = cax * ezx[1:-1, 1:-1] + cbx * (hy[1:, 1:-1] - hy[:-1, 1:-1])
        ezy[1:-1, 1:-1] = cay * ezy[1:-1, 1:-1] - cby * (hx[1:-1, 1:] - hx[1:-1, :-1])
        t = (k + 1) * dt
        if len(diel[0]):
            ezx[diel] -= fac * (drive_d(t) - drive_d(t - dt))
        if len(pec_i[0]):
            ezx[pec_i] = -drive_pec(t)
            ezy[pec_i] = 0.0
        ez = ezx + ezy
        hx = dax * hx - dbx * (ez[:, 1:] - ez[:, :-1])
        hy = day * hy + dby * (ez[1:, :] - ez[:-1, :])
        if k >= steps - n_dft:
            acc += ez[ev] * np.exp(1j * w * t)
    run = time.perf_counter() - t1
    phasor = acc * (2.0 / n_dft)
    p = np.column_stack([X[ev], Y[ev]])
    exact = scattered_field(p, kind, freq=freq, radius=radius, eps_r=eps_r, core_radius=core_radius)
    rr = np.hypot(p[:, 0], p[:, 1])
    ring = (rr > radius) & (rr <= 2 * radius)
    method = (f"Yee FDTD ({eps_mode})" if kind != "pec" else "Yee FDTD (staircased)") + (
        " time-corr." if time_correction else "")
    return {"method": method, "case": kind,
            "n_radial": n_radial, "unknowns": unknowns, "error": l2_error(phasor, exact),
            "ring_error": l2_error(phasor[ring], exact[ring]), "setup": setup, "run": run, "steps": steps,
            "ns_per_unknown_step": 1e9 * run / (steps * unknowns)}


# ----------------------------------------------------------------------------- cost per unknown (issue 21)
def _yee_pml_grid(n, d, pml_cells, freq):
    """A numpy Yee step with split-field PML on every side and a hard line source (the update lines of
    :func:`run_yee_scattering`, no scatterer): returns ``(step(k), unknowns, ez())``."""
    from manifold_sph.spem.pml import PML
    from manifold_sph.spem.sources import Sinusoid

    size = (n - 2 * pml_cells) * d
    x = np.arange(n + 1) * d - pml_cells * d
    X, Y = np.meshgrid(x, x, indexing="ij")
    pml = PML(pml_cells * d, interior=(0.0, size, 0.0, size))
    sx, sy = (v.reshape(X.shape) for v in pml.sigma(np.column_stack([X.ravel(), Y.ravel()])))
    sy_hx = pml.sigma(np.column_stack([X[:, :-1].ravel(), (Y[:, :-1] + d / 2).ravel()]))[1].reshape(n + 1, n)
    sx_hy = pml.sigma(np.column_stack([(X[:-1, :] + d / 2).ravel(), Y[:-1, :].ravel()]))[0].reshape(n, n + 1)
    dt = 0.99 / math.sqrt(2) * d / C0

    def coef(sg, m):
        a = sg * dt / (2 * m)
        return (1 - a) / (1 + a), (dt / m) / (1 + a) / d

    cax, cbx = (v[1:-1, 1:-1] for v in coef(sx, EPS0))
    cay, cby = (v[1:-1, 1:-1] for v in coef(sy, EPS0))
    dax, dbx = coef(sy_hx * MU0 / EPS0, MU0)
    day, dby = coef(sx_hy * MU0 / EPS0, MU0)
    f = {"ezx": np.zeros(X.shape), "ezy": np.zeros(X.shape), "hx": np.zeros((n + 1, n)), "hy": np.zeros((n, n + 1)),
         "ez": np.zeros(X.shape)}
    wave = Sinusoid(freq, ramp=2.0)
    j_src = pml_cells + 1  # the line y = d inside the interior

    def step(k):
        ezx, ezy, hx, hy = f["ezx"], f["ezy"], f["hx"], f["hy"]
        ezx[1:-1, 1:-1] = cax * ezx[1:-1, 1:-1] + cbx * (hy[1:, 1:-1] - hy[:-1, 1:-1])
        ezy[1:-1, 1:-1] = cay * ezy[1:-1, 1:-1] - cby * (hx[1:-1, 1:] - hx[1:-1, :-1])
        ezx[1:-1, j_src] = wave((k + 1) * dt)
        ezy[1:-1, j_src] = 0.0
        ez = ezx + ezy
        f["hx"] = dax * hx - dbx * (ez[:, 1:] - ez[:, :-1])
        f["hy"] = day * hy + dby * (ez[1:, :] - ez[:-1, :])
        f["ez"] = ez

    return step, (n + 1) ** 2 + 2 * n * (n + 1), lambda: f["ez"]


def _interleaved_ns(runs, steps, unknowns, repeat):
    """Median ns per unknown and step of each ``run(k)`` in ``runs``, timed in turn ``repeat`` times (so that a
    change of the machine's load hits every method alike); each run gets an untimed step before its timed ones
    (warm-up, and the switch between SPEM's two step kinds)."""
    times = [[] for _ in runs]
    for run in runs:
        run(max(2, steps // 10))  # warm-up (compilation, caches)
    for _ in range(repeat):
        for j, (run, u) in enumerate(zip(runs, unknowns)):
            run(1)
            t0 = time.perf_counter()
            run(steps)
            times[j].append((time.perf_counter() - t0) / (steps * u))
    return [1e9 * float(np.median(t)) for t in times]


def cost_main(sizes=(1e4, 9e4, 1e6), repeat=7, pml_cells=10):
    """ns per unknown (Ez + Hx + Hy, the held PEC nodes included on both sides) and step, median of ``repeat``
    timed runs of ``steps`` steps (about 3e7 / unknowns, at least 10; the three methods timed in turn in each
    repeat, the same solver switching between its two step kinds), on square lattices of about ``sizes``
    unknowns: the numpy Yee (:class:`YeeTMz` on a PEC square; the split-field PML update of
    :func:`run_yee_scattering` with a hard line source), SPEM's previous compiled CSR step
    (``TMzSolver(stencil=False)``) and its stencil runs (``stencil=True``, :mod:`manifold_sph.spem.stencil`) on
    the same solver and Yee layout (default ``sbp`` coupling). ``rows in runs``: the share of E and H rows the
    stencil kernels apply; ``rel diff``: max |Ez_stencil - Ez_csr| / max |Ez_csr| after 200 steps from the
    same start. Last, SPEM's two steps on the circular cavity (disk layout, 20 and 40 spacings per radius)."""
    from manifold_sph.spem import PML, Sinusoid, Source, TMzSolver, yee_layout

    print("ns per unknown and step (median of %d runs; unknowns = Ez + Hx + Hy on the lattice)" % repeat)
    print(f"{'case':<10s} {'cells':>6s} {'unknowns':>9s} {'steps':>6s} {'Yee':>7s} {'CSR':>7s} {'stencil':>8s} "
          f"{'st/Yee':>7s} {'CSR/Yee':>8s} {'runs %':>7s} {'rel diff':>9s} {'setup s':>8s}")
    for target in sizes:
        n = max(2 * pml_cells + 4, int(round(math.sqrt(float(target) / 3.0))))
        d = 1e-3
        for case in ("cavity", "planewave"):
            if case == "cavity":
                x = np.arange(n + 1) * d
                X, Y = np.meshgrid(x, x, indexing="ij")
                pec = (X <= 0) | (X >= n * d) | (Y <= 0) | (Y >= n * d)
                yee = YeeTMz(n, d, pec)
                yee.set_initial(np.exp(-((X - n * d / 2) ** 2 + (Y - n * d / 2) ** 2) / (0.1 * n * d) ** 2))
                yee_unknowns = (n + 1) ** 2 + 2 * n * (n + 1)

                def yee_run(k, yee=yee):
                    for _ in range(k):
                        yee.step()
            else:
                freq = C0 / (20 * d)  # 20 cells per wavelength
                step, yee_unknowns, _ = _yee_pml_grid(n, d, pml_cells, freq)

                def yee_run(k, step=step):
                    for j in range(k):
                        step(j)
            steps = max(10, int(3e7 / yee_unknowns))
            t0 = time.perf_counter()
            if case == "cavity":
                lay = yee_layout((0.0, n * d, 0.0, n * d), d)
                s = TMzSolver(lay)
                e = lay.e
                start = np.exp(-((e[:, 0] - n * d / 2) ** 2 + (e[:, 1] - n * d / 2) ** 2) / (0.1 * n * d) ** 2)
            else:
                size = (n - 2 * pml_cells) * d
                pml = PML(pml_cells * d, interior=(0.0, size, 0.0, size))
                lay = yee_layout(pml.outer_bounds(), d)
                e = lay.e
                band = np.flatnonzero((np.abs(e[:, 1] - d) <= 0.5 * d) & ~lay.e_fixed)
                wave = Sinusoid(C0 / (20 * d), ramp=2.0)
                s = TMzSolver(lay, pml=pml, sources=[Source(band, lambda t, wave=wave: wave(t))])
                start = np.zeros(len(e))
            s._step_plan()  # the runs are found on the first step; counted as set-up here
            setup = time.perf_counter() - t0
            pl = s._step_plan()
            rows = pl.e.n_rows + pl.h.n_rows
            covered = pl.e.covered + pl.h.covered
            fields = {}
            for mode in (False, True):
                s.stencil = mode
                s.set_initial(start)
                s.run(200)
                fields[mode] = s.e_field.copy()
            diff = float(np.abs(fields[True] - fields[False]).max() / np.abs(fields[False]).max())
            s.set_initial(start)

            def spem_run(k, mode, s=s):
                s.stencil = mode
                s.run(k)

            t_yee, t_csr, t_st = _interleaved_ns([yee_run, lambda k: spem_run(k, False), lambda k: spem_run(k, True)],
                                                 steps, [yee_unknowns, lay.n_particles, lay.n_particles], repeat)
            print(f"{case:<10s} {n:>6d} {lay.n_particles:>9d} {steps:>6d} {t_yee:>7.2f} {t_csr:>7.2f} "
                  f"{t_st:>8.2f} {t_st / t_yee:>7.2f} {t_csr / t_yee:>8.2f} {100 * covered / rows:>7.1f} "
                  f"{diff:>9.1e} {setup:>8.1f}", flush=True)
            del s
    # the circular cavity of the accuracy table (disk layout, eps_r 10, the whole operator corrected): its
    # corrected rows all differ, so only weighted runs apply
    from manifold_sph.spem import disk_layout

    for n_radial in (20, 40):
        r0 = 0.1
        lay = disk_layout((r0, r0), r0, r0 / n_radial)
        s = TMzSolver(lay, eps_r=10.0, sbp_layers=None)
        pl = s._step_plan()
        r = np.hypot(lay.e[:, 0] - r0, lay.e[:, 1] - r0)
        s.set_initial(np.clip(1 - r**2 / r0**2, 0, None))

        def disk_run(k, mode, s=s):
            s.stencil = mode
            s.run(k)

        steps = max(10, int(3e7 / lay.n_particles))
        t_csr, t_st = _interleaved_ns([lambda k: disk_run(k, False), lambda k: disk_run(k, True)], steps,
                                      [lay.n_particles] * 2, repeat)
        covered = 100 * (pl.e.covered + pl.h.covered) / (pl.e.n_rows + pl.h.n_rows)
        print(f"{'disk n_r=' + str(n_radial):<10s} {'-':>6s} {lay.n_particles:>9d} {steps:>6d} {'-':>7s} {t_csr:>7.2f} "
              f"{t_st:>8.2f} {'-':>7s} {'-':>8s} {covered:>7.1f} {'-':>9s} {'-':>8s}", flush=True)


if __name__ == "__main__":
    main()
