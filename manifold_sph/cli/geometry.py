"""``manifold-sph curvature | geodesic | transport | logmap | smooth``: the geometry of a point-cloud file."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from .common import (
    SubParsers,
    UserError,
    add_picture_options,
    check_free,
    pair_arg,
    percent_arg,
    positive_int_arg,
    xyz_arg,
)
from .inputs import SAVE_SUFFIXES, add_input, add_surface_options, draw, save_values

__all__ = ["add_parsers"]


def _scale_arg(text: str):
    if text == "auto":
        return "auto"
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"expected a positive length or 'auto', got {text!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"expected a positive length or 'auto', got {text!r}")
    return value


def _vector_arg(text: str) -> np.ndarray:
    parts = text.split(",")
    try:
        v = np.array([float(p) for p in parts])
    except ValueError:
        raise ValueError(f"expected three numbers X,Y,Z, got {text!r}") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"expected three finite numbers X,Y,Z, got {text!r}")
    return v


_scale_arg.__name__ = "length or 'auto'"
_vector_arg.__name__ = "vector X,Y,Z"


def add_parsers(sub: SubParsers, schemes: list[str]) -> None:
    """Register ``curvature``, ``geodesic``, ``transport``, ``logmap`` and ``smooth``."""
    from ..geometry import CURVATURE_METHODS, GEODESIC_METHODS, SMOOTH_METHODS

    def common(q, scheme=True, picture=True):
        add_input(q)  # the file, --duplicates
        if scheme:
            add_surface_options(q, schemes)  # --scheme, --neighbors, --area, --h
        q.add_argument("--save", default=None, help="save the per-point result: .npy (the array) or the cloud with the "
                                                   "result as a field (ply, vtp, vtk, npz, csv, ...)")
        if picture:
            q.add_argument("--out", default=None, help="also render the field, off-screen, to this PNG file")
            q.add_argument("--clim", type=pair_arg, default=None, help="colour limits LOW,HIGH of the picture")
            q.add_argument("--cmap", default=None, help="matplotlib colour map of the picture")
            add_picture_options(q)
        else:
            q.add_argument("--overwrite", action="store_true", help="replace existing output files")
        q.add_argument("--json", action="store_true", help="print the summary as JSON")

    def source(q, many):
        where = q.add_mutually_exclusive_group(required=True) if many else q
        where.add_argument("--source", type=int, action="append" if many else "store", required=not many, metavar="I",
                           help="index of a source particle (0-based)" + ("; repeat for several sources" if many else ""))
        if many:
            where.add_argument("--boundary", action="store_true",
                               help="the distance from the cloud's open boundary (instead of --source)")
            where.add_argument("--source-xyz", type=xyz_arg, action="append", metavar="X,Y,Z",
                               help="the particle nearest to this point as a source; repeat for several")
        q.add_argument("--to", type=int, action="append", default=None, metavar="J",
                       help="print the result at these particles (repeat)")

    cur = sub.add_parser("curvature", help="mean, Gaussian or principal curvature of a point-cloud file")
    common(cur)
    cur.add_argument("--quantity", default="mean", choices=["mean", "gaussian", "k1", "k2"],
                     help="mean H = (k1 + k2) / 2, Gaussian K = k1 k2, or a principal curvature k1 >= k2 (default mean)")
    cur.add_argument("--method", default=None, choices=CURVATURE_METHODS,
                     help="pointwise --quantity mean: from the normals' gradient or the Laplacian of the coordinates "
                          "(default auto: the normals' gradient)")
    cur.add_argument("--scale", type=_scale_arg, default=None,
                     help="curvature at this length (quadrics fitted over that radius), or 'auto' (a radius chosen "
                          "per particle from the noise): for noisy scans (default: pointwise)")
    cur.add_argument("--robust", type=percent_arg, default=None,
                     help="clip this percentage at each end of the colour range (0: full range; default: 2-98 %% "
                          "narrowed for heavy tails)")

    geo = sub.add_parser("geodesic", help="geodesic distance from particles (or the boundary) of a point-cloud file")
    common(geo)
    source(geo, many=True)
    geo.add_argument("--method", default="wavefront", choices=GEODESIC_METHODS,
                     help="wavefront propagation over the local Delaunay triangles (default), or the heat method")
    geo.add_argument("--denoise", default="auto", choices=("auto", "yes", "no"),
                     help="wavefront: measure over the cloud smoothed onto its local quadrics (auto: when the cloud "
                          "reads noisy, default)")
    geo.add_argument("--robust", type=percent_arg, default=None,
                     help="clip this percentage at each end of the colour range (0: full range; default: 2-98 %% "
                          "narrowed for heavy tails)")

    tra = sub.add_parser("transport", help="parallel transport of a tangent vector from a particle (vector heat method)")
    common(tra, picture=False)
    source(tra, many=False)
    tra.add_argument("--vector", type=_vector_arg, required=True, help="the vector X,Y,Z at the source (projected to its tangent plane)")

    log = sub.add_parser("logmap", help="logarithmic map at a particle: 2-D coordinates in its tangent frame")
    common(log, picture=False)
    source(log, many=False)

    smo = sub.add_parser("smooth", help="smooth (denoise) a point-cloud file")
    add_input(smo, help="point cloud to smooth")
    smo.add_argument("--save", required=True, help="the smoothed cloud's file")
    smo.add_argument("--method", default="jet", choices=SMOOTH_METHODS,
                     help="jet: onto local quadrics (default); flow: implicit mean-curvature flow")
    smo.add_argument("--scale", type=float, default=None, help="length over which noise is removed (default 4 spacings for jet)")
    smo.add_argument("--iterations", type=positive_int_arg, default=3, help="passes (default 3)")
    smo.add_argument("--features", action=argparse.BooleanOptionalAction, default=True,
                     help="robust fits that keep sharp edges, corners and thin parts (jet; default on)")
    smo.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    smo.add_argument("--json", action="store_true", help="print the summary as JSON")

    cur.set_defaults(func=_cmd_curvature)
    geo.set_defaults(func=_cmd_geodesic)
    tra.set_defaults(func=_cmd_transport)
    log.set_defaults(func=_cmd_logmap)
    smo.set_defaults(func=_cmd_smooth)


def _png_target(args):
    """The --out picture, checked before any work: a .png in an existing folder, free unless --overwrite,
    and off-screen rendering available. ``None`` without --out."""
    if not getattr(args, "out", None):
        return None
    out = Path(args.out)
    if out.suffix.lower() != ".png":
        raise UserError(f"--out must name a .png file, got {args.out!r}")
    if not out.parent.is_dir():
        raise UserError(f"--out {args.out!r}: the folder {str(out.parent)!r} does not exist")
    check_free([out], args.overwrite)
    from ..viz.render import rendering_available

    ok, why = rendering_available()
    if not ok:
        raise RuntimeError(f"cannot render here: {why}")
    return out


def _out_target(args):
    """The --save file, checked before any work (its folder exists; free unless --overwrite)."""
    if not getattr(args, "save", None):
        return None
    out = Path(args.save)
    if args.command != "smooth" and out.suffix.lower() not in SAVE_SUFFIXES:
        raise UserError(f"--save must name a {', '.join(SAVE_SUFFIXES)} file, got {args.save!r}")
    if not out.parent.is_dir():
        raise UserError(f"--save {args.save!r}: the folder {str(out.parent)!r} does not exist")
    check_free([out], args.overwrite)
    return out


def _read(args):
    from ..scans.io import read

    return read(args.file, duplicates=args.duplicates)


def _check_indices(args, n, *names):
    for name in names:
        value = getattr(args, name, None)
        if value is None:
            continue
        for i in np.atleast_1d(value):
            if not 0 <= int(i) < n:
                raise UserError(f"--{name} {int(i)} is out of range: {args.file!r} has {n} points, indices 0 to {n - 1}")


def _geometry_surface(args, cloud, bar):
    """The Surface of the file's cloud (its normals if it has them, else estimated by Surface)."""
    from ..surface import Surface

    s = Surface(cloud, scheme=getattr(args, "scheme", "msph"), neighbors=getattr(args, "neighbors", None),
                area=getattr(args, "area", "numerical"), h=getattr(args, "h", None))
    bar.update()
    return s


