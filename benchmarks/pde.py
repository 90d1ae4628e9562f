"""Implicit heat steps and Poisson solves on the stable Laplacian, side by side with scipy (issue 34).

    python benchmarks/pde.py                               # 100,000 random sphere points, and the Igea scan
    python benchmarks/pde.py --sizes 20000,100000 --steps 20 --json pde.json
    python benchmarks/pde.py --no-scan

Clouds: uniformly random points on the unit sphere (``--sizes``, exact normals), and the
Igea scan of ``../shared/data/scans`` (134,345 vertices as bare points, normals
estimated; skipped when absent or with ``--no-scan``).

For each cloud, with the stable Laplacian (``K``, ``M``) and the ``dt`` that
``pde.heat(s, u0, reach=0.1)`` chooses (about one spacing of diffusion a step):

- ``heat(reach=0.1)``: the whole call as a user makes it (set-up, every step, snapshots);
- one implicit (backward Euler) step ``(M + dt K) u' = M u``: the set-up (factorisation or
  multigrid hierarchy) once, then the time of a step, the median over ``--steps`` steps:
  ``ours, cholesky`` and ``ours, amg`` are :func:`manifold_sph.pde.heat` with
  ``solver="direct"`` and ``"iterative"``, timed between its callbacks (a step includes the
  right-hand side, the solve, the finiteness check and the snapshot bookkeeping; the set-up
  is the time to the first callback less one step); the peers solve the same system:
  scipy's sparse LU (``splu``, factorised once) and scipy's CG with a Jacobi preconditioner
  (started from the current state, ``rtol=1e-10``);
- ``difference``: the largest difference of the state after the steps from the LU's, relative to
  its largest value;
- Poisson ``K u = -M f`` (zero mean): ours (one value pinned per piece, Cholesky or
  AMG-CG) against scipy's ``spsolve`` on the bordered saddle-point system.

Wall seconds on the machine it runs on; the target is 0.1 s per implicit step at 100,000
points (issue 34).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time
import warnings

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from manifold_sph import Surface, pde, read

SCAN = pathlib.Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "scans" / "igea.ply"


def random_sphere(n: int, seed: int = 0) -> np.ndarray:
    p = np.random.default_rng(seed).standard_normal((n, 3))
    return p / np.linalg.norm(p, axis=1)[:, None]


def hot_spot(points: np.ndarray) -> np.ndarray:
    c = points[np.argmax(points.sum(axis=1))]
    d = 2 * np.linalg.norm(points - points.mean(axis=0), axis=1).max()
    return np.exp(-(np.linalg.norm(points - c, axis=1) / (0.1 * d)) ** 2)


def clock(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def bench_cloud(name: str, points: np.ndarray, normals: np.ndarray | None, steps: int) -> dict:
    row: dict = {"cloud": name, "n": int(len(points))}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the build's one summary
        row["build s"], s = clock(lambda: Surface(points, normals))
        row["stable K, M s"], _ = clock(s.stiffness_matrix)
    K, M = s.stiffness_matrix(), s.mass_matrix()
    m = M.diagonal()
    u0 = hot_spot(s.points)
    row["heat(reach=0.1) s"], sol = clock(lambda: pde.heat(s, u0, reach=0.1, laplacian="stable"))
    dt = sol.dt
    row["heat steps"], row["dt"], row["heat solver"] = int(sol.times.size and round(sol.times[-1] / dt)), dt, sol.solver
    A = (M + dt * K).tocsc()
    # scipy's sparse LU, the reference state after `steps` steps
    t_lu, lu = clock(lambda: spla.splu(A))
    u, times = u0.copy(), []
    for _ in range(steps):
        t, u = clock(lambda u=u: lu.solve(m * u))
        times.append(t)
    ref = u
    results = {"scipy splu": (t_lu, float(np.median(times)), 0.0)}
    # scipy CG with a Jacobi preconditioner, warm-started
    dinv = sp.diags(1.0 / A.diagonal())
    u, times = u0.copy(), []
    for _ in range(steps):
        t, (u, info) = clock(lambda u=u: spla.cg(A, m * u, x0=u, rtol=1e-10, M=dinv, maxiter=5000))
        times.append(t)
    results["scipy cg + jacobi"] = (0.0, float(np.median(times)), float(np.abs(u - ref).max() / np.abs(ref).max()))
    for solver, label in (("direct", "ours, cholesky"), ("iterative", "ours, amg")):
        stamps: list[float] = []
        t0 = time.perf_counter()
        after = pde.heat(s, u0, dt=dt, steps=steps, laplacian="stable", solver=solver,
                         callback=lambda step, t, u: stamps.append(time.perf_counter()))
        per = float(np.median(np.diff([t0] + stamps)[1:]))  # the steps after the first
        setup = stamps[0] - t0 - per  # the first step also sets the solver up
        results[f"{label} ({after.solver})"] = (max(setup, 0.0), per, float(np.abs(after.u - ref).max() / np.abs(ref).max()))
    row["step"] = results
    # Poisson: ours against spsolve on the bordered system
    x = s.points
    f = np.cos(3 * x[:, 0]) * x[:, 1] + x[:, 2] ** 2
    f -= (m @ f) / m.sum()
    n = len(m)
    B = sp.bmat([[K, sp.csr_matrix(np.ones((n, 1)))], [sp.csr_matrix(m[None, :]), None]], format="csc")
    t_ref, sol_ref = clock(lambda: spla.spsolve(B, np.append(-m * f, 0.0)))
    ref = sol_ref[:n]
    pois = {"scipy spsolve (bordered)": (t_ref, 0.0)}
    for solver, label in (("direct", "ours, cholesky"), ("iterative", "ours, amg")):
        t, u = clock(lambda: pde.poisson(s, f, laplacian="stable", solver=solver))
        pois[label] = (t, float(np.abs(u - ref).max() / np.abs(ref).max()))
    row["poisson"] = pois
    return row


def print_row(row: dict) -> None:
    print(f"\n{row['cloud']}, N = {row['n']:,}: build {row['build s']:.1f} s, stable K and M {row['stable K, M s']:.1f} s; "
          f"pde.heat(s, u0, reach=0.1): {row['heat steps']} steps of dt = {row['dt']:.3g} ({row['heat solver']}) in "
          f"{row['heat(reach=0.1) s']:.1f} s")
    print("| implicit step (M + dt K) u' = M u | set-up s | per step s | difference from splu |")
    print("|---|---|---|---|")
    for k, (a, b, c) in row["step"].items():
        print(f"| {k} | {a:.2f} | {b:.4f} | {c:.1e} |")
    print("| Poisson K u = -M f | seconds | difference from spsolve |")
    print("|---|---|---|")
    for k, (a, c) in row["poisson"].items():
        print(f"| {k} | {a:.2f} | {c:.1e} |")
    sys.stdout.flush()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="100000", help="random sphere sizes, comma-separated (default 100000)")
    ap.add_argument("--steps", type=int, default=10, help="steps timed per method (default 10)")
    ap.add_argument("--no-scan", action="store_true", help="skip the Igea scan")
    ap.add_argument("--json", default=None, help="also write the rows to this JSON file")
    args = ap.parse_args(argv)
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        Surface(random_sphere(2000), random_sphere(2000)).stiffness_matrix()  # compile the kernels (numba cache)
    for n in (int(v) for v in args.sizes.split(",")):
        p = random_sphere(n)
        rows.append(bench_cloud("random sphere", p, p.copy(), args.steps))
        print_row(rows[-1])
    if not args.no_scan and SCAN.exists():
        cloud = read(SCAN)
        rows.append(bench_cloud("Igea scan (bare points)", cloud.points, None, args.steps))
        print_row(rows[-1])
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
