"""Neighbourhood of a particle at a tip of the sausage ([1] Fig. 39; docs/method.md): the normal filter.

    python examples/sausage_neighbourhood.py --out pictures [--quick]

The two ends of the bent capsule are 0.09 apart. A radius search from a particle
at one tip also finds particles of the other tip; the normal filter
(``n_i . n_j > 0``) drops them. Writes ``sausage_neighbourhood.png``.
"""

import numpy as np
from _common import can_render, parse, report

from manifold_sph import Surface
from manifold_sph.neighbors import find_neighbors
from manifold_sph.reference import shapes


def main(argv=None) -> int:
    args = parse(argv, __doc__.splitlines()[0])
    n = 1200 if args.quick else 2652
    cloud = shapes.sausage(n, seed=0)
    s = Surface(cloud, scheme="cspm")
    x, nrm = cloud.points, cloud.normals
    end1 = x[:, 1] > 0  # the ends are mirror images in the plane y = 0
    # particles of one end within reach of the other end; of those the outermost (seen by the camera)
    d_other = np.min(np.linalg.norm(x[end1][:, None, :] - x[~end1][None, ::7, :], axis=2), axis=1) if n < 5000 else None
    close = np.flatnonzero(end1)[d_other < 2.0 * cloud.geometry.gap + 0.05]
    i = int(close[np.argmin(x[close, 0])])
    h = float(s.h[i])  # the smoothing length the Surface uses
    raw = find_neighbors(x[i : i + 1], None, h=h, support=s.kernel.support, candidates=x).neighbors_of(0)
    kept = find_neighbors(x[i : i + 1], nrm[i : i + 1], h=h, support=s.kernel.support, candidates=x,
                          candidate_normals=nrm).neighbors_of(0)
    dropped = np.setdiff1d(raw, kept)
    print(f"particle {i}: {raw.size} particles within the support, {kept.size} kept by the normal filter, "
          f"{dropped.size} dropped (normals facing away: the other end, the far side of the tube)")
    label = np.zeros(n)
    label[kept] = 1.0
    label[dropped] = 2.0
    label[i] = 3.0
    out = []
    if can_render():
        from manifold_sph.viz.render import render_field

        out.append(args.out / "sausage_neighbourhood.png")
        # zoom on the gap: this end near the particle, and of the other end only the dropped neighbours
        near = (np.linalg.norm(x - x[i], axis=1) < 0.45) & (end1 | (label == 2))
        side = -np.cross(nrm[i], [0.0, 0.0, 1.0]) + 0.4 * nrm[i]
        render_field(x[near], label[near], cmap="tab10", clim=(-0.5, 9.5), show_scalar_bar=False,
                     title="red particle: kept (orange), dropped (green)",
                     camera=(tuple(side), (0.0, 0.0, 1.0)), window_size=(560, 480), filename=out[0],
                     overwrite=args.overwrite)
    report(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
