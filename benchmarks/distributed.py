"""Single process against TiledSurface: equality, time, memory, scaling, out of core.

    python benchmarks/distributed.py                     # 200k sphere (given / estimated normals) + the Igea scan
    python benchmarks/distributed.py --quick             # 20k sphere, no scan
    python benchmarks/distributed.py --throughput 1000000   # build speed per core at 1M points, 1 and 2 workers
    python benchmarks/distributed.py --big 20000000 --out /tmp/big   # out of core: terrain-like cloud, 2 workers x 4 GB
    python benchmarks/distributed.py --throughput 1000000 --sampling random --keep stable   # random points, K and M rows
    python benchmarks/distributed.py --solves 262144      # global solves: single process, local engine, MPI at 1 and 2 ranks
    python benchmarks/distributed.py --solves 1048576 --problems heat,poisson,geodesic --tiled-only   # engines only, no eigs
    python benchmarks/distributed.py --scale 10000000 --memory-limit 5GB   # 10M points: build K, M rows, implicit step
    python benchmarks/distributed.py --scale 20000000 --tile-points 625000 --memory-limit 6GB --engine mpi \
        --problems heat,geodesic --out /tmp/s20m    # 20M points: heat step and geodesic on 2 MPI ranks (tiles kept)

Equality table. Each case is built once in a fresh process (``Surface`` with the same
local options: ``area="shepard"``, and the scan settings ``h="adaptive"`` on the scan,
whose "given" normals are those :func:`estimate_normals` finds on the whole scan)
and once by ``TiledSurface`` on a LocalCluster of 2 worker processes (one thread each)
with at least 4 tiles. Printed: points, tiles, wall times (single: construction;
tiled: the whole build, driver steps included, then the five results computed), peak
resident memory (single: the process's ``ru_maxrss``; tiled: the largest worker's),
and ``max |tiled - single| / max |single|`` over the Laplacian, gradient and
divergence of ``f = cos(xz - sin y)`` (scaled to the cloud), the normals and the mean
curvature.

``--throughput N``: the build alone on the unit sphere (given normals, shepard
areas). The reference is the single process building exactly what the tiles keep
(``Surface`` and the operators named by ``--keep``; compiled code warm), with 1 and 2
threads, each in a fresh process; then TiledSurface with 1 and 2 workers (one thread
each), 4 tiles. Per-core throughput = single process with one thread / tiled with one
worker, by wall time and by CPU seconds (``process_time`` of the tiles' builds plus the
driver's, the steadier measure on a shared machine). Then the makespan of the measured
tile times list-scheduled on 1..16 workers plus the measured driver time: a simulation
of how the build would scale on more cores. ``--sampling random`` uses uniformly random
points; ``--keep`` what the tiles build.

``--solves N``: the global solves on an N-point Fibonacci sphere. Single process:
``K, M`` (``Surface``), one implicit heat step ``(M + dt K) u = M u0`` with
:func:`manifold_sph.solvers.spd_solver` (set-up, then each step), the geodesic heat method
(:func:`manifold_sph.distributed.solve.geodesic_from_matrices`, first query) and
``Surface.eigs(50)``; seconds and peak resident memory, each in a fresh process. Then
``TiledSurface(keep=("stable", "derivatives"))`` (4 tiles) with the local engine and, when
petsc4py is installed, the MPI engine at 1 and 2 ranks: iterations, seconds, peak GB per
rank and ``max |x - x_local| / max |x_local|`` (eigenvalues: each nonzero one relative),
and the method each engine used.

``--big N``: a terrain-like surface ``z = sum of sines + noise`` sampled at N uniformly
random points (spacing about 1), written to ``OUT/terrain.npy`` in chunks; then
``TiledSurface`` with estimated normals on 2 workers with ``--memory-limit`` each
(default 4GB), keeping only the Laplacian; the Laplacian of the height, the normals
and the mean curvature written to ``OUT/*.npy`` in the input order. Printed: times of
every stage, the largest worker's peak resident memory against the limit, whether any
worker was restarted, and the disk used by the tiles.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import multiprocessing as mp
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

# this file is named like the ``distributed`` package, which dask imports: keep its folder off the path
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]

import numpy as np  # noqa: E402

SCANS = Path(__file__).resolve().parents[2] / "shared" / "data" / "scans"


def field(x):
    c = x - x.mean(axis=0)
    c = c / np.abs(c).max()
    f = np.cos(c[:, 0] * c[:, 2] - np.sin(c[:, 1]))
    F = np.c_[c[:, 1] * f, -c[:, 0], c[:, 2] ** 2]
    return f, F


def _single(points, normals, options, threads):
    """Construction in this (fresh) process; the five results and the peak RSS."""
    import manifold_sph
    from manifold_sph import Surface

    manifold_sph.set_num_threads(threads)
    Surface(points[:200], None if normals is None else normals[:200], area="shepard")  # load the compiled kernels
    f, F = field(points)
    t0 = time.perf_counter()
    s = Surface(points, normals, **options)
    t_build = time.perf_counter() - t0
    out = {"lap": s.laplacian(f, form="strong"), "grad": s.gradient(f), "div": s.divergence(F), "normals": s.normals,
           "H": s.mean_curvature()}
    return t_build, out, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def single(points, normals, options, threads=2):
    with cf.ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as ex:
        return ex.submit(_single, points, normals, options, threads).result()


def tiled(points, normals, options, tile_points, client, **kw):
    from manifold_sph.distributed import TiledSurface

    f, F = field(points)
    t0 = time.perf_counter()
    ts = TiledSurface(points, normals, tile_points=tile_points, client=client, **options, **kw)
    t_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    out = {"lap": ts.gather(ts.laplacian(f)), "grad": ts.gather(ts.gradient(f)), "div": ts.gather(ts.divergence(F)),
           "normals": ts.gather(ts.normals), "H": ts.gather(ts.mean_curvature())}
    t_apply = time.perf_counter() - t0
    return ts, t_build, t_apply, out


def rel(a, b):
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


def worker_rss(client):
    return max(client.run(lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0).values())


def equality_table(cases, client):
    print(f"{'case':28s} {'points':>8s} {'tiles':>5s} {'single s':>8s} {'tiled s':>8s} {'apply s':>7s} "
          f"{'single MB':>9s} {'worker MB':>9s} {'lap':>8s} {'grad':>8s} {'div':>8s} {'normals':>8s} {'H':>8s}")
    for name, points, normals, options, tile_points in cases:
        t_single, ref, rss_single = single(points, normals, options)
        ts, t_build, t_apply, out = tiled(points, normals, options, tile_points, client)
        errs = [rel(out[k], ref[k]) for k in ("lap", "grad", "div", "normals", "H")]
        print(f"{name:28s} {points.shape[0]:8d} {len(ts.chunks):5d} {t_single:8.2f} {t_build:8.2f} {t_apply:7.2f} "
              f"{rss_single:9.0f} {worker_rss(client):9.0f} " + " ".join(f"{e:8.1e}" for e in errs), flush=True)
        ts.close()


def local_client(n_workers, memory_limit=None):
    from dask.distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                           memory_limit=memory_limit or "auto", silence_logs=40)
    return Client(cluster, set_as_default=False), cluster


def warm(client):
    """Import the package and load the compiled kernels on every worker, as the single-process reference has them."""
    def job():
        from manifold_sph import Surface
        from manifold_sph.distributed import TiledSurface
        from manifold_sph.reference import shapes

        c = shapes.sphere(2000)
        s = Surface(c.points, c.normals, area="shepard")
        s.laplacian_matrix(form="strong"), s.derivative_matrices(), s.stiffness_matrix()
        keep = ("laplacian", "derivatives", "stable")  # a tile build's own compiled helpers too
        TiledSurface(c.points, c.normals, tile_points=1000, scheduler="synchronous", keep=keep, area="shepard").close()
        return 1

    client.run(job)


def throughput(n, sampling="fibonacci", keep=("laplacian", "derivatives")):
    from manifold_sph.distributed import TiledSurface
    from manifold_sph.reference import shapes

    cloud = shapes.sphere(n, sampling=sampling, seed=1)
    opts = {"area": "shepard"}
    print(f"build of a {n}-point unit sphere ({sampling}, given normals, area='shepard', msph, keep={keep})")
    print("  the single process builds what the tiles keep (Surface, then the kept operators), in a fresh process")
    ref = {}
    for threads in (1, 2):
        wall, cpu, rss = _single_keep(cloud.points, cloud.normals, opts, keep, threads)
        ref[threads] = (wall, cpu)
        print(f"  single process, {threads} thread(s): {wall:7.2f} s wall {cpu:7.2f} CPU s   peak {rss:6.0f} MB", flush=True)
    rows = {}
    for w in (1, 2):
        client, cluster = local_client(w)
        warm(client)
        tmp = tempfile.mkdtemp(prefix="msph-bench-")
        t0 = time.perf_counter()
        c0 = time.process_time()
        ts = TiledSurface(cloud.points, cloud.normals, tile_points=-(-n // 4), client=client, cache_dir=tmp, keep=keep,
                          **opts)
        tw = time.perf_counter() - t0
        driver_cpu = time.process_time() - c0
        tiles = [r["seconds"] for r in ts.report]
        cpu = sum(r["cpu_seconds"] for r in ts.report)
        rows[w] = (tw, tiles, worker_rss(client), cpu + driver_cpu)
        print(f"  TiledSurface, {w} worker(s): {tw:7.2f} s   tiles {len(tiles)} ({', '.join(f'{t:.2f}' for t in tiles)} s)"
              f"   peak worker {rows[w][2]:6.0f} MB   CPU: tiles {cpu:.2f} s + driver {driver_cpu:.2f} s", flush=True)
        ts.close()
        shutil.rmtree(tmp, ignore_errors=True)
        client.close()
        cluster.close()
    print(f"  per-core throughput, wall (single 1 thread / tiled 1 worker): {ref[1][0] / rows[1][0]:.0%}")
    print(f"  per-core throughput, CPU seconds (single 1 thread / tiles + driver, 1 worker): {ref[1][1] / rows[1][3]:.0%}")
    print(f"  speed-up 1 -> 2 workers: {rows[1][0] / rows[2][0]:.2f}x; tiled 2 workers vs single 2 threads (wall): "
          f"{ref[2][0] / rows[2][0]:.0%}")
    # simulated scaling from the measured tile times (one worker = one core), 4 tiles and 16 tiles
    tiles = np.array(rows[1][1])
    driver = rows[1][0] - tiles.sum()
    print(f"  simulation: driver {driver:.2f} s (partition, h fit, orientation, files) + tile times list-scheduled")
    for parts in (1, 4):  # the 4 measured tiles, and each split in 4 (16 tiles) at the same total work
        work = np.repeat(tiles / parts, parts)
        line = []
        for w in (1, 2, 4, 8, 16):
            load = np.zeros(w)
            for x in sorted(work, reverse=True):
                load[np.argmin(load)] += x
            line.append(f"{w}: {driver + load.max():6.2f} s")
        print(f"    {work.size:2d} tiles -> " + "   ".join(line))


def _keep_job(points, normals, options, keep, threads):
    """Surface and the operators ``keep`` names, with ``threads`` threads: (wall s, CPU s, peak MB), compiled code warm."""
    from manifold_sph import Surface
    from manifold_sph import threads as threads_

    def build(p, nrm):
        s = Surface(p, nrm, **options)
        if "laplacian" in keep:
            s.laplacian_matrix(form="strong")
        if "derivatives" in keep:
            s.derivative_matrices()
        if "stable" in keep:
            s.stiffness_matrix(), s.mass_matrix()

    with threads_.limit(threads):
        build(points[:2000], normals[:2000])
        t0, c0 = time.perf_counter(), time.process_time()
        build(points, normals)
        return time.perf_counter() - t0, time.process_time() - c0, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _single_keep(points, normals, options, keep, threads):
    with cf.ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as ex:
        return ex.submit(_keep_job, points, normals, options, keep, threads).result()


def _solve_job(n, what):
    import numpy as np
    import scipy.sparse as sp

    from manifold_sph import Surface
    from manifold_sph.distributed.solve import geodesic_from_matrices
    from manifold_sph.reference import shapes
    from manifold_sph.solvers import spd_solver

    cloud = shapes.sphere(n)
    t0 = time.perf_counter()
    s = Surface(cloud.points, cloud.normals, area="shepard")
    K, m = s.stiffness_matrix(), s.mass_matrix().diagonal()
    out = {"K, M": time.perf_counter() - t0}
    t0 = time.perf_counter()
    if what == "heat":
        A = spd_solver(sp.diags(m) + 1e-3 * K)
        out["set-up"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        A.solve(m * cloud.points[:, 2])
        out["step"] = time.perf_counter() - t0
        out["method"] = A.method
    elif what == "geodesic":
        dx, dy = s.derivative_matrices()
        d, info = geodesic_from_matrices(K, m, dx, dy, s.u, s.v, cloud.points, np.array([0]))
        out["first query"] = time.perf_counter() - t0
        exact = np.arccos(np.clip(cloud.points @ cloud.points[0], -1, 1))
        out["rel. error"] = float(np.linalg.norm(d - exact) / np.linalg.norm(exact))
        out["method"] = info["method"]
    else:
        ev = s.eigs(50)
        out["eigs(50)"] = time.perf_counter() - t0
        out["method"] = ev.method
    out["peak GB"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    return out


SOLVES = ("heat", "poisson", "geodesic", "eigs")


def solves(n, single_only=False, problems=SOLVES, tiled_only=False):
    from manifold_sph.distributed import TiledSurface
    from manifold_sph.distributed.solve import engine_available
    from manifold_sph.reference import shapes

    print(f"global solves, {n}-point Fibonacci sphere")
    if not tiled_only:
        print("single process (each in a fresh process):")
    for what in [p for p in ("heat", "geodesic", "eigs") if p in problems and not tiled_only]:
        with cf.ProcessPoolExecutor(1, mp_context=mp.get_context("spawn")) as ex:
            out = ex.submit(_solve_job, n, what).result()
        print("  " + what + ": " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in out.items()),
              flush=True)
    if single_only:
        return
    cloud = shapes.sphere(n)
    x = cloud.points
    u0 = np.exp(-10 * ((x - [0, 0, 1]) ** 2).sum(axis=1))
    with TiledSurface(x, cloud.normals, tile_points=-(-n // 4), scheduler="synchronous", keep=("stable", "derivatives"),
                      area="shepard") as ts:
        calls = {
            "heat step": lambda e, r: ts.gather(ts.heat(u0, 1e-3, 1, method="implicit", engine=e, ranks=r)),
            "poisson": lambda e, r: ts.gather(ts.poisson(x[:, 2], engine=e, ranks=r)),
            "geodesic": lambda e, r: ts.gather(ts.geodesic_distance(0, engine=e, ranks=r)),
            "eigs(50)": lambda e, r: ts.eigs(50, engine=e, ranks=r)[0],
        }
        calls = {name: call for (name, call), p in zip(calls.items(), SOLVES) if p in problems}
        why = engine_available()
        engines = [("local", 1)] + ([("mpi", 1), ("mpi", 2)] if why is None else [])
        if why:
            print(f"MPI engine not run: {why}")
        print(f"{'solve':10s} {'engine':6s} {'ranks':>5s} {'iterations':>14s} {'seconds':>8s} {'GB/rank':>8s} {'vs local':>9s}"
              "  method")
        for name, call in calls.items():
            ref = None
            for e, r in engines:
                got = call(e, r)
                info = ts.last_solve
                diff = "" if ref is None else f"{_difference(got, ref, name.startswith('eigs')):9.1e}"
                ref = got if ref is None else ref
                print(f"{name:10s} {e:6s} {r:5d} {str(info.get('iterations'))[:14]:>14s} {info['seconds']:8.2f} "
                      f"{info.get('peak_gb_per_rank', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20):8.2f} {diff}"
                      f"  {info.get('method', '')}{_inside(info)}", flush=True)


def _inside(info):
    """The MPI engine's own times: tiles read, solves (set-up included); the rest of ``seconds`` is mpirun and files."""
    if "solve_seconds" not in info:
        return ""
    return f" (read {info['read_seconds']:.2f} s, solves {sum(info['solve_seconds']):.2f} s)"


