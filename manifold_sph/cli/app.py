"""The ``manifold-sph`` parser and entry point: each subcommand module registers its parsers."""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence

from . import demo, evolve, geometry, render, scan, spem, studies
from .common import STATE, Parser, error_json
from .inputs import notes

__all__ = ["build_parser", "main", "COMMANDS"]


#: The subcommands, in the order of ``manifold-sph --help``.
COMMANDS = ("demo", "operators", "convergence", "heat", "wave", "poisson", "render", "normals", "eigs", "curvature",
            "geodesic", "spem")


def build_parser() -> argparse.ArgumentParser:
    """The whole ``manifold-sph`` parser; every subcommand sets ``func`` (what runs it)."""
    from ..schemes import SCHEMES

    p = Parser(
        prog="manifold-sph",
        description="Consistent SPH operators on point-cloud surfaces: errors against exact references, PDEs, pictures.",
    )
    sub = p.add_subparsers(dest="command", required=True)
    schemes = sorted(SCHEMES)
    demo.add_parsers(sub)
    studies.add_parsers(sub, schemes)
    evolve.add_parsers(sub, schemes)
    render.add_parsers(sub, schemes)
    scan.add_parsers(sub, schemes)
    geometry.add_parsers(sub, schemes)
    spem.add_parsers(sub)
    return p


def value_options(parser: argparse.ArgumentParser) -> set[str]:
    """Every ``--option`` of every subcommand that takes a value."""
    out: set[str] = set()
    todo = [parser]
    while todo:
        q = todo.pop()
        for action in q._actions:
            if isinstance(action, argparse._SubParsersAction):
                todo.extend(action.choices.values())
            elif action.option_strings and action.nargs != 0:
                out.update(o for o in action.option_strings if o.startswith("--"))
    return out


def join_negative_values(argv: list[str], options: set[str]) -> list[str]:
    """``--sizes -600,-1200`` -> ``--sizes=-600,-1200``: argparse takes a value starting with '-'
    that is not a plain number for an option and says "expected one argument"; joined, the
    option's own check names the problem.

    Examples
    --------
    >>> join_negative_values(["convergence", "--sizes", "-600,-1200"], {"--sizes"})
    ['convergence', '--sizes=-600,-1200']
    """
    out, i = [], 0
    while i < len(argv):
        tok = argv[i]
        if tok in options and i + 1 < len(argv) and re.match(r"^-[\d.]", argv[i + 1]):
            out.append(f"{tok}={argv[i + 1]}")
            i += 2
            continue
        out.append(tok)
        i += 1
    return out


#: Exceptions that are the user's mistake (exit code 2), the rest are failures (exit code 1).
USER_ERRORS = (ValueError, TypeError, FileNotFoundError, FileExistsError, IsADirectoryError, NotADirectoryError,
               PermissionError)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``manifold-sph`` console script.

    Examples
    --------
    >>> main(["operators", "--n", "5", "--json"])  # doctest: +ELLIPSIS
    {"error": "--n must be at least 10 points, got 5", "type": "UserError", "command": "operators", "exit_code": 2}
    2
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    STATE.json = "--json" in argv
    STATE.command = next((a for a in argv if not a.startswith("-")), None)
    STATE.command = STATE.command if STATE.command in COMMANDS else None
    parser = build_parser()
    args = parser.parse_args(join_negative_values(argv, value_options(parser)))
    command = args.command
    try:
        with notes():  # the library's warnings: one line each on stderr, each once
            return args.func(args)
    except USER_ERRORS as exc:
        code, kind, msg = 2, type(exc).__name__, " ".join(str(exc).split())
        print(f"manifold-sph: error: {msg}", file=sys.stderr)
    except MemoryError as exc:
        code, kind = 1, "MemoryError"
        msg = ("ran out of memory" + (f" ({' '.join(str(exc).split())})" if str(exc) else "")
               + "; try smaller sizes (--n, --sizes, or the case's resolution options)")
        print(f"manifold-sph: failed: MemoryError: {msg}", file=sys.stderr)
    except Exception as exc:  # noqa: BLE001 - one line for the user, exit code 1
        code, kind, msg = 1, type(exc).__name__, " ".join(str(exc).split())
        print(f"manifold-sph: failed: {kind}: {msg}", file=sys.stderr)
    if getattr(args, "json", False):
        error_json(msg, kind, command, code)
    return code
