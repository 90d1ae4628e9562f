"""``manifold-sph render``: a picture of a field on a point-cloud file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .common import SubParsers, UserError, add_picture_options
from .inputs import (
    add_colour_options,
    add_input,
    add_out,
    add_save,
    add_surface_options,
    build_surface,
    check_outputs,
    draw,
    progress,
    read_input,
    save_values,
)

__all__ = ["add_parsers"]


def add_parsers(sub: SubParsers, schemes: list[str]) -> None:
    """Register ``render``."""
    ren = sub.add_parser("render", help="picture of a field on a point-cloud file")
    add_input(ren)
    ren.add_argument(
        "--field", default="z",
        help="a field stored in the file, a coordinate x/y/z, or a test function name (default z)",
    )
    ren.add_argument("--operator", default="none", choices=["none", "laplacian", "gradient"],
                     help="draw the SPH Laplacian of the field, or the field with its gradient as arrows")
    add_surface_options(ren, schemes)
    add_out(ren, "the picture (default: FILE with the field name and .png)")
    add_save(ren, "the values drawn (the Laplacian with --operator laplacian, the gradient with gradient)")
    add_colour_options(ren)
    ren.add_argument("--transparent", action="store_true", help="transparent background")
    ren.add_argument("--json", action="store_true", help="print what was written as JSON")
    add_picture_options(ren)
    ren.set_defaults(func=_cmd_render)


def _cmd_render(args) -> int:
    from ..reference.accuracy import SCALAR_FUNCTIONS, get_function

    if not args.out:
        args.out = str(Path(args.file).with_name(f"{Path(args.file).stem}_{args.field}_{args.operator}.png"))
    check_outputs(args)
    steps = 3 + (2 if args.operator != "none" else 0)
    with progress(args, steps, "render") as bar:
        cloud, fields = read_input(args, bar)
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
        vectors, label, shown = None, name, cloud
        if args.operator != "none":
            s, _ = build_surface(args, cloud, bar)
            shown = s
            if args.operator == "laplacian":
                values, label = s.laplacian(values), f"Lap {name}"
            else:
                vectors = s.gradient(values)
        bar.step("values")
        saved = save_values(args, shown, {label if vectors is None else f"grad {name}": values if vectors is None else vectors})
        bar.update()
        bar.step("picture")
        draw(args, shown, values, title=f"{label}, {Path(args.file).name}", name=label, vectors=vectors,
             transparent=args.transparent)
        bar.update()
    if args.json:
        print(json.dumps({"file": str(args.out), "field": name, "operator": args.operator, "n": len(x),
                          **({"save": saved} if saved else {})}))
    else:
        print(f"wrote {args.out}")
        if saved:
            print(f"wrote {saved}")
    return 0