def _difference(got, ref, eigenvalues):
    """``max |x - x_local| / max |x_local|``; eigenvalues: ``max |lambda - lambda_local| / lambda_local`` over the nonzero ones."""
    if eigenvalues:
        nz = ref > 1e-9 * ref.max()
        return float(np.max(np.abs(got[nz] - ref[nz]) / ref[nz]))
    return float(np.abs(got - ref).max() / np.abs(ref).max())


def scale(n, tile_points, memory_limit, steps=1, engine="local", ranks=2, problems=("heat",), out=None):
    """One machine to N points: a tiled build keeping K and M rows (and the derivatives for a geodesic), then implicit
    heat steps (and a geodesic) on ``engine``; ``out`` keeps the tiles for the next run (reused when they match)."""
    from manifold_sph.distributed import TiledSurface
    from manifold_sph.reference import shapes

    t0 = time.perf_counter()
    cloud = shapes.sphere(n)
    x = cloud.points
    print(f"{n}-point Fibonacci sphere: sampled in {time.perf_counter() - t0:.1f} s", flush=True)
    client, cluster = local_client(2, memory_limit)
    tmp = str(out) if out else tempfile.mkdtemp(prefix="msph-scale-")
    keep = ("stable", "derivatives") if "geodesic" in problems else ("stable",)
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        ts = TiledSurface(x, cloud.normals, tile_points=tile_points, client=client, cache_dir=tmp, keep=keep,
                          area="shepard")
        tb = time.perf_counter() - t0
        cpu = sum(r["cpu_seconds"] for r in ts.report)
        peak = max(r["peak_rss_mb"] for r in ts.report) / 1024
        disk = sum(f.stat().st_size for f in Path(tmp).rglob("*") if f.is_file()) / 2**30
        reused = sum(bool(r.get("reused")) for r in ts.report)
        print(f"  build ({', '.join(keep)}): {len(ts.chunks)} tiles on 2 workers ({memory_limit} each), {reused} reused from "
              f"{tmp}: {tb:.1f} s wall, tiles {cpu:.1f} CPU s, driver {time.process_time() - c0:.1f} CPU s, "
              f"peak worker {peak:.2f} GB, tiles on disk {disk:.2f} GB", flush=True)
        client.close()
        cluster.close()  # the workers' memory back before the solves
        u0 = np.exp(-10 * ((x - [0, 0, 1]) ** 2).sum(axis=1))
        del cloud
        on = f"{engine} engine" + (f", {ranks} ranks" if engine == "mpi" else "")
        if "heat" in problems:
            t0 = time.perf_counter()
            u = ts.gather(ts.heat(u0, 1e-4, steps, method="implicit", engine=engine, ranks=ranks))
            info = ts.last_solve
            print(f"  implicit heat, {steps} step(s), {on} ({info['method']}): {time.perf_counter() - t0:.1f} s "
                  f"(solve {info['seconds']:.1f} s, iterations {info['iterations']}), max u {u.max():.4f}, "
                  + (f"peak per rank {info['peak_gb_per_rank']:.2f} GB" if engine == "mpi" else
                     f"driver peak {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GB"), flush=True)
            del u
        if "geodesic" in problems:
            t0 = time.perf_counter()
            d = ts.gather(ts.geodesic_distance(0, engine=engine, ranks=ranks))
            info = ts.last_solve
            its = info["iterations"]
            exact = np.arccos(np.clip(x @ x[0], -1, 1))
            err = np.linalg.norm(d - exact) / np.linalg.norm(exact)
            print(f"  geodesic from one source, {on} ({info['method']}): {time.perf_counter() - t0:.1f} s "
                  f"(solve {info['seconds']:.1f} s; {len(its) - 1} heat solves, {sum(its[:-1])} iterations, Poisson "
                  f"{its[-1]}), relative L2 error {err:.2e}, "
                  + (f"peak per rank {info['peak_gb_per_rank']:.2f} GB" if engine == "mpi" else
                     f"driver peak {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GB"), flush=True)
        ts.close()
    finally:
        client.close()
        cluster.close()
        if not out:
            shutil.rmtree(tmp, ignore_errors=True)


