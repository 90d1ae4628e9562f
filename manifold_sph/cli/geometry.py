"""``manifold-sph curvature | geodesic``: the geometry of a point-cloud file."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from .common import UserError, add_picture_options, check_free, pair_arg, percent_arg, positive_int_arg

__all__ = ["add_parsers"]


def add_parsers(sub, schemes: list[str]) -> None:
    """Register ``curvature`` and ``geodesic``."""
    from ..geometry import CURVATURE_METHODS

    def geometry(q):
        q.add_argument("file", help="point cloud (ply, pcd, xyz, csv, obj, npy, npz, las, laz, e57, vtk); its normals are used "
                                    "if it has them, else estimated")
        q.add_argument("--scheme", default="msph", choices=schemes)
        q.add_argument("--neighbors", type=positive_int_arg, default=None, help="mean neighbour count (default: the scheme's)")
        q.add_argument("--png", default=None, help="also render the field, off-screen, to this PNG file")
        q.add_argument("--clim", type=pair_arg, default=None, help="colour limits LOW,HIGH of the picture")
        q.add_argument("--cmap", default=None, help="matplotlib colour map of the picture")
        q.add_argument("--json", action="store_true", help="print the summary as JSON")
        add_picture_options(q)

    cur = sub.add_parser("curvature", help="mean, Gaussian or principal curvature of a point-cloud file")
    geometry(cur)
    cur.add_argument("--quantity", default="mean", choices=["mean", "gaussian", "k1", "k2"],
                     help="mean H = (k1 + k2) / 2, Gaussian K = k1 k2, or a principal curvature k1 >= k2 (default mean)")
    cur.add_argument("--method", default=None, choices=CURVATURE_METHODS,
                     help="for --quantity mean: from the normals' gradient or the Laplacian of the coordinates "
                          "(default auto: the normals' gradient, the more accurate with the jet-fitted normals estimated here)")
    cur.add_argument("--robust", type=percent_arg, default=2.0,
                     help="clip this percentage at each end of the colour range (default 2; 0: full range)")

    geo = sub.add_parser("geodesic", help="geodesic distance from particles of a point-cloud file (heat method)")
    geometry(geo)
    geo.add_argument("--source", type=int, action="append", required=True, metavar="I",
                     help="index of a source particle (0-based); repeat for several sources")
    geo.add_argument("--robust", type=percent_arg, default=0.0,
                     help="clip this percentage at each end of the colour range (default 0: full range)")
    cur.set_defaults(func=_cmd_curvature)
    geo.set_defaults(func=_cmd_geodesic)


def _png_target(args):
    """The --png file, checked before any work: a .png in an existing folder, free unless --overwrite,
    and off-screen rendering available. ``None`` without --png."""
    if not args.png:
        return None
    out = Path(args.png)
    if out.suffix.lower() != ".png":
        raise UserError(f"--png must name a .png file, got {args.png!r}")
    if not out.parent.is_dir():
        raise UserError(f"--png {args.png!r}: the folder {str(out.parent)!r} does not exist")
    check_free([out], args.overwrite)
    from ..viz.render import rendering_available

    ok, why = rendering_available()
    if not ok:
        raise RuntimeError(f"cannot render here: {why}")
    return out


def _geometry_surface(args, cloud, bar):
    """The Surface of the file's cloud (its normals if it has them, else estimated by Surface)."""
    from ..surface import Surface

    s = Surface(cloud, scheme=args.scheme, neighbors=args.neighbors)
    bar.update()
    return s


def _stats(values) -> dict:
    v = np.asarray(values, dtype=np.float64)
    return {"min": float(v.min()), "median": float(np.median(v)), "max": float(v.max())}


def _render_geometry(args, out, points, values, title, bar_title, cmap):
    from ..viz.render import render_field

    render_field(
        points, values, title=title, bar_title=bar_title, camera=args.camera, window_size=args.size or (800, 600),
        clim=args.clim, robust=args.robust or None, cmap=args.cmap or cmap, filename=out, overwrite=args.overwrite,
    )


