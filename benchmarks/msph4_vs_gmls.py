"""msph4 (and msph5) against GMLS (pycompadre) on the unit sphere, plus torus studies (issue 9).

    python benchmarks/msph4_vs_gmls.py                  # N = 4032, 32672: errors, orders, timings
    python benchmarks/msph4_vs_gmls.py --full           # adds N = 131072 and the torus / double torus tables
    python benchmarks/msph4_vs_gmls.py --neighbours     # msph4's neighbour-count trade-off
    python benchmarks/msph4_vs_gmls.py --no-gmls        # ours only

Unit sphere, Fibonacci points, exact normals, f = cos(xz - sin y); relative L2
errors of the Laplace-Beltrami operator and of the surface gradient against the
exact references of :mod:`manifold_sph.reference.shapes`. Every number is measured in
this run, on the same points, one after the other.

GMLS is pycompadre's manifold GMLS (``problem_type="MANIFOLD"``, QR, polynomial
order 4 unless ``--gmls-order``, curvature order 2, neighbours from its k-NN
search with epsilon multiplier 1.6: all its defaults), with its default
weighting (``power`` 2) and with ``power`` 4. It estimates the tangent planes
itself; the exact normals only orient them. Build time: KD-tree, neighbour
search and ``generateAlphas`` (the stencil weights; not converted to a sparse
matrix). Ours: the whole :class:`~manifold_sph.Surface` construction
(neighbours, frames, area elements, assembly into CSR matrices) with
``area="shepard"``: the msph schemes do not use area elements, so the operators
are identical to the default ``area="numerical"``, whose iterative solve would
only add time. Sphere build times are the median of ``--repeat`` builds (default 3)
for both, so one-time start-up costs (imports, caches, thread pools) count for neither.
pycompadre runs Kokkos/OpenMP on all cores; numpy's threads are
not limited either. pycompadre is the ``bench`` extra: without it the GMLS
rows are skipped with a message.
"""

from __future__ import annotations

import argparse
import gc
import os
import sys
import time
import warnings

# pycompadre's Kokkos/OpenMP threads spin while idle by default and would steal the
# second core from our threaded steps run between its calls; let them sleep instead.
# Set before any OpenMP runtime loads; an explicit user setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np

from manifold_sph import Surface
from manifold_sph.reference import shapes
from manifold_sph.reference.accuracy import convergence, exact_operators, get_function
from manifold_sph.reference.errors import error_summary, fit_order

SIZES = [4032, 32672]
FULL = [4032, 32672, 131072]
FUNCTION = "cos_xz_sin_y"


def _gmls_module():
    try:
        import pycompadre
    except ImportError as exc:  # pragma: no cover - depends on the environment
        print(f"pycompadre is not installed ({exc}); GMLS rows skipped. Install the bench extra: pip install pycompadre\n")
        return None
    return pycompadre


def ours(cloud, scheme, **kw):
    f, grad, lap = exact_operators(cloud, get_function(FUNCTION))
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        s = Surface(cloud, scheme=scheme, area="shepard", **kw)
    build = time.perf_counter() - t0
    fb = int(sum(v.size for v in s.fallback.values()))
    return {
        "method": scheme + (f" k={kw['neighbors']}" if "neighbors" in kw else ""),
        "lap": error_summary(s.laplacian(f, form="strong"), lap)["l2_rel"],
        "grad": error_summary(s.gradient(f), grad)["l2_rel"],
        "build": build,
        "note": f"{s.neighborhood.counts.mean():.0f} nb, {fb} fallback",
    }


def gmls(pc, cloud, order, power=None):
    """pycompadre's manifold GMLS; ``power=None`` keeps its default weighting.

    A cloud without an analytic shape (a scan) gets its build time only (errors NaN)."""
    if cloud.geometry is not None:
        f, grad, lap = exact_operators(cloud, get_function(FUNCTION))
    else:
        f, grad, lap = get_function(FUNCTION).value(cloud.points), None, None
    x = np.array(cloud.points, order="C")
    ops = [pc.TargetOperation.LaplacianOfScalarPointEvaluation, pc.TargetOperation.GradientOfScalarPointEvaluation]
    t0 = time.perf_counter()
    g = pc.GMLS(order, 3, "QR", "MANIFOLD")
    if power is not None:
        g.setWeightingType("power")
        g.setWeightingParameter(power)
    helper = pc.ParticleHelper(g)
    helper.generateKDTree(x)
    helper.setReferenceOutwardNormalDirection(np.array(cloud.normals, order="C"), True)
    g.addTargets(ops)
    helper.generateNeighborListsFromKNNSearchAndSet(x, order, 2, 1.6)
    g.generateAlphas(1, False)
    build = time.perf_counter() - t0
    fc = np.array(f, order="C")
    L = helper.applyStencil(fc, ops[0])
    G = helper.applyStencil(fc, ops[1])
    nb = helper.getNeighborLists()
    mean_nb = nb.getTotalNeighborsOverAllLists() / len(x)
    row = {
        "method": f"gmls p{order} " + ("default(power 2)" if power is None else f"power {power}"),
        "lap": error_summary(L, lap)["l2_rel"] if lap is not None else float("nan"),
        "grad": error_summary(G, grad)["l2_rel"] if grad is not None else float("nan"),
        "build": build,
        "note": f"{mean_nb:.0f} nb",
    }
    del helper, g, nb
    gc.collect()
    return row


