"""Shared command-line handling of the examples: ``python examples/NAME.py --out DIR [--quick] [--overwrite]``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def parse(argv, description: str, **extra) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--out", required=True, help="folder for the pictures (created if missing)")
    p.add_argument("--quick", action="store_true", help="small clouds and few steps (smoke test)")
    p.add_argument("--overwrite", action="store_true", help="replace existing pictures")
    for flag, kw in extra.items():
        p.add_argument(flag, **kw)
    args = p.parse_args(argv)
    args.out = Path(args.out)
    args.out.mkdir(parents=True, exist_ok=True)
    return args


def can_render() -> bool:
    """True when off-screen 3D rendering works; otherwise says why on stderr (plots are still made)."""
    from manifold_sph.viz.render import rendering_available

    ok, why = rendering_available()
    if not ok:
        print(f"note: skipping 3D pictures ({why})", file=sys.stderr)
    return ok


def report(paths) -> None:
    for p in paths:
        print(f"wrote {p}")
