"""The ``manifold-sph`` command line.

Subcommands: ``demo`` (the main job: four schemes against the exact operators
on a sphere, a short heat and wave run, pictures and a summary table),
``operators``, ``convergence``, ``heat``, ``wave``, ``poisson``, ``render``, and the
geometry of a point-cloud file: ``curvature`` and ``geodesic``.

Exit codes: 0 success, 1 failure while computing, 2 a user mistake (reported
in one line, without a traceback). With ``--json`` a failure also prints one
JSON object on stdout, ``{"error": ..., "type": ..., "command": ..., "exit_code": ...}``,
for every subcommand (argument errors included).
"""

from __future__ import annotations

import argparse
import contextlib
import io as _stdio
import json
import os
import re
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["main", "run_demo", "FOUR_SCHEMES"]

#: The four schemes of the thesis [1] (docs/method.md section 4) compared by ``demo`` and ``operators --scheme all``.
FOUR_SCHEMES = ("standard", "cspm", "msph", "ncsph")


class UserError(ValueError):
    """A mistake in the command line or its inputs (exit code 2)."""


#: Whether the command line being parsed asked for ``--json`` (argument errors are then JSON too),
#: and its first word (the subcommand, if it is one).
_JSON = False
_COMMAND_WORD = None

#: Largest picture side in pixels (an off-screen VTK window of 100000 x 100000 aborts in std::bad_alloc).
MAX_WINDOW = 8192

#: A lower bound on the memory one particle takes while a Surface is built (measured: a
#: million-point cspm build peaks at 1.5 GB, README "Speed and threads"); sizes needing more
#: than the machine's memory are refused before any work.
BYTES_PER_POINT = 1024


def _error_json(message: str, kind: str, command, code: int) -> None:
    print(json.dumps({"error": message, "type": kind, "command": command, "exit_code": code}))


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one JSON object on stdout when ``--json`` was given."""

    def error(self, message):
        if _JSON:
            words = self.prog.split()
            command = words[1] if len(words) > 1 else _COMMAND_WORD
            _error_json(" ".join(message.split()), "ArgumentError", command, 2)
        super().error(message)


def _memory_bytes():
    """Physical memory of this machine in bytes, or None where it cannot be read."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def _check_size(option: str, n: int) -> int:
    """Refuse, before any allocation, a cloud size below PointCloud's minimum or beyond memory."""
    from .pointcloud import MIN_POINTS

    if n < MIN_POINTS:
        raise UserError(f"{option} must be at least {MIN_POINTS} points, got {n}")
    mem = _memory_bytes()
    need = n * BYTES_PER_POINT
    if mem is not None and need > mem:
        raise UserError(
            f"{option} {n} needs at least {need / 2**30:.3g} GB of memory (about {BYTES_PER_POINT} bytes per point), "
            f"this machine has {mem / 2**30:.3g} GB"
        )
    return n


