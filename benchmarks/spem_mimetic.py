"""SPEM on irregular layouts: the "mimetic" coupling against "sbp" (issue 21 item 2).

Prints JSON lines:
- phase: the measured phase velocity of the TM22 mode of a unit PEC square (14 / 28 / 56 spacings per
  side: 9.9 / 19.8 / 39.6 particles per wavelength), jittered (0.2 dr) and Poisson layouts (seed 1), with
  the fitted order of |v - 1| and the set-up / run seconds (also the joint Poisson layout,
  :func:`manifold_sph.spem.layouts.joint_poisson_layout`);
- cavity: the circular PEC cavity (TM010 start 1 - r^2/r0^2, one period) on jittered, Poisson and joint
  Poisson disks (seed 0) at 10 / 20 / 40 spacings per radius, error against the Bessel series, fitted order,
  set-up and run seconds;
- modes (``--only modes``): the spurious localised modes of the mimetic E -> E operator
  (:func:`manifold_sph.spem.mimetic.localised_modes`; participation number below 20) on unit PEC squares
  (seeds 0-5, 16 / 24 / 32 spacings) and the unit disk (10 / 20 spacings per radius): the lowest localised
  eigenvalue among the 40 lowest, how many fall below 3x the sixth exact one, the largest error of the six
  lowest physical ones, layout and set-up seconds; ``poisson-balanced`` is
  :func:`manifold_sph.spem.layouts.balanced_poisson_layout` / ``balanced_disk_layout``;
- energy: the leap-frog modified energy over 10^4 steps on a Poisson square (relative drift);
- planewave (``--only planewave``): the plane wave with PML (0.2 m square, 20 and 40 particles per
  wavelength, jittered and Poisson) with set-up and run seconds.
- scattering (``--only scattering``): the dielectric (eps_r 4) and coated cylinders at ka = 2 (Yee-style
  lattice with a conforming wall, cell-averaged eps_r, PML; :func:`manifold_sph.spem.cases.run_scattering`,
  20 periods) with ``mimetic_fast`` (h/dr 1.5, the correction in a band along the walls) and ``sbp``, against
  the staircased Yee grid and Yee with the same cell-averaged eps_r of ``benchmarks/spem_vs_yee.py``, in the
  same run: error at equal unknowns and CPU at equal error.
- setup (``--only setup``): set-up against run seconds (one TM11 period on the unit PEC square, seed=1, at
  ``--cells`` spacings; the circular cavity's one period at ``--radial`` spacings per radius) with the set-up's
  parts from ``MimeticOperators.seconds`` (fits, conditions, normal equations, factorisation and solve) and
  where the correction was made (``path``: band, wall band or whole operator);
- cylinders (``--only cylinders``): the PEC / coated cylinders (``--cases``) with ``mimetic_fast`` at
  ``--radial`` spacings per radius: set-up seconds and error (the band with the wall closure, see
  :func:`manifold_sph.spem.mimetic.mimetic_operators`).

"mimetic-fast" is the ``fast`` variant of :func:`manifold_sph.spem.mimetic.mimetic_operators` (the
correction keeps quadratic exactness and touches only pairs closer than 2 spacings), switched on here
through the module constants ``CORRECTION_DEGREE, CORRECTION_RADIUS = FAST``.

Run: .venv/bin/python benchmarks/spem_mimetic.py [--quick] [--only ...] [--couplings sbp,mimetic,mimetic-fast]
(--quick: the two coarser resolutions only)
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

import manifold_sph.spem.mimetic as mimetic
from manifold_sph.spem import EPS0, MU0, TMzSolver, make_layout
from manifold_sph.spem.cases import cavity_exact, cavity_frequency, run_planewave, run_scattering
from manifold_sph.spem.cases.common import fit_solver_dt, relative_error
from manifold_sph.spem.layouts import balanced_disk_layout, balanced_poisson_layout, disk_layout, joint_poisson_layout
from manifold_sph.spem.mimetic import localised_modes
from manifold_sph.spem.operators import MIMETIC_H_RATIO

_DEFAULT = (mimetic.CORRECTION_DEGREE, mimetic.CORRECTION_RADIUS)


def _coupling(name):
    """The solver's coupling for a benchmark name; "mimetic-fast" sets the module constants to FAST."""
    mimetic.CORRECTION_DEGREE, mimetic.CORRECTION_RADIUS = mimetic.FAST if name == "mimetic-fast" else _DEFAULT
    return "mimetic" if name.startswith("mimetic") else name