def _stats(values) -> dict:
    v = np.asarray(values, dtype=np.float64)
    return {"min": float(v.min()), "median": float(np.median(v)), "max": float(v.max())}


def _render_geometry(args, out, points, values, title, bar_title):
    draw(args, points, values, title=title, name=bar_title, out=out, overwrite=True)  # the picture defaults


def _write_field(out, cloud_or_points, normals, name, values):
    import argparse

    from ..pointcloud import PointCloud

    target = argparse.Namespace(save=str(out), overwrite=True)  # checked free before any work
    save_values(target, PointCloud(cloud_or_points, normals), {name: values})


def _finish(args, summary, text, outs):
    for key, path in outs.items():
        if path is not None:
            summary[key] = str(path)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(text)
        for path in outs.values():
            if path is not None:
                print(f"wrote {path}")
    return 0


def _cmd_curvature(args) -> int:
    from tqdm import tqdm

    from ..geometry import curvature_method

    if args.method is not None and args.quantity != "mean":
        raise UserError(f"--method applies to --quantity mean only (Gaussian and principal curvatures always come "
                        f"from the normals' gradient), got --quantity {args.quantity}")
    if args.method == "laplacian" and args.scale is not None:
        raise UserError("--method laplacian is pointwise; --scale fits quadrics (drop one of them)")
    png, out = _png_target(args), _out_target(args)
    t0 = time.perf_counter()
    cloud = _read(args)
    with tqdm(total=3 if png else 2, desc="curvature", disable=args.json, file=sys.stderr) as bar:
        s = _geometry_surface(args, cloud, bar)
        method = None
        if args.quantity == "mean":
            method = curvature_method(s, args.method or "auto")
            values = s.mean_curvature(method, scale=args.scale)
        elif args.quantity == "gaussian":
            values = s.gaussian_curvature(scale=args.scale)
        else:
            k1, k2, _, _ = s.principal_curvatures(scale=args.scale)
            values = k1 if args.quantity == "k1" else k2
        bar.update()
        if not np.all(np.isfinite(values)):
            raise RuntimeError(f"{int((~np.isfinite(values)).sum())} curvature value(s) are not finite")
        seconds = time.perf_counter() - t0
        label = {"mean": "H", "gaussian": "K", "k1": "k1", "k2": "k2"}[args.quantity]
        if png:
            _render_geometry(args, png, s, values, f"{args.quantity} curvature {label} ({args.scheme}), "
                             f"{Path(args.file).name}", label)
            bar.update()
    if out:
        _write_field(out, s.points, s.normals, label, values)
    summary = {
        "command": "curvature", "file": str(args.file), "n": int(s.n_points), "scheme": args.scheme,
        "quantity": args.quantity, "method": method, "scale": args.scale, "normals_estimated": bool(s.normals_estimated),
        **_stats(values), "seconds": round(seconds, 3),
    }
    normals = "normals estimated" if s.normals_estimated else "normals from the file"
    how = {"normals": ", from the normals' gradient", "laplacian": ", from the Laplacian of x"}.get(method or "", "")
    if args.scale is not None:
        how = f", at scale {args.scale}" if args.scale != "auto" else ", at an automatic scale"
    text = (f"{args.quantity} curvature of {args.file} (N = {summary['n']}, {args.scheme}, {normals}{how}): "
            f"min {summary['min']:.4g}, median {summary['median']:.4g}, max {summary['max']:.4g} ({seconds:.2f} s)")
    return _finish(args, summary, text, {"out": png, "save": out})


