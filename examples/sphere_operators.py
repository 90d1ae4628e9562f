"""Gradient, divergence and Laplace-Beltrami on the sphere, four schemes ([1] Figs. 43, 45, 47; docs/method.md).

    python examples/sphere_operators.py --out pictures [--quick]

f = cos(xz - sin y) and the tangent field F = grad_S(xyz) on the unit sphere
(Fibonacci points). Writes boxplots of the pointwise errors per scheme for each
operator and, for CSPM, the panels f | exact | SPH | error and the gradient arrows.
"""


from _common import can_render, parse, report

from manifold_sph import Surface
from manifold_sph.reference import functions, shapes
from manifold_sph.reference.errors import absolute_error, error_summary
from manifold_sph.viz.plots import error_boxplot

SCHEMES = ("standard", "cspm", "msph", "ncsph")


def main(argv=None) -> int:
    args = parse(argv, __doc__.splitlines()[0])
    n = 1002 if args.quick else 4032
    cloud = shapes.sphere(n)
    x = cloud.points
    fn = functions.cos_xz_sin_y
    f, g, H = fn.value(x), fn.gradient(x), fn.hessian(x)
    grad_ex = cloud.geometry.surface_gradient(x, g)
    lap_ex = cloud.geometry.laplace_beltrami(x, g, H)
    # F = grad_S(xyz), the tangent part of (yz, xz, xy): div_S F = Lap_S(xyz) exactly
    F = cloud.geometry.surface_gradient(x, functions.xyz.gradient(x))
    div_ex = cloud.geometry.laplace_beltrami(x, functions.xyz.gradient(x), functions.xyz.hessian(x))
    errs = {"gradient": {}, "divergence": {}, "laplacian": {}}
    surfaces = {}
    print(f"sphere, N = {n}: relative L2 errors")
    for name in SCHEMES:
        s = surfaces[name] = Surface(cloud, scheme=name)
        approx = {"gradient": (s.gradient(f), grad_ex), "divergence": (s.divergence(F), div_ex),
                  "laplacian": (s.laplacian(f, form="strong"), lap_ex)}
        line = []
        for op, (a, e) in approx.items():
            errs[op][name] = absolute_error(a, e)
            line.append(f"{op} {error_summary(a, e)['l2_rel']:.3e}")
        print(f"  {name:<9}" + "  ".join(line))
    out = []
    for op, fig_no in (("gradient", 43), ("divergence", 45), ("laplacian", 47)):
        out.append(args.out / f"sphere_{op}_boxplot.png")
        error_boxplot(errs[op], title=f"{op} on the sphere, N = {n} (cf. de Jesus 2017, Fig. {fig_no})",
                      ylabel="pointwise absolute error", filename=out[-1], overwrite=args.overwrite)
    if can_render():
        from manifold_sph.viz.render import render_comparison, render_field

        s = surfaces["cspm"]
        out.append(args.out / "sphere_laplacian_cspm.png")
        render_comparison(s, f, lap_ex, s.laplacian(f, form="strong"), names=("f", "exact", "CSPM", "error"),
                          camera="equator", panel_size=(300, 300), filename=out[-1], overwrite=args.overwrite)
        out.append(args.out / "sphere_gradient_cspm.png")
        render_field(s, f, vectors=s.gradient(f), bar_title="f", camera="north_pole", window_size=(560, 500),
                     title="CSPM gradient of cos(xz - sin y)", filename=out[-1], overwrite=args.overwrite)
    report(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
