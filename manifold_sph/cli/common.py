"""What every ``manifold-sph`` subcommand shares: errors, argument types, option groups, inputs and outputs."""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn, TypeAlias

if TYPE_CHECKING:
    from ..pointcloud import PointCloud


__all__ = ["FOUR_SCHEMES", "MAX_WINDOW", "BYTES_PER_POINT", "STATE", "UserError", "Parser", "SubParsers", "error_json",
           "check_size", "sizes_arg", "pair_arg", "window_arg", "positive_int_arg", "percent_arg", "h_arg", "xyz_arg",
           "up_arg", "add_common_options", "add_picture_options", "surface_kwargs", "cloud_from_args", "out_dir",
           "check_free", "render_ok"]


#: The four schemes of the thesis [1] (docs/method.md section 4) compared by ``demo`` and ``operators --scheme all``.
FOUR_SCHEMES = ("standard", "cspm", "msph", "ncsph")

#: Largest picture side in pixels (an off-screen VTK window of 100000 x 100000 aborts in std::bad_alloc).
MAX_WINDOW = 8192

#: A lower bound on the memory one particle takes while a Surface is built (measured: a
#: million-point cspm build peaks at 1.5 GB); sizes needing more than the machine's memory
#: are refused before any work.
BYTES_PER_POINT = 1024


@dataclass
class ParseState:
    """Whether the command line being parsed asked for ``--json`` (argument errors are then JSON
    too), and its first word (the subcommand, if it is one). Set by :func:`manifold_sph.cli.main`."""

    json: bool = False
    command: str | None = None


STATE = ParseState()


class UserError(ValueError):
    """A mistake in the command line or its inputs (exit code 2)."""


def error_json(message: str, kind: str, command: str | None, code: int) -> None:
    print(json.dumps({"error": message, "type": kind, "command": command, "exit_code": code}))


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one JSON object on stdout when ``--json`` was given."""

    def error(self, message: str) -> NoReturn:
        if STATE.json:
            words = self.prog.split()
            command = words[1] if len(words) > 1 else STATE.command
            error_json(" ".join(message.split()), "ArgumentError", command, 2)
        super().error(message)


#: What ``Parser.add_subparsers`` returns: each command module adds its subcommands to it
#: (a string, for type checkers: argparse's action class cannot be subscripted at run time).
SubParsers: TypeAlias = "argparse._SubParsersAction[Parser]"


def memory_bytes() -> int | None:
    """Physical memory of this machine in bytes, or None where it cannot be read."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def check_size(option: str, n: int) -> int:
    """Refuse, before any allocation, a cloud size below PointCloud's minimum or beyond memory."""
    from ..pointcloud import MIN_POINTS

    if n < MIN_POINTS:
        raise UserError(f"{option} must be at least {MIN_POINTS} points, got {n}")
    mem = memory_bytes()
    need = n * BYTES_PER_POINT
    if mem is not None and need > mem:
        raise UserError(
            f"{option} {n} needs at least {need / 2**30:.3g} GB of memory (about {BYTES_PER_POINT} bytes per point), "
            f"this machine has {mem / 2**30:.3g} GB"
        )
    return n


def sizes_arg(text: str) -> list[int]:
    try:
        sizes = [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sizes must be comma-separated integers, got {text!r}") from None
    if len(sizes) < 2:
        raise argparse.ArgumentTypeError(f"--sizes needs at least two sizes, got {text!r}")
    if min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"--sizes must be positive point counts, got {text!r}")
    return sizes