_DENOISE: dict[str, bool | str] = {"auto": "auto", "yes": True, "no": False}


def _cmd_geodesic(args) -> int:
    import warnings

    from tqdm import tqdm

    from ..exceptions import ManifoldSPHWarning
    from ..geometry import GeodesicSolver

    png, out = _png_target(args), _out_target(args)
    t0 = time.perf_counter()
    cloud = _read(args)
    _check_indices(args, len(cloud), "source", "to")  # before any work
    if args.source_xyz:  # the particles nearest to these points
        from scipy.spatial import cKDTree

        nearest = np.atleast_1d(cKDTree(cloud.points).query(np.asarray(args.source_xyz))[1]).tolist()
        args.source = [*(args.source or []), *nearest]
    with tqdm(total=3 if png else 2, desc="geodesic", disable=args.json, file=sys.stderr) as bar:
        target = _geometry_surface(args, cloud, bar) if args.method == "heat" else cloud
        if args.method != "heat":
            bar.update()
        if args.denoise == "yes" and args.method == "heat":
            raise UserError("--denoise yes needs --method wavefront (for the heat method smooth the file first: "
                            "manifold-sph smooth)")
        solver = GeodesicSolver(target, method=args.method, denoise=_DENOISE[args.denoise])
        if args.boundary:
            if solver.boundary.size == 0:
                raise UserError(f"{args.file!r} has no open boundary (every particle's neighbourhood closes round it)")
            sources = solver.boundary
        else:
            sources = np.asarray(args.source, dtype=np.int64)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ManifoldSPHWarning)  # reported in the summary
            d = solver.distance(sources)
        bar.update()
        seconds = time.perf_counter() - t0
        reached = np.isfinite(d)
        if png:
            title = ("geodesic distance from the boundary" if args.boundary else
                     f"geodesic distance from {', '.join(str(i) for i in sorted(set(args.source)))}") + f", {Path(args.file).name}"
            _render_geometry(args, png, cloud, d, title, "distance")  # unreached (inf): dark grey, counted
            bar.update()
    if out:
        _write_field(out, cloud.points, cloud.normals, "distance", d)
    summary = {
        "command": "geodesic", "file": str(args.file), "n": len(cloud), "method": args.method,
        "sources": "boundary" if args.boundary else sorted(set(args.source)), "n_sources": int(np.unique(sources).size),
        "max": float(d[reached].max()), "mean": float(d[reached].mean()),
        "unreached": int((~reached).sum()), "pieces": int(solver.n_components), "seconds": round(seconds, 3),
    }
    if args.method == "wavefront":
        summary["noise"], summary["denoised"] = round(solver.noise, 4), solver.denoised
    if args.to:
        summary["to"] = {str(j): float(d[j]) for j in args.to}
    src = "the boundary" if args.boundary else "particle(s) " + ", ".join(str(i) for i in summary["sources"])
    how = args.method + (", denoised" if summary.get("denoised") else "")
    text = (f"geodesic distance on {args.file} (N = {summary['n']}, {how}) from {src}: "
            f"max {summary['max']:.4g}, mean {summary['mean']:.4g} ({seconds:.2f} s)")
    if args.to:
        text += "\n" + "\n".join(f"  to {j}: {v:.6g}" for j, v in summary["to"].items())
    if summary["unreached"]:
        text += (f"\n{summary['unreached']} particle(s) lie in pieces of the cloud without a source "
                 f"({summary['pieces']} pieces): distance inf")
    return _finish(args, summary, text, {"out": png, "save": out})


