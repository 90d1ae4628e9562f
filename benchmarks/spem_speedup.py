"""SPEM: wall time per step on 1 and 2 threads, and the case table.

Run: .venv/bin/python benchmarks/spem_speedup.py [--cells 100] [--steps 200] [--coupling sbp]
Prints a JSON object: set-up seconds, per-step seconds with workers=1 and 2, the speedup
and nanoseconds per unknown (E + Hx + Hy) per step (best of 3 repetitions; timings are
noisy on a shared machine). The default coupling's set-up is a global sparse solve: keep
--cells moderate.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from manifold_sph.spem import TMzSolver, yee_layout


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--cells", type=int, default=100)
    ap.add_argument("--coupling", default="sbp")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    dr = 1e-3
    lay = yee_layout((0, a.cells * dr, 0, a.cells * dr), dr)
    r = np.hypot(lay.e[:, 0] - a.cells * dr / 2, lay.e[:, 1] - a.cells * dr / 2)
    out = {"particles": lay.n_particles, "steps": a.steps}
    fields = {}
    for w in (1, 2):
        t0 = time.perf_counter()
        s = TMzSolver(lay, workers=w, coupling=a.coupling)
        out[f"setup_seconds_workers{w}"] = time.perf_counter() - t0
        best = np.inf
        for _ in range(a.repeat):
            s.set_initial(np.exp(-((r / (20 * dr)) ** 2)))
            t0 = time.perf_counter()
            s.run(a.steps)
            best = min(best, time.perf_counter() - t0)
        fields[w] = s.e_field.copy()
        out[f"seconds_per_step_workers{w}"] = best / a.steps
    out["speedup"] = out["seconds_per_step_workers1"] / out["seconds_per_step_workers2"]
    out["ns_per_unknown_step"] = 1e9 * out["seconds_per_step_workers1"] / lay.n_particles
    out["coupling"] = a.coupling
    out["identical_fields"] = bool(np.array_equal(fields[1], fields[2]))
    print(json.dumps(out))


if __name__ == "__main__":
    main()
