"""TEz: the circular PEC cavity (curved walls) beside the rectangle, with fitted orders.

Run: .venv/bin/python benchmarks/spem_tez.py            (about 1 min)
     .venv/bin/python benchmarks/spem_tez.py --sweep    (also h_ratio 0.6-2 and eps_r on the disk: 10^4 steps each)

Disk: ``run_tez_circular_cavity`` (radius 0.1 m, TE11 + TE21; error after one TE11 period; the TE11
resonance fitted to the projection of Hz onto the mode and read from a probe spectrum, 10 periods).
Rectangle: ``run_tez_cavity`` (0.1 x 0.06 m, TE10 + TE11). ``k dr``: the first mode's wavenumber times
the spacing (the disk's TE11 at n spacings per radius has k dr = 1.84 / n; the rectangle's TE10 at n
spacings along 0.06 m has k dr = 0.6 pi / n), so rows with equal k dr have equal particles per wavelength.
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from manifold_sph.spem import tez


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


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--sweep", action="store_true")
    args = p.parse_args()
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
          [(n, tez.run_tez_cavity(n=n, layout="jittered", h_ratio=0.8)) for n in (6, 12, 24)], rect_kdr)
    table("PEC rectangle jittered 0.2 dr (seed=0), wall_closure=True (h/dr 0.8)",
          [(n, tez.run_tez_cavity(n=n, layout="jittered", wall_closure=True)) for n in (6, 12, 24)], rect_kdr)
    if args.sweep:
        sweep()


if __name__ == "__main__":
    main()