def _vector_heat(args, bar):
    from ..geometry import VectorHeatSolver

    cloud = _read(args)
    _check_indices(args, len(cloud), "source", "to")
    s = _geometry_surface(args, cloud, bar)
    return s, VectorHeatSolver(s)


def _cmd_transport(args) -> int:
    from tqdm import tqdm

    out = _out_target(args)
    t0 = time.perf_counter()
    with tqdm(total=2, desc="transport", disable=args.json, file=sys.stderr) as bar:
        s, vh = _vector_heat(args, bar)
        tangent = args.vector - (args.vector @ s.normals[args.source]) * s.normals[args.source]
        if not np.linalg.norm(tangent) > 0:
            raise UserError(f"--vector {args.vector.tolist()} is normal to the surface at particle {args.source}: "
                            "it has no tangent part to transport")
        Y = vh.transport(args.source, args.vector)
        bar.update()
    seconds = time.perf_counter() - t0
    if out:
        _write_field(out, s.points, s.normals, "vector", Y)
    summary = {"command": "transport", "file": str(args.file), "n": int(s.n_points), "source": args.source,
               "vector": tangent.tolist(), "seconds": round(seconds, 3)}
    if args.to:
        summary["to"] = {str(j): Y[j].tolist() for j in args.to}
    text = (f"parallel transport on {args.file} (N = {summary['n']}) of {np.round(tangent, 6).tolist()} from particle "
            f"{args.source} ({seconds:.2f} s)")
    if args.to:
        text += "\n" + "\n".join(f"  at {j}: {np.round(v, 6).tolist()}" for j, v in summary["to"].items())
    return _finish(args, summary, text, {"save": out})