def median_build(fn, repeat):
    """``fn()`` run ``repeat`` times; the last row with the median build time."""
    runs = [fn() for _ in range(max(1, repeat))]
    row = runs[-1]
    row["build"] = float(np.median([r["build"] for r in runs]))
    return row


def sphere_table(sizes, schemes, pc, gmls_order, repeat=3):
    rows = []
    for n in sizes:
        cloud = shapes.sphere(n)
        for sch in schemes:
            rows.append({"n": n, **median_build(lambda: ours(cloud, sch), repeat)})
        if pc is not None:
            for power in (None, 4):
                rows.append({"n": n, **median_build(lambda: gmls(pc, cloud, gmls_order, power), repeat)})
    print(f"{'N':>7} {'method':<24} {'lap L2':>10} {'grad L2':>10} {'build s':>8}  note")
    for r in rows:
        print(f"{r['n']:>7d} {r['method']:<24} {r['lap']:>10.3e} {r['grad']:>10.3e} {r['build']:>8.2f}  {r['note']}")
    if len(sizes) > 1:
        print("\nfitted orders (h ~ N^-1/2):")
        for m in dict.fromkeys(r["method"] for r in rows):
            sub = [r for r in rows if r["method"] == m]
            ns = [r["n"] for r in sub]
            ol = fit_order(ns, [r["lap"] for r in sub])
            og = fit_order(ns, [r["grad"] for r in sub])
            print(f"  {m:<24} lap {ol:5.2f}  grad {og:5.2f}")
    if pc is not None:
        print("\nratios (GMLS / ours; > 1: ours better or faster):")
        for n in sizes:
            at = {r["method"]: r for r in rows if r["n"] == n}
            for sch in schemes:
                for m in [k for k in at if k.startswith("gmls")]:
                    a, b = at[sch], at[m]
                    print(
                        f"  N={n:<7d} {sch} vs {m:<24} lap x{b['lap'] / a['lap']:5.1f}  "
                        f"grad x{b['grad'] / a['grad']:5.1f}  build x{b['build'] / a['build']:5.1f}"
                    )
    return rows


def neighbour_scan(n=8672):
    print(f"## msph4 neighbour-count trade-off (sphere N = {n}, Fibonacci; Poisson-disk sphere N = 8000 for fallbacks)\n")
    fib, poi = shapes.sphere(n), shapes.sphere(8000, sampling="poisson", seed=0)
    for k in (22, 26, 30, 36, 45, 60, 80):
        a, b = ours(fib, "msph4", neighbors=k), ours(poi, "msph4", neighbors=k)
        print(f"  k={k:<3d} fib lap {a['lap']:.3e} grad {a['grad']:.3e} | poisson lap {b['lap']:.3e} ({b['note']})")
    print()


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--full", action="store_true", help="N up to 131072, and the torus / double torus tables")
    ap.add_argument("--sizes", type=int, nargs="+", help="sphere sizes (default 4032 32672)")
    ap.add_argument("--schemes", nargs="+", default=["msph4", "msph5"])
    ap.add_argument("--gmls-order", type=int, default=4)
    ap.add_argument("--no-gmls", action="store_true")
    ap.add_argument("--repeat", type=int, default=3, help="builds per method and size on the sphere; the median time is reported")
    ap.add_argument("--neighbours", action="store_true", help="only the neighbour-count scan")
    args = ap.parse_args(argv)
    if args.neighbours:
        neighbour_scan()
        return
    sizes = args.sizes or (FULL if args.full else SIZES)
    print(f"threads: OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}, cores={os.cpu_count()}\n")
    pc = None if args.no_gmls else _gmls_module()
    kp = pc.KokkosParser(sys.argv[:1]) if pc is not None else None
    print(f"## Unit sphere, Fibonacci points, exact normals, f = {FUNCTION}\n")
    sphere_table(sizes, args.schemes, pc, args.gmls_order, args.repeat)
    gc.collect()
    del kp
    if args.full:
        for shape in ("torus", "double_torus"):
            print(f"\n## {shape}, Poisson-disk points, f = xyz\n")
            for sch in args.schemes:
                print(f"### {sch}\n{convergence(shape, [4000, 8000, 16000, 32000, 64000], sch, 'xyz').to_text()}\n")


if __name__ == "__main__":
    main()
