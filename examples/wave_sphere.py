"""Wave equation on the sphere ([1] Figs. 52-53; docs/method.md), as a GIF, and its energy drift.

    python examples/wave_sphere.py --out pictures [--quick] [--mp4]

A Gaussian bump at the north pole travels to the south pole and back (CSPM
Laplacian, centred scheme at half the stability limit). Writes ``wave_sphere.gif``
(``.mp4`` with --mp4) and a plot of the discrete energy over time.
"""

import numpy as np
from _common import can_render, parse, report

from manifold_sph import Surface, pde
from manifold_sph.reference import shapes
from manifold_sph.viz.plots import save_figure


def main(argv=None) -> int:
    args = parse(argv, __doc__.splitlines()[0], **{"--mp4": {"action": "store_true", "help": "also write an MP4"}})
    n = 1002 if args.quick else 4032
    cloud = shapes.sphere(n)
    s = Surface(cloud, scheme="cspm")
    x = cloud.points
    u0 = np.exp(-np.sum((x - [0.0, 0.0, 1.0]) ** 2, axis=1) / (2 * 0.25**2))
    dt = 0.5 * pde.explicit_dt_limit(s, equation="wave")
    t_end = 1.0 if args.quick else 2 * np.pi  # a wave on the unit sphere refocuses at the south pole at t = pi
    steps = int(np.ceil(t_end / dt))
    dt = t_end / steps
    states = []
    frames = 5 if args.quick else 40  # GIF frames (the smoke test renders few)
    res = pde.wave(s, u0, dt=dt, steps=steps, every=max(1, steps // frames),
                   callback=lambda k, t, u: states.append(u.copy()))
    energy = [pde.wave_energy(s, a, b, dt) for a, b in zip(states[:-1], states[1:])]
    print(f"N = {n}, {steps} steps of {dt:.4g} to t = {t_end:.3g}: energy {energy[0]:.5f} -> {energy[-1]:.5f}")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 3.5), layout="constrained")
    ax = fig.add_subplot()
    ax.plot(dt * np.arange(2, len(energy) + 2), energy)
    ax.set_xlabel("t")
    ax.set_ylabel("discrete energy")
    ax.set_title(f"wave on the sphere, CSPM, N = {n}")
    out = [save_figure(fig, args.out / "wave_sphere_energy.png", overwrite=args.overwrite)]
    if can_render():
        from manifold_sph.viz.render import animate

        lim = float(np.abs(res.snapshots).max())
        kw = dict(title="wave equation (CSPM)", bar_title="u", camera="equator", cmap="coolwarm", clim=(-lim, lim),
                  overwrite=args.overwrite)
        out.append(animate(s, res, args.out / "wave_sphere.gif", window_size=(360, 320), **kw))
        if args.mp4:
            out.append(animate(s, res, args.out / "wave_sphere.mp4", window_size=(480, 400), **kw))
    report(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