def pair_arg(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected two comma-separated numbers LOW,HIGH, got {text!r}") from None
    return lo, hi


def window_arg(text: str) -> tuple[int, int]:
    try:
        w, h = (int(t) for t in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size must be WIDTHxHEIGHT in pixels, e.g. 800x600, got {text!r}") from None
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"--size must be at least 16x16, got {text!r}")
    if w > MAX_WINDOW or h > MAX_WINDOW:
        raise argparse.ArgumentTypeError(
            f"--size must be at most {MAX_WINDOW}x{MAX_WINDOW} pixels, got {text!r} "
            f"(an off-screen picture of that size needs {w * h * 4 / 2**30:.3g} GB per buffer)"
        )
    return w, h


def positive_int_arg(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


def percent_arg(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a percentage in [0, 50), got {text!r}") from None
    if not 0 <= v < 50:
        raise argparse.ArgumentTypeError(f"expected a percentage in [0, 50), got {text!r}")
    return v


def h_arg(text: str) -> float | str:
    """``--h``: a positive smoothing length, or "adaptive"."""
    if text == "adaptive":
        return text
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--h must be a positive number or 'adaptive', got {text!r}") from None
    if not v > 0 or v == float("inf"):
        raise argparse.ArgumentTypeError(f"--h must be a positive number or 'adaptive', got {text!r}")
    return v


def xyz_arg(text: str) -> tuple[float, float, float]:
    """``X,Y,Z``: a point in space."""
    try:
        x, y, z = (float(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a point X,Y,Z (three comma-separated numbers), got {text!r}") from None
    if not all(abs(c) < float("inf") for c in (x, y, z)):
        raise argparse.ArgumentTypeError(f"expected a finite point X,Y,Z, got {text!r}")
    return x, y, z


def up_arg(text: str) -> str | tuple[float, float, float]:
    """``--up``: auto, x, y, z (a leading - turns it over) or a direction X,Y,Z."""
    if text.lstrip("+-") in ("x", "y", "z") or text == "auto":
        return text
    try:
        return xyz_arg(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"--up must be auto, x, y, z, -x, -y, -z or a direction X,Y,Z, got {text!r}") from None


def add_common_options(q: argparse.ArgumentParser, function: bool = True, surface: bool = True) -> None:
    """The options of the commands that build a cloud of a built-in shape: shape, function, sampling, and
    (``surface``) the Surface options ``--neighbors``, ``--kernel``, ``--area``."""
    from ..reference.accuracy import SCALAR_FUNCTIONS, SHAPES

    q.add_argument("--shape", default="sphere", choices=sorted(SHAPES), help="built-in surface (default sphere)")
    if function:
        q.add_argument("--function", default="cos_xz_sin_y", choices=SCALAR_FUNCTIONS, help="test function")
    q.add_argument("--sampling", default=None, help="sampling of the shape (default: its near-uniform one)")
    q.add_argument("--seed", type=int, default=0, help="random seed of the sampling")
    if surface:
        q.add_argument("--neighbors", type=int, default=27, help="mean neighbour count (default 27)")
        q.add_argument("--kernel", default="quintic", help="kernel (default quintic)")
        q.add_argument("--area", default="numerical", choices=["numerical", "geometric", "shepard"])
        q.add_argument("--h", type=h_arg, default=None,
                       help="smoothing length: a number, or 'adaptive' (each particle its own, for variable density)")
    q.add_argument("--json", action="store_true", help="print JSON instead of a table")


def add_picture_options(q: argparse.ArgumentParser) -> None:
    """Camera, up axis, picture size and ``--overwrite``."""
    from ..viz.render import CAMERAS

    q.add_argument("--camera", default="iso", choices=sorted(CAMERAS), help="camera preset (default iso)")
    q.add_argument("--up", type=up_arg, default="auto",
                   help="the axis pointing up in the picture: auto (default: the axis the object stands on), x, y, z, "
                        "-z... or X,Y,Z")
    q.add_argument("--size", type=window_arg, default=None, help="image size WIDTHxHEIGHT in pixels")
    q.add_argument("--overwrite", action="store_true", help="replace existing output files")


def surface_kwargs(args: argparse.Namespace) -> dict:
    return dict(neighbors=args.neighbors, kernel=args.kernel, area=args.area, h=getattr(args, "h", None))


def cloud_from_args(args: argparse.Namespace) -> PointCloud:
    """A PointCloud from the input file (duplicates as ``--duplicates`` says) or from --shape/--n."""
    from ..reference.accuracy import make_cloud

    if getattr(args, "file", None):
        from ..scans.io import read

        return read(args.file, duplicates=getattr(args, "duplicates", "merge"))
    check_size("--n", args.n)
    return make_cloud(args.shape, args.n, args.sampling, args.seed)


def out_dir(path: str | os.PathLike[str], create: bool = True) -> Path:
    d = Path(path)
    if d.exists() and not d.is_dir():
        raise UserError(f"--out {str(d)!r} exists and is not a folder")
    if create:
        d.mkdir(parents=True, exist_ok=True)
    return d


def check_free(paths: Iterable[str | os.PathLike[str]], overwrite: bool) -> None:
    """Refuse, before any work, to overwrite existing outputs (one line naming them)."""
    from .._validation import check_output_path

    for p in paths:
        try:
            check_output_path("output", p, True)  # a folder, or a missing folder: no --overwrite helps
        except (IsADirectoryError, FileNotFoundError) as exc:
            raise UserError(str(exc)) from None
    if overwrite:
        return
    taken = [str(p) for p in paths if Path(p).exists()]
    if taken:
        more = f" and {len(taken) - 1} more" if len(taken) > 1 else ""
        raise UserError(f"{taken[0]!r}{more} exist(s); pass --overwrite to replace")


def render_ok(need: bool) -> bool:
    """Whether 3D pictures can be drawn; a one-line note on stderr when they cannot."""
    if not need:
        return False
    from ..viz.render import rendering_available

    ok, why = rendering_available()
    if not ok:
        print(f"manifold-sph: note: skipping 3D pictures ({why})", file=sys.stderr)
    return ok
