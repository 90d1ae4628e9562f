"""TEz on Poisson layouts (issue 21 item 4): the PEC rectangle with the wall closure, and the circular cavity.

Run: .venv/bin/python benchmarks/spem_tez_poisson.py                 (about 20 min)
     .venv/bin/python benchmarks/spem_tez_poisson.py --only modes    (one of: convergence, energy, modes,
                                                                      disk, disk-modes, edges)
     .venv/bin/python benchmarks/spem_tez_poisson.py --ns 12 24 --seeds 0 1

Layouts (:func:`manifold_sph.spem.tez_layout`): "poisson" (independent Poisson Hz, Ex, Ey sets),
"poisson-shared" (one Poisson E set carrying Ex and Ey) and, for comparison, the jittered lattice
(amplitude 0.2), each through :func:`~manifold_sph.spem.wall_closure_layout` (coupling "sbp").

* convergence: ``run_tez_cavity`` (0.1 x 0.06 m, TE10 + TE11, ``n`` spacings along 0.06 m): relative L2
  error of Hz after one TE10 period and the TE10 resonance error (fitted over 5 periods), per seed;
  refused layouts (ValueError of the wall correction) are counted.
* energy: relative change of the discrete energy over 10^4 steps from a random Hz(0).
* set-up vs run: the solver's construction against 1000 steps.
* modes: the lowest eigenvalues of the Hz -> Hz operator (symmetrised in the volumes) against the exact
  TE_mn resonances, and each mode's participation number ``1 / sum v^4`` over the Hz particles (a
  spurious localised mode has a participation of a few particles; the physical ones a sizeable fraction
  of all).

Measured (2 Dec 2026, 2 shared cores):

* rectangle, mean over seeds 0-2 at 12 / 24 / 48 spacings: "poisson" error 1.31e-1 / 2.85e-2 / 6.29e-3
  (order 2.19), f error 3.7e-4 / 5.5e-4 / 1.6e-4; "poisson-shared" 1.07e-1 / 2.89e-2 / 6.54e-3 (order 2.02),
  f error 3.0e-3 / 1.2e-3 / 3.0e-4; jittered lattice 1.88e-2 / 3.80e-3 / 9.01e-4, f error 6.2e-4 / 1.2e-4 /
  1.1e-5; none refused; dt 0.83-0.90 of the CFL step at h/dr 1.2 (jittered: 0.58-0.67 at 0.8).
* disk, seeds 0-1 at 10 / 20 / 40 per radius: "poisson" error 1.78e-1 / 4.12e-2 / 9.49e-3 (order 2.11),
  f error 3.3e-3 / 1.6e-3 / 4.4e-4; "poisson-shared" 1.77e-1 / 4.15e-2 and 1.09e-2 (seed=1; seed=0 at 40
  refused: a fitted volume at 2 % of its cell); jittered 1.98e-2 / 7.07e-3 / 2.69e-3.
* energy over 10^4 steps (12 spacings): |E/E0 - 1| <= 2e-15 on every layout; set-up 0.2-0.4 s against
  0.03-0.06 s per 1000 steps.
* edges (a lead, not in the package; 18 spacings, seeds 0-2): one E set at the Delaunay-edge midpoints of
  the Poisson Hz set (about 2.8 E per Hz particle) leaves no mode below TE10 and 7 / 15 / 1 spurious ones
  between TE10 and TE01 (the lowest at 1.49 / 1.32 / 1.56 f_10); a Poisson E set of the same count 22 / 23 / 16
  (the lowest at 1.01-1.22 f_10): staggering, not only the count, pushes them up.
* modes: rectangle (18 spacings, seeds 0-2) "poisson" 18 / 11 / 11 and "poisson-shared" 24 / 21 / 24 of
  the 24 lowest non-static modes below 0.98 f_10, the lowest at 0.36-0.65 f_10 (participation 14-25 of 540
  Hz particles); the jittered lattice: none (all 24 within 5 % of the exact TE_mn); disk (12 per radius)
  15-24 of the 24 lowest below TE11; the jittered and Yee disks: none.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from manifold_sph import spem as tez
from manifold_sph.spem.constants import C0

A, B = 0.1, 0.06
KINDS = ("poisson", "poisson-shared", "jittered")



def _summary(kind, ns, seeds, errs, ferrs, refused):
    """Mean error and frequency error over the seeds where every seed ran, and their orders."""
    full = [n for n in ns if len(errs[n]) == len(seeds)]
    if len(full) >= 2:
        me = [float(np.mean(errs[n])) for n in full]
        mf = [float(np.mean(ferrs[n])) for n in full]
        print(f"{kind:>15} mean over seeds: error {', '.join(f'{v:.2e}' for v in me)}; f error "
              f"{', '.join(f'{v:.2e}' for v in mf)} (n = {full}); order error {order(full, me):.2f}, "
              f"f {order(full, mf):.2f}; refused {refused}")

def order(ns, values):
    """Least-squares slope of log(value) against log(n)."""
    return float(-np.polyfit(np.log(ns), np.log(values), 1)[0])


def layout(kind, n, seed):
    dr = B / n
    if kind == "jittered":
        lay = tez.tez_layout((0.0, A, 0.0, B), dr, amplitude=0.2, seed=seed)
    else:
        lay = tez.tez_layout((0.0, A, 0.0, B), dr, kind=kind, seed=seed)
    return tez.wall_closure_layout(lay)


def h_ratio(kind):
    return tez.DISK_H_RATIO if kind == "jittered" else tez.POISSON_H_RATIO


def convergence(ns, seeds):
    print("\nConvergence: TE10 + TE11, error after one TE10 period, TE10 frequency error (5 periods)")
    print(f"{'layout':>15} {'seed':>4} {'n':>4} {'particles':>9} {'error':>9} {'f error':>9} {'dt/CFL':>7} {'s':>6}")
    for kind in KINDS:
        refused = 0
        errs = {n: [] for n in ns}
        ferrs = {n: [] for n in ns}
        for seed in seeds:
            for n in ns:
                try:
                    r = tez.run_tez_cavity(n=n, layout=kind, seed=seed, wall_closure=True, support_check=False)
                except ValueError as exc:
                    refused += 1
                    print(f"{kind:>15} {seed:4d} {n:4d} refused: {str(exc)[:90]}")
                    continue
                cfl = h_ratio(kind) * r.dr / (math.sqrt(2.0) * C0)
                print(f"{kind:>15} {seed:4d} {n:4d} {r.particles:9d} {r.error:9.2e} {r.frequency_error:9.2e} "
                      f"{r.dt / cfl:7.3f} {r.seconds:6.1f}", flush=True)
                errs[n].append(r.error)
                ferrs[n].append(r.frequency_error)
        _summary(kind, ns, seeds, errs, ferrs, refused)


def energy(n=12, steps=10_000, seeds=(0,)):
    print(f"\nEnergy over {steps} steps (n = {n}, random Hz(0)); set-up vs 1000 steps")
    for kind in KINDS:
        for seed in seeds:
            t0 = time.perf_counter()
            s = tez.TEzSolver(layout(kind, n, seed), h_ratio=h_ratio(kind))
            setup = time.perf_counter() - t0
            s.set_initial(np.random.default_rng(seed).standard_normal(len(s.layout.hz)))
            t0 = time.perf_counter()
            s.run(1000)
            run = time.perf_counter() - t0
            s.run(steps - 1000)
            print(f"{kind:>15} seed={seed}: |E/E0 - 1| = {abs(s.energy() / s.energy0 - 1):.2e}, set-up {setup:.2f} s, "
                  f"1000 steps {run:.2f} s, particles {s.n_particles}", flush=True)


def modes(n=18, k=24, seeds=(0, 1, 2)):
    exact = sorted(tez.tez_cavity_frequency(A, B, m, q) for m in range(8) for q in range(8) if m or q)
    print(f"\nModes: n = {n}, the {k} lowest of the Hz operator; frequency / exact and participation "
          f"(particles; a mode below 5 % of the Hz particles flagged)")
    for kind in KINDS:
        for seed in seeds:
            s = tez.TEzSolver(layout(kind, n, seed), h_ratio=h_ratio(kind))
            r = np.sqrt(s.vol_hz)
            L = (s.Dx @ s.Gx + s.Dy @ s.Gy).toarray() / (s.eps * s.mu)
            S = -(r[:, None] * L / r[None, :])
            ev, V = np.linalg.eigh(0.5 * (S + S.T))
            ev, V = ev[1 : k + 1], V[:, 1 : k + 1]  # the first: the static Hz = const (TE00)
            f = np.sqrt(np.maximum(ev, 0.0)) / (2 * math.pi)
            part = 1.0 / (V**4).sum(axis=0)
            low = part < 0.05 * len(s.vol_hz)
            print(f"{kind:>15} seed={seed}: below 0.98 f_10 {int(np.sum(f < 0.98 * exact[0]))} of {k}; lowest "
                  f"{f[0] / exact[0]:.3f} f_10 (participation {part[0]:.0f}); f/exact "
                  f"{', '.join(f'{a / b:.3f}' for a, b in zip(f[:8], exact))} ...; max |f/exact - 1| "
                  f"(first {k}) {float(np.max(np.abs(f / np.array(exact[:k]) - 1))):.3f}; min participation "
                  f"{part.min():.0f} of {len(s.vol_hz)}; localised {int(low.sum())}", flush=True)


def disk_convergence(ns, seeds):
    print("\nDisk (radius 0.1 m, n spacings per radius): TE11 + TE21, error after one TE11 period, TE11 frequency "
          "error (5 periods; fitted and probe peak)")
    print(f"{'layout':>15} {'seed':>4} {'n':>4} {'particles':>9} {'error':>9} {'f error':>9} {'probe f':>9} "
          f"{'dt/CFL':>7} {'s':>6}")
    for kind in ("poisson", "poisson-shared", "jittered"):
        errs, ferrs, refused = {n: [] for n in ns}, {n: [] for n in ns}, 0
        for seed in seeds:
            for n in ns:
                try:
                    r = tez.run_tez_circular_cavity(n_radial=n, layout=kind, seed=seed, spectrum_periods=5.0)
                except ValueError as exc:
                    refused += 1
                    print(f"{kind:>15} {seed:4d} {n:4d} refused: {str(exc)[:90]}")
                    continue
                print(f"{kind:>15} {seed:4d} {n:4d} {r.particles:9d} {r.error:9.2e} {r.frequency_error:9.2e} "
                      f"{r.probe_frequency_error:9.2e} {r.stable_fraction:7.3f} {r.seconds:6.1f}", flush=True)
                errs[n].append(r.error)
                ferrs[n].append(r.frequency_error)
        _summary(kind, ns, seeds, errs, ferrs, refused)


def disk_modes(n=12, k=24, seeds=(0, 1, 2)):
    """Lowest modes of the disk's Hz operator against the exact TE_mn (m > 0 twice: cos and sin)."""
    R = 0.1
    exact = sorted([tez.tez_disk_frequency(R, m, q) for m in range(12) for q in range(1, 6)
                    for _ in range(1 if m == 0 else 2)])
    print(f"\nDisk modes: n = {n} per radius, the {k} lowest of the Hz operator (f / f_TE11)")
    for kind in ("poisson", "poisson-shared", "jittered", "yee"):
        for seed in (seeds if kind != "yee" else seeds[:1]):
            lay = tez.tez_disk_layout((R, R), R, R / n, kind="lattice" if kind in ("yee", "jittered") else kind,
                                      amplitude=0.2 if kind == "jittered" else 0.0, seed=seed)
            s = tez.TEzSolver(lay, h_ratio=tez.DISK_H_RATIO if kind in ("yee", "jittered") else tez.POISSON_H_RATIO)
            r = np.sqrt(s.vol_hz)
            L = (s.Dx @ s.Gx + s.Dy @ s.Gy).toarray() / (s.eps * s.mu)
            S = -(r[:, None] * L / r[None, :])
            ev, V = np.linalg.eigh(0.5 * (S + S.T))
            f = np.sqrt(np.maximum(ev[1 : k + 1], 0.0)) / (2 * math.pi) / exact[0]
            part = 1.0 / (V[:, 1 : k + 1] ** 4).sum(axis=0)
            print(f"{kind:>15} seed={seed}: below 0.98 f_TE11 {int(np.sum(f < 0.98))}; lowest "
                  f"{', '.join(f'{a:.3f} ({p:.0f})' for a, p in zip(f[:6], part[:6]))} (participation of "
                  f"{len(r)} Hz)", flush=True)


