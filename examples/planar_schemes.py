"""The planar schemes of [1] (docs/method.md), chapter 2: four schemes on [-1, 1]^2, with and without mirroring.

    python examples/planar_schemes.py --out pictures [--quick]

Gradient of xy, divergence of (sin pi x, sin pi y) and Laplacian of
sin(pi x) cos(pi y) on Poisson-disk points. Without ghost particles the kernel
sums are truncated at the boundary and the standard scheme's errors pile up
there; the corrected schemes and the mirror strips (periodic ghosts) fix it.
Writes boxplots of the Laplacian errors and the error fields in the plane.
"""

import numpy as np
from _common import can_render, parse, report

from manifold_sph import Domain2D
from manifold_sph.reference import functions
from manifold_sph.reference.accuracy import planar_errors
from manifold_sph.reference.errors import absolute_error
from manifold_sph.reference.sampling import square
from manifold_sph.viz.plots import error_boxplot

SCHEMES = ("standard", "cspm", "msph", "ncsph")


def main(argv=None) -> int:
    args = parse(argv, __doc__.splitlines()[0])
    n = 900 if args.quick else 3600
    p = square(n, seed=0)
    print(f"square [-1, 1]^2, N = {n}: relative L2 errors")
    for mirror in (False, True):
        for r in planar_errors(p, SCHEMES, mirror=mirror):
            print(f"  mirror={str(mirror):<5} {r['scheme']:<9} grad {r['grad_l2']:.3e}  div {r['div_l2']:.3e}  lap {r['lap_l2']:.3e}")
    fn = functions.sin_pi_x_cos_pi_y
    f = fn.value(p)
    exact = np.trace(fn.hessian(p), axis1=1, axis2=2)
    errs = {s: absolute_error(Domain2D(p, scheme=s).laplacian(f, form="strong"), exact) for s in SCHEMES}
    out = [args.out / "planar_laplacian_boxplot.png"]
    error_boxplot(errs, title=f"Laplacian of sin(pi x) cos(pi y), square, N = {n}", filename=out[0],
                  overwrite=args.overwrite)
    if can_render():
        from manifold_sph.viz.render import render_panels

        out.append(args.out / "planar_laplacian_errors.png")
        render_panels(p, {s: errs[s] for s in SCHEMES}, cmap="magma", robust=1, camera="top", panel_size=(260, 280),
                      filename=out[-1], overwrite=args.overwrite)
    report(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