def square_layout(layout, cells, seed, a=1.0):
    """The square's layout by name (``poisson-balanced``: :func:`balanced_poisson_layout`)."""
    dr = a / cells
    if layout == "poisson-joint":
        return joint_poisson_layout((0.0, a, 0.0, a), dr, seed=seed)
    if layout == "poisson-balanced":
        return balanced_poisson_layout((0.0, a, 0.0, a), dr, seed=seed)
    return make_layout(layout, (0.0, a, 0.0, a), dr, seed=seed)


def disk(layout, c, r0, dr, seed):
    """The disk's layout by name (``poisson-balanced``: :func:`balanced_disk_layout`)."""
    if layout == "poisson-balanced":
        return balanced_disk_layout(c, r0, dr, seed=seed)
    return disk_layout(c, r0, dr, kind=layout, seed=seed)


def modes(layout, cells, seed, k=40, fast=False, disk_case=False):
    """Lowest ``k`` modes of the mimetic E -> E operator (:func:`localised_modes`): the lowest localised
    one (participation < 20) over (pi c)^2 on the unit square (exact 2, 5, 5, 8, 10, 10, ...) or over the
    fundamental on the unit disk (``cells`` spacings per radius), and the largest relative error of the six
    lowest non-localised ones."""
    from scipy.special import jn_zeros

    t0 = time.perf_counter()
    if disk_case:
        lay = disk(layout, (0.0, 0.0), 1.0, 1.0 / cells, seed)
        ref = np.sort(np.r_[jn_zeros(0, 3), np.repeat(jn_zeros(1, 2), 2), np.repeat(jn_zeros(2, 2), 2),
                            np.repeat(jn_zeros(3, 1), 2)]) ** 2
        norm = ref[0]
        exact = ref[:6] / norm
    else:
        lay = square_layout(layout, cells, seed)
        norm = math.pi**2
        exact = np.array([2.0, 5.0, 5.0, 8.0, 10.0, 10.0])
    t_layout = time.perf_counter() - t0
    free = ~lay.e_fixed
    t0 = time.perf_counter()
    ops = mimetic.mimetic_operators(lay.e, free, [(lay.hy, 0), (lay.hx, 1)], MIMETIC_H_RATIO * lay.dr, scale=lay.dr,
                                    fast=fast)
    setup = time.perf_counter() - t0
    m = localised_modes(ops, free, k=k)
    ev = m.eigenvalues / norm
    phys = ev[~m.localised][:6]
    return {"layout": layout, "cells": cells, "seed": seed, "h_over_e": round(len(lay.hx) / len(lay.e), 3),
            "lowest_localised": round(float(ev[m.localised].min()), 2) if m.localised.any() else None,
            "localised_below_3x": int((ev[m.localised] < 3 * exact[-1]).sum()), "checked_up_to": round(float(ev[-1]), 1),
            "max_rel_err_6": round(float(np.abs(phys / exact[: len(phys)] - 1).max()), 4),
            "layout_s": round(t_layout, 2), "setup_s": round(setup, 2)}


def phase(layout, coupling, cells, m=2, steps=400, seed=1):
    a, dr = 1.0, 1.0 / cells
    lay = square_layout(layout, cells, seed, a)
    t0 = time.perf_counter()
    s = TMzSolver(lay, coupling=_coupling(coupling), courant=0.9)
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


