"""SPEM on irregular layouts: the "mimetic" coupling against "sbp" (issue 21 item 2).

Prints JSON lines:
- phase: the measured phase velocity of the TM22 mode of a unit PEC square (14 / 28 / 56 spacings per
  side: 9.9 / 19.8 / 39.6 particles per wavelength), jittered (0.2 dr) and Poisson layouts (seed 1), with
  the fitted order of |v - 1| and the set-up / run seconds;
- cavity: the circular PEC cavity (TM010 start 1 - r^2/r0^2, one period) on jittered and Poisson disks
  (seed 0) at 10 / 20 / 40 spacings per radius, error against the Bessel series and fitted order;
- energy: the leap-frog modified energy over 10^4 steps on a Poisson square (relative drift).

Run: .venv/bin/python benchmarks/spem_mimetic.py [--quick]   (--quick: the two coarser resolutions only)
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from manifold_sph.spem import EPS0, MU0, TMzSolver, make_layout
from manifold_sph.spem.cases import run_cavity


def phase(layout, coupling, cells, m=2, steps=400, seed=1):
    a, dr = 1.0, 1.0 / cells
    lay = make_layout(layout, (0.0, a, 0.0, a), dr, seed=seed)
    t0 = time.perf_counter()
    s = TMzSolver(lay, coupling=coupling, courant=0.9)
    setup = time.perf_counter() - t0
    e = lay.e
    mode = np.sin(m * np.pi * e[:, 0]) * np.sin(m * np.pi * e[:, 1])
    s.set_initial(mode)
    t0 = time.perf_counter()
    x = [mode @ s.e_field]
    for _ in range(steps):
        s.step()
        x.append(mode @ s.e_field)
    run = time.perf_counter() - t0
    x = np.asarray(x)
    cos_wdt = (x[1:-1] @ (x[2:] + x[:-2])) / (2 * x[1:-1] @ x[1:-1])
    w = math.acos(float(np.clip(cos_wdt, -1, 1))) / s.dt
    k = math.sqrt(2) * m * math.pi / a
    return {"v_minus_1_pct": round(100 * (w / (2.99792458e8 * k) - 1), 4), "ppw": round(2 * math.pi / k / dr, 1),
            "setup_s": round(setup, 2), "run_s": round(run, 2), "steps": steps,
            "dt_over_cfl": round(s.courant / math.sqrt(2) * math.sqrt(2), 3)}


def order(errs, ns):
    return [round(math.log(abs(errs[k]) / abs(errs[k + 1])) / math.log(ns[k + 1] / ns[k]), 2)
            for k in range(len(errs) - 1)]


def energy_drift(coupling, steps=10000, cells=15, seed=1):
    A = 0.1
    lay = make_layout("poisson", (0.0, A, 0.0, A), A / cells, seed=seed)
    s = TMzSolver(lay, coupling=coupling, eps_r=lambda p: 1.0 + 3.0 * (p[:, 0] > A / 2))
    fr, e = s.free, lay.e
    s.set_initial(np.exp(-(((e[:, 0] - A / 3) ** 2 + (e[:, 1] - A / 2) ** 2) / (0.1 * A) ** 2)))
    ve = s.vol_e
    vx = getattr(s, "vol_hx", np.ones(len(lay.hx)))
    vy = getattr(s, "vol_hy", np.ones(len(lay.hy)))

    def modified():
        ez = s.e_field
        hxp, hyp = s.hx + s.db_x * (s.Dy_hx @ ez), s.hy - s.db_y * (s.Dx_hy @ ez)
        return (EPS0 * (ve * s.eps_r[fr] * ez[fr] ** 2).sum() + MU0 * (vx * s.mu_r_x * s.hx * hxp).sum()
                + MU0 * (vy * s.mu_r_y * s.hy * hyp).sum())

    w = [modified()]
    for _ in range(10):
        s.run(steps // 10)
        w.append(modified())
    w = np.asarray(w)
    return float(np.ptp(w) / w[0])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", choices=("phase", "cavity", "energy"), default=None)
    args = ap.parse_args()
    cells = (14, 28) if args.quick else (14, 28, 56)
    radial = (10, 20) if args.quick else (10, 20, 40)
    if args.only in (None, "phase"):
        for layout in ("jittered", "poisson"):
            for coupling in ("sbp", "mimetic"):
                rows = [phase(layout, coupling, c) for c in cells]
                print(json.dumps({"run": "phase TM22 PEC square", "layout": layout, "coupling": coupling,
                                  "cells": cells, "rows": rows,
                                  "order": order([r["v_minus_1_pct"] for r in rows], cells)}), flush=True)
    if args.only in (None, "cavity"):
        for layout in ("jittered", "poisson"):
            for coupling in ("sbp", "mimetic"):
                rows = []
                for n in radial:
                    t0 = time.perf_counter()
                    try:
                        r = run_cavity(n_radial=n, layout=layout, coupling=coupling, spectrum_periods=0.0)
                    except ValueError as exc:
                        rows.append({"n_radial": n, "refused": str(exc)[:160]})
                        continue
                    total = time.perf_counter() - t0
                    rows.append({"n_radial": n, "error": float(f"{r.error:.3e}"), "run_s": round(r.step_seconds, 2),
                                 "setup_s": round(total - r.step_seconds, 2), "steps": r.steps})
                errs = [r["error"] for r in rows if "error" in r]
                print(json.dumps({"run": "cavity", "layout": layout, "coupling": coupling, "rows": rows,
                                  "order": order(errs, radial[: len(errs)])}), flush=True)
    if args.only in (None, "energy"):
        for coupling in ("sbp", "mimetic"):
            print(json.dumps({"run": "energy drift, 10^4 steps, Poisson square, eps_r 1|4", "coupling": coupling,
                              "relative_drift": energy_drift(coupling)}), flush=True)


if __name__ == "__main__":
    main()
