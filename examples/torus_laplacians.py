"""Laplace-Beltrami on the torus and the double torus ([1] Figs. 49-50; docs/method.md).

    python examples/torus_laplacians.py --out pictures [--quick]

f = cos(xz - sin y) on Poisson-disk samples (4800 and 3070 points as in the
source). Writes the panels f | exact | MSPH | error for each shape and boxplots of
the pointwise errors of the four schemes.
"""

import warnings

from _common import can_render, parse, report

from manifold_sph import Surface
from manifold_sph.exceptions import ManifoldSPHWarning
from manifold_sph.reference import functions, shapes
from manifold_sph.reference.errors import absolute_error, error_summary
from manifold_sph.viz.plots import error_boxplot

SCHEMES = ("standard", "cspm", "msph", "ncsph")


def main(argv=None) -> int:
    args = parse(argv, __doc__.splitlines()[0])
    clouds = {
        "torus": shapes.torus(1200 if args.quick else 4800, seed=0),
        "double_torus": shapes.double_torus(1000 if args.quick else 3070, seed=0),
    }
    fn = functions.cos_xz_sin_y
    out = []
    render = can_render()
    for shape, cloud in clouds.items():
        x = cloud.points
        f = fn.value(x)
        exact = cloud.geometry.laplace_beltrami(x, fn.gradient(x), fn.hessian(x))
        errs, lap = {}, {}
        for name in SCHEMES:
            with warnings.catch_warnings(record=True) as caught:  # cspm's inconsistent rows: said, not fatal
                warnings.simplefilter("always", ManifoldSPHWarning)
                lap[name] = Surface(cloud, scheme=name).laplacian(f, form="strong")
            for w in caught:
                print(f"{shape:<12} note: {w.message}")
            errs[name] = absolute_error(lap[name], exact)
            print(f"{shape:<12} N = {len(x):>5} {name:<9} relative L2 error {error_summary(lap[name], exact)['l2_rel']:.3e}")
        out.append(args.out / f"{shape}_laplacian_boxplot.png")
        error_boxplot(errs, title=f"Laplace-Beltrami on the {shape.replace('_', ' ')}, N = {len(x)}",
                      filename=out[-1], overwrite=args.overwrite)
        if render:
            from manifold_sph.viz.render import render_comparison

            out.append(args.out / f"{shape}_laplacian_msph.png")
            render_comparison(cloud, f, exact, lap["msph"], names=("f", "exact", "MSPH", "error"), robust=0.5,
                              camera=((0.3, -1.0, 1.2), (0.0, 0.0, 1.0)), panel_size=(300, 260),
                              filename=out[-1], overwrite=args.overwrite)
    report(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
