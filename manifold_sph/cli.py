"""The ``manifold-sph`` command line.

Exit codes: 0 success, 1 failure while computing, 2 a user mistake (reported
in one line, without a traceback).
"""

from __future__ import annotations

import argparse
import json
import sys

__all__ = ["main"]


def _sizes(text: str) -> list[int]:
    try:
        sizes = [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sizes must be comma-separated integers, got {text!r}") from None
    if len(sizes) < 2:
        raise argparse.ArgumentTypeError(f"--sizes needs at least two sizes, got {text!r}")
    return sizes


def _parser() -> argparse.ArgumentParser:
    from .accuracy import SCALAR_FUNCTIONS, SHAPES
    from .schemes import SCHEMES

    p = argparse.ArgumentParser(
        prog="manifold-sph",
        description="Consistent SPH operators on point-cloud surfaces: errors against exact references.",
    )
    sub = p.add_subparsers(dest="command", required=True)

    def common(q):
        q.add_argument("--shape", default="sphere", choices=sorted(SHAPES), help="built-in surface (default sphere)")
        q.add_argument("--function", default="cos_xz_sin_y", choices=SCALAR_FUNCTIONS, help="test function")
        q.add_argument("--sampling", default=None, help="sampling of the shape (default: its near-uniform one)")
        q.add_argument("--seed", type=int, default=0, help="random seed of the sampling")
        q.add_argument("--neighbors", type=int, default=27, help="mean neighbour count (default 27)")
        q.add_argument("--kernel", default="quintic", help="kernel (default quintic)")
        q.add_argument("--area", default="numerical", choices=["numerical", "geometric", "shepard"])
        q.add_argument("--json", action="store_true", help="print JSON instead of a table")

    ops = sub.add_parser("operators", help="errors of every scheme on one cloud")
    common(ops)
    ops.add_argument("--n", type=int, default=4032, help="number of points (default 4032)")
    ops.add_argument("--scheme", default="all", choices=["all", *sorted(SCHEMES)])

    conv = sub.add_parser("convergence", help="errors and fitted orders over several cloud sizes")
    common(conv)
    conv.add_argument("--sizes", type=_sizes, default=[1002, 2012, 4032, 8672, 15872, 32672])
    conv.add_argument("--scheme", default="cspm", choices=sorted(SCHEMES))
    return p


def _run(args) -> int:
    from .accuracy import convergence, format_rows, make_cloud, operator_errors

    kw = dict(neighbors=args.neighbors, kernel=args.kernel, area=args.area)
    if args.command == "operators":
        cloud = make_cloud(args.shape, args.n, args.sampling, args.seed)
        schemes = None if args.scheme == "all" else [args.scheme]
        rows = operator_errors(cloud, args.function, schemes, **kw)
        if args.json:
            print(json.dumps({"shape": args.shape, "function": args.function, "rows": rows}, indent=2))
        else:
            print(f"{args.shape}, N = {args.n}, f = {args.function}: relative errors against the exact operators")
            print(format_rows(rows))
        return 0
    if args.command == "convergence":
        from tqdm import tqdm

        with tqdm(total=len(args.sizes), desc=f"{args.scheme} on {args.shape}", disable=args.json, file=sys.stderr) as bar:
            table = convergence(
                args.shape, args.sizes, args.scheme, args.function,
                sampling=args.sampling, seed=args.seed, progress=bar.update, **kw,
            )
        if args.json:
            print(json.dumps(table.to_dict(), indent=2))
        else:
            print(f"{args.scheme} on {args.shape}, f = {args.function} (orders fitted against h ~ N^-1/2)")
            print(table.to_text())
        return 0
    raise AssertionError(args.command)  # pragma: no cover - argparse enforces the choices


def main(argv=None) -> int:
    """Entry point of the ``manifold-sph`` console script."""
    args = _parser().parse_args(argv)
    try:
        return _run(args)
    except (ValueError, TypeError) as exc:
        print(f"manifold-sph: error: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 - one line for the user, exit code 1
        print(f"manifold-sph: failed: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
