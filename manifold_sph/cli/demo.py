"""``manifold-sph demo``: the main job (four schemes against the exact operators on a sphere, heat, wave, pictures)."""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

from .common import FOUR_SCHEMES, SubParsers, UserError, check_free, check_size, out_dir, render_ok

__all__ = ["add_parsers", "run_demo"]


def add_parsers(sub: SubParsers) -> None:
    """Register ``demo``."""
    demo = sub.add_parser("demo", help="the main job: schemes vs exact operators on a sphere, heat and wave, pictures")
    demo.add_argument("--out", required=True, help="folder for the pictures and summary (created if missing)")
    demo.add_argument("--n", type=int, default=4032, help="number of points on the sphere (default 4032)")
    demo.add_argument("--no-render", action="store_true", help="skip the 3D pictures (tables and plots only)")
    demo.add_argument("--overwrite", action="store_true", help="replace existing output files")
    demo.add_argument("--json", action="store_true", help="print the summary as JSON")
    demo.set_defaults(func=_cmd_demo)


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

    from .. import pde
    from ..reference import functions
    from ..reference.accuracy import exact_operators, format_rows, operator_errors
    from ..reference.errors import absolute_error, l2_error
    from ..reference.shapes import sphere
    from ..surface import Surface
    from ..viz import plots

    out = out_dir(out)
    names = ["summary.json", "summary.txt", "boxplot_laplacian.png", "boxplot_gradient.png", "area_histogram.png"]
    if render:
        names += ["laplacian_cspm.png", "gradient_cspm.png", "heat.gif", "wave.gif"]
    check_free([out / nm for nm in names], overwrite)
    t_start = time.perf_counter()
    bar = tqdm(total=8 if render else 6, desc="demo", disable=not progress, file=sys.stderr)

    cloud = sphere(n)
    fn = functions.cos_xz_sin_y
    f, grad_ex, lap_ex = exact_operators(cloud, fn)
    rows = operator_errors(cloud, fn, FOUR_SCHEMES)
    bar.update()
    surfaces = {name: Surface(cloud, scheme=name) for name in FOUR_SCHEMES}
    lap = {k: s.laplacian(f, form="strong") for k, s in surfaces.items()}
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
    if render_ok(render):
        from ..viz.render import animate, render_comparison, render_field

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


def _cmd_demo(args) -> int:
    if args.n < 500:
        raise UserError(f"--n must be at least 500 for the demo, got {args.n}")
    check_size("--n", args.n)
    summary = run_demo(args.out, n=args.n, render=not args.no_render, overwrite=args.overwrite, progress=not args.json)
    text = summary.pop("text")
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(text, end="")
        print(f"pictures and summary written to {args.out} ({summary['seconds']:.1f} s)")
    return 0