def _sizes(text: str) -> list[int]:
    try:
        sizes = [int(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sizes must be comma-separated integers, got {text!r}") from None
    if len(sizes) < 2:
        raise argparse.ArgumentTypeError(f"--sizes needs at least two sizes, got {text!r}")
    if min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"--sizes must be positive point counts, got {text!r}")
    return sizes


def _pair(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected two comma-separated numbers LOW,HIGH, got {text!r}") from None
    return lo, hi


def _window(text: str) -> tuple[int, int]:
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


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


def _percent(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a percentage in [0, 50), got {text!r}") from None
    if not 0 <= v < 50:
        raise argparse.ArgumentTypeError(f"expected a percentage in [0, 50), got {text!r}")
    return v


def _parser() -> argparse.ArgumentParser:
    from .reference.accuracy import SCALAR_FUNCTIONS, SHAPES
    from .geometry import CURVATURE_METHODS
    from .viz.render import CAMERAS
    from .schemes import SCHEMES

    p = _Parser(
        prog="manifold-sph",
        description="Consistent SPH operators on point-cloud surfaces: errors against exact references, PDEs, pictures.",
    )
    sub = p.add_subparsers(dest="command", required=True)
    schemes = sorted(SCHEMES)

    def common(q, function=True):
        q.add_argument("--shape", default="sphere", choices=sorted(SHAPES), help="built-in surface (default sphere)")
        if function:
            q.add_argument("--function", default="cos_xz_sin_y", choices=SCALAR_FUNCTIONS, help="test function")
        q.add_argument("--sampling", default=None, help="sampling of the shape (default: its near-uniform one)")
        q.add_argument("--seed", type=int, default=0, help="random seed of the sampling")
        q.add_argument("--neighbors", type=int, default=27, help="mean neighbour count (default 27)")
        q.add_argument("--kernel", default="quintic", help="kernel (default quintic)")
        q.add_argument("--area", default="numerical", choices=["numerical", "geometric", "shepard"])
        q.add_argument("--json", action="store_true", help="print JSON instead of a table")

    def pictures(q):
        q.add_argument("--camera", default="iso", choices=sorted(CAMERAS), help="camera preset (default iso)")
        q.add_argument("--size", type=_window, default=None, help="image size WIDTHxHEIGHT in pixels")
        q.add_argument("--overwrite", action="store_true", help="replace existing output files")

    demo = sub.add_parser("demo", help="the main job: schemes vs exact operators on a sphere, heat and wave, pictures")
    demo.add_argument("--out", required=True, help="folder for the pictures and summary (created if missing)")
    demo.add_argument("--n", type=int, default=4032, help="number of points on the sphere (default 4032)")
    demo.add_argument("--no-render", action="store_true", help="skip the 3D pictures (tables and plots only)")
    demo.add_argument("--overwrite", action="store_true", help="replace existing output files")
    demo.add_argument("--json", action="store_true", help="print the summary as JSON")

    ops = sub.add_parser("operators", help="errors of every scheme on one cloud")
    common(ops)
    ops.add_argument("--n", type=int, default=4032, help="number of points (default 4032)")
    ops.add_argument("--file", default=None, help="read the points from this file instead (they must lie on --shape)")
    ops.add_argument("--scheme", default="all", choices=["all", *schemes], help="'all': the four source schemes")

    conv = sub.add_parser("convergence", help="errors and fitted orders over several cloud sizes")
    common(conv)
    conv.add_argument("--sizes", type=_sizes, default=[1002, 2012, 4032, 8672, 15872, 32672])
    conv.add_argument("--scheme", default="msph", choices=schemes)
    conv.add_argument("--plot", default=None, help="also write a log-log plot to this PNG/PDF/SVG file")
    conv.add_argument("--overwrite", action="store_true", help="replace an existing --plot file")

    for name, helptext in (("heat", "heat equation u_t = k Lap u"), ("wave", "wave equation u_tt = c^2 Lap u")):
        q = sub.add_parser(name, help=helptext + " on a built-in shape or a file")
        common(q, function=False)
        q.add_argument("--file", default=None, help="read the points (and normals) from this file")
        q.add_argument("--n", type=int, default=4032, help="number of points (default 4032)")
        q.add_argument("--scheme", default="msph", choices=schemes)
        q.add_argument(
            "--init", default="hotspot",
            help="initial state: 'hotspot' (a Gaussian bump at the top), 'harmonic' (z + xy, exact solution "
                 "known on the unit sphere) or a test function name (default hotspot)",
        )
        q.add_argument("--dt", type=float, default=None, help="time step (default: heat 1e-3, wave half the stability limit)")
        q.add_argument("--steps", type=_positive_int, default=200, help="number of steps (default 200)")
        q.add_argument("--every", type=_positive_int, default=None, help="save a frame every this many steps (default steps/40)")
        if name == "heat":
            q.add_argument("--k", type=float, default=1.0, help="diffusivity (default 1)")
            q.add_argument("--method", default="implicit", choices=["implicit", "crank-nicolson", "explicit"])
        else:
            q.add_argument("--c", type=float, default=1.0, help="wave speed (default 1)")
        q.add_argument("--out", default=None, help="folder for the final picture and the animation")
        q.add_argument("--format", default="gif", choices=["gif", "mp4"], help="animation format (mp4 needs imageio-ffmpeg)")
        pictures(q)

    poi = sub.add_parser("poisson", help="solve Lap u = Lap f on a closed built-in shape and compare u with f")
    common(poi)
    poi.add_argument("--n", type=int, default=4032, help="number of points (default 4032)")
    poi.add_argument("--scheme", default="msph", choices=schemes)
    poi.add_argument("--out", default=None, help="folder for a picture: f | exact | solution | error")
    pictures(poi)

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
    ren.add_argument("--clim", type=_pair, default=None, help="colour limits LOW,HIGH")
    ren.add_argument("--robust", type=float, default=None, help="clip this percentage at each end of the colour range")
    ren.add_argument("--cmap", default="viridis", help="matplotlib colour map (default viridis)")
    ren.add_argument("--transparent", action="store_true", help="transparent background")
    ren.add_argument("--json", action="store_true", help="print what was written as JSON")
    pictures(ren)

    def geometry(q):
        q.add_argument("file", help="point cloud (ply, pcd, xyz, csv, obj, npy, npz, las, laz, e57, vtk); its normals are used "
                                    "if it has them, else estimated")
        q.add_argument("--scheme", default="msph", choices=schemes)
        q.add_argument("--neighbors", type=_positive_int, default=None, help="mean neighbour count (default: the scheme's)")
        q.add_argument("--png", default=None, help="also render the field, off-screen, to this PNG file")
        q.add_argument("--clim", type=_pair, default=None, help="colour limits LOW,HIGH of the picture")
        q.add_argument("--cmap", default=None, help="matplotlib colour map of the picture")
        q.add_argument("--json", action="store_true", help="print the summary as JSON")
        pictures(q)

    cur = sub.add_parser("curvature", help="mean, Gaussian or principal curvature of a point-cloud file")
    geometry(cur)
    cur.add_argument("--quantity", default="mean", choices=["mean", "gaussian", "k1", "k2"],
                     help="mean H = (k1 + k2) / 2, Gaussian K = k1 k2, or a principal curvature k1 >= k2 (default mean)")
    cur.add_argument("--method", default=None, choices=CURVATURE_METHODS,
                     help="for --quantity mean: from the normals' gradient or the Laplacian of the coordinates "
                          "(default auto: the normals' gradient, the more accurate with the jet-fitted normals estimated here)")
    cur.add_argument("--robust", type=_percent, default=2.0,
                     help="clip this percentage at each end of the colour range (default 2; 0: full range)")

    geo = sub.add_parser("geodesic", help="geodesic distance from particles of a point-cloud file (heat method)")
    geometry(geo)
    geo.add_argument("--source", type=int, action="append", required=True, metavar="I",
                     help="index of a source particle (0-based); repeat for several sources")
    geo.add_argument("--robust", type=_percent, default=0.0,
                     help="clip this percentage at each end of the colour range (default 0: full range)")
    from .spem.cli import add_parser as _add_spem_parser

    _add_spem_parser(sub)
    return p


# --- shared pieces -------------------------------------------------------------------


def _surface_kwargs(args) -> dict:
    return dict(neighbors=args.neighbors, kernel=args.kernel, area=args.area)


def _cloud_from_args(args):
    """A PointCloud from --file (with normals estimated if missing) or from --shape/--n."""
    from .reference.accuracy import make_cloud

    if getattr(args, "file", None):
        from .scans.io import read

        return read(args.file)
    _check_size("--n", args.n)
    return make_cloud(args.shape, args.n, args.sampling, args.seed)


def _attach_shape(cloud, shape_name: str, path: str):
    """The cloud with the exact shape ``shape_name`` attached, if its points lie on it."""
    from .pointcloud import PointCloud
    from .reference.shapes import SHAPES

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


def _initial_state(name: str, points: np.ndarray) -> np.ndarray:
    from .reference.accuracy import SCALAR_FUNCTIONS, get_function

    x = points
    if name == "hotspot":
        top = x[np.argmax(x[:, 2])]
        sigma = 0.15 * float(np.ptp(x, axis=0).max())
        return np.exp(-np.sum((x - top) ** 2, axis=1) / (2 * sigma**2))
    if name == "harmonic":
        return x[:, 2] + x[:, 0] * x[:, 1]
    if name in SCALAR_FUNCTIONS:
        return get_function(name).value(x)
    raise UserError(f"--init must be 'hotspot', 'harmonic' or one of {list(SCALAR_FUNCTIONS)}, got {name!r}")


def _out_dir(path, create: bool = True) -> Path:
    d = Path(path)
    if d.exists() and not d.is_dir():
        raise UserError(f"--out {str(d)!r} exists and is not a folder")
    if create:
        d.mkdir(parents=True, exist_ok=True)
    return d


def _check_free(paths, overwrite: bool) -> None:
    """Refuse, before any work, to overwrite existing outputs (one line naming them)."""
    from ._validation import check_output_path

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


def _render_ok(need: bool) -> bool:
    """Whether 3D pictures can be drawn; a one-line note on stderr when they cannot."""
    if not need:
        return False
    from .viz.render import rendering_available

    ok, why = rendering_available()
    if not ok:
        print(f"manifold-sph: note: skipping 3D pictures ({why})", file=sys.stderr)
    return ok


# --- demo ----------------------------------------------------------------------------


def run_demo(out: str | os.PathLike[str], *, n: int = 4032, render: bool = True, overwrite: bool = False, progress: bool = False) -> dict:
    """The main job: the four schemes against the exact operators on a sphere, heat, wave, pictures.

    On the unit sphere (``n`` Fibonacci points), with ``f = cos(xz - sin y)``:
    relative errors of the Laplace-Beltrami and gradient of standard SPH, CSPM,
    MSPH and NCSPH (:func:`manifold_sph.reference.accuracy.operator_errors`); a
    Crank-Nicolson heat run and a centred wave run (CSPM) from
    ``u0 = z + xy``, compared with the exact solutions
    ``z exp(-2t) + xy exp(-6t)`` and ``z cos(sqrt(2) t) + xy cos(sqrt(6) t)``.

    Writes to ``out``: ``summary.json``, ``summary.txt``, ``boxplot_laplacian.png``,
    ``boxplot_gradient.png``, ``area_histogram.png`` and, when ``render``,
    ``laplacian_cspm.png`` (f | exact | SPH | error), ``gradient_cspm.png``
    (gradient arrows), ``heat.gif`` and ``wave.gif``.

    Returns
    -------
    dict
        The summary (also in ``summary.json``).
    """
    from tqdm import tqdm

    from . import pde
    from .reference import functions
    from .viz import plots
    from .reference.accuracy import exact_operators, format_rows, operator_errors
    from .reference.errors import absolute_error, l2_error
    from .reference.shapes import sphere
    from .surface import Surface

    out = _out_dir(out)
    names = ["summary.json", "summary.txt", "boxplot_laplacian.png", "boxplot_gradient.png", "area_histogram.png"]
    if render:
        names += ["laplacian_cspm.png", "gradient_cspm.png", "heat.gif", "wave.gif"]
    _check_free([out / nm for nm in names], overwrite)
    t_start = time.perf_counter()
    bar = tqdm(total=8 if render else 6, desc="demo", disable=not progress, file=sys.stderr)

    cloud = sphere(n)
    fn = functions.cos_xz_sin_y
    f, grad_ex, lap_ex = exact_operators(cloud, fn)
    rows = operator_errors(cloud, fn, FOUR_SCHEMES)
    bar.update()
    surfaces = {name: Surface(cloud, scheme=name) for name in FOUR_SCHEMES}
    lap = {k: s.laplacian(f) for k, s in surfaces.items()}
    grad = {k: s.gradient(f) for k, s in surfaces.items()}
    bar.update()
    plots.error_boxplot(
        {k: absolute_error(v, lap_ex) for k, v in lap.items()},
        title=f"Laplace-Beltrami of cos(xz - sin y), sphere N = {n}", ylabel="|Lap_SPH f - Lap_S f|",
        filename=out / "boxplot_laplacian.png", overwrite=overwrite,
    )
    plots.error_boxplot(
        {k: absolute_error(v, grad_ex) for k, v in grad.items()},
        title=f"Surface gradient of cos(xz - sin y), sphere N = {n}", ylabel="|grad_SPH f - grad_S f|",
        filename=out / "boxplot_gradient.png", overwrite=overwrite,
    )
    plots.area_histogram(
        {"numerical": surfaces["cspm"].dV},
        reference=4 * np.pi / n, title=f"Area elements, sphere N = {n} (reference 4 pi / N)",
        filename=out / "area_histogram.png", overwrite=overwrite,
    )
    bar.update()

    s = surfaces["cspm"]
    x = cloud.points
    z, xy = x[:, 2], x[:, 0] * x[:, 1]
    u0 = z + xy
    t_end_heat, heat_steps = 0.2, 40
    heat = pde.heat(s, u0, dt=t_end_heat / heat_steps, steps=heat_steps, method="crank-nicolson", every=2)
    heat_exact = z * np.exp(-2 * t_end_heat) + xy * np.exp(-6 * t_end_heat)
    heat_err = l2_error(heat.u, heat_exact)
    bar.update()
    dt_lim = pde.explicit_dt_limit(s, equation="wave")
    t_end_wave = 2.0
    wave_steps = int(np.ceil(t_end_wave / (0.5 * dt_lim)))
    dt_wave = t_end_wave / wave_steps
    wave = pde.wave(s, u0, dt=dt_wave, steps=wave_steps, every=max(1, wave_steps // 24))
    wave_exact = z * np.cos(np.sqrt(2.0) * t_end_wave) + xy * np.cos(np.sqrt(6.0) * t_end_wave)
    wave_err = l2_error(wave.u, wave_exact)
    bar.update()

    summary = {
        "shape": "sphere",
        "n": int(n),
        "function": "cos_xz_sin_y",
        "rows": rows,
        "heat": {
            "scheme": "cspm", "method": "crank-nicolson", "u0": "z + xy", "t": t_end_heat, "dt": t_end_heat / heat_steps,
            "steps": heat_steps, "l2_rel_error": heat_err, "exact": "z exp(-2t) + xy exp(-6t)",
        },
        "wave": {
            "scheme": "cspm", "u0": "z + xy", "t": t_end_wave, "dt": dt_wave, "steps": wave_steps,
            "dt_limit": dt_lim, "l2_rel_error": wave_err, "exact": "z cos(sqrt(2) t) + xy cos(sqrt(6) t)",
        },
    }
    if _render_ok(render):
        from .viz.render import animate, render_comparison, render_field

        render_comparison(
            s, f, lap_ex, lap["cspm"], names=("f", "exact Lap_S f", "CSPM", "error"), panel_size=(300, 300),
            filename=out / "laplacian_cspm.png", overwrite=overwrite,
        )
        render_field(
            s, f, vectors=grad["cspm"], bar_title="f", title="f = cos(xz - sin y) and its CSPM gradient",
            window_size=(600, 500), camera="equator", filename=out / "gradient_cspm.png", overwrite=overwrite,
        )
        bar.update()
        animate(s, heat, out / "heat.gif", title="heat, u0 = z + xy (CSPM, Crank-Nicolson)", bar_title="u",
                window_size=(360, 320), fps=8, overwrite=overwrite)
        animate(s, wave, out / "wave.gif", title="wave, u0 = z + xy (CSPM)", bar_title="u",
                window_size=(360, 320), fps=10, overwrite=overwrite)
        bar.update()
        summary["pictures"] = True
    else:
        summary["pictures"] = False
    bar.close()
    summary["seconds"] = round(time.perf_counter() - t_start, 2)
    text = (
        f"sphere, N = {n}, f = cos(xz - sin y): relative errors against the exact operators\n"
        f"{format_rows(rows)}\n\n"
        f"heat (cspm, Crank-Nicolson, t = {t_end_heat:g}, {heat_steps} steps): relative L2 error {heat_err:.3e}\n"
        f"wave (cspm, centred, t = {t_end_wave:g}, {wave_steps} steps, dt = {dt_wave:.3g}): relative L2 error {wave_err:.3e}\n"
    )
    (out / "summary.txt").write_text(text)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    summary["text"] = text
    return summary


# --- subcommands ---------------------------------------------------------------------


def _cmd_demo(args) -> int:
    if args.n < 500:
        raise UserError(f"--n must be at least 500 for the demo, got {args.n}")
    _check_size("--n", args.n)
    summary = run_demo(args.out, n=args.n, render=not args.no_render, overwrite=args.overwrite, progress=not args.json)
    text = summary.pop("text")
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(text, end="")
        print(f"pictures and summary written to {args.out} ({summary['seconds']:.1f} s)")
    return 0


def _cmd_operators(args) -> int:
    from .reference.accuracy import format_rows, operator_errors

    if args.file:
        cloud = _attach_shape(_cloud_from_args(args), args.shape, args.file)
    else:
        cloud = _cloud_from_args(args)
    schemes = list(FOUR_SCHEMES) if args.scheme == "all" else [args.scheme]
    rows = operator_errors(cloud, args.function, schemes, **_surface_kwargs(args))
    if args.json:
        print(json.dumps({"shape": args.shape, "function": args.function, "rows": rows}, indent=2))
    else:
        print(f"{args.shape}, N = {len(cloud)}, f = {args.function}: relative errors against the exact operators")
        print(format_rows(rows))
    return 0


def _cmd_convergence(args) -> int:
    from tqdm import tqdm

    from .reference.accuracy import convergence

    for n in args.sizes:
        _check_size("--sizes", n)
    if args.plot:
        _check_free([args.plot], args.overwrite)
    with tqdm(total=len(args.sizes), desc=f"{args.scheme} on {args.shape}", disable=args.json, file=sys.stderr) as bar:
        table = convergence(
            args.shape, args.sizes, args.scheme, args.function,
            sampling=args.sampling, seed=args.seed, progress=bar.update, **_surface_kwargs(args),
        )
    if args.plot:
        from .viz.plots import convergence_plot

        convergence_plot(
            {args.scheme: table}, reference_order=2,
            title=f"{args.scheme} on {args.shape}, f = {args.function} (relative errors)",
            filename=args.plot, overwrite=args.overwrite,
        )
    if args.json:
        print(json.dumps(table.to_dict(), indent=2))
    else:
        print(f"{args.scheme} on {args.shape}, f = {args.function} (orders fitted against h ~ N^-1/2)")
        print(table.to_text())
        if args.plot:
            print(f"plot written to {args.plot}")
    return 0


def _cmd_evolve(args) -> int:
    from tqdm import tqdm

    from . import pde
    from .reference.errors import l2_error
    from .surface import Surface

    cloud = _cloud_from_args(args)
    s = Surface(cloud, scheme=args.scheme, **_surface_kwargs(args))
    x = s.points
    u0 = _initial_state(args.init, x)
    every = args.every or max(1, args.steps // 40)
    files = []
    if args.out:
        out = _out_dir(args.out)
        files = [out / f"{args.command}_final.png", out / f"{args.command}.{args.format}"]
        _check_free(files, args.overwrite)
    with tqdm(total=args.steps, desc=args.command, disable=args.json, file=sys.stderr, unit="step") as bar:
        cb = lambda step, t, u: bar.update()  # noqa: E731
        if args.command == "heat":
            dt = 1e-3 if args.dt is None else args.dt
            res = pde.heat(s, u0, dt=dt, steps=args.steps, diffusivity=args.k, method=args.method, every=every, callback=cb)
        else:
            dt = 0.5 * pde.explicit_dt_limit(s, c=args.c, equation="wave") if args.dt is None else args.dt
            res = pde.wave(s, u0, dt=dt, steps=args.steps, c=args.c, every=every, callback=cb)
    u = res.u
    t = float(res.times[-1])
    summary = {
        "command": args.command, "n": int(s.n_points), "scheme": args.scheme, "init": args.init,
        "dt": dt, "steps": args.steps, "t": t,
        "min": float(u.min()), "max": float(u.max()), "mean": float(np.dot(s.dV, u) / s.dV.sum()),
    }
    exact_known = args.init == "harmonic" and not args.file and args.shape == "sphere"
    if exact_known:
        z, xy = x[:, 2], x[:, 0] * x[:, 1]
        if args.command == "heat":
            ex = z * np.exp(-2 * args.k * t) + xy * np.exp(-6 * args.k * t)
        else:
            ex = z * np.cos(np.sqrt(2.0) * args.c * t) + xy * np.cos(np.sqrt(6.0) * args.c * t)
        summary["l2_rel_error"] = l2_error(u, ex)
    if args.out and _render_ok(True):
        from .viz.render import animate, render_field

        size = args.size or (480, 400)
        lim = (float(res.snapshots.min()), float(res.snapshots.max()))
        render_field(s, u, title=f"{args.command}, t = {t:.4g}", bar_title="u", camera=args.camera, window_size=size,
                     clim=lim if lim[1] > lim[0] else None, filename=files[0], overwrite=args.overwrite)
        animate(s, res, files[1], title=f"{args.command} ({args.scheme})", bar_title="u", camera=args.camera,
                window_size=size, progress=not args.json, overwrite=args.overwrite)
        summary["files"] = [str(f) for f in files]
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(
            f"{args.command} on {args.file or args.shape} (N = {summary['n']}, {args.scheme}), {args.steps} steps of dt = {dt:.4g}, "
            f"t = {t:.4g}: min {summary['min']:.4g}, max {summary['max']:.4g}, mean {summary['mean']:.4g}"
        )
        if "l2_rel_error" in summary:
            print(f"relative L2 error against the exact solution: {summary['l2_rel_error']:.3e}")
        for f in summary.get("files", []):
            print(f"wrote {f}")
    return 0


def _cmd_poisson(args) -> int:
    from . import pde
    from .reference.accuracy import exact_operators, get_function
    from .reference.errors import l2_error, linf_error
    from .surface import Surface

    cloud = _cloud_from_args(args)
    s = Surface(cloud, scheme=args.scheme, **_surface_kwargs(args))
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
        out = _out_dir(args.out)
        target = out / f"poisson_{args.shape}_{args.scheme}.png"
        _check_free([target], args.overwrite)
        if _render_ok(True):
            from .viz.render import render_comparison

            w, h = args.size or (300, 300)
            render_comparison(s, rhs, ref, u, names=("rhs", "exact u", "SPH u", "error"), camera=args.camera,
                              panel_size=(w, h), filename=target, overwrite=args.overwrite)
            summary["files"] = [str(target)]
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


def _cmd_render(args) -> int:
    from .reference.accuracy import SCALAR_FUNCTIONS, get_function
    from .scans.io import read

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
    _check_free([out], args.overwrite)
    from .viz.render import render_field, rendering_available

    ok, why = rendering_available()
    if not ok:
        raise RuntimeError(f"cannot render here: {why}")

    vectors, label = None, name
    if args.operator != "none":
        from .surface import Surface

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
    _check_free([out], args.overwrite)
    from .viz.render import rendering_available

    ok, why = rendering_available()
    if not ok:
        raise RuntimeError(f"cannot render here: {why}")
    return out


def _geometry_surface(args, cloud, bar):
    """The Surface of the file's cloud (its normals if it has them, else estimated by Surface)."""
    from .surface import Surface

    s = Surface(cloud, scheme=args.scheme, neighbors=args.neighbors)
    bar.update()
    return s


def _stats(values) -> dict:
    v = np.asarray(values, dtype=np.float64)
    return {"min": float(v.min()), "median": float(np.median(v)), "max": float(v.max())}


def _render_geometry(args, out, points, values, title, bar_title, cmap):
    from .viz.render import render_field

    render_field(
        points, values, title=title, bar_title=bar_title, camera=args.camera, window_size=args.size or (800, 600),
        clim=args.clim, robust=args.robust or None, cmap=args.cmap or cmap, filename=out, overwrite=args.overwrite,
    )


def _cmd_curvature(args) -> int:
    from tqdm import tqdm

    from .geometry import curvature_method
    from .scans.io import read

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

    from .scans.io import read

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


def _cmd_spem(args) -> int:
    """``spem CASE``: picture targets checked before the run; with --json, a failure reported by the
    SPEM command (one line on stderr) is also printed as the JSON error object."""
    from .spem.cli import run

    for option in ("png", "gif"):
        target = getattr(args, option, None)
        if target:
            try:
                from ._validation import check_output_path

                check_output_path(f"--{option}", target, args.overwrite, hint="--overwrite")
            except (IsADirectoryError, FileNotFoundError, FileExistsError) as exc:
                raise UserError(str(exc)) from None
    if not args.json:
        return run(args)
    err = _stdio.StringIO()
    with contextlib.redirect_stderr(err):
        code = run(args)
    text = err.getvalue()
    sys.stderr.write(text)
    if code != 0:
        lines = [ln for ln in text.splitlines() if ln.strip()]
        message = re.sub(r"^manifold-sph( spem)?: error: ", "", lines[-1]) if lines else f"spem {args.case} failed"
        _error_json(message, "UserError" if code == 2 else "Error", "spem", code)
    return code


_COMMANDS = {
    "spem": _cmd_spem,
    "demo": _cmd_demo,
    "operators": _cmd_operators,
    "convergence": _cmd_convergence,
    "heat": _cmd_evolve,
    "wave": _cmd_evolve,
    "poisson": _cmd_poisson,
    "render": _cmd_render,
    "curvature": _cmd_curvature,
    "geodesic": _cmd_geodesic,
}


def _value_options(parser: argparse.ArgumentParser) -> set[str]:
    """Every ``--option`` of every subcommand that takes a value."""
    out = set()
    todo = [parser]
    while todo:
        q = todo.pop()
        for action in q._actions:
            if isinstance(action, argparse._SubParsersAction):
                todo.extend(action.choices.values())
            elif action.option_strings and action.nargs != 0:
                out.update(o for o in action.option_strings if o.startswith("--"))
    return out


def _join_negative_values(argv: list[str], options: set[str]) -> list[str]:
    """``--sizes -600,-1200`` -> ``--sizes=-600,-1200``: argparse takes a value starting with '-'
    that is not a plain number for an option and says "expected one argument"; joined, the
    option's own check names the problem.

    Examples
    --------
    >>> _join_negative_values(["convergence", "--sizes", "-600,-1200"], {"--sizes"})
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
_USER_ERRORS = (ValueError, TypeError, FileNotFoundError, FileExistsError, IsADirectoryError, NotADirectoryError,
                PermissionError)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``manifold-sph`` console script.

    Examples
    --------
    >>> main(["operators", "--n", "5", "--json"])  # doctest: +ELLIPSIS
    {"error": "--n must be at least 10 points, got 5", "type": "UserError", "command": "operators", "exit_code": 2}
    2
    """
    global _JSON, _COMMAND_WORD
    argv = list(sys.argv[1:] if argv is None else argv)
    _JSON = "--json" in argv
    _COMMAND_WORD = next((a for a in argv if not a.startswith("-")), None)
    _COMMAND_WORD = _COMMAND_WORD if _COMMAND_WORD in _COMMANDS else None
    parser = _parser()
    args = parser.parse_args(_join_negative_values(argv, _value_options(parser)))
    command = args.command
    try:
        return _COMMANDS[command](args)
    except _USER_ERRORS as exc:
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
        _error_json(msg, kind, command, code)
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
