"""Geometry of a range scan from its points alone: mean curvature and geodesic distance.

    python examples/scan_geometry.py --out pictures [--scan PATH] [--quick]

By default the Stanford bunny's vertices from the workspace's shared scans
(``../shared/data/scans/stanford-bunny.obj``, faces ignored, normals estimated,
as a scanner would deliver it). Without that file, or with --quick, a torus
(R = 0.8, r = 0.2, Poisson-disk points, normals estimated as well), whose exact
mean curvature is known and printed beside the SPH one.

The mean curvature ``H = (k1 + k2) / 2`` comes from the tangential gradient of
the normals (estimated by jet fits; :meth:`manifold_sph.Surface.mean_curvature`,
``method="auto"``; ``method="laplacian"`` takes it from ``Lap_S x = -2 H n``); the
geodesic distance from one particle (the highest one of a scan, up as guessed by
:func:`manifold_sph.viz.render.detect_up_axis`: the tip of the bunny's ear; a point on the
torus' outer equator) by wavefront propagation (:meth:`manifold_sph.Surface.geodesic_distance`).
Writes ``scan_geometry_mean_curvature.png`` and ``scan_geometry_geodesic.png``
when off-screen rendering works (curvature coloured over its 2nd-98th percentiles:
a scan has a few extreme values at creases and holes), and always
``scan_geometry_histograms.png`` (histograms of both fields).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from _common import can_render, parse, report

from manifold_sph import Surface, read
from manifold_sph.reference import shapes
from manifold_sph.viz.plots import save_figure
from manifold_sph.viz.render import detect_up_axis

BUNNY = Path(__file__).resolve().parents[2] / "shared" / "data" / "scans" / "stanford-bunny.obj"


def main(argv=None) -> int:
    args = parse(argv, __doc__.splitlines()[0], **{"--scan": {"default": None, "help": "point cloud file (default: the bunny)"}})
    exact_H = None
    if args.scan is not None:
        path = Path(args.scan)
        points, name = read(path, normals="none").points, path.name
    elif BUNNY.exists() and not args.quick:
        points, name = read(BUNNY, normals="none").points, "Stanford bunny"
    else:
        torus = shapes.torus(1500 if args.quick else 8000, seed=0)
        points, name = torus.points, "torus"
        exact_H = 0.5 * torus.geometry.mean_curvature(points)  # the shapes give the sum k1 + k2
    t0 = time.perf_counter()
    s = Surface(points, scheme="msph")  # no normals given: estimated (and oriented) from the points
    H = s.mean_curvature()  # "auto": half the trace of the shape operator (the normals' gradient)
    t1 = time.perf_counter()
    p = s.points
    extent = np.ptp(p, axis=0)
    # the source: the highest particle of a scan (the tip of the bunny's ear), on the torus the outermost in +x
    up = 0 if exact_H is not None else "xyz".index(detect_up_axis(p))
    source = int(np.argmax(p[:, up]))
    d = s.geodesic_distance(source)
    t2 = time.perf_counter()
    lo, med, hi = np.percentile(H, [2, 50, 98])
    print(f"{name}: {len(p)} points, size {extent.max():.3g}; normals estimated; Surface and mean curvature "
          f"{t1 - t0:.2f} s")
    print(f"mean curvature H: 2nd percentile {lo:.4g}, median {med:.4g}, 98th percentile {hi:.4g} "
          f"(full range {H.min():.4g} to {H.max():.4g})")
    if exact_H is not None:
        err = np.linalg.norm(H - exact_H) / np.linalg.norm(exact_H)
        print(f"relative L2 error of H against the torus' exact mean curvature: {err:.3e}")
    reached = np.isfinite(d)
    print(f"geodesic distance from particle {source}: max {d[reached].max():.4g}, "
          f"{int((~reached).sum())} particle(s) unreached; {t2 - t1:.2f} s")

    out = []
    fig_path = args.out / "scan_geometry_histograms.png"
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9.0, 3.6), layout="constrained")
    ax1, ax2 = fig.subplots(1, 2)
    ax1.hist(np.clip(H, lo, hi), bins=60, color="tab:red", alpha=0.8)
    ax1.set(title=f"mean curvature H, {name} (2-98 %)", xlabel="H", ylabel="particles")
    ax2.hist(d[reached], bins=60, color="tab:blue", alpha=0.8)
    ax2.set(title=f"geodesic distance from particle {source}", xlabel="distance", ylabel="particles")
    out.append(save_figure(fig, fig_path, overwrite=args.overwrite))
    if can_render():
        from manifold_sph.viz.render import render_field

        size = (360, 300) if args.quick else (700, 600)
        out.append(args.out / "scan_geometry_mean_curvature.png")
        render_field(s, H, robust=2, cmap="coolwarm", bar_title="H", title=f"mean curvature, {name}",
                     window_size=size, filename=out[-1], overwrite=args.overwrite)
        out.append(args.out / "scan_geometry_geodesic.png")
        render_field(p[reached], d[reached], bar_title="distance", title=f"geodesic distance from particle {source}",
                     window_size=size, filename=out[-1], overwrite=args.overwrite)
    report(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
