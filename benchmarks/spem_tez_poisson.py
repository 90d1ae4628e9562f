"""TEz on Poisson layouts (issue 21 item 4): the PEC rectangle with the wall closure.

Run: .venv/bin/python benchmarks/spem_tez_poisson.py                 (about 8 min)
     .venv/bin/python benchmarks/spem_tez_poisson.py --only modes    (one of: convergence, energy, modes)
     .venv/bin/python benchmarks/spem_tez_poisson.py --ns 12 24 --seeds 0 1

Layouts (:func:`manifold_sph.spem.tez.tez_layout`): "poisson" (independent Poisson Hz, Ex, Ey sets),
"poisson-shared" (one Poisson E set carrying Ex and Ey) and, for comparison, the jittered lattice
(amplitude 0.2), each through :func:`~manifold_sph.spem.tez.wall_closure_layout` (coupling "sbp").

* convergence: ``run_tez_cavity`` (0.1 x 0.06 m, TE10 + TE11, ``n`` spacings along 0.06 m): relative L2
  error of Hz after one TE10 period and the TE10 resonance error (fitted over 5 periods), per seed;
  refused layouts (ValueError of the wall correction) are counted.
* energy: relative change of the discrete energy over 10^4 steps from a random Hz(0).
* set-up vs run: the solver's construction against 1000 steps.
* modes: the lowest eigenvalues of the Hz -> Hz operator (symmetrised in the volumes) against the exact
  TE_mn resonances, and each mode's participation number ``1 / sum v^4`` over the Hz particles (a
  spurious localised mode has a participation of a few particles; the physical ones a sizeable fraction
  of all).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from manifold_sph.spem import tez
from manifold_sph.spem.constants import C0

A, B = 0.1, 0.06
KINDS = ("poisson", "poisson-shared", "jittered")


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
                    r = tez.run_tez_cavity(n=n, layout=kind, seed=seed, wall_closure=True)
                except ValueError as exc:
                    refused += 1
                    print(f"{kind:>15} {seed:4d} {n:4d} refused: {str(exc)[:90]}")
                    continue
                cfl = h_ratio(kind) * r.dr / (math.sqrt(2.0) * C0)
                print(f"{kind:>15} {seed:4d} {n:4d} {r.particles:9d} {r.error:9.2e} {r.frequency_error:9.2e} "
                      f"{r.dt / cfl:7.3f} {r.seconds:6.1f}", flush=True)
                errs[n].append(r.error)
                ferrs[n].append(r.frequency_error)
        full = [n for n in ns if len(errs[n]) == len(seeds)]
        if len(full) >= 2:
            me = [float(np.mean(errs[n])) for n in full]
            mf = [float(np.mean(ferrs[n])) for n in full]
            print(f"{kind:>15} mean over seeds: error {', '.join(f'{v:.2e}' for v in me)}; f error "
                  f"{', '.join(f'{v:.2e}' for v in mf)} (n = {full}); order error {order(full, me):.2f}, "
                  f"f {order(full, mf):.2f}; refused {refused}")


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
            print(f"{kind:>15} seed={seed}: static mode {abs(np.linalg.eigvalsh(0.5 * (S + S.T))[0]):.1e}, "
                  f"f/exact {', '.join(f'{a / b:.3f}' for a, b in zip(f[:8], exact))} ...; max |f/exact - 1| "
                  f"(first {k}) {float(np.max(np.abs(f / np.array(exact[:k]) - 1))):.3f}; min participation "
                  f"{part.min():.0f} of {len(s.vol_hz)}; localised {int(low.sum())}", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=("convergence", "energy", "modes"))
    ap.add_argument("--ns", type=int, nargs="+", default=[12, 24, 48])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = ap.parse_args()
    if args.only in (None, "modes"):
        modes(seeds=tuple(args.seeds))
    if args.only in (None, "energy"):
        energy(seeds=tuple(args.seeds[:2]))
    if args.only in (None, "convergence"):
        convergence(args.ns, args.seeds)


if __name__ == "__main__":
    main()