def _cmd_logmap(args) -> int:
    from tqdm import tqdm

    out = _out_target(args)
    t0 = time.perf_counter()
    with tqdm(total=2, desc="logmap", disable=args.json, file=sys.stderr) as bar:
        s, vh = _vector_heat(args, bar)
        L = vh.log_map(args.source)
        bar.update()
    seconds = time.perf_counter() - t0
    if out:
        _write_field(out, s.points, s.normals, "logmap", np.where(np.isfinite(L), L, 0.0))
    r = np.linalg.norm(L, axis=1)
    summary = {"command": "logmap", "file": str(args.file), "n": int(s.n_points), "source": args.source,
               "frame": {"u": s.u[args.source].tolist(), "v": s.v[args.source].tolist()},
               "max_radius": float(np.nanmax(r)), "unreached": int(np.isnan(r).sum()), "seconds": round(seconds, 3)}
    if args.to:
        summary["to"] = {str(j): L[j].tolist() for j in args.to}
    text = (f"logarithmic map on {args.file} (N = {summary['n']}) at particle {args.source}: largest radius "
            f"{summary['max_radius']:.4g} ({seconds:.2f} s)")
    if args.to:
        text += "\n" + "\n".join(f"  {j}: {np.round(v, 6).tolist()}" for j, v in summary["to"].items())
    return _finish(args, summary, text, {"save": out})


def _cmd_smooth(args) -> int:
    from ..geometry import smooth

    if args.scale is not None and not (np.isfinite(args.scale) and args.scale > 0):
        raise UserError(f"--scale must be a positive length, got {args.scale}")
    out = _out_target(args)
    t0 = time.perf_counter()
    cloud = _read(args)
    res = smooth(cloud, method=args.method, scale=args.scale, iterations=args.iterations, features=args.features)
    from ..scans.io import write

    write(out, res, overwrite=True)  # checked free before any work
    moved = np.linalg.norm(res.points - cloud.points, axis=1)
    seconds = time.perf_counter() - t0
    summary = {"command": "smooth", "file": str(args.file), "n": len(cloud), "method": args.method,
               "features": bool(args.features), "iterations": args.iterations, "mean_move": float(moved.mean()),
               "max_move": float(moved.max()), "seconds": round(seconds, 3)}
    text = (f"smoothed {args.file} (N = {summary['n']}, {args.method}{', robust fits' if args.features and args.method == 'jet' else ''}): "
            f"points moved {summary['mean_move']:.4g} on average, at most {summary['max_move']:.4g} ({seconds:.2f} s)")
    return _finish(args, summary, text, {"save": out})
