"""``manifold-sph spem CASE``: the SPEM validation cases (:mod:`manifold_sph.spem.cli`) with the CLI's JSON errors."""

from __future__ import annotations

import contextlib
import io
import re
import sys

from .common import SubParsers, UserError, error_json

__all__ = ["add_parsers"]


def add_parsers(sub: SubParsers) -> None:
    """Register ``spem`` (its options are defined by :func:`manifold_sph.spem.cli.add_parser`)."""
    from ..spem.cli import add_parser

    add_parser(sub).set_defaults(func=_cmd_spem)


def _cmd_spem(args) -> int:
    """``spem CASE``: picture targets checked before the run; with --json, a failure reported by the
    SPEM command (one line on stderr) is also printed as the JSON error object."""
    from ..spem.cli import run

    for option in ("png", "gif"):
        target = getattr(args, option, None)
        if target:
            try:
                from .._validation import check_output_path

                check_output_path(f"--{option}", target, args.overwrite, hint="--overwrite")
            except (IsADirectoryError, FileNotFoundError, FileExistsError) as exc:
                raise UserError(str(exc)) from None
    if not args.json:
        return run(args)
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = run(args)
    text = err.getvalue()
    sys.stderr.write(text)
    if code != 0:
        lines = [ln for ln in text.splitlines() if ln.strip()]
        message = re.sub(r"^manifold-sph( spem)?: error: ", "", lines[-1]) if lines else f"spem {args.case} failed"
        error_json(message, "UserError" if code == 2 else "Error", "spem", code)
    return code
