"""Accuracy tables of the operators issue: errors against exact references and fitted orders.

    python benchmarks/accuracy.py                 # sphere to N = 131072, torus, double torus, sausage, plane
    python benchmarks/accuracy.py --quick         # smaller sizes (about a minute)

Prints plain-text tables; every number is measured in this run.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

from manifold_sph.reference import shapes
from manifold_sph.reference.accuracy import convergence, curvature_errors, format_rows, operator_errors, planar_errors

SPHERE = [1002, 2012, 4032, 8672, 15872, 32672, 65536, 131072]
OTHERS = [2000, 4000, 8000, 16000, 32000, 64000]
PLANE = [1007, 2012, 4029, 8052]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="smaller sizes")
    args = ap.parse_args()
    sphere = SPHERE[:5] if args.quick else SPHERE
    others = OTHERS[:3] if args.quick else OTHERS
    warnings.simplefilter("ignore", RuntimeWarning)

    print("## Unit sphere, Fibonacci points, f = cos(xz - sin y), 27 neighbours, quintic, numerical area\n")
    for scheme in ("cspm", "msph", "ncsph"):
        t = convergence("sphere", sphere, scheme, "cos_xz_sin_y")
        print(f"### {scheme}\n{t.to_text()}\n")
        worst = operator_errors(shapes.sphere(sphere[-1]), "cos_xz_sin_y", [scheme])[0]["lap_worst"]
        z = shapes.sphere(sphere[-1]).points[worst, 2]
        print(f"largest Laplacian error at N = {sphere[-1]}: particle {worst}, z = {z:+.4f}\n")

    for shape, fn in (("torus", "xyz"), ("double_torus", "xyz"), ("sausage", "xyz")):
        print(f"## {shape}, Poisson-disk points, f = {fn}\n")
        for scheme in ("cspm", "msph", "ncsph"):
            print(f"### {scheme}\n{convergence(shape, others, scheme, fn).to_text()}\n")

    print("## Curvature: relative L2 errors of H and K, Poisson-disk points, exact normals (bare points: estimated)\n")
    print(f"{'shape':<13} {'N':>6} {'scheme':<7} {'normals':<8} {'H L2':>9} {'K L2':>9} {'s':>6}")
    for shape in ("torus", "double_torus", "sausage"):
        for n in others[:3]:
            cloud = getattr(shapes, shape)(n)
            for est in (False, True):
                for r in curvature_errors(cloud, ("msph", "msph4"), estimated_normals=est):
                    print(f"{shape:<13} {n:>6} {r['scheme']:<7} {'bare' if est else 'exact':<8} {r['H_l2']:>9.2e} "
                          f"{r['K_l2']:>9.2e} {r['seconds']:>6.2f}")
    print()

    print("## Sausage N = 2652, f = xyz: normal filter on (threshold 0) and off (threshold -1)\n")
    cloud = shapes.sausage(2652)
    print(format_rows(operator_errors(cloud, "xyz")))
    print("filter off:")
    print(format_rows(operator_errors(cloud, "xyz", normal_threshold=-1.0)))

    print("\n## Plane [-1, 1]^2, Poisson-disk points: grad(xy), div(sin pi x, sin pi y), Lap(sin pi x cos pi y)\n")
    print(f"{'N':>5} {'scheme':<9} {'mirror':>6} {'grad L2':>9} {'div L2':>9} {'lap L2':>9} {'lap Linf':>9}")
    for n in PLANE[:2] if args.quick else PLANE:
        p = shapes.square(n, sampling="poisson", seed=0)
        for mirror in (False, True):
            for r in planar_errors(p, mirror=mirror):
                print(
                    f"{n:>5} {r['scheme']:<9} {int(mirror):>6} {r['grad_l2']:>9.2e} {r['div_l2']:>9.2e} "
                    f"{r['lap_l2']:>9.2e} {r['lap_linf']:>9.2e}"
                )


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
