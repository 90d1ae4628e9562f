"""Driven runs until steady: the extrapolated steady phasor against long runs (docs/spem.md, "Driven runs until
steady").

Run: .venv/bin/python benchmarks/spem_steady.py           (about 2 min)
     .venv/bin/python benchmarks/spem_steady.py --sweep   (also six seeds of every jittered case at 4 and 8 spacings
                                                          per radius against their lattice, about 3 min)

Each scattering case runs with ``periods="auto"`` (the default: until the steady phasor extrapolated from the
periods run is estimated within 1e-4) and is compared with two references from longer runs of the same
discretisation: the same extrapolation with a 1e-7 tolerance (it then uses later periods only, up to 400), and the
plain DFT over the last 2 of a fixed run of ``--long`` periods (a fair reference only where every mode has decayed
by then: its own window estimate is printed beside it). ``dist`` is the relative L2 distance of the default run's
phasor from a reference; ``est`` the default run's own estimate of it (``transient``); ``gain`` the extrapolation's
(above 10 a resonant mode is named and the CLI exits 3).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from manifold_sph.spem.cases.scattering import run_scattering, run_tez_scattering
from manifold_sph.spem.steady import GAIN_MAX

#: (label, "tmz" | "tez", kind, keyword arguments)
CASES = [
    ("TMz PEC, jittered", "tmz", "pec", dict(layout="jittered")),
    ("TMz dielectric, jittered, seed=0", "tmz", "dielectric", dict(layout="jittered", seed=0)),
    ("TMz dielectric, jittered, seed=1", "tmz", "dielectric", dict(layout="jittered", seed=1)),
    ("TMz dielectric, jittered, seed=2", "tmz", "dielectric", dict(layout="jittered", seed=2)),
    ("TMz coated, jittered", "tmz", "coated", dict(layout="jittered")),
    ("TMz dielectric eps_r 8, lattice", "tmz", "dielectric", dict(eps_r=8.0)),
    ("TEz dielectric eps_r 8, lattice, auto interface", "tez", "dielectric", dict(eps_r=8.0, average="auto")),
    ("TEz dielectric eps_r 8, 4 per radius, auto", "tez", "dielectric", dict(eps_r=8.0, average="auto", n_radial=4)),
    ("TEz PEC, lattice, 4 per radius (resonant)", "tez", "pec", dict(n_radial=4)),
]


def _run(which, kind, **kw):
    return (run_scattering if which == "tmz" else run_tez_scattering)(kind, **kw)


def _dist(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def table(long: float) -> None:
    print(f"{'case':48s} {'periods':>7} {'est':>8} {'gain':>6} {'error':>9} | {'tight: periods':>14} {'dist':>8} | "
          f"{'DFT of ' + format(long, 'g') + ' periods: window est':>34} {'dist':>8} | {'s':>5}")
    for label, which, kind, kw in CASES:
        t = time.perf_counter()
        r = _run(which, kind, **kw)
        tight = _run(which, kind, steady_tol=1e-7, **kw)
        fixed = _run(which, kind, periods=long, **kw)
        flag = "" if r.certified else "  (not certified: " + r.certificate_failures[0][:60] + "...)"
        print(f"{label:48s} {r.periods:7.0f} {r.transient:8.1e} {r.gain:6.2f} {r.error:9.3e} | {tight.periods:14.0f} "
              f"{_dist(r.phasor, tight.phasor):8.1e} | {fixed.transient:34.1e} {_dist(r.phasor, fixed.phasor):8.1e} | "
              f"{time.perf_counter() - t:5.1f}{flag}", flush=True)


def sweep() -> None:
    print(f"\nEvery jittered scattering case, seeds 0-5, against its lattice (error ratio, periods, gain; a gain above "
          f"{GAIN_MAX:g} or a transient left above 1e-3 is not certified)")
    for which, kinds in (("tmz", ("pec", "dielectric", "coated")), ("tez", ("pec", "dielectric"))):
        for kind in kinds:
            for nr in (4, 8):
                lat = _run(which, kind, n_radial=nr)
                cells = []
                for seed in range(6):
                    r = _run(which, kind, n_radial=nr, layout="jittered", seed=seed)
                    cells.append(f"{r.error / lat.error:4.1f}x {r.periods:3.0f} {r.gain:4.1f}{'' if r.certified else '!'}")
                print(f"{which} {kind:10s} {nr:2d} per radius: lattice {lat.error:.2e} ({lat.periods:.0f} periods, gain "
                      f"{lat.gain:.1f}{'' if lat.certified else ', not certified'}) | " + " | ".join(cells), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--long", type=float, default=300.0, help="periods of the fixed reference run (default 300)")
    ap.add_argument("--sweep", action="store_true", help="also the seed sweep of the jittered cases")
    args = ap.parse_args()
    table(args.long)
    if args.sweep:
        sweep()


if __name__ == "__main__":
    main()
