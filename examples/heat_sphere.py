"""Heat equation on the sphere from a hot spot at the north pole ([1] Fig. 51; docs/method.md), as a GIF.

    python examples/heat_sphere.py --out pictures [--quick] [--mp4]

CSPM Laplacian, Crank-Nicolson steps. Writes ``heat_sphere.gif`` (and ``.mp4``
with --mp4, which needs imageio-ffmpeg) and the final state as a PNG; prints the
total heat, which diffusion conserves up to the scheme's error.
"""

import numpy as np
from _common import can_render, parse, report

from manifold_sph import Surface, pde
from manifold_sph.reference import shapes


def main(argv=None) -> int:
    args = parse(argv, __doc__.splitlines()[0], **{"--mp4": {"action": "store_true", "help": "also write an MP4"}})
    n = 1002 if args.quick else 4032
    steps = 20 if args.quick else 120
    cloud = shapes.sphere(n)
    s = Surface(cloud, scheme="cspm")
    x = cloud.points
    u0 = np.exp(-np.sum((x - [0.0, 0.0, 1.0]) ** 2, axis=1) / (2 * 0.2**2))
    frames = 5 if args.quick else 30  # GIF frames (the smoke test renders few)
    res = pde.heat(s, u0, dt=0.005, steps=steps, method="crank-nicolson", every=max(1, steps // frames))
    total0, total1 = float(s.dV @ res.snapshots[0]), float(s.dV @ res.snapshots[-1])
    print(f"N = {n}, {steps} steps of 0.005: total heat {total0:.5f} -> {total1:.5f}; max {u0.max():.3f} -> {res.u.max():.3f}")
    out = []
    if can_render():
        from manifold_sph.viz.render import animate, render_field

        out.append(animate(s, res, args.out / "heat_sphere.gif", title="heat equation (CSPM)", bar_title="u",
                           camera="equator", window_size=(360, 320), clim=(0, 1), overwrite=args.overwrite))
        if args.mp4:
            out.append(animate(s, res, args.out / "heat_sphere.mp4", title="heat equation (CSPM)", bar_title="u",
                               camera="equator", window_size=(480, 400), clim=(0, 1), overwrite=args.overwrite))
        out.append(args.out / "heat_sphere_final.png")
        render_field(s, res.u, camera="equator", bar_title="u", title=f"t = {res.times[-1]:.3g}",
                     window_size=(400, 360), filename=out[-1], overwrite=args.overwrite)
    report(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
