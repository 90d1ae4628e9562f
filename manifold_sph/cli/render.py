"""``manifold-sph render``: a picture of a field on a point-cloud file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .common import UserError, add_picture_options, check_free, pair_arg

__all__ = ["add_parsers"]


def add_parsers(sub, schemes: list[str]) -> None:
    """Register ``render``."""
    ren = sub.add_parser("render", help="picture of a field on a point-cloud file")
    ren.add_argument("file", help="point cloud (ply, pcd, xyz, csv, obj, npy, npz, las, laz, e57, vtk)")
    ren.add_argument(
        "--field", default="z",
        help="a field stored in the file, a coordinate x/y/z, or a test function name (default z)",
    )
    ren.add_argument("--operator", default="none", choices=["none", "laplacian", "gradient"],
                     help="draw the SPH Laplacian of the field, or the field with its gradient as arrows")
    ren.add_argument("--scheme", default="msph", choices=schemes)
    ren.add_argument("--out", default=None, help="PNG file to write (default: FILE with the field name and .png)")
    ren.add_argument("--clim", type=pair_arg, default=None, help="colour limits LOW,HIGH")
    ren.add_argument("--robust", type=float, default=None, help="clip this percentage at each end of the colour range")
    ren.add_argument("--cmap", default="viridis", help="matplotlib colour map (default viridis)")
    ren.add_argument("--transparent", action="store_true", help="transparent background")
    ren.add_argument("--json", action="store_true", help="print what was written as JSON")
    add_picture_options(ren)
    ren.set_defaults(func=_cmd_render)


def _cmd_render(args) -> int:
    from ..reference.accuracy import SCALAR_FUNCTIONS, get_function
    from ..scans.io import read

    cloud, fields = read(args.file, return_fields=True)
    x = cloud.points
    name = args.field
    if name in fields and np.asarray(fields[name]).shape == (len(x),):
        values = np.asarray(fields[name], dtype=np.float64)
    elif name in ("x", "y", "z"):
        values = x[:, "xyz".index(name)]
    elif name in SCALAR_FUNCTIONS:
        values = get_function(name).value(x)
    else:
        stored = sorted(k for k, v in fields.items() if np.asarray(v).shape == (len(x),))
        raise UserError(
            f"--field {name!r} is neither a field of {args.file!r} (it has {stored}) nor x, y, z "
            f"nor a test function {list(SCALAR_FUNCTIONS)}"
        )
    out = Path(args.out) if args.out else Path(args.file).with_name(f"{Path(args.file).stem}_{name}_{args.operator}.png")
    check_free([out], args.overwrite)
    from ..viz.render import render_field, rendering_available

    ok, why = rendering_available()
    if not ok:
        raise RuntimeError(f"cannot render here: {why}")

    vectors, label = None, name
    if args.operator != "none":
        from ..surface import Surface

        s = Surface(cloud, scheme=args.scheme)
        if args.operator == "laplacian":
            values, label = s.laplacian(values), f"Lap {name}"
        else:
            vectors, cloud = s.gradient(values), s
    render_field(
        cloud, values, vectors=vectors, bar_title=label, camera=args.camera, window_size=args.size or (800, 600),
        clim=args.clim, robust=args.robust, cmap=args.cmap, transparent=args.transparent,
        filename=out, overwrite=args.overwrite,
    )
    if args.json:
        print(json.dumps({"file": str(out), "field": name, "operator": args.operator, "n": len(x)}))
    else:
        print(f"wrote {out}")
    return 0
