"""SPEM against a staircased Yee FDTD on the circular PEC cavity (TMz, [2] sec. 4.3).

Run: .venv/bin/python benchmarks/spem_vs_yee.py [--full]

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
    unknowns = r1["particles"]  # E (free and wall) + Hx + Hy; the wall E are held at 0
    return {"method": f"SPEM {coupling}", "n_radial": n_radial, "unknowns": unknowns, "error": r1["error"],
            "f1_error": r["f1_error"], "setup": r1["seconds"] - r1["step_seconds"], "run": r1["step_seconds"],
            "steps": r1["steps"], "ns_per_unknown_step": 1e9 * r1["step_seconds"] / (r1["steps"] * unknowns)}


def row(r):
    return (f"{r['method']:<24s} {r['n_radial']:>4d} {r['unknowns']:>8d} {r['error']:>10.3e} {r['f1_error']:>10.3e} "
            f"{r['setup']:>8.2f} {r['run']:>8.3f} {r['steps']:>6d} {r['ns_per_unknown_step']:>8.1f}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--full", action="store_true", help="add SPEM at 80 spacings per radius (set-up ~40 s)")
    a = ap.parse_args()
    e1, e2 = yee_square_check()
    print(f"Yee check, square PEC cavity TM11 at 40 cells: frequency error {e1:.2e} against the exact mode, "
          f"{e2:.1e} against the Yee dispersion relation")
    head = f"{'method':<24s} {'n_r':>4s} {'unknowns':>8s} {'error':>10s} {'f1_error':>10s} {'setup s':>8s} {'run s':>8s} {'steps':>6s} {'ns/u/st':>8s}"
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


if __name__ == "__main__":
    main()
