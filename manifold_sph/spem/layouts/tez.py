"""TEz particle sets: Hz, Ex and Ey particles, with wall particles on curved or closure walls.

:func:`tez_layout` gives the TEz Yee lattice of a rectangle (Hz at the cell
centres, Ex at ``(i + 1/2, j) dr``, Ey at ``(i, j + 1/2) dr``; the tangential E
particles on the walls flagged fixed), jittered or Poisson sets;
:func:`tez_disk_layout` a circular PEC cavity whose wall particles lie on the
circle with their outward normals and arc lengths; :func:`wall_closure_layout`
turns a rectangle's fixed wall particles into such closure walls.

Examples
--------
>>> lay = tez_layout((0.0, 0.1, 0.0, 0.06), 0.01)
>>> lay.hz.shape, lay.ex.shape, lay.ey.shape
((60, 2), (70, 2), (66, 2))
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..._validation import check_in, check_positive

__all__ = ["TEZ_LAYOUT_KINDS", "POISSON_H_RATIO", "TEzLayout", "tez_layout", "tez_disk_layout", "wall_closure_layout"]


#: Default ``h / dr`` of Poisson layouts (:func:`tez_layout` ``kind="poisson"`` / ``"poisson-shared"``) with the
#: wall closure. Measured (0.1 x 0.06 m, TE10 + TE11, seeds 0-2 at 12 and 24 spacings): 0.8 was refused on
#: 9 of 12 layouts (the wall correction drove a volume negative or missed its conditions), 1.0 on 2 of 12,
#: 1.2 on none (benchmarks/spem_tez_poisson.py).
POISSON_H_RATIO = 1.2


@dataclass(frozen=True)
class TEzLayout:
    """Particles of a TEz problem.

    Attributes
    ----------
    hz, ex, ey : (N, 2) arrays
        Hz, Ex and Ey particles.
    ex_fixed, ey_fixed : bool arrays
        E particles held at zero (tangential E on a PEC wall).
    dr : float
        Spacing.
    bounds : tuple
        ``(xmin, xmax, ymin, ymax)``.
    wall, wall_normal : (M, 2) arrays or None
        Curved PEC walls (:func:`tez_disk_layout`): particles on the conductor
        carrying the tangential E (held at zero) and the outward unit normals.
    wall_length : (M,) array or None
        Arc length of the wall per wall particle (the boundary quadrature).
    volumes : tuple of three arrays or None
        Initial particle volumes (Hz, Ex, Ey; in units of ``dr^2``), e.g. the
        areas of their Voronoi cells clipped to the domain.
    """

    hz: np.ndarray
    ex: np.ndarray
    ey: np.ndarray
    ex_fixed: np.ndarray
    ey_fixed: np.ndarray
    dr: float
    bounds: tuple
    wall: np.ndarray | None = None
    wall_normal: np.ndarray | None = None
    wall_length: np.ndarray | None = None
    volumes: tuple | None = None

    @property
    def curved(self) -> bool:
        """True when the layout has curved PEC walls (wall particles)."""
        return self.wall is not None

    @property
    def n_particles(self) -> int:
        """Hz + Ex + Ey particles (and the wall particles)."""
        return len(self.hz) + len(self.ex) + len(self.ey) + (0 if self.wall is None else len(self.wall))


#: Layout kinds of :func:`tez_layout` and :func:`tez_disk_layout`: the Yee lattice (optionally jittered),
#: independent Poisson-disk sets for Hz, Ex and Ey ("poisson"), or one Poisson set carrying both Ex and Ey
#: ("poisson-shared").
TEZ_LAYOUT_KINDS = ("lattice", "poisson", "poisson-shared")


def _poisson_sets(kind, boxes, rng):
    """Hz, Ex and Ey particles of a Poisson TEz layout: each set a near-uniform sampling
    (:func:`manifold_sph.reference.sampling.square`) of its box (``boxes``: ``(bounds, n)`` for Hz, Ex, Ey,
    and for the E set of "poisson-shared", which carries both Ex and Ey)."""
    from ...reference.sampling import square

    def sample(box):
        return square(max(10, int(box[1])), bounds=box[0], sampling="poisson", seed=rng)

    hz = sample(boxes[0])
    if kind == "poisson-shared":
        e = sample(boxes[3])
        return hz, e, e.copy()
    return hz, sample(boxes[1]), sample(boxes[2])


def tez_layout(bounds: Sequence[float], dr: float, *, amplitude: float = 0.0, seed: int | None = 0,
               kind: str = "lattice") -> TEzLayout:
    """The TEz Yee lattice in a PEC rectangle (the sides multiples of ``dr``), optionally jittered, or a
    Poisson layout.

    ``amplitude`` > 0 moves every Hz particle and every free E particle by a
    uniform random offset of at most ``amplitude * dr`` per coordinate
    (clipped into the rectangle); the wall E particles stay on the walls.

    ``kind="poisson"``: the wall E particles of the lattice (Ex on ``y = const``,
    Ey on ``x = const``, spacing ``dr``), and independent near-uniform random
    sets (:func:`manifold_sph.reference.sampling.square`, seeded) of mean spacing
    ``dr``: Hz in the rectangle, free Ex and free Ey in the rectangle shrunk by
    ``dr / 2`` on each side. ``kind="poisson-shared"``: one such E set carries
    both Ex and Ey (``ex`` and ``ey`` hold the same free points). The Hz
    particles nearest the 2 x 2 corner cells of each corner move to those cells'
    centres (else the closure next to a corner could not meet its conditions).
    ``amplitude`` applies to the lattice only. Run Poisson layouts through
    :func:`wall_closure_layout` (as ``run_tez_cavity(wall_closure=True)`` does).

    >>> lay = tez_layout((0.0, 1.0, 0.0, 0.5), 0.25)
    >>> len(lay.hz), len(lay.ex), int(lay.ex_fixed.sum()), len(lay.ey), int(lay.ey_fixed.sum())
    (8, 12, 8, 10, 4)
    """
    dr = check_positive("dr", dr)
    b = np.asarray(bounds, dtype=np.float64)
    if b.shape != (4,) or not np.all(np.isfinite(b)) or b[1] <= b[0] or b[3] <= b[2]:
        raise ValueError(f"bounds must be (xmin, xmax, ymin, ymax) with xmin < xmax and ymin < ymax, got {bounds!r}")
    nx = int(round((b[1] - b[0]) / dr))
    ny = int(round((b[3] - b[2]) / dr))
    if nx < 2 or ny < 2 or abs(nx * dr - (b[1] - b[0])) > 1e-6 * dr or abs(ny * dr - (b[3] - b[2])) > 1e-6 * dr:
        raise ValueError(f"the sides of bounds {tuple(b.tolist())} must be multiples (>= 2) of dr = {dr}")

    def grid(mx, my, ox, oy):
        X, Y = np.meshgrid(b[0] + (np.arange(mx) + ox) * dr, b[2] + (np.arange(my) + oy) * dr, indexing="ij")
        return np.column_stack([X.ravel(), Y.ravel()])

    check_in("kind", kind, TEZ_LAYOUT_KINDS)
    hz = grid(nx, ny, 0.5, 0.5)
    ex = grid(nx, ny + 1, 0.5, 0.0)
    ey = grid(nx + 1, ny, 0.0, 0.5)
    tol = 1e-6 * dr
    ex_fixed = (np.abs(ex[:, 1] - b[2]) < tol) | (np.abs(ex[:, 1] - b[3]) < tol)
    ey_fixed = (np.abs(ey[:, 0] - b[0]) < tol) | (np.abs(ey[:, 0] - b[1]) < tol)
    amplitude = check_positive("amplitude", amplitude, allow_zero=True)
    if amplitude >= 0.5:
        raise ValueError(f"amplitude must be below 0.5 (particles would cross), got {amplitude}")
    if kind != "lattice":
        if amplitude:
            raise ValueError(f"amplitude applies to kind='lattice' only, got amplitude={amplitude} with kind={kind!r}")
        rng = np.random.default_rng(seed)
        # free Ex / Ey stay dr / 2 off the walls on which they are tangential (the sampler keeps about half
        # a spacing off every side of its box: the first free row is about dr from the wall particles)
        full = tuple(float(v) for v in b)
        boxes = ((full, nx * ny), ((b[0], b[1], b[2] + 0.5 * dr, b[3] - 0.5 * dr), nx * (ny - 1)),
                 ((b[0] + 0.5 * dr, b[1] - 0.5 * dr, b[2], b[3]), (nx - 1) * ny), (full, nx * ny))
        hz, exf, eyf = _poisson_sets(kind, boxes, rng)
        # the 2 x 2 cells at each corner get lattice Hz particles (the nearest Poisson ones move there): the
        # sampler leaves the corners sparse, and the closure of the wall particles there (2-3 Hz particles
        # within reach, nearly collinear) could not meet its conditions (residual 0.3-0.5, seed=1 at 12 and 24)
        hz = hz.copy()
        used = np.zeros(len(hz), bool)
        for cx in (b[0] + 0.5 * dr, b[0] + 1.5 * dr, b[1] - 1.5 * dr, b[1] - 0.5 * dr):
            for cy in (b[2] + 0.5 * dr, b[2] + 1.5 * dr, b[3] - 1.5 * dr, b[3] - 0.5 * dr):
                d = np.where(used, np.inf, np.hypot(hz[:, 0] - cx, hz[:, 1] - cy))
                j = int(np.argmin(d))
                hz[j], used[j] = (cx, cy), True
        ex = np.vstack([exf, ex[ex_fixed]])
        ey = np.vstack([eyf, ey[ey_fixed]])
        ex_fixed = np.r_[np.zeros(len(exf), bool), np.ones(int(ex_fixed.sum()), bool)]
        ey_fixed = np.r_[np.zeros(len(eyf), bool), np.ones(int(ey_fixed.sum()), bool)]
        return TEzLayout(hz, ex, ey, ex_fixed, ey_fixed, dr, tuple(float(v) for v in b))
    if amplitude:
        rng = np.random.default_rng(seed)
        lo, hi = np.array([b[0], b[2]]), np.array([b[1], b[3]])

        def move(p, frozen):
            q = p + amplitude * dr * rng.uniform(-1.0, 1.0, p.shape)
            q[frozen] = p[frozen]
            return np.clip(q, lo, hi)

        hz = move(hz, np.zeros(len(hz), bool))
        ex = move(ex, ex_fixed)
        ey = move(ey, ey_fixed)
    return TEzLayout(hz, ex, ey, ex_fixed, ey_fixed, dr, tuple(float(v) for v in b))


def tez_disk_layout(center: ArrayLike, radius: float, dr: float, *, wall_spacing: float = 0.5,
                    wall_margin: float = 0.3, partner_reach: float = 0.8, amplitude: float = 0.0,
                    seed: int | None = 0, kind: str = "lattice") -> TEzLayout:
    """The TEz Yee lattice clipped to a circular PEC cavity, with wall particles on the circle.

    Hz at ``c + (i + 1/2, j + 1/2) dr``, Ex at ``c + (i + 1/2, j) dr``, Ey at
    ``c + (i, j + 1/2) dr`` (``c`` the centre) strictly inside the circle; E
    particles closer than ``wall_margin * dr`` to the wall are dropped, and so
    is an E particle within 1.5 dr of the wall without an Hz particle on each
    side along its derivative axis (Ex: y, Ey: x) within ``partner_reach * dr``
    (lateral offset at most 0.6 dr): such a particle (its Yee partner cut off
    by the wall) pushed its fitted volume to 1 % of its cell. The wall
    particles (spacing about ``wall_spacing * dr``) carry the tangential E,
    held at zero. ``volumes``: the areas of the particles' Voronoi cells (each
    set on its own) inside the circle, sampled at ``dr / 8``. ``amplitude`` > 0
    then moves every Hz and E particle by a uniform random offset of at most
    ``amplitude * dr`` per coordinate (seeded; particles pushed beyond
    ``radius - 0.05 dr`` are put back on that circle): a jittered layout.
    ``kind="poisson"`` / ``"poisson-shared"``: the Hz, Ex and Ey sets (one E set
    for both components with "poisson-shared") are near-uniform random samplings
    (:func:`manifold_sph.reference.sampling.square`, seeded) of the circle's
    bounding square at density ``1 / dr^2``, clipped as the lattice's
    (``amplitude`` must be 0).

    Examples
    --------
    >>> lay = tez_disk_layout((0.0, 0.0), 0.1, 0.02)
    >>> lay.curved, len(lay.wall), bool(np.all(np.hypot(*lay.hz.T) < 0.1))
    (True, 63, True)
    >>> round(float(lay.volumes[0].sum()) * 0.02**2 / (np.pi * 0.01), 2)  # the Hz cells fill the disk
    1.0
    """
    from scipy.spatial import cKDTree

    radius = check_positive("radius", radius)
    dr = check_positive("dr", dr)
    wall_spacing = check_positive("wall_spacing", wall_spacing)
    wall_margin = check_positive("wall_margin", wall_margin, allow_zero=True)
    partner_reach = check_positive("partner_reach", partner_reach)
    try:
        c = np.asarray(center, dtype=np.float64).reshape(2)
    except (TypeError, ValueError):
        raise ValueError(f"center must be a point (x, y), got {center!r}") from None
    if not np.all(np.isfinite(c)):
        raise ValueError(f"center must be finite, got {center!r}")
    if radius < 2.5 * dr:
        raise ValueError(f"dr = {dr} is too large for radius {radius}: need at least 2.5 spacings per radius")
    if wall_margin >= 1.0:
        raise ValueError(f"wall_margin must be below 1 (spacings), got {wall_margin}")
    n = int(math.ceil(radius / dr)) + 1
    idx = np.arange(-n, n + 1)

    def grid(ox, oy, margin):
        X, Y = np.meshgrid((idx + ox) * dr, (idx + oy) * dr, indexing="ij")
        p = np.column_stack([X.ravel(), Y.ravel()])
        return p[np.hypot(p[:, 0], p[:, 1]) < radius - margin]

    check_in("kind", kind, TEZ_LAYOUT_KINDS)
    if kind == "lattice":
        hz = grid(0.5, 0.5, 0.0)
        candidates = (grid(0.5, 0.0, wall_margin * dr), grid(0.0, 0.5, wall_margin * dr))
    else:
        if amplitude:
            raise ValueError(f"amplitude applies to kind='lattice' only, got amplitude={amplitude} with kind={kind!r}")
        box = ((-radius, radius, -radius, radius), round((2 * radius / dr) ** 2))
        hz, px, py = _poisson_sets(kind, (box, box, box, box), np.random.default_rng(seed))
        hz = hz[np.hypot(hz[:, 0], hz[:, 1]) < radius]
        candidates = tuple(p[np.hypot(p[:, 0], p[:, 1]) < radius - wall_margin * dr] for p in (px, py))
    tree = cKDTree(hz)
    e_sets = []
    for p, axis in zip(candidates, (1, 0)):
        near = np.flatnonzero(np.hypot(p[:, 0], p[:, 1]) > radius - 1.5 * dr)
        keep = np.ones(len(p), bool)
        for q, nb in zip(near, tree.query_ball_point(p[near], partner_reach * dr)):
            d = (hz[nb] - p[q]) / dr
            lateral = np.abs(d[:, 1 - axis]) <= 0.6
            keep[q] = bool(((d[:, axis] > 0.05) & lateral).any() and ((d[:, axis] < -0.05) & lateral).any())
        e_sets.append(p[keep])
    ex, ey = e_sets
    amplitude = check_positive("amplitude", amplitude, allow_zero=True)
    if amplitude >= 0.5:
        raise ValueError(f"amplitude must be below 0.5 (particles would cross), got {amplitude}")
    if amplitude:
        rng = np.random.default_rng(seed)
        lim = radius - 0.05 * dr

        def move(p):
            q = p + amplitude * dr * rng.uniform(-1.0, 1.0, p.shape)
            r = np.hypot(q[:, 0], q[:, 1])
            out = r > lim
            q[out] *= (lim / r[out])[:, None]
            return q

        hz, ex, ey = move(hz), move(ex), move(ey)
    m = max(8, int(math.ceil(2 * math.pi * radius / (wall_spacing * dr))))
    th = 2 * np.pi * (np.arange(m) + 0.5) / m
    normal = np.column_stack([np.cos(th), np.sin(th)])
    # Voronoi areas inside the circle (units of dr^2), sampled on a lattice of spacing dr / 8
    k = 8
    g = (np.arange(-n * k, n * k) + 0.5) / k
    X, Y = np.meshgrid(g, g)
    samples = np.column_stack([X.ravel(), Y.ravel()])
    samples = samples[np.hypot(samples[:, 0], samples[:, 1]) < radius / dr]
    vols = tuple(np.bincount(cKDTree(pts / dr).query(samples)[1], minlength=len(pts)) / k**2 for pts in (hz, ex, ey))
    b = (c[0] - radius, c[0] + radius, c[1] - radius, c[1] + radius)
    return TEzLayout(hz + c, ex + c, ey + c, np.zeros(len(ex), bool), np.zeros(len(ey), bool), dr, b,
                     wall=c + radius * normal, wall_normal=normal, wall_length=np.full(m, 2 * math.pi * radius / m),
                     volumes=vols)


def wall_closure_layout(layout: TEzLayout) -> TEzLayout:
    """A rectangle's layout with its PEC walls treated as curved ones (the wall correction of :class:`TEzSolver`).

    The fixed E particles (tangential E on the walls) become wall particles
    (closure columns, normals outward, each standing for ``dr`` of wall: the
    midpoint rule), the free ones stay unknowns, and the volumes are the
    particles' Voronoi areas in the rectangle (sampled at ``dr / 8``). On
    jittered layouts this converges where the unit-volume ``sbp_pair``
    coupling does not (benchmarks/spem_tez.py).

    >>> lay = wall_closure_layout(tez_layout((0.0, 1.0, 0.0, 0.5), 0.25))
    >>> lay.curved, len(lay.wall), len(lay.ex), len(lay.ey)
    (True, 12, 4, 6)
    """
    from scipy.spatial import cKDTree

    if not isinstance(layout, TEzLayout):
        raise TypeError(f"layout must be a TEzLayout, got {type(layout).__name__}")
    if layout.curved:
        raise ValueError("layout already has wall (closure) particles")
    x0, x1, y0, y1 = layout.bounds
    dr = layout.dr
    exw, eyw = layout.ex[layout.ex_fixed], layout.ey[layout.ey_fixed]
    sy = np.where(np.abs(exw[:, 1] - y0) < np.abs(exw[:, 1] - y1), -1.0, 1.0)
    sx = np.where(np.abs(eyw[:, 0] - x0) < np.abs(eyw[:, 0] - x1), -1.0, 1.0)
    wall = np.vstack([exw, eyw])
    normal = np.vstack([np.column_stack([np.zeros(len(sy)), sy]), np.column_stack([sx, np.zeros(len(sx))])])
    ex, ey = layout.ex[~layout.ex_fixed], layout.ey[~layout.ey_fixed]
    k = 8
    gx = x0 + (np.arange(int(round((x1 - x0) / dr)) * k) + 0.5) * dr / k
    gy = y0 + (np.arange(int(round((y1 - y0) / dr)) * k) + 0.5) * dr / k
    X, Y = np.meshgrid(gx, gy)
    samples = np.column_stack([X.ravel(), Y.ravel()])
    vols = tuple(np.bincount(cKDTree(p).query(samples)[1], minlength=len(p)) / k**2 for p in (layout.hz, ex, ey))
    return TEzLayout(layout.hz, ex, ey, np.zeros(len(ex), bool), np.zeros(len(ey), bool), dr, layout.bounds,
                     wall=wall, wall_normal=normal, wall_length=np.full(len(wall), dr), volumes=vols)
