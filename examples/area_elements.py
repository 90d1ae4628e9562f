"""Area elements on the sphere ([1] Fig. 40; docs/method.md): numerical (partition of unity) vs Shepard.

    python examples/area_elements.py --out pictures [--quick]

Writes ``area_elements_sphere.png`` (dV on the points, two panels) and
``area_elements_histogram.png``; prints the total area against 4 pi.
"""

import numpy as np
from _common import can_render, parse, report

from manifold_sph import Surface
from manifold_sph.reference import shapes
from manifold_sph.viz.plots import area_histogram


def main(argv=None) -> int:
    args = parse(argv, __doc__.splitlines()[0])
    n = 1002 if args.quick else 4032
    cloud = shapes.sphere(n, sampling="poisson", seed=0)
    dv = {a: Surface(cloud, area=a).dV for a in ("numerical", "shepard")}
    for a, v in dv.items():
        print(f"{a:>9}: total area {v.sum():.6f} (4 pi = {4 * np.pi:.6f}), {int((v < 0).sum())} negative, "
              f"min {v.min():.3e}, max {v.max():.3e}")
    out = [args.out / "area_elements_histogram.png"]
    area_histogram(dv, reference=4 * np.pi / n, title=f"Area elements, Poisson-disk sphere, N = {n}",
                   filename=out[0], overwrite=args.overwrite)
    if can_render():
        from manifold_sph.viz.render import render_panels

        out.append(args.out / "area_elements_sphere.png")
        render_panels(cloud, {f"dV {a}": v for a, v in dv.items()}, shared_clim=True, robust=1,
                      cmap="plasma", panel_size=(360, 360), filename=out[1], overwrite=args.overwrite)
    report(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
