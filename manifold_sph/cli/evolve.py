"""``manifold-sph heat | wave``: time-dependent problems on a built-in shape or a file."""

from __future__ import annotations

import json

import numpy as np

from .common import SubParsers, UserError, add_common_options, add_picture_options, cloud_from_args, positive_int_arg
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
    save_values,
)

__all__ = ["add_parsers"]


def add_parsers(sub: SubParsers, schemes: list[str]) -> None:
    """Register ``heat`` and ``wave``."""
    for name, helptext in (("heat", "heat equation u_t = diffusivity Lap u"), ("wave", "wave equation u_tt = c^2 Lap u")):
        q = sub.add_parser(name, help=helptext + " on a point-cloud file or a built-in shape")
        add_input(q, optional=True, help="point cloud or mesh file (without it: the built-in --shape)")
        add_common_options(q, function=False, surface=False)
        q.add_argument("--n", type=int, default=4032, help="number of points of the built-in shape (default 4032)")
        add_surface_options(q, schemes, neighbors=27, kernel=True)
        q.add_argument(
            "--init", default="hotspot",
            help="initial state: 'hotspot' (a Gaussian bump at the top), 'harmonic' (z + xy, exact solution "
                 "known on the unit sphere) or a test function name (default hotspot)",
        )
        reach = "0.1: heat spreads over a tenth" if name == "heat" else "1: a front crosses the cloud once"
        q.add_argument("--reach", type=float, default=None,
                       help=f"how far the solution travels, as a fraction of the cloud's diameter (default {reach})")
        q.add_argument("--t-end", type=float, default=None, help="final time in the cloud's units (instead of --reach)")
        q.add_argument("--dt", type=float, default=None,
                       help="time step (default: chosen from the point spacing" +
                            (")" if name == "heat" else " and the stability limit)"))
        q.add_argument("--steps", type=positive_int_arg, default=None,
                       help="number of steps (with --dt: an absolute duration; alone: splits the duration)")
        q.add_argument("--every", type=positive_int_arg, default=None, help="save a frame every this many steps (default steps/40)")
        if name == "heat":
            q.add_argument("--diffusivity", type=float, default=1.0, help="diffusivity (default 1)")
            q.add_argument("--method", default="implicit", choices=["implicit", "crank-nicolson", "explicit"])
        else:
            q.add_argument("--c", type=float, default=1.0, help="wave speed (default 1)")
        add_out(q, "the final state (.png) or the animation (.gif, .mp4: the video extra)", (".png", ".gif", ".mp4"),
                repeat=True)
        add_save(q, "the final state u")
        add_colour_options(q)
        add_picture_options(q)
        q.set_defaults(func=_cmd_evolve)


def _initial_state(name: str, points: np.ndarray) -> np.ndarray:
    from ..reference.accuracy import SCALAR_FUNCTIONS, get_function

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


def _mean(s, u) -> float:
    """The area-weighted mean of ``u`` (the stable Laplacian's mass matrix: positive weights)."""
    m = np.asarray(s.mass_matrix().diagonal())
    return float(np.dot(m, u) / m.sum())


def _time_steps(args, s) -> tuple[float, int]:
    """``(dt, steps)`` from --reach / --t-end / --dt / --steps (default: --reach 0.1 for heat, 1 for wave)."""
    from .. import pde

    heat = args.command == "heat"
    duration = {"reach": args.reach, "t_end": args.t_end, "dt": args.dt, "steps": args.steps}
    if args.reach is None and args.t_end is None and (args.dt is None or args.steps is None):
        duration["reach"] = 0.1 if heat else 1.0  # no absolute time suits every cloud
    speed = {"diffusivity": args.diffusivity, "method": args.method} if heat else {"c": args.c}
    try:
        return pde.time_steps(s, equation=args.command, **duration, **speed)
    except ValueError as exc:  # name the options, not the keywords
        raise UserError(str(exc).replace("reach=", "--reach ").replace("t_end=", "--t-end ").replace("dt=", "--dt ")
                        .replace("steps=", "--steps ")) from exc


def _cmd_evolve(args) -> int:
    from .. import pde
    from ..reference.errors import l2_error

    check_outputs(args)
    with progress(args, 3 if args.file else 2, args.command) as bar:
        if args.file:
            bar.step("reading")
        cloud = cloud_from_args(args)
        if args.file:
            bar.update()
        s, _ = build_surface(args, cloud, bar)
    x = s.points
    u0 = _initial_state(args.init, x)
    dt, steps = _time_steps(args, s)
    every = args.every or max(1, steps // 40)
    with progress(args, steps, args.command) as bar:
        bar.step("steps")
        cb = lambda step, t, u: bar.update()  # noqa: E731
        if args.command == "heat":
            res = pde.heat(s, u0, dt=dt, steps=steps, diffusivity=args.diffusivity, method=args.method, every=every,
                           callback=cb)
        else:
            res = pde.wave(s, u0, dt=dt, steps=steps, c=args.c, every=every, callback=cb)
    u = res.u
    t = float(res.times[-1])
    summary = {
        "command": args.command, "n": int(s.n_points), "scheme": args.scheme, "init": args.init,
        "dt": dt, "steps": steps, "t": t, "laplacian": res.laplacian, "solver": res.solver,
        "adapted": [a.summary for a in s.report()],
        "min": float(u.min()), "max": float(u.max()), "mean": _mean(s, u),
    }
    exact_known = args.init == "harmonic" and not args.file and args.shape == "sphere"
    if exact_known:
        z, xy = x[:, 2], x[:, 0] * x[:, 1]
        if args.command == "heat":
            ex = z * np.exp(-2 * args.diffusivity * t) + xy * np.exp(-6 * args.diffusivity * t)
        else:
            ex = z * np.cos(np.sqrt(2.0) * args.c * t) + xy * np.cos(np.sqrt(6.0) * args.c * t)
        summary["l2_rel_error"] = l2_error(u, ex)
    files = []
    saved = save_values(args, s, {"u": u})
    if saved:
        files.append(saved)
    # one colour range for the whole run (the solution's own: no outliers to clip in a PDE solution)
    lo, hi = float(res.snapshots.min()), float(res.snapshots.max())
    lim = (lo, hi) if hi > lo else None
    where = args.file or args.shape
    for out in args.out:
        if out.lower().endswith(".png"):
            draw(args, s, u, title=f"{args.command}, t = {t:.4g}, {where}", name="u", out=out,
                 **({"clim": args.clim or lim} if lim or args.clim else {}))
        else:
            from ..viz.render import animate

            robust = args.robust
            animate(s, res, out, title=f"{args.command} ({args.scheme}), {where}", bar_title="u", camera=args.camera,
                    up=args.up, cmap=args.cmap or "auto", clim=args.clim or lim,
                    robust=True if robust is None else (robust if robust > 0 else False),
                    window_size=args.size or (480, 400), progress=not args.json, overwrite=args.overwrite)
        files.append(out)
    if files:
        summary["files"] = files
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(
            f"{args.command} on {where} (N = {summary['n']}, {args.scheme}, {res.laplacian} Laplacian), {steps} steps "
            f"of dt = {dt:.4g}, t = {t:.4g}: min {summary['min']:.4g}, max {summary['max']:.4g}, "
            f"mean {summary['mean']:.4g}"
        )
        if "l2_rel_error" in summary:
            print(f"relative L2 error against the exact solution: {summary['l2_rel_error']:.3e}")
        for f in summary.get("files", []):
            print(f"wrote {f}")
    return 0