def terrain(path: Path, n: int, seed=0):
    """N uniformly random (x, y) on a square with spacing about 1, z a sum of sines plus noise; chunked."""
    L = np.sqrt(n)
    out = np.lib.format.open_memmap(str(path), mode="w+", dtype=np.float64, shape=(n, 3))
    rng = np.random.default_rng(seed)
    step = 1 << 21
    for lo in range(0, n, step):
        m = min(step, n - lo)
        xy = rng.uniform(0, L, size=(m, 2))
        x, y = xy[:, 0], xy[:, 1]
        z = (0.05 * L * np.sin(2 * np.pi * x / L) * np.cos(2 * np.pi * y / L)
             + 3.0 * np.sin(x / 25.0 + 0.3) * np.sin(y / 31.0)
             + 0.5 * np.sin(x / 4.0) * np.cos(y / 5.0)
             + 0.01 * rng.standard_normal(m))
        out[lo : lo + m] = np.c_[x, y, z]
    out.flush()


def big(n, out: Path, memory_limit: str, tile_points: int):
    from manifold_sph.distributed import TiledSurface

    out.mkdir(parents=True, exist_ok=True)
    src = out / "terrain.npy"
    t0 = time.perf_counter()
    terrain(src, n)
    print(f"terrain of {n} points written to {src} ({src.stat().st_size / 2**30:.2f} GiB) in {time.perf_counter() - t0:.1f} s", flush=True)
    client, cluster = local_client(2, memory_limit)
    warm(client)
    before = set(client.scheduler_info()["workers"])
    cache = out / "tiles"
    t0 = time.perf_counter()
    ts = TiledSurface(str(src), tile_points=tile_points, client=client, cache_dir=cache, keep="laplacian",
                      h="adaptive", progress=False)
    t_build = time.perf_counter() - t0
    rss_build = max(r.get("peak_rss_mb", 0.0) for r in ts.report)
    print(f"build: {len(ts.chunks)} tiles of <= {tile_points} points in {t_build:.1f} s "
          f"(tile times {np.median([r['seconds'] for r in ts.report]):.1f} s median, "
          f"{max(r['seconds'] for r in ts.report):.1f} s max; attempts {max(r['attempts'] for r in ts.report)}; "
          f"halo {ts.halo:.3g}, mean halo/own {np.mean([r['n_halo'] / max(r['n_own'], 1) for r in ts.report]):.2f})", flush=True)
    t0 = time.perf_counter()
    ts.to_npy(ts.laplacian(lambda p: p[:, 2]), out / "laplacian_z.npy")
    t_lap = time.perf_counter() - t0
    t0 = time.perf_counter()
    ts.to_npy(ts.normals, out / "normals.npy")
    ts.to_npy(ts.mean_curvature(), out / "mean_curvature.npy")
    t_geo = time.perf_counter() - t0
    rss = worker_rss(client)
    after = set(client.scheduler_info()["workers"])
    disk = sum(f.stat().st_size for f in cache.iterdir()) / 2**30
    H = np.load(out / "mean_curvature.npy", mmap_mode="r")
    nz = np.load(out / "normals.npy", mmap_mode="r")[:: max(1, n // 100000), 2]
    print(f"Laplacian of z written in {t_lap:.1f} s; normals and mean curvature in {t_geo:.1f} s")
    print(f"peak resident memory: largest worker {rss:.0f} MB (build {rss_build:.0f} MB) against a limit of {memory_limit}; "
          f"driver {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    print(f"workers restarted: {'no' if before == after else 'YES'}; tiles on disk {disk:.1f} GiB; "
          f"normals up (n_z > 0) {np.mean(nz > 0):.4f}; median |H| {np.median(np.abs(H[::97])):.3g}")
    print(f"total {t_build + t_lap + t_geo:.1f} s for {n} points")
    ts.close()
    client.close()
    cluster.close()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--n", type=int, default=200_000, help="sphere size of the equality table")
    ap.add_argument("--scan", type=Path, default=SCANS / "igea.ply")
    ap.add_argument("--throughput", type=int, default=None, metavar="N")
    ap.add_argument("--big", type=int, default=None, metavar="N")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--memory-limit", default="4GB")
    ap.add_argument("--tile-points", type=int, default=500_000)
    ap.add_argument("--sampling", default="fibonacci", choices=("fibonacci", "random"))
    ap.add_argument("--keep", default="laplacian,derivatives", help="comma-separated: laplacian, derivatives, stable")
    ap.add_argument("--solves", type=int, default=None, metavar="N")
    ap.add_argument("--scale", type=int, default=None, metavar="N", help="build K, M rows of N points on 2 workers, "
                    "then an implicit heat step on one process")
    ap.add_argument("--single-only", action="store_true", help="--solves: the single-process rows only")
    ap.add_argument("--engine", default="local", choices=("local", "mpi"), help="--scale: the engine of the solves")
    ap.add_argument("--ranks", type=int, default=2, help="--scale: MPI ranks")
    ap.add_argument("--tiled-only", action="store_true", help="--solves: the TiledSurface engines' rows only")
    ap.add_argument("--problems", default=",".join(SOLVES), help="--solves: comma-separated, of " + ", ".join(SOLVES))
    args = ap.parse_args()
    if args.scale:
        scale(args.scale, args.tile_points, args.memory_limit, engine=args.engine, ranks=args.ranks,
              problems=tuple(p for p in args.problems.split(",") if p) if args.problems != ",".join(SOLVES) else ("heat",),
              out=args.out)
        return
    if args.solves:
        problems = [p for p in args.problems.split(",") if p]
        if not set(problems) <= set(SOLVES):
            ap.error(f"--problems takes {', '.join(SOLVES)}, got {args.problems!r}")
        solves(args.solves, args.single_only, problems, args.tiled_only)
        return
    if args.big:
        big(args.big, args.out or Path(tempfile.mkdtemp(prefix="msph-big-")), args.memory_limit, args.tile_points)
        return
    if args.throughput:
        throughput(args.throughput, args.sampling, tuple(args.keep.split(",")))
        return
    from manifold_sph.reference import shapes

    n = 20_000 if args.quick else args.n
    cloud = shapes.sphere(n)
    cases = [
        ("sphere, given normals", cloud.points, cloud.normals, {"area": "shepard"}, -(-n // 4)),
        ("sphere, estimated normals", cloud.points, None, {"area": "shepard"}, -(-n // 4)),
    ]
    if not args.quick and args.scan.exists():
        from manifold_sph import estimate_normals
        from manifold_sph.scans.io import read

        scan = read(args.scan, normals="none")
        quarter = -(-scan.points.shape[0] // 4)
        opts = {"area": "shepard", "h": "adaptive"}
        cases.append((f"{args.scan.stem}, given normals", scan.points, estimate_normals(scan.points), opts, quarter))
        cases.append((f"{args.scan.stem}, estimated normals", scan.points, None, opts, quarter))
    elif not args.quick:
        print(f"skipping the scan: {args.scan} not found")
    client, cluster = local_client(2)
    warm(client)
    equality_table(cases, client)
    client.close()
    cluster.close()


if __name__ == "__main__":
    sys.exit(main())
