"""``manifold-sph operators | convergence | poisson``: errors against the exact references of the built-in shapes."""

from __future__ import annotations

import json
import sys

import numpy as np

from .common import (
    FOUR_SCHEMES,
    SubParsers,
    UserError,
    add_common_options,
    add_picture_options,
    check_free,
    check_size,
    cloud_from_args,
    sizes_arg,
    surface_kwargs,
)
from .inputs import add_input, add_out, check_outputs

__all__ = ["add_parsers"]


def add_parsers(sub: SubParsers, schemes: list[str]) -> None:
    """Register ``operators``, ``convergence`` and ``poisson``."""
    ops = sub.add_parser("operators", help="errors of every scheme on one cloud")
    add_input(ops, optional=True, help="read the points from this file (they must lie on --shape) instead of sampling it")
    add_common_options(ops)
    ops.add_argument("--n", type=int, default=4032, help="number of points (default 4032)")
    ops.add_argument("--scheme", default="all", choices=["all", *schemes], help="'all': the four source schemes")

    conv = sub.add_parser("convergence", help="errors and fitted orders over several cloud sizes")
    add_common_options(conv)
    conv.add_argument("--sizes", type=sizes_arg, default=[1002, 2012, 4032, 8672, 15872, 32672])
    conv.add_argument("--scheme", default="msph", choices=schemes)
    add_out(conv, "a log-log plot of the errors", (".png", ".pdf", ".svg"))
    conv.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    ops.set_defaults(func=_cmd_operators)
    conv.set_defaults(func=_cmd_convergence)

    poi = sub.add_parser("poisson", help="solve Lap u = Lap f on a closed built-in shape and compare u with f")
    add_common_options(poi)
    poi.add_argument("--n", type=int, default=4032, help="number of points (default 4032)")
    poi.add_argument("--scheme", default="msph", choices=schemes)
    add_out(poi, "a picture rhs | exact u | SPH u | error")
    add_picture_options(poi)
    poi.set_defaults(func=_cmd_poisson)


def _attach_shape(cloud, shape_name: str, path: str):
    """The cloud with the exact shape ``shape_name`` attached, if its points lie on it."""
    from ..pointcloud import PointCloud
    from ..reference.shapes import SHAPES

    shape = SHAPES[shape_name]()
    x = cloud.points
    dist = float(np.abs(np.linalg.norm(shape.project(x) - x, axis=1)).max())
    ext = float(np.ptp(x, axis=0).max())
    if not dist <= 1e-6 * ext:
        raise UserError(
            f"the points of {path!r} do not lie on the default {shape_name} (largest distance {dist:.3g}); "
            "give the --shape they sample"
        )
    return PointCloud(x, cloud.normals, geometry=shape)


def _cmd_operators(args) -> int:
    from ..reference.accuracy import format_rows, operator_errors

    if args.file:
        cloud = _attach_shape(cloud_from_args(args), args.shape, args.file)
    else:
        cloud = cloud_from_args(args)
    schemes = list(FOUR_SCHEMES) if args.scheme == "all" else [args.scheme]
    rows = operator_errors(cloud, args.function, schemes, **surface_kwargs(args))
    if args.json:
        print(json.dumps({"shape": args.shape, "function": args.function, "rows": rows}, indent=2))
    else:
        print(f"{args.shape}, N = {len(cloud)}, f = {args.function}: relative errors against the exact operators")
        print(format_rows(rows))
    return 0


def _cmd_convergence(args) -> int:
    from tqdm import tqdm

    from ..reference.accuracy import convergence

    for n in args.sizes:
        check_size("--sizes", n)
    if args.out:
        check_free([args.out], args.overwrite)
    with tqdm(total=len(args.sizes), desc=f"{args.scheme} on {args.shape}", disable=args.json, file=sys.stderr) as bar:
        table = convergence(
            args.shape, args.sizes, args.scheme, args.function,
            sampling=args.sampling, seed=args.seed, progress=bar.update, **surface_kwargs(args),
        )
    if args.out:
        from ..viz.plots import convergence_plot

        convergence_plot(
            {args.scheme: table}, reference_order=2,
            title=f"{args.scheme} on {args.shape}, f = {args.function} (relative errors)",
            filename=args.out, overwrite=args.overwrite,
        )
    if args.json:
        print(json.dumps(table.to_dict(json=True), indent=2))
    else:
        print(f"{args.scheme} on {args.shape}, f = {args.function} (orders fitted against h ~ N^-1/2)")
        print(table.to_text())
        if args.out:
            print(f"wrote {args.out}")
    return 0


def _cmd_poisson(args) -> int:
    from .. import pde
    from ..reference.accuracy import exact_operators, get_function
    from ..reference.errors import l2_error, linf_error
    from ..surface import Surface

    check_outputs(args)
    cloud = cloud_from_args(args)
    s = Surface(cloud, scheme=args.scheme, **surface_kwargs(args))
    f, _, lap_ex = exact_operators(cloud, get_function(args.function))
    dV = s.dV
    rhs = lap_ex - np.dot(dV, lap_ex) / dV.sum()
    u = pde.poisson(s, rhs)
    ref = f - np.dot(dV, f) / dV.sum()
    summary = {
        "shape": args.shape, "n": int(s.n_points), "scheme": args.scheme, "function": args.function,
        "l2_rel_error": l2_error(u, ref), "linf_rel_error": linf_error(u, ref),
    }
    if args.out:
        from ..viz.render import render_comparison

        w, h = args.size or (300, 300)
        render_comparison(s, rhs, ref, u, names=("rhs", "exact u", "SPH u", "error"), camera=args.camera, up=args.up,
                          panel_size=(w, h), filename=args.out, overwrite=args.overwrite)
        summary["files"] = [str(args.out)]
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(
            f"poisson on {args.shape} (N = {summary['n']}, {args.scheme}), Lap u = Lap f with f = {args.function}: "
            f"relative error of u (zero mean) L2 {summary['l2_rel_error']:.3e}, Linf {summary['linf_rel_error']:.3e}"
        )
        for fl in summary.get("files", []):
            print(f"wrote {fl}")
    return 0