def _cmd_curvature(args) -> int:
    from tqdm import tqdm

    from ..geometry import curvature_method
    from ..scans.io import read

    if args.method is not None and args.quantity != "mean":
        raise UserError(f"--method applies to --quantity mean only (Gaussian and principal curvatures always come "
                        f"from the normals' gradient), got --quantity {args.quantity}")
    out = _png_target(args)
    t0 = time.perf_counter()
    cloud = read(args.file)
    with tqdm(total=3 if out else 2, desc="curvature", disable=args.json, file=sys.stderr) as bar:
        s = _geometry_surface(args, cloud, bar)
        method = None
        if args.quantity == "mean":
            method = curvature_method(s, args.method or "auto")
            values = s.mean_curvature(method)
        elif args.quantity == "gaussian":
            values = s.gaussian_curvature()
        else:
            k1, k2, _, _ = s.principal_curvatures()
            values = k1 if args.quantity == "k1" else k2
        bar.update()
        if not np.all(np.isfinite(values)):
            raise RuntimeError(f"{int((~np.isfinite(values)).sum())} curvature value(s) are not finite")
        seconds = time.perf_counter() - t0
        if out:
            label = {"mean": "H", "gaussian": "K", "k1": "k1", "k2": "k2"}[args.quantity]
            _render_geometry(args, out, s, values, f"{args.quantity} curvature {label} ({args.scheme}), "
                             f"{Path(args.file).name}", label, "coolwarm")
            bar.update()
    summary = {
        "command": "curvature", "file": str(args.file), "n": int(s.n_points), "scheme": args.scheme,
        "quantity": args.quantity, "method": method, "normals_estimated": bool(s.normals_estimated),
        **_stats(values), "seconds": round(seconds, 3),
    }
    if out:
        summary["png"] = str(out)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        normals = "normals estimated" if s.normals_estimated else "normals from the file"
        how = {"normals": ", from the normals' gradient", "laplacian": ", from the Laplacian of x"}.get(method, "")
        print(f"{args.quantity} curvature of {args.file} (N = {summary['n']}, {args.scheme}, {normals}{how}): "
              f"min {summary['min']:.4g}, median {summary['median']:.4g}, max {summary['max']:.4g} "
              f"({seconds:.2f} s)")
        if out:
            print(f"wrote {out}")
    return 0


def _cmd_geodesic(args) -> int:
    from tqdm import tqdm

    from ..scans.io import read

    out = _png_target(args)
    t0 = time.perf_counter()
    cloud = read(args.file)
    n = len(cloud)
    bad = [i for i in args.source if not 0 <= i < n]  # checked before the Surface is built
    if bad:
        raise UserError(f"--source {bad[0]} is out of range: {args.file!r} has {n} points, indices 0 to {n - 1}")
    with tqdm(total=3 if out else 2, desc="geodesic", disable=args.json, file=sys.stderr) as bar:
        s = _geometry_surface(args, cloud, bar)
        d = s.geodesic_distance(np.asarray(args.source, dtype=np.int64))
        bar.update()
        seconds = time.perf_counter() - t0
        reached = np.isfinite(d)
        if out:
            src = ", ".join(str(i) for i in sorted(set(args.source)))
            title = f"geodesic distance from {src} ({args.scheme}), {Path(args.file).name}"
            if not reached.all():
                title += f"; {int((~reached).sum())} unreached not drawn"
            _render_geometry(args, out, s.points[reached], d[reached], title, "distance", "viridis")
            bar.update()
    summary = {
        "command": "geodesic", "file": str(args.file), "n": int(s.n_points), "scheme": args.scheme,
        "sources": sorted(set(args.source)), "normals_estimated": bool(s.normals_estimated),
        "max": float(d[reached].max()), "mean": float(d[reached].mean()),
        "unreached": int((~reached).sum()), "seconds": round(seconds, 3),
    }
    if out:
        summary["png"] = str(out)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        srcs = ", ".join(str(i) for i in summary["sources"])
        print(f"geodesic distance on {args.file} (N = {summary['n']}, {args.scheme}) from particle(s) {srcs}: "
              f"max {summary['max']:.4g}, mean {summary['mean']:.4g} ({seconds:.2f} s)")
        if summary["unreached"]:
            print(f"{summary['unreached']} particle(s) lie in pieces of the cloud without a source (distance inf)")
        if out:
            print(f"wrote {out}")
    return 0