def cavity(layout, coupling, n_radial, r0=0.1, eps_r=10.0, seed=0):
    """:func:`manifold_sph.spem.cases.run_cavity` (one period, courant 0.9) on any ``disk_layout`` kind."""
    dr, c = r0 / n_radial, (r0, r0)
    lay = disk(layout, c, r0, dr, seed)
    t0 = time.perf_counter()
    s = TMzSolver(lay, coupling=_coupling(coupling), eps_r=eps_r, courant=0.9, sbp_layers=None)
    setup = time.perf_counter() - t0
    dt, steps = fit_solver_dt(s, 1.0 / cavity_frequency(r0, eps_r))
    r = np.hypot(lay.e[:, 0] - c[0], lay.e[:, 1] - c[1])
    s.set_initial(np.clip(1.0 - r**2 / r0**2, 0.0, None))
    t0 = time.perf_counter()
    s.run(steps)
    run = time.perf_counter() - t0
    err = relative_error(s.e_field, cavity_exact(r, s.t, r0, eps_r))
    return {"n_radial": n_radial, "error": float(f"{err:.3e}"), "setup_s": round(setup, 2), "run_s": round(run, 2),
            "steps": steps, "dt_over_cfl": round(s.courant, 3), "particles": lay.n_particles, **_parts(s)}


def _parts(s):
    """The mimetic set-up's parts (``MimeticOperators.seconds``) and where the correction was made."""
    ops = getattr(s, "mimetic", None)
    if ops is None:
        return {}
    return {"path": ops.path, "residual": float(f"{ops.residual:.2e}"),
            **{f"{k}_s": round(v, 2) for k, v in ops.seconds.items()}}


def setup_profile(layout, coupling, cells, seed=1):
    """Set-up against run seconds on the unit PEC square: the set-up's parts (volumes and gradient fits, the
    conditions, the normal equations, their factorisation and solve) and one period of the TM11 mode."""
    lay = square_layout(layout, cells, seed)
    t0 = time.perf_counter()
    s = TMzSolver(lay, coupling=_coupling(coupling), courant=0.9)
    setup = time.perf_counter() - t0
    e = lay.e
    s.set_initial(np.sin(np.pi * e[:, 0]) * np.sin(np.pi * e[:, 1]))
    steps = int(math.ceil(math.sqrt(2.0) / 2.99792458e8 / s.dt))  # one period of TM11 (f = c sqrt(2) / 2)
    t0 = time.perf_counter()
    s.run(steps)
    run = time.perf_counter() - t0
    return {"cells": cells, "particles": lay.n_particles, "setup_s": round(setup, 2), "run_s": round(run, 2),
            "steps": steps, "setup_over_run": round(setup / run, 1), **_parts(s)}


def order(errs, ns):
    return [round(math.log(abs(errs[k]) / abs(errs[k + 1])) / math.log(ns[k + 1] / ns[k]), 2)
            for k in range(len(errs) - 1)]


