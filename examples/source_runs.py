"""The heat and wave runs on the sphere of [1] (docs/method.md; sec. 3.5, Figs. 51-53) with its parameters.

    python examples/source_runs.py --out pictures [--quick]

Heat: 8672 points, CSPM, explicit Euler with dt = 0.001 and k = 1.5 (the choice
of [1]; stable, the limit is printed), a source held at 1 at the north pole,
snapshots at t = 0, 3.5, 7 and 10. Wave: c = 0.5, dt = 0.005, to t = 2, with one
source (a bump at the north pole) and with two sources in the northern
hemisphere. Writes the snapshots as PNG panels (when off-screen rendering works)
and as ``source_runs.npz``; prints the heat and energy budgets.
"""

from __future__ import annotations

import numpy as np
from _common import can_render, parse, report

from manifold_sph import Surface, pde
from manifold_sph.reference import shapes


def bump(x, centre, width=0.15):
    c = np.asarray(centre, dtype=float)
    c /= np.linalg.norm(c)
    return np.exp(-np.sum((x - c) ** 2, axis=1) / (2 * width**2))


def main(argv=None) -> int:
    args = parse(argv, __doc__.splitlines()[0])
    n = 1002 if args.quick else 8672
    t_heat = (0.0, 0.035, 0.07, 0.1) if args.quick else (0.0, 3.5, 7.0, 10.0)
    t_wave = 0.2 if args.quick else 2.0
    cloud = shapes.sphere(n)
    s = Surface(cloud, scheme="cspm")
    x = cloud.points
    north = int(np.argmax(x[:, 2]))

    dt, k = 0.001, 1.5
    limit = pde.explicit_dt_limit(s, diffusivity=k)
    print(f"heat: N = {n}, explicit Euler dt = {dt} (stability limit {limit:.4g}), k = {k}, source at the north pole")
    every = int(round(t_heat[1] / dt))
    heat = pde.heat(s, np.zeros(n), dt=dt, steps=int(round(t_heat[-1] / dt)), diffusivity=k, method="explicit",
                    fixed=[north], fixed_values=1.0, every=every)
    for t, u in zip(heat.times, heat.snapshots):
        print(f"   t = {t:5.2f}: mean temperature {np.dot(s.dV, u) / s.dV.sum():.4f}, south pole {u[np.argmin(x[:, 2])]:.4f}")

    c, dtw = 0.5, 0.005
    wl = pde.explicit_dt_limit(s, c=c, equation="wave")
    steps = int(round(t_wave / dtw))
    waves = {}
    for label, u0 in (
        ("one source", bump(x, (0, 0, 1))),
        ("two sources", bump(x, (0.6, 0, 0.8)) + bump(x, (-0.6, 0, 0.8))),
    ):
        w = pde.wave(s, u0, dt=dtw, steps=steps, c=c, every=max(1, steps // 4))
        print(f"wave ({label}): c = {c}, dt = {dtw} (limit {wl:.4g}), {steps} steps; "
              f"max |u| {np.abs(w.snapshots[-1]).max():.3f}; "
              f"mass {np.dot(s.dV, w.snapshots[0]):.4f} -> {np.dot(s.dV, w.snapshots[-1]):.4f}")
        waves[label] = w

    out = []
    npz = args.out / "source_runs.npz"
    if npz.exists() and not args.overwrite:
        raise SystemExit(f"{npz} exists; pass --overwrite to replace it")
    np.savez_compressed(npz, points=x, heat=heat.snapshots, heat_times=heat.times,
                        wave_one=waves["one source"].snapshots, wave_two=waves["two sources"].snapshots,
                        wave_times=waves["one source"].times)
    out.append(npz)
    if can_render():
        from manifold_sph.viz.render import render_panels

        size = (260, 240) if args.quick else (360, 330)
        panels = {"source_heat.png": ("equator", {f"heat t = {t:g}": u for t, u in zip(heat.times, heat.snapshots)})}
        for label, w in waves.items():
            name = "source_wave_" + label.replace(" ", "_") + ".png"
            panels[name] = ("iso", {f"t = {t:.2f}": u for t, u in zip(w.times, w.snapshots)})
        for name, (camera, fields) in panels.items():
            render_panels(s, fields, camera=camera, panel_size=size, shared_clim=True,
                          filename=args.out / name, overwrite=args.overwrite)
            out.append(args.out / name)
    report(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
