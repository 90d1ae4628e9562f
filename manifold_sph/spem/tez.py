"""TEz polarisation (Hz, Ex, Ey) on particles, beside the TMz solver (issue 21 item 4).

The fields of TEz waves in the plane:

    mu dHz/dt = dEx/dy - dEy/dx,   eps dEx/dt = dHz/dy,   eps dEy/dt = -dHz/dx,

leap-frog with Hz at integer and E at half steps. The layout is the Yee
lattice of TEz (:func:`tez_layout`): Hz at the cell centres, Ex at
``(i + 1/2, j) dr`` and Ey at ``(i, j + 1/2) dr``; on a PEC wall the
tangential E particles (Ex on the walls ``y = const``, Ey on ``x = const``)
are held at zero and Hz needs no boundary particle (its condition,
``dHz/dn = 0``, is natural).

Couplings, as in :class:`.TMzSolver`:

``"sbp"`` (default)
    The Hz rows ``D`` (CSPM derivatives of the free E particles; the wall
    particles carry zero) are corrected by :func:`.operators.sbp_pair` so
    that the E rows ``-V_E^-1 D^T V_Hz`` are exact for linear fields: a
    skew-adjoint pair, so leap-frog conserves the discrete energy.
``"adjoint"``
    The E rows are ``-D^T`` without the correction (energy-conserving, not
    consistent next to walls).
``"direct"``
    Each set by its own CSPM derivatives; the spectrum of the Hz -> Hz
    operator is computed and a growing layout refused (ValueError).

Curved PEC walls (:func:`tez_disk_layout`, :func:`run_tez_circular_cavity`)
    Wall particles on the conductor carry only the tangential component of
    E, held at zero (no normal E on the wall, as on the straight walls of the
    rectangle). The Hz rows are one curl operator ``C`` over every free Ex
    and Ey particle plus *closure* columns at the wall particles (they
    multiply zero fields). In the flux weights ``Q = V_Hz C`` and the
    particle volumes ``V_Hz``, ``V_E`` the conditions below are linear; the
    smallest change of the CSPM weights and of the Voronoi volumes (in a band
    next to the wall; the lattice interior meets them already) that meets
    them exactly is one sparse normal-equations solve (:func:`_curl_sbp`):
    ``C`` exact for linear (Ex, Ey) (the wall particles' tangential
    components included), ``G = -V_E^-1 C^T V_Hz`` exact for linear Hz at
    every free E particle, and the closure columns equal to the wall's
    arc-length quadrature (``sum_i Q_iw phi_i = -s_w phi(x_w)`` for linear
    ``phi``: the discrete form of ``int phi curl E = -int E . curl phi -
    oint phi E_t``). The pair is skew-adjoint in the volume inner products,
    so leap-frog conserves ``sum V mu Hz^2 + sum V eps E^{n+1/2} E^{n-1/2}``.
    Without the quadrature condition the frequency does not converge
    (the closure then places the wall O(dr) off).

Poisson layouts (``kind="poisson"`` / ``"poisson-shared"`` of :func:`tez_layout` and :func:`tez_disk_layout`)
    Near-uniform random Hz, Ex and Ey sets (or one E set carrying both
    components), run with the wall correction above (the rectangle through
    :func:`wall_closure_layout`) at ``h / dr`` = :data:`POISSON_H_RATIO`.
    Measured (benchmarks/spem_tez_poisson.py, seeds 0-2): the error of smooth
    modes converges at second order (rectangle 12 / 24 / 48 spacings:
    1.3e-1 / 2.9e-2 / 6.3e-3, the jittered lattice 1.9e-2 / 3.8e-3 / 9.0e-4),
    energy is conserved, but the Hz operator has spurious modes below the
    fundamental (11-24 of its 24 lowest on the rectangle at 18 spacings and the
    disk at 12 per radius, the lowest at 0.36-0.66 of the fundamental frequency,
    spread over 7-80 particles; none on the lattices): the CSPM gradient at the E
    particles, averaged over a kernel of 2.4 dr, hardly sees short-wave Hz
    patterns of an unstaggered set (larger ``h`` lowers them further; below
    1.2 dr the wall correction was refused on most layouts). Adding E particles
    where Hz outnumbers them (``layouts.balance_h``) or relaxing the E sets
    into the Hz gaps (``layouts.relax_h``) did not remove them (rectangle,
    seed=1, 18 spacings: all 13 lowest non-static modes below TE10, the lowest
    at 0.62 / 0.53 of it, against 11 and 0.64 without). Smooth fields hardly
    excite them; a broadband source would. A lead (not built): one E set at
    the midpoints of the Hz set's Delaunay edges left none below TE10 on the
    rectangle (the lowest spurious at 1.3-1.6 f_10; a Poisson E set of the
    same count: 1.0-1.2; benchmarks/spem_tez_poisson.py --only edges).

Examples
--------
>>> r = run_tez_cavity(n=6, modes=((1, 0),))
>>> r.case, r.frequency_error < 0.02
('tez-cavity', True)
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from .._validation import check_in, check_int, check_positive
from .constants import C0, EPS0, MU0
from .operators import SBP_LAYERS, cross_gradient, sbp_pair
from .solver import COUPLINGS, DEFAULT_COUPLING, DEFAULT_H_RATIO, STABILITY_MARGIN, leapfrog_growth, spectral_radius_bound

#: Couplings of :class:`TEzSolver` (those of :class:`.TMzSolver` but "mimetic").
TEZ_COUPLINGS = tuple(c for c in COUPLINGS if c != "mimetic")

__all__ = ["TEZ_LAYOUT_KINDS", "POISSON_H_RATIO", "TEzLayout", "tez_layout",
           "tez_disk_layout", "wall_closure_layout", "TEzSolver", "TEzCavityResult",
           "tez_cavity_frequency",
           "run_tez_cavity", "tez_disk_frequency", "tez_disk_mode", "run_tez_circular_cavity"]

#: Default ``h / dr`` of the circular TEz cavity. Measured (TE11 + TE21, 10 / 20 / 40 spacings per radius):
#: 0.7 gave a stable step of 0.68 / 0.57 / 0.29 of the CFL step (stiff particles next to the wall), 0.8
#: 0.89 / 0.89 / 0.84 with errors within 30 %; at 0.8 the frequency error is the lattice's own dispersion.
DISK_H_RATIO = 0.8
#: Weight of the relative volume changes against the flux-weight changes in the wall correction.
DISK_VOLUME_WEIGHT = 0.01
#: The wall correction changes flux weights and volumes within ``max(DISK_BAND * dr, 2 kappa h)`` of the wall.
DISK_BAND = 3.0
#: Default ``h / dr`` of Poisson layouts (:func:`tez_layout` ``kind="poisson"`` / ``"poisson-shared"``) with the
#: wall closure. Measured (0.1 x 0.06 m, TE10 + TE11, seeds 0-2 at 12 and 24 spacings): 0.8 was refused on
#: 9 of 12 layouts (the wall correction drove a volume negative or missed its conditions), 1.0 on 2 of 12,
#: 1.2 on none (benchmarks/spem_tez_poisson.py).
POISSON_H_RATIO = 1.2
#: Closure (wall) columns get every Hz particle within ``max(DISK_CLOSURE_REACH * dr, kappa h)`` of the wall particle.
DISK_CLOSURE_REACH = 2.0


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
    from ..reference.sampling import square

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


def _curl_sbp(hz: np.ndarray, cols: np.ndarray, dirs: np.ndarray, C0: sp.csr_matrix, n_free: int,
              wall_length: np.ndarray, vol_hz: np.ndarray, vol_e: np.ndarray, width: float, scale: float,
              volume_weight: float = DISK_VOLUME_WEIGHT):
    """Flux weights and volumes of the energy-conserving TEz curl pair next to curved walls (module docstring).

    ``C0`` (Hz rows) approximates ``dEx/dy - dEy/dx`` from the E columns: the
    first ``n_free`` are free Ex / Ey particles, the rest wall (closure)
    columns; column ``k`` carries the component ``dirs[k] . E`` at ``cols[k]``.
    Unknowns: ``Q = V_Hz C`` on the pattern of ``C0``, ``V_Hz``, ``V_E`` (units
    ``dr^2``); only those of particles within ``width`` of a wall particle or
    of a particle farther than ``2 width`` from the wall that misses its
    conditions (everywhere on irregular layouts, nowhere inside a lattice)
    change; when that band cannot meet the conditions (to 1e-6) the whole
    operator does. Conditions: every Hz row exact for the six linear (Ex, Ey);
    every free column's adjoint ``-V_E^-1 C^T V_Hz`` exact for linear Hz;
    every closure column ``sum_i Q_iw {1, x_i - x_w, y_i - y_w} = {-s_w, 0, 0}``.
    Minimum of ``|dQ|^2 + sum (dV / V0)^2 / volume_weight`` by one sparse
    normal-equations solve.

    Returns
    -------
    C : csr (n_hz, n_cols)
        ``Q / V_Hz`` (closure columns included).
    vol_hz, vol_e : arrays
        The volumes (units of ``dr^2``).
    residual : float
        Largest violated condition (dimensionless).
    """
    from scipy.sparse.linalg import spsolve

    C0 = sp.csr_matrix(C0)
    C0.sort_indices()
    nr, nc = C0.shape
    i = np.repeat(np.arange(nr), np.diff(C0.indptr))
    k = C0.indices
    P = len(k)
    x = (cols[k] - hz[i]) / scale
    d = dirs[k]
    y = -x
    # row conditions (6 per Hz particle): E = (1, 0), (0, 1), (x, 0), (y, 0), (0, x), (0, y); curl = dEx/dy - dEy/dx
    r_idx = [6 * i + m for m in range(6)]
    r_val = [d[:, 0], d[:, 1], d[:, 0] * x[:, 0], d[:, 0] * x[:, 1], d[:, 1] * x[:, 0], d[:, 1] * x[:, 1]]
    ar = np.arange(nr)
    # column conditions (3 per column): sum_i Q_ik {1, x_i - x_k, y_i - y_k} = V_k {0, d_y, -d_x} (free columns)
    c_idx = [6 * nr + 3 * k + m for m in range(3)]
    c_val = [np.ones(P), y[:, 0], y[:, 1]]
    ae = np.arange(n_free)
    rows = np.concatenate(r_idx + c_idx + [6 * ar + 3, 6 * ar + 4, 6 * nr + 3 * ae + 1, 6 * nr + 3 * ae + 2])
    unk = np.concatenate([np.tile(np.arange(P), 9), P + ar, P + ar, P + nr + ae, P + nr + ae])
    vals = np.concatenate(r_val + c_val + [-np.ones(nr), np.ones(nr), -dirs[:n_free, 1], dirs[:n_free, 0]])
    n_con = 6 * nr + 3 * nc
    A = sp.csr_matrix((vals, (rows, unk)), shape=(n_con, P + nr + n_free))
    target = np.zeros(n_con)
    target[6 * nr + 3 * n_free :: 3] = -np.asarray(wall_length) / scale
    u0 = np.r_[C0.data * scale * vol_hz[i], vol_hz, vol_e]
    weight = np.r_[np.ones(P), volume_weight * np.r_[vol_hz, vol_e] ** 2]
    r = target - A @ u0
    from scipy.spatial import cKDTree

    bad = np.r_[np.abs(r[: 6 * nr]).reshape(nr, 6).max(axis=1), np.abs(r[6 * nr : 6 * nr + 3 * n_free])
                .reshape(n_free, 3).max(axis=1)] > 1e-9
    # seeds: the wall, and the particles missing their conditions farther from it than 2 widths (irregular
    # layouts; on a lattice every such particle is next to the wall, and a band grown around them spread the
    # correction and measured a less accurate field: 5.3e-3 against 7.8e-3 at 20 spacings per radius)
    wall_tree = cKDTree(cols[n_free:])
    far = np.r_[wall_tree.query(hz)[0], wall_tree.query(cols[:n_free])[0]] > 2.0 * width
    seeds = np.vstack([cols[n_free:], hz[(bad & far)[:nr]], cols[:n_free][(bad & far)[nr:]]])
    tree = cKDTree(seeds)
    near_hz = tree.query(hz, distance_upper_bound=width)[0] < width
    near_c = tree.query(cols, distance_upper_bound=width)[0] < width
    on = np.r_[near_hz[i] | near_c[k], near_hz, near_c[:n_free]]
    for attempt in range(2):
        con = np.asarray(abs(A[:, on]).sum(axis=1)).ravel() > 0
        As = A[con][:, on]
        ws = weight[on]
        M = (As @ sp.diags(ws) @ As.T).tocsc()
        M = M + sp.identity(M.shape[0], format="csc") * (1e-12 * M.diagonal().max())
        u = u0.copy()
        u[on] += ws * (As.T @ spsolve(M, r[con]))
        residual = float(np.abs(target - A @ u).max())
        if residual < 1e-6 or on.all():
            break
        on = np.ones(len(u0), bool)  # the band could not meet them (small or irregular layouts): the whole operator
    vh, ve = u[P : P + nr], u[P + nr :]
    with np.errstate(divide="ignore", invalid="ignore"):
        C = sp.csr_matrix((u[:P] / scale / vh[i], C0.indices.copy(), C0.indptr.copy()), shape=C0.shape)
    return C, vh, ve, residual


class TEzSolver:
    """Leap-frog SPEM for TEz waves (module docstring) in a PEC rectangle or a cavity with curved PEC walls.

    Parameters
    ----------
    layout : TEzLayout
        :func:`tez_layout` (rectangle) or :func:`tez_disk_layout` (curved walls: couplings "sbp" and
        "adjoint"; "direct" is refused).
    h_ratio : float
        ``h / dr`` (default 0.7, cubic kernel; :data:`DISK_H_RATIO` suits curved walls).
    eps_r, mu_r : float
        Relative permittivity (E particles) and permeability (Hz particles), finite and > 0.
    coupling : {"sbp", "adjoint", "direct"}
    courant : float
        Fraction of the smaller of the CFL step ``h / (sqrt(2) c_max)`` and
        the spectral limit ``2 / sqrt(rho)`` (default 0.9).
    kernel, form : str
        As :func:`.operators.cross_gradient`.
    sbp_layers : int or None
        As :class:`.TMzSolver`.

    Examples
    --------
    >>> s = TEzSolver(tez_layout((0.0, 0.1, 0.0, 0.1), 0.01))
    >>> s.set_initial(np.cos(np.pi * s.layout.hz[:, 0] / 0.1))
    >>> _ = s.run(50)
    >>> bool(abs(s.energy() / s.energy0 - 1) < 1e-12)  # "sbp": the discrete energy is conserved
    True
    """

    def __init__(self, layout: TEzLayout, *, h_ratio: float = DEFAULT_H_RATIO, eps_r: float = 1.0, mu_r: float = 1.0,
                 coupling: str = DEFAULT_COUPLING, courant: float = 0.9, kernel: str = "cubic", form: str = "fpm",
                 sbp_layers: int | None = SBP_LAYERS) -> None:
        if not isinstance(layout, TEzLayout):
            raise TypeError(f"layout must be a TEzLayout, got {type(layout).__name__}")
        self.layout = layout
        self.h = check_positive("h_ratio", h_ratio) * layout.dr
        if coupling == "mimetic":  # not built for TEz (its wall particles are the vector set's): never run another
            raise ValueError("coupling 'mimetic' is available for TMz only (TMzSolver); TEzSolver offers "
                             f"{', '.join(repr(c) for c in TEZ_COUPLINGS)}")
        self.coupling = check_in("coupling", coupling, TEZ_COUPLINGS)
        courant = check_positive("courant", courant)
        if courant > 1:
            raise ValueError(f"courant must be at most 1, got {courant}")
        self.eps = EPS0 * check_positive("eps_r", eps_r)
        self.mu = MU0 * check_positive("mu_r", mu_r)
        self.c_max = 1.0 / math.sqrt(self.eps * self.mu)
        lay = layout
        self.fx = np.flatnonzero(~lay.ex_fixed)
        self.fy = np.flatnonzero(~lay.ey_fixed)
        self.vol_hz, self.vol_ex, self.vol_ey = np.ones(len(lay.hz)), np.ones(len(self.fx)), np.ones(len(self.fy))
        self.sbp_residual = 0.0
        kw = {"kernel": kernel, "form": form}
        if lay.curved:
            self._assemble_curved(kw)
        else:
            self._assemble_straight(kw, sbp_layers)
        L = (self.Dx @ self.Gx + self.Dy @ self.Gy) / (self.eps * self.mu)  # Hz'' = L Hz
        self._check_spectrum(L.tocsr(), courant)
        self.reset()

    def _assemble_straight(self, kw, sbp_layers):
        """Rectangles: the Hz rows from the free E particles (wall E columns dropped), corrected by ``sbp_pair``."""
        lay = self.layout
        # Hz rows: d/dx of Ey and d/dy of Ex (the wall E particles carry zero: their columns are dropped)
        Dx = cross_gradient(lay.hz, lay.ey, self.h, row_name="Hz particles", col_name="Ey particles", **kw)[0]
        Dy = cross_gradient(lay.hz, lay.ex, self.h, row_name="Hz particles", col_name="Ex particles", **kw)[1]
        Dx, Dy = sp.csr_matrix(Dx)[:, self.fy], sp.csr_matrix(Dy)[:, self.fx]
        if self.coupling == "sbp":
            vol_h = np.ones(len(lay.hz))
            Dx, _ = sbp_pair(Dx, lay.hz, lay.ey[self.fy], 0, vol_h, np.ones(len(self.fy)), scale=lay.dr,
                             layers=sbp_layers)
            Dy, _ = sbp_pair(Dy, lay.hz, lay.ex[self.fx], 1, vol_h, np.ones(len(self.fx)), scale=lay.dr,
                             layers=sbp_layers)
        if self.coupling == "direct":
            Gx = cross_gradient(lay.ey[self.fy], lay.hz, self.h, row_name="Ey particles", col_name="Hz particles",
                                **kw)[0]
            Gy = cross_gradient(lay.ex[self.fx], lay.hz, self.h, row_name="Ex particles", col_name="Hz particles",
                                **kw)[1]
        else:
            Gx, Gy = -Dx.T, -Dy.T
        self.Dx, self.Dy, self.Gx, self.Gy = (sp.csr_matrix(M) for M in (Dx, Dy, Gx, Gy))

    def _assemble_curved(self, kw):
        """Curved PEC walls: one curl operator over the free E particles and the wall closure (module docstring)."""
        from scipy.spatial import cKDTree

        from ..kernels import get_kernel

        lay = self.layout
        if self.coupling == "direct":
            raise ValueError("coupling 'direct' is not available with curved PEC walls (its spectrum is not "
                             "controlled next to the wall); use coupling='sbp' (energy-conserving) or 'adjoint'")
        dr, wall, nrm = lay.dr, lay.wall, lay.wall_normal
        ex, ey = lay.ex[self.fx], lay.ey[self.fy]
        nx, ny, nw = len(ex), len(ey), len(wall)
        Dy = sp.csr_matrix(cross_gradient(lay.hz, np.vstack([ex, wall]), self.h, row_name="Hz particles",
                                          col_name="Ex and wall particles", **kw)[1])
        Dx = sp.csr_matrix(cross_gradient(lay.hz, np.vstack([ey, wall]), self.h, row_name="Hz particles",
                                          col_name="Ey and wall particles", **kw)[0])
        tau = np.column_stack([-nrm[:, 1], nrm[:, 0]])
        # the wall columns: only the tangential component (held at zero); the normal one is not represented
        Cw = Dy[:, nx:] @ sp.diags(tau[:, 0]) - Dx[:, ny:] @ sp.diags(tau[:, 1])
        support = get_kernel(kw["kernel"]).support * self.h
        reach = max(DISK_CLOSURE_REACH * dr, support)
        pairs = cKDTree(wall).sparse_distance_matrix(cKDTree(lay.hz), reach, output_type="ndarray")
        Cw = (Cw + sp.csr_matrix((np.full(len(pairs), 1e-300), (pairs["j"], pairs["i"])), shape=Cw.shape)).tocsr()
        C0 = sp.hstack([Dy[:, :nx], -Dx[:, :ny], Cw]).tocsr()
        vh0 = lay.volumes[0] if lay.volumes is not None else np.ones(len(lay.hz))
        ve0 = np.r_[lay.volumes[1][self.fx], lay.volumes[2][self.fy]] if lay.volumes is not None else np.ones(nx + ny)
        if self.coupling == "sbp":
            cols = np.vstack([ex, ey, wall])
            dirs = np.vstack([np.tile([1.0, 0.0], (nx, 1)), np.tile([0.0, 1.0], (ny, 1)), tau])
            width = max(DISK_BAND * dr, 2.0 * support)
            C, vh, ve, self.sbp_residual = _curl_sbp(lay.hz, cols, dirs, C0, nx + ny, lay.wall_length, vh0, ve0,
                                                     width, dr)
            if self.sbp_residual > 1e-6:
                raise ValueError(f"the wall correction cannot meet its conditions (largest residual "
                                 f"{self.sbp_residual:.3g}): the operators would be inconsistent; change h_ratio "
                                 f"or the layout")
            if not (np.all(vh > 0.05 * vh0) and np.all(ve > 0.05 * ve0)):
                raise ValueError(f"the wall correction left a particle volume at or below 5 % of its cell "
                                 f"(min Hz {float(np.min(vh / vh0)):.3g}, E {float(np.min(ve / ve0)):.3g} of the "
                                 f"cell): change h_ratio or the layout's wall_spacing / wall_margin")
        else:  # "adjoint": the uncorrected curl and its adjoint in the Voronoi volumes (energy-conserving)
            C, vh, ve = C0, vh0, ve0
        self.curl = C[:, : nx + ny].tocsr()
        self.closure = C[:, nx + ny :].tocsr()  # multiplies the zero tangential E on the wall
        self.vol_hz, self.vol_ex, self.vol_ey = vh, ve[:nx], ve[nx:]
        G = (sp.diags(1.0 / ve) @ (-self.curl.T) @ sp.diags(vh)).tocsr()
        # as the rectangle's four matrices: mu dHz/dt = Dy Ex - Dx Ey, eps dEx/dt = Gy Hz, eps dEy/dt = -Gx Hz
        self.Dy, self.Dx = self.curl[:, :nx].tocsr(), (-self.curl[:, nx:]).tocsr()
        self.Gy, self.Gx = G[:nx].tocsr(), (-G[nx:]).tocsr()

    def _check_spectrum(self, L, courant):
        from scipy.sparse.linalg import eigs

        if self.coupling == "direct":
            lam = np.linalg.eigvals(L.toarray()) if L.shape[0] <= 900 else np.concatenate(
                [eigs(L, k=8, which="LM", return_eigenvectors=False), eigs(L, k=8, which="LI",
                                                                        return_eigenvectors=False)])
            rho = float(np.abs(lam).max())
        else:
            lam = None
            r = np.sqrt(self.vol_hz)
            S = (sp.diags(r) @ L @ sp.diags(1.0 / r)).tocsr()  # V^1/2 L V^-1/2 = -V^1/2 C V_E^-1 C^T V^1/2 / (eps mu)
            theta, bound = spectral_radius_bound(0.5 * (S + S.T))  # negative semi-definite
            rho = max(bound, theta * (1.0 + STABILITY_MARGIN)) / (1.0 + STABILITY_MARGIN)  # as TMzSolver's
        self.dt_stable = 2.0 / math.sqrt(rho * (1.0 + STABILITY_MARGIN))  # the margin: at least 0.5 %
        self.dt = courant * min(self.dt_stable, self.h / (math.sqrt(2.0) * self.c_max))
        if lam is not None:
            g = float(leapfrog_growth(lam, self.dt).max())
            if g > 1.0 + 1e-12:
                raise ValueError(f"the direct coupling is unstable on this layout: a leap-frog mode grows by {g:.6g} "
                                 f"per step; use coupling='sbp' (energy-conserving)")

    @property
    def n_particles(self) -> int:
        """Hz + Ex + Ey particles."""
        return self.layout.n_particles

    def reset(self) -> None:
        """Zero the fields, t = 0."""
        self.hz = np.zeros(len(self.layout.hz))
        self.ex = np.zeros(len(self.fx))
        self.ey = np.zeros(len(self.fy))
        self.t, self.n = 0.0, 0
        self.energy0 = 0.0

    def set_dt(self, dt: float) -> None:
        """Change the step (below the CFL and spectral limits); call before :meth:`set_initial`."""
        dt = check_positive("dt", dt)
        limit = min(self.dt_stable, self.h / (math.sqrt(2.0) * self.c_max))
        if dt >= limit:
            raise ValueError(f"dt = {dt:.4g} s exceeds the stability limit {limit:.4g} s")
        self.dt = dt

    def set_initial(self, hz0: ArrayLike) -> None:
        """Hz(0) = hz0 with E(0) = 0, E advanced half a step (second order for fields even in time)."""
        from .._validation import as_field

        self.reset()
        self.hz = as_field("hz0", hz0, len(self.layout.hz)).copy()
        self.ex = 0.5 * self.dt / self.eps * (self.Gy @ self.hz)
        self.ey = -0.5 * self.dt / self.eps * (self.Gx @ self.hz)
        self.energy0 = self.energy()

    def energy(self) -> float:
        """``mu Hz^n . V Hz^n + eps E^{n+1/2} . V E^{n-1/2}``, conserved by leap-frog when ``G = -V^-1 D^T V``.

        The volumes ``V`` are 1 on rectangles and fitted next to curved walls ("sbp", "adjoint").

        ``E^{n-1/2}`` is reconstructed from the last update.
        """
        ex_prev = self.ex - self.dt / self.eps * (self.Gy @ self.hz)
        ey_prev = self.ey + self.dt / self.eps * (self.Gx @ self.hz)
        return float(self.mu * (self.vol_hz * self.hz) @ self.hz
                     + self.eps * ((self.vol_ex * self.ex) @ ex_prev + (self.vol_ey * self.ey) @ ey_prev))

    def step(self) -> None:
        """Hz to t + dt, then E to t + 3 dt / 2."""
        self.hz += self.dt / self.mu * (self.Dy @ self.ex - self.Dx @ self.ey)
        self.n += 1
        self.t = self.n * self.dt
        self.ex += self.dt / self.eps * (self.Gy @ self.hz)
        self.ey -= self.dt / self.eps * (self.Gx @ self.hz)

    def run(self, steps: int, probe: int | None = None) -> np.ndarray:
        """Advance ``steps`` steps; the Hz series at particle ``probe`` (empty without)."""
        steps = check_int("steps", steps, minimum=0)
        out = np.empty(steps if probe is not None else 0)
        for k in range(steps):
            self.step()
            if probe is not None:
                out[k] = self.hz[probe]
        return out


def tez_cavity_frequency(a: float, b: float, m: int, n: int, eps_r: float = 1.0, mu_r: float = 1.0) -> float:
    """Exact TE_mn resonance ``c / (2 sqrt(eps_r mu_r)) sqrt((m/a)^2 + (n/b)^2)`` of a PEC rectangle a x b (Hz).

    >>> round(tez_cavity_frequency(0.1, 0.05, 1, 0) / 1e9, 6)
    1.498962
    """
    a, b = check_positive("a", a), check_positive("b", b)
    m, n = check_int("m", m, minimum=0), check_int("n", n, minimum=0)
    if m == n == 0:
        raise ValueError("m and n must not both be 0 (TE_00 is not a mode)")
    return C0 / (2 * math.sqrt(eps_r * mu_r)) * math.hypot(m / a, n / b)


@dataclass(frozen=True)
class TEzCavityResult:
    """What :func:`run_tez_cavity` measured.

    ``error``: relative L2 error of Hz after ``periods`` periods of the first
    mode (its initial field evolved exactly); ``frequency_error``: relative
    error of that mode's resonance, fitted to the projection of Hz onto the mode.
    :func:`run_tez_circular_cavity` also gives ``probe_frequency_error`` (the
    peak of the spectrum of Hz at one particle) and ``stable_fraction`` (the
    time step over the CFL step ``h / (sqrt(2) c)``).
    """

    case: str
    error: float
    frequency_error: float
    frequency: float
    exact_frequency: float
    particles: int
    steps: int
    seconds: float
    dr: float
    dt: float
    coupling: str
    layout: str
    probe_frequency_error: float | None = None
    stable_fraction: float | None = None

    def to_dict(self) -> dict:
        """The fields as a JSON-ready dict."""
        return dict(self.__dict__)


def _check_modes(modes) -> list[tuple[int, int]]:
    """``modes`` as a non-empty list of ``(m, n)`` integer pairs (ValueError otherwise)."""
    try:
        modes = [(int(m), int(k)) for m, k in modes]
    except (TypeError, ValueError):
        raise ValueError(f"modes must be a sequence of (m, n) integer pairs, got {modes!r}") from None
    if not modes:
        raise ValueError("modes must name at least one (m, n) mode")
    return modes


def run_tez_cavity(*, a: float = 0.1, b: float = 0.06, n: int = 12, modes: Sequence[tuple[int, int]] = ((1, 0), (1, 1)),
                   eps_r: float = 1.0, layout: str = "yee", amplitude: float = 0.2, seed: int | None = 0,
                   coupling: str = DEFAULT_COUPLING, h_ratio: float | None = None,
                   courant: float = 0.9, periods: float = 1.0, spectrum_periods: float = 5.0,
                   sbp_layers: int | None = SBP_LAYERS, wall_closure: bool = False) -> TEzCavityResult:
    """TEz modes of a PEC rectangle ``a x b``: ``Hz = sum cos(m pi x/a) cos(n pi y/b) cos(w_mn t)``.

    ``n`` spacings along ``b`` (``dr = b / n``; ``a`` must be a multiple of
    ``dr``). The field starts as the sum of the ``modes`` (each ``(m, n)``),
    runs ``periods`` periods of the first, and is compared with the exact
    evolution (``error``; on ``layout="jittered"`` particles the particles
    move by up to ``amplitude * dr``); the run continues ``spectrum_periods``
    periods and the first mode's resonance is fitted to the projection of Hz
    onto it (``frequency_error``). ``wall_closure=True``: the walls as closure
    columns with fitted volumes (:func:`wall_closure_layout`; couplings "sbp"
    and "adjoint"), which converges on jittered layouts too. ``h_ratio``
    defaults to 0.7, with ``wall_closure`` to :data:`DISK_H_RATIO` (at 0.7 an Hz
    volume of the lattice rectangle's correction turns negative and the layout is refused).

    Examples
    --------
    >>> r = run_tez_cavity(n=6)
    >>> r.error < 0.05, r.frequency_error < 0.005  # measured 4.2e-2 and 3.3e-3
    (True, True)
    """
    t0 = time.perf_counter()
    n = check_int("n", n, minimum=2)
    periods = check_positive("periods", periods)
    spectrum_periods = check_positive("spectrum_periods", spectrum_periods)
    modes = _check_modes(modes)
    dr = check_positive("b", b) / n
    check_in("layout", layout, ("yee", "jittered", "poisson", "poisson-shared"))
    if not isinstance(wall_closure, bool):
        raise TypeError(f"wall_closure must be True or False, got {wall_closure!r}")
    lay = tez_layout((0.0, check_positive("a", a), 0.0, b), dr, amplitude=amplitude if layout == "jittered" else 0.0,
                     seed=seed, kind=layout if layout.startswith("poisson") else "lattice")
    if wall_closure:
        lay = wall_closure_layout(lay)
    if h_ratio is None:
        h_ratio = (POISSON_H_RATIO if layout.startswith("poisson") else DISK_H_RATIO) if wall_closure \
            else DEFAULT_H_RATIO
    s = TEzSolver(lay, h_ratio=h_ratio, eps_r=eps_r, coupling=coupling, courant=courant, sbp_layers=sbp_layers)
    x, y = lay.hz.T
    shapes = [np.cos(m * np.pi * x / a) * np.cos(k * np.pi * y / b) for m, k in modes]
    freqs = [tez_cavity_frequency(a, b, m, k, eps_r) for m, k in modes]
    T = periods / freqs[0]
    steps = int(math.ceil(T / s.dt - 1e-9))
    s.set_dt(T / steps)
    s.set_initial(sum(shapes))
    s.run(steps)
    exact = sum(f * math.cos(2 * math.pi * fr * s.t) for f, fr in zip(shapes, freqs))
    err = float(np.linalg.norm(s.hz - exact) / np.linalg.norm(exact))
    # the first mode's resonance: its amplitude a(t) = q.Hz over ``spectrum_periods`` more periods, fitted by
    # A cos(w t) + B sin(w t) (least squares over w)
    q = shapes[0] / (shapes[0] @ shapes[0])
    more = int(round(spectrum_periods / freqs[0] / s.dt))
    amp = np.empty(more)
    for k in range(more):
        s.step()
        amp[k] = q @ s.hz
    fm = _fit_frequency(amp, s.dt * (steps + 1 + np.arange(more)), freqs[0])
    return TEzCavityResult("tez-cavity", err, abs(fm - freqs[0]) / freqs[0], fm, freqs[0], lay.n_particles, s.n,
                           time.perf_counter() - t0, dr, s.dt, coupling, layout)


def _fit_frequency(signal, times, f0):
    """The frequency ``f`` near ``f0`` (within 10 %) of the best fit ``A cos(2 pi f t) + B sin(2 pi f t)``."""
    from scipy.optimize import minimize_scalar

    def residual(f):
        M = np.column_stack([np.cos(2 * np.pi * f * times), np.sin(2 * np.pi * f * times)])
        coef = np.linalg.lstsq(M, signal, rcond=None)[0]
        return float(np.sum((M @ coef - signal) ** 2))

    grid = f0 * np.linspace(0.9, 1.1, 81)
    k = int(np.argmin([residual(f) for f in grid]))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    return float(minimize_scalar(residual, bounds=(lo, hi), method="bounded", options={"xatol": 1e-9 * f0}).x)


def tez_disk_frequency(radius: float, m: int, n: int, eps_r: float = 1.0, mu_r: float = 1.0) -> float:
    """Exact TE_mn resonance ``c j'_mn / (2 pi a sqrt(eps_r mu_r))`` of a circular PEC cavity of radius ``a`` (Hz).

    ``j'_mn`` is the n-th positive zero of ``J_m'`` (TE11: 1.8412, TE21: 3.0542, TE01: 3.8317).

    >>> [round(tez_disk_frequency(0.1, m, 1) * 2 * np.pi * 0.1 / C0, 4) for m in (1, 0)]
    [1.8412, 3.8317]
    """
    from scipy.special import jnp_zeros

    radius = check_positive("radius", radius)
    m, n = check_int("m", m, minimum=0), check_int("n", n, minimum=1)
    eps_r, mu_r = check_positive("eps_r", eps_r), check_positive("mu_r", mu_r)
    return float(C0 * jnp_zeros(m, n)[-1] / (2 * math.pi * radius * math.sqrt(eps_r * mu_r)))


def tez_disk_mode(points: ArrayLike, center: ArrayLike, radius: float, m: int, n: int) -> np.ndarray:
    """The TE_mn mode ``Hz = J_m(j'_mn r / a) cos(m phi)`` of a circular PEC cavity at ``points`` ((N, 2)).

    >>> float(tez_disk_mode([[0.0, 0.0]], (0.0, 0.0), 0.1, 0, 1)[0])
    1.0
    """
    from scipy.special import jnp_zeros, jv

    from .._validation import as_points

    p = as_points("points", points, dim=2) - np.asarray(center, dtype=np.float64).reshape(2)
    radius = check_positive("radius", radius)
    m, n = check_int("m", m, minimum=0), check_int("n", n, minimum=1)
    r = np.hypot(p[:, 0], p[:, 1])
    return jv(m, jnp_zeros(m, n)[-1] * r / radius) * np.cos(m * np.arctan2(p[:, 1], p[:, 0]))


def run_tez_circular_cavity(*, radius: float = 0.1, n_radial: int = 20,
                            modes: Sequence[tuple[int, int]] = ((1, 1), (2, 1)), eps_r: float = 1.0,
                            coupling: str = DEFAULT_COUPLING, h_ratio: float | None = None, courant: float = 0.9,
                            periods: float = 1.0, spectrum_periods: float = 10.0, wall_spacing: float = 0.5,
                            wall_margin: float = 0.3, layout: str = "yee", amplitude: float = 0.2,
                            seed: int | None = 0) -> TEzCavityResult:
    """TE modes of a circular PEC cavity (curved walls, :func:`tez_disk_layout`) against the exact Bessel modes.

    ``Hz(0) = sum_(m, n) J_m(j'_mn r / a) cos(m phi)`` over ``modes`` (E = 0), ``dr = radius / n_radial``.
    After ``periods`` periods of the first mode Hz is compared with the exact
    evolution (``error``: relative L2 error in the Hz volumes); the run continues
    ``spectrum_periods`` periods and the first mode's resonance is fitted to the
    projection of Hz onto it (``frequency_error``) and read from the spectrum of
    Hz at the particle where that mode is largest (``probe_frequency_error``:
    Hann window, zero padding, parabolic peak). ``layout="jittered"``: every
    particle moved by up to ``amplitude * dr`` (seeded; the wall correction then
    covers the whole operator); ``"poisson"`` / ``"poisson-shared"``: the Poisson
    layouts of :func:`tez_disk_layout` (seeded). ``h_ratio`` defaults to
    :data:`DISK_H_RATIO` on the lattice, :data:`POISSON_H_RATIO` on Poisson layouts.

    Examples
    --------
    >>> r = run_tez_circular_cavity(n_radial=6, spectrum_periods=3.0)
    >>> r.case, r.frequency_error < 0.005, r.error < 0.05  # measured 1.4e-3 and 3.3e-2
    ('tez-disk', True, True)
    """
    t0 = time.perf_counter()
    radius = check_positive("radius", radius)
    n_radial = check_int("n_radial", n_radial, minimum=3)
    periods = check_positive("periods", periods)
    spectrum_periods = check_positive("spectrum_periods", spectrum_periods)
    eps_r = check_positive("eps_r", eps_r)
    modes = _check_modes(modes)
    if any(m < 0 or k < 1 for m, k in modes):
        raise ValueError(f"modes must be (m, n) with m >= 0 and n >= 1 (TE_mn), got {modes!r}")
    if coupling == "direct":
        raise ValueError("coupling must be 'sbp' or 'adjoint' for the circular cavity ('direct' is not available "
                         "with curved walls)")
    check_in("coupling", coupling, ("sbp", "adjoint"))
    check_in("layout", layout, ("yee", "jittered", "poisson", "poisson-shared"))
    poisson = layout.startswith("poisson")
    if h_ratio is None:
        h_ratio = POISSON_H_RATIO if poisson else DISK_H_RATIO
    dr = radius / n_radial
    c = (radius, radius)
    lay = tez_disk_layout(c, radius, dr, wall_spacing=wall_spacing, wall_margin=wall_margin,
                          amplitude=amplitude if layout == "jittered" else 0.0, seed=seed,
                          kind=layout if poisson else "lattice")
    s = TEzSolver(lay, h_ratio=h_ratio, eps_r=eps_r, coupling=coupling, courant=courant)
    shapes = [tez_disk_mode(lay.hz, c, radius, m, k) for m, k in modes]
    freqs = [tez_disk_frequency(radius, m, k, eps_r) for m, k in modes]
    T = periods / freqs[0]
    steps = int(math.ceil(T / s.dt - 1e-9))
    s.set_dt(T / steps)
    s.set_initial(sum(shapes))
    s.run(steps)
    exact = sum(f * math.cos(2 * math.pi * fr * s.t) for f, fr in zip(shapes, freqs))
    v = s.vol_hz
    err = float(math.sqrt(((s.hz - exact) ** 2 @ v) / (exact**2 @ v)))
    q = shapes[0] * v / ((shapes[0] * v) @ shapes[0])
    probe = int(np.argmax(np.abs(shapes[0])))
    more = int(round(spectrum_periods / freqs[0] / s.dt))
    amp, sig = np.empty(more), np.empty(more)
    for k in range(more):
        s.step()
        amp[k] = q @ s.hz
        sig[k] = s.hz[probe]
    fm = _fit_frequency(amp, s.dt * (steps + 1 + np.arange(more)), freqs[0])
    fp = _probe_peak(sig, s.dt, freqs[0])
    cfl = s.h / (math.sqrt(2.0) * s.c_max)
    return TEzCavityResult("tez-disk", err, abs(fm - freqs[0]) / freqs[0], fm, freqs[0], lay.n_particles, s.n,
                           time.perf_counter() - t0, dr, s.dt, coupling, f"disk-{layout}",
                           probe_frequency_error=abs(fp - freqs[0]) / freqs[0], stable_fraction=s.dt / cfl)


def _probe_peak(signal, dt, f0):
    """The largest spectral peak of ``signal`` within 25 % of ``f0`` (Hann window, 16x zero padding, parabola)."""
    x = np.asarray(signal, dtype=np.float64)
    x = (x - x.mean()) * np.hanning(len(x))
    nfft = 16 * int(2 ** math.ceil(math.log2(len(x))))
    spec = np.abs(np.fft.rfft(x, nfft))
    f = np.fft.rfftfreq(nfft, dt)
    spec[(f < 0.75 * f0) | (f > 1.25 * f0)] = 0.0
    k = min(max(int(np.argmax(spec)), 1), len(spec) - 2)
    a, b, c = np.log(spec[k - 1 : k + 2] + 1e-300)
    den = a - 2 * b + c
    return float(f[k] + (0.5 * (a - c) / den if den != 0 else 0.0) * (f[1] - f[0]))