def energy_drift(coupling, steps=10000, cells=15, seed=1):
    A = 0.1
    lay = make_layout("poisson", (0.0, A, 0.0, A), A / cells, seed=seed)
    s = TMzSolver(lay, coupling=_coupling(coupling), eps_r=lambda p: 1.0 + 3.0 * (p[:, 0] > A / 2))
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
    ap.add_argument("--only", choices=("phase", "cavity", "energy", "planewave", "scattering", "cavity-vs-yee", "modes",
                                       "setup", "cylinders"),
                    default=None)
    ap.add_argument("--couplings", default="sbp,mimetic,mimetic-fast")
    ap.add_argument("--cases", default="dielectric,coated", help="--only scattering: the cylinders")
    ap.add_argument("--layouts", default="jittered,poisson,poisson-joint,poisson-balanced")
    ap.add_argument("--seeds", default="0,1,2,3,4,5", help="--only modes: the squares' seeds")
    ap.add_argument("--cells", default="16,24,32,48", help="--only setup: the squares' spacings per side")
    ap.add_argument("--radial", default="20,40", help="--only setup / cylinders: spacings per radius")
    args = ap.parse_args()
    couplings = args.couplings.split(",")
    layouts = args.layouts.split(",")
    cells = (14, 28) if args.quick else (14, 28, 56)
    radial = (10, 20) if args.quick else (10, 20, 40)
    if args.only in (None, "phase"):
        for layout in layouts:
            for coupling in couplings:
                rows = [phase(layout, coupling, c) for c in cells]
                print(json.dumps({"run": "phase TM22 PEC square", "layout": layout, "coupling": coupling,
                                  "cells": cells, "rows": rows,
                                  "order": order([r["v_minus_1_pct"] for r in rows], cells)}), flush=True)
    if args.only in (None, "cavity"):
        for layout in layouts:
            for coupling in couplings:
                rows = []
                for n in radial:
                    try:
                        rows.append(cavity(layout, coupling, n))
                    except ValueError as exc:
                        rows.append({"n_radial": n, "refused": str(exc)[:160]})
                errs = [r["error"] for r in rows if "error" in r]
                print(json.dumps({"run": "cavity", "layout": layout, "coupling": coupling, "rows": rows,
                                  "order": order(errs, radial[: len(errs)])}), flush=True)
    if args.only in (None, "energy"):
        for coupling in couplings:
            print(json.dumps({"run": "energy drift, 10^4 steps, Poisson square, eps_r 1|4", "coupling": coupling,
                              "relative_drift": energy_drift(coupling)}), flush=True)

    if args.only == "planewave":
        for layout in layouts:
            for coupling in couplings:
                rows = []
                for ppw in (20.0, 40.0)[: 1 if args.quick else 2]:
                    t0 = time.perf_counter()
                    try:
                        r = run_planewave(size=0.2, ppw=ppw, layout=layout, coupling=_coupling(coupling))
                    except ValueError as exc:
                        rows.append({"ppw": ppw, "refused": str(exc)[:160]})
                        continue
                    total = time.perf_counter() - t0
                    rows.append({"ppw": ppw, "error": float(f"{r.error:.3e}"), "error_centre": float(f"{r.error_centre:.3e}"),
                                 "particles": r.particles, "run_s": round(r.step_seconds, 2),
                                 "setup_s": round(total - r.step_seconds, 2), "steps": r.steps})
                errs = [r["error_centre"] for r in rows if "error" in r]
                print(json.dumps({"run": "planewave with PML, 0.2 m", "layout": layout, "coupling": coupling,
                                  "rows": rows, "order_centre": order(errs, [20.0, 40.0][: len(errs)])}), flush=True)

    if args.only == "modes":
        for layout in layouts:
            for seed in (int(x) for x in args.seeds.split(",")):
                for n in (16, 24) if args.quick else (16, 24, 32):
                    print(json.dumps({"run": "modes, unit PEC square", **modes(layout, n, seed)}), flush=True)
            for n in (10, 20):
                print(json.dumps({"run": "modes, unit PEC disk (seed=0), spacings per radius",
                                  **modes(layout, n, 0, disk_case=True)}), flush=True)

    if args.only == "setup":
        for layout in layouts:
            for coupling in couplings:
                for c in (int(x) for x in args.cells.split(",")):
                    print(json.dumps({"run": "setup vs one TM11 period, unit PEC square (seed=1)", "layout": layout,
                                      "coupling": coupling, **setup_profile(layout, coupling, c)}), flush=True)
                for n in (int(x) for x in args.radial.split(",")):
                    print(json.dumps({"run": "setup vs run, circular cavity (seed=0, one period)", "layout": layout,
                                      "coupling": coupling, **cavity(layout, coupling, n)}), flush=True)
    if args.only == "cylinders":
        for kind in args.cases.split(","):
            for n in (int(x) for x in args.radial.split(",")):
                t0 = time.perf_counter()
                r = run_scattering(kind, n_radial=n, coupling="mimetic", mimetic_fast=True, periods=12.0)
                total = time.perf_counter() - t0
                print(json.dumps({"run": "cylinder, mimetic_fast (set-up and error)", "case": kind, "n_radial": n,
                                  "error": float(f"{r.error:.3e}"), "ring_error": float(f"{r.ring_error:.3e}"),
                                  "particles": r.particles, "setup_s": round(r.setup_seconds, 2),
                                  "total_s": round(total, 1), "steps": r.steps}), flush=True)
    if args.only == "scattering":
        scattering(args.quick, tuple(args.cases.split(",")))
    if args.only == "cavity-vs-yee":
        cavity_vs_yee(args.quick)


