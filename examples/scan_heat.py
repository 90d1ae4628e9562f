"""Heat flow on a real range scan: read, clean, estimate normals, find holes, diffuse.

    python examples/scan_heat.py --out pictures [--scan PATH] [--quick]

By default the Stanford bunny's vertices from the workspace's shared scans
(``../shared/data/scans/stanford-bunny.obj``, faces ignored, as a scanner would
deliver it). Without that file, or with --quick, a synthetic scan is made: a
sphere sampled at random, with a hole cut out, position noise and no normals.
The Laplacian is the standard (Taylor) one with Shepard area elements and
adaptive smoothing lengths: an M-matrix, so implicit heat obeys the maximum
principle (the printed range stays within [0, 1]); open boundaries act as
insulated (Neumann) walls. The initial state is a hot spot around the highest point. Writes ``scan_heat.png`` (snapshots) and
``scan_heat.gif`` when off-screen rendering works.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _common import can_render, parse, report

from manifold_sph import Surface, estimate_normals, pde, read
from manifold_sph.reference import shapes
from manifold_sph.scans.boundary import detect_boundary
from manifold_sph.scans.cleaning import clean

BUNNY = Path(__file__).resolve().parents[2] / "shared" / "data" / "scans" / "stanford-bunny.obj"


def synthetic_scan(n: int, seed: int = 0) -> np.ndarray:
    """A holey, noisy random sample of the unit sphere, without normals."""
    p = shapes.sphere(n, sampling="random", seed=seed).points
    p = p[p[:, 2] > -0.8]  # a hole around the south pole
    spacing = np.sqrt(4 * np.pi / n)
    return p + 0.1 * spacing * np.random.default_rng(seed + 1).standard_normal(p.shape)


def main(argv=None) -> int:
    args = parse(argv, __doc__.splitlines()[0], **{"--scan": {"default": None, "help": "point cloud file (default: the bunny)"}})
    if args.scan is not None:
        path = Path(args.scan)
        points, name = read(path, normals="none").points, path.name
    elif BUNNY.exists() and not args.quick:
        points, name = read(BUNNY, normals="none").points, BUNNY.name
    else:
        points, name = synthetic_scan(3000 if args.quick else 20000), "synthetic holey sphere"
    cleaned = clean(points)
    print(f"{name}: {len(points)} points\n" + cleaned.report)
    p = cleaned.points
    normals, confidence = estimate_normals(p, return_confidence=True)
    print(f"normals estimated; {int((confidence < 0.5).sum())} with confidence below 0.5")
    print(detect_boundary(p, normals).report)
    s = Surface(p, normals, scheme="standard", area="shepard", h="adaptive")

    extent = np.ptp(p, axis=0).max()
    top = p[np.argmax(p[:, 2])]  # a hot spot around the highest point
    u0 = np.exp(-np.sum((p - top) ** 2, axis=1) / (2 * (0.1 * extent) ** 2))
    dt = 1e-3 * extent**2
    steps = 20 if args.quick else 60
    res = pde.heat(s, u0, dt=dt, steps=steps, every=max(1, steps // 6))
    last = res.u
    print(f"implicit heat: {steps} steps of dt = {dt:.3g}; range [{last.min():.3g}, {last.max():.3g}] "
          f"(maximum principle: within [0, 1]); mean {np.dot(s.dV, last) / s.dV.sum():.4f}")

    out = []
    if can_render():
        from manifold_sph.viz.render import animate, render_panels

        fields = {f"t = {t:.3g}": u for t, u in list(zip(res.times, res.snapshots))[1::2]}
        png = args.out / "scan_heat.png"
        render_panels(p, fields, camera="iso", panel_size=(300, 280) if args.quick else (420, 380),
                      shared_clim=True, filename=png, overwrite=args.overwrite)
        out.append(png)
        if not args.quick:
            out.append(animate(p, res, args.out / "scan_heat.gif", fps=4, overwrite=args.overwrite))
    report(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