def edges(n=18, k=24, seeds=(0, 1, 2)):
    """A lead, not in the package: the Poisson Hz set with one E set (both components) at the midpoints of its
    Delaunay edges shorter than 1.6 dr (a staggered unstructured layout, about 3 E per Hz particle), against a
    Poisson E set of the same count (not staggered); h/dr 1.2, wall closure, rectangle."""
    from scipy.spatial import Delaunay

    from manifold_sph.reference.sampling import square

    dr = B / n
    exact = np.array(sorted(tez.tez_cavity_frequency(A, B, m, q) for m in range(8) for q in range(8) if m or q))
    print(f"\nLead: E at Delaunay-edge midpoints of the Poisson Hz set (n = {n}); f / f_10 of the lowest modes "
          f"(exact: {', '.join(f'{v:.3f}' for v in exact[:6] / exact[0])})")
    for seed in seeds:
        base = tez.tez_layout((0.0, A, 0.0, B), dr, kind="poisson", seed=seed)
        hz = base.hz
        tri = Delaunay(hz).simplices
        pairs = np.unique(np.sort(np.vstack([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]]]), axis=1), axis=0)
        length = np.linalg.norm(hz[pairs[:, 0]] - hz[pairs[:, 1]], axis=1)
        mid = 0.5 * (hz[pairs[:, 0]] + hz[pairs[:, 1]])[length < 1.6 * dr]
        dense = square(len(mid), bounds=base.bounds, sampling="poisson", seed=seed + 100)
        for name, e in (("edge midpoints", mid), ("Poisson, same count", dense)):
            ex = e[(e[:, 1] > 0.3 * dr) & (e[:, 1] < B - 0.3 * dr)]
            ey = e[(e[:, 0] > 0.3 * dr) & (e[:, 0] < A - 0.3 * dr)]
            fx, fy = base.ex_fixed, base.ey_fixed
            lay = tez.TEzLayout(hz, np.vstack([ex, base.ex[fx]]), np.vstack([ey, base.ey[fy]]),
                                np.r_[np.zeros(len(ex), bool), np.ones(int(fx.sum()), bool)],
                                np.r_[np.zeros(len(ey), bool), np.ones(int(fy.sum()), bool)], dr, base.bounds)
            try:
                s = tez.TEzSolver(tez.wall_closure_layout(lay), h_ratio=tez.POISSON_H_RATIO)
            except ValueError as exc:
                print(f"  seed={seed} {name}: refused ({str(exc)[:80]})")
                continue
            r = np.sqrt(s.vol_hz)
            L = (s.Dx @ s.Gx + s.Dy @ s.Gy).toarray() / (s.eps * s.mu)
            S = -(r[:, None] * L / r[None, :])
            f = np.sqrt(np.maximum(np.linalg.eigvalsh(0.5 * (S + S.T))[1 : k + 1], 0.0)) / (2 * math.pi) / exact[0]
            print(f"  seed={seed} {name:>20} ({len(e)} E): below 0.98 f_10 {int(np.sum(f < 0.98))}, between TE10 and "
                  f"TE01 {int(np.sum((f > 1.02) & (f < 0.98 * exact[1] / exact[0])))}; lowest "
                  f"{', '.join(f'{v:.3f}' for v in f[:6])}", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=("convergence", "energy", "modes", "disk", "disk-modes", "edges"))
    ap.add_argument("--disk-ns", type=int, nargs="+", default=[10, 20, 40])
    ap.add_argument("--ns", type=int, nargs="+", default=[12, 24, 48])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = ap.parse_args()
    if args.only in (None, "modes"):
        modes(seeds=tuple(args.seeds))
    if args.only in (None, "energy"):
        energy(seeds=tuple(args.seeds[:2]))
    if args.only in (None, "convergence"):
        convergence(args.ns, args.seeds)
    if args.only in (None, "disk-modes"):
        disk_modes(seeds=tuple(args.seeds))
    if args.only in (None, "disk"):
        disk_convergence(args.disk_ns, args.seeds)
    if args.only in (None, "edges"):
        edges(seeds=tuple(args.seeds))


if __name__ == "__main__":
    main()