def _vs_yee():
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("spem_vs_yee", Path(__file__).with_name("spem_vs_yee.py"))
    vs = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(vs)
    return vs


def cavity_vs_yee(quick=False):
    """The circular cavity on the lattice disk (conforming wall), mimetic-fast and sbp, against the staircased Yee."""
    from manifold_sph.spem.cases import run_cavity

    vs = _vs_yee()
    yee = [vs.run_yee_cavity(n) for n in (10, 20, 40, 80, 160)[: 3 if quick else 5]]
    for r in yee:
        r["case"] = "cavity"
        print(json.dumps({k: (float(f"{v:.3e}") if isinstance(v, float) else v) for k, v in r.items()}), flush=True)
    for name, kw in {"mimetic-fast": dict(coupling="mimetic", mimetic_fast=True), "sbp": dict(coupling="sbp")}.items():
        rows = []
        for n in (10, 20) if quick else (10, 20, 40):
            r = run_cavity(n_radial=n, **kw)
            rows.append({"method": f"SPEM {name}", "case": "cavity", "n_radial": n, "unknowns": r.particles,
                         "error": r.error, "setup": r.seconds - r.step_seconds, "run": r.step_seconds,
                         "steps": r.steps})
        print(json.dumps({"run": "cavity vs Yee", "coupling": name,
                          "rows": [{k: (float(f"{v:.3e}") if isinstance(v, float) else v) for k, v in r.items()}
                                   for r in rows], "order": order([r["error"] for r in rows], [r["n_radial"] for r in rows])}),
              flush=True)
        print(f"cavity, SPEM {name} against the staircased Yee:")
        vs._compare(rows, yee, "Yee")


def scattering(quick=False, kinds=("dielectric", "coated")):
    """Cylinder scattering, mimetic (fast, band) and sbp against the staircased and the cell-averaged Yee."""
    vs = _vs_yee()
    sizes = (4, 8) if quick else (4, 8, 16)
    for kind in kinds:
        yee = [vs.run_yee_scattering(kind, n, periods=20.0) for n in (4, 8, 16, 32, 64)[: 3 if quick else 5]]
        avg = [vs.run_yee_scattering(kind, n, periods=20.0, eps_mode="average") for n in (4, 8, 16, 32)[: 3 if quick else 4]]
        runs = {"mimetic-fast": dict(coupling="mimetic", h_ratio=1.5, mimetic_fast=True),
                "mimetic-fast h/dr 1.2": dict(coupling="mimetic", h_ratio=1.2, mimetic_fast=True),
                "sbp": dict(coupling="sbp")}
        if kind == "coated":  # the band fails next to the conductor: the whole operator, minutes at 16
            runs.pop("mimetic-fast h/dr 1.2")
        for name, kw in runs.items():
            rows = [vs.run_spem_scattering(kind, n, periods=20.0, **kw) for n in sizes]
            for r in rows:
                r["method"] = f"SPEM {name}"
            print(json.dumps({"run": "scattering", "case": kind, "coupling": name,
                              "rows": [{k: (float(f"{v:.3e}") if isinstance(v, float) else v) for k, v in r.items()}
                                       for r in rows],
                              "order": order([r["error"] for r in rows], sizes)}), flush=True)
            print(f"{kind}, SPEM {name} against the staircased Yee:")
            vs._compare(rows, yee, "Yee")
            print(f"{kind}, SPEM {name} against Yee with the same cell-averaged eps:")
            vs._compare(rows, avg, "Yee-avg")
        for r in yee + avg:
            print(json.dumps({k: (float(f"{v:.3e}") if isinstance(v, float) else v) for k, v in r.items()}), flush=True)


if __name__ == "__main__":
    main()
