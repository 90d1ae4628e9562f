"""The sausage's high-curvature outliers ([1] Figs. 54-55; docs/method.md).

    python examples/sausage_outliers.py --out pictures [--quick]

Laplace-Beltrami of f = cos(xz - sin y) on the bent capsule: the largest errors
sit at the two tips, where the curvature is highest. With the full colour range
the error picture is dominated by a few particles (the source fixed the range by
hand); robust limits (1 % clipped at each end) show the bulk. Writes both
pictures, the boxplot per scheme, and prints where the Tukey outliers are.
"""

import numpy as np
from _common import can_render, parse, report

from manifold_sph import Surface
from manifold_sph.reference import functions, shapes
from manifold_sph.reference.errors import absolute_error, boxplot_summary
from manifold_sph.viz.plots import error_boxplot

SCHEMES = ("standard", "cspm", "msph", "ncsph")


def main(argv=None) -> int:
    args = parse(argv, __doc__.splitlines()[0])
    cloud = shapes.sausage(1200 if args.quick else 2652, seed=0)
    x = cloud.points
    fn = functions.cos_xz_sin_y
    f = fn.value(x)
    exact = cloud.geometry.laplace_beltrami(x, fn.gradient(x), fn.hessian(x))
    tip_dist = np.min(np.linalg.norm(x[:, None, :] - cloud.geometry.tips[None], axis=2), axis=1)
    errs = {}
    for name in SCHEMES:
        errs[name] = absolute_error(Surface(cloud, scheme=name).laplacian(f, form="strong"), exact)
        out_idx = boxplot_summary(errs[name]).outliers
        near = float(np.mean(tip_dist[out_idx] < 0.3)) if out_idx.size else float("nan")
        print(f"{name:<9} {out_idx.size:>4} outliers, {100 * near:.0f} % of them within 0.3 of a tip; "
              f"largest error {errs[name].max():.3g} at distance {tip_dist[np.argmax(errs[name])]:.3f} from a tip")
    out = [args.out / "sausage_laplacian_boxplot.png"]
    error_boxplot(errs, title=f"Laplace-Beltrami on the sausage, N = {len(x)}", filename=out[0], overwrite=args.overwrite)
    if can_render():
        from manifold_sph.viz.render import render_panels

        out.append(args.out / "sausage_error_full_vs_robust.png")
        e = errs["msph"]
        full = render_panels(cloud, {"error, full range": e}, cmap="magma", camera="north_pole", panel_size=(360, 360))
        robust = render_panels(cloud, {"error, 1 % clipped": e}, cmap="magma", robust=1, camera="north_pole",
                               panel_size=(360, 360))
        from manifold_sph.viz.render import save_png

        save_png(np.concatenate([full, robust], axis=1), out[-1], overwrite=args.overwrite)
    report(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
