"""Open boundaries: finding the particles whose neighbourhood is one-sided.

A scan with holes (the bunny is open at the bottom) has particles on the rim of
each hole. In the tangent plane of such a particle its neighbours all lie on one
side. Two measures of that, per particle, from the projected neighbour offsets
``x_ij`` (docs/method.md section 2.3):

- ``gap``: the largest angle between consecutive neighbour directions around the
  particle (radians). Interior particles of a cloud with ~20 neighbours have gaps
  well under 90 degrees; a particle on a straight rim has a gap near 180 degrees.
- ``offset``: ``|mean_j x_ij| / mean_j |x_ij|``, the centroid shift of the
  neighbourhood, ~0 inside and ~0.64 on a straight rim of a uniform cloud.

A particle is a boundary candidate when both ``gap > max_gap`` and ``offset > max_offset``
(either alone flags interior particles of clumpy random samples; both together
did not in the tests: on a uniformly random hemisphere of 2000 points, interior
gaps reach about 120 degrees at the 99th percentile and offsets 0.5, but rarely
together, while rim particles have gaps of 130-190 degrees and offsets above 0.4).
For bare points, only neighbours whose normal agrees with the particle's (either
sign) and that lie near its tangent plane count, so that another sheet nearby
does not close a rim. Candidates linked in the neighbour graph form pieces; a
piece is kept when it has a few particles and one with a gap above ``seed_gap``
(hysteresis), which drops isolated specks of clumpy or anisotropic samplings.
Last, for bare points, a candidate whose empty side ends at a particle of the same
smooth sheet, no more than ``resolve`` times farther than the next step beyond
it, is dropped: there the sampling only gets sparser (a density change), no hole.

What the operators and PDEs do there
------------------------------------
No ghost particles are added on an open surface: the operators use the one-sided
neighbourhood as it is. The corrected schemes (cspm, msph, ncsph) stay
consistent there (their moment matrices are built from the actual neighbours,
so linear fields, and for msph/ncsph quadratics, are still differentiated
exactly), at the price of larger errors and condition numbers; ill-conditioned
particles fall back to lower-order schemes (``Surface.fallback``). The standard
scheme is not consistent at a boundary (its gradient of a linear field is wrong
there). The standard (Taylor) Laplacian with positive area elements
(``area="shepard"``) has non-negative off-diagonal weights and zero row sums: a
weighted graph Laplacian, so heat (:func:`manifold_sph.pde.heat`) with no other
condition behaves as an insulated (homogeneous Neumann, "natural") boundary:
no heat leaves, values stay within the initial bounds, and the solution tends to
a constant on every connected piece. For Dirichlet data hold the boundary
particles: ``heat(surface, u0, dt, steps, fixed=mask, fixed_values=...)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from .._validation import as_points, check_bool, check_int, check_positive
from ..frames import tangent_frames
from ..pointcloud import PointCloud
from ..threads import get_num_threads

if TYPE_CHECKING:
    from ..operators import OperatorSet

__all__ = ["BoundaryReport", "detect_boundary", "angular_gaps"]


@dataclass(frozen=True)
class BoundaryReport:
    """Boundary particles and the measures behind the decision.

    Attributes
    ----------
    mask : ndarray of bool, shape (N,)
        True on boundary particles.
    gap : ndarray, shape (N,)
        Largest angular gap between neighbour directions (radians).
    offset : ndarray, shape (N,)
        Centroid shift of the neighbourhood over its mean radius.
    n_loops : int
        Connected pieces of the boundary (holes, rims) in the neighbour graph.
    labels : ndarray of int, shape (N,)
        Boundary piece of each boundary particle, -1 elsewhere.
    """

    mask: np.ndarray
    gap: np.ndarray
    offset: np.ndarray
    n_loops: int
    labels: np.ndarray

    @property
    def indices(self) -> np.ndarray:
        return np.flatnonzero(self.mask)

    @property
    def n_boundary(self) -> int:
        return int(self.mask.sum())

    @property
    def report(self) -> str:
        n = self.mask.size
        if not self.n_boundary:
            return f"no boundary: all {n} particles have two-sided neighbourhoods (closed surface)"
        sizes = np.bincount(self.labels[self.mask]) if self.n_loops else np.zeros(0, int)
        top = ", ".join(str(int(s)) for s in np.sort(sizes)[::-1][:5])
        return (
            f"{self.n_boundary} of {n} particles ({100 * self.n_boundary / n:.2f}%) are on an open boundary, "
            f"in {self.n_loops} connected piece(s) (largest: {top} particles)"
        )

    def __str__(self) -> str:
        return self.report


def angular_gaps(xy: np.ndarray, indptr: np.ndarray) -> np.ndarray:
    """Largest angle between consecutive directions in each row of CSR-stored 2D offsets.

    Zero offsets (the particle itself) are ignored; rows with fewer than two
    directions get ``2 pi``.

    Examples
    --------
    >>> import numpy as np
    >>> xy = np.array([[0.0, 0], [1, 0], [0, 1], [-1, 0], [0, -1], [1, 0], [0, 1], [-1, 0.01]])
    >>> np.degrees(angular_gaps(xy, np.array([0, 5, 8]))).round(1).tolist()
    [90.0, 180.6]
    """
    n = indptr.size - 1
    counts = np.diff(indptr)
    rows = np.repeat(np.arange(n), counts)
    r = np.hypot(xy[:, 0], xy[:, 1])
    ok = r > 0
    ang = np.arctan2(xy[ok, 1], xy[ok, 0])
    rows = rows[ok]
    m = np.bincount(rows, minlength=n)
    width = int(m.max()) if m.size else 0
    if width == 0:
        return np.full(n, 2 * np.pi)
    table = np.full((n, width), np.inf)
    start = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(m, out=start[1:])
    col = np.arange(rows.size) - start[rows]
    table[rows, col] = ang
    table.sort(axis=1)
    idx = np.arange(width)
    valid = idx[None, :] < m[:, None]
    with np.errstate(invalid="ignore"):  # inf - inf in the padding
        diffs = np.where(valid[:, 1:], np.diff(table, axis=1), -np.inf) if width > 1 else np.full((n, 0), -np.inf)
    # rows with no direction at all (every neighbour filtered out) hold only the inf
    # padding: inf - inf would be NaN (a RuntimeWarning); they get 2 pi below anyway
    first = np.where(m > 0, table[:, 0], 0.0)
    last = np.where(m > 0, table[np.arange(n), np.maximum(m - 1, 0)], 0.0)
    wrap = first + 2 * np.pi - last
    gap = np.max(np.concatenate([diffs, wrap[:, None]], axis=1), axis=1)
    return np.where(m >= 2, gap, 2 * np.pi)


_CHUNK = 65536  # rows per batch of the dense (rows, k) arrays


def _dense_gaps(ang: np.ndarray, valid: np.ndarray, bisector: bool = False):
    """Largest circular gap between the valid angles of each row (2 pi with fewer than two);
    with ``bisector``, also the angle halfway across that gap (0 for rows without two angles)."""
    n, k = ang.shape
    a = np.where(valid, ang, np.inf)
    a.sort(axis=1)
    m = valid.sum(axis=1)
    last = a[np.arange(n), np.maximum(m - 1, 0)]
    first = a[:, 0]
    wrap = np.where(m > 0, first + 2 * np.pi - np.where(m > 0, last, 0.0), 2 * np.pi)
    if k > 1:
        inside = np.arange(1, k)[None, :] < m[:, None]
        d = np.where(inside, np.diff(np.where(np.isfinite(a), a, 0.0), axis=1), 0.0)
        j = d.argmax(axis=1)
        inner = d[np.arange(n), j]
        gap = np.maximum(inner, wrap)
        start = np.where(inner > wrap, a[np.arange(n), j], np.where(m > 0, last, 0.0))
    else:
        gap = wrap
        start = np.where(m > 0, last, 0.0)
    gap = np.where(m >= 2, gap, 2 * np.pi)
    if not bisector:
        return gap
    return gap, np.where(m >= 2, start + gap / 2, 0.0)


_CONSENSUS = 9  # the particle and its 8 nearest neighbours vote on its normal


def _consensus_normals(nrm, idx, oriented=False):
    """The particle's normal or, when most of its nearest neighbours' normals disagree with it
    (by more than 70 degrees, either sign: a normal turned across the surface), the
    neighbour normal that agrees with the most of them. ``oriented``: then given the sign
    of the neighbours' sum (a lone flipped normal is turned back)."""
    C = nrm[idx]
    agree = np.abs(np.einsum("ncd,nmd->ncm", C, C)) > np.cos(np.radians(70))
    votes = agree.sum(axis=2)
    own_ok = 2 * votes[:, 0] > idx.shape[1]
    best = votes.argmax(axis=1)
    out = np.where(own_ok[:, None], C[:, 0], C[np.arange(idx.shape[0]), best])
    if oriented:
        sgn = np.sign(np.einsum("nd,nmd->n", out, C[:, 1:]))
        out = out * np.where(sgn == 0, 1.0, sgn)[:, None]
    return out


def _neighbour_filter(pts, nrm, ni, centre, nb, thr, tan_el, oriented):
    """Tangential offsets ``t`` (rows, k, 3), their lengths and the mask of the neighbours ``nb``
    of the particles ``centre`` (normals ``ni``) that count: on the same sheet (module notes)."""
    d = pts[nb] - pts[centre][:, None, :]
    h = np.einsum("nd,nkd->nk", ni, d)
    t = d - h[..., None] * ni[:, None, :]
    r = np.linalg.norm(t, axis=2)
    keep = (r > 0) & (np.abs(h) <= tan_el * r)
    dots = np.einsum("nd,nkd->nk", ni, nrm[nb])
    keep &= (dots if oriented else np.abs(dots)) > thr
    return t, r, keep


def _cloud_measures(pts, nrm, idx, normal_threshold, max_elevation, oriented=False):
    """Gap, centroid shift, consensus normal and the direction (a unit tangent vector) across
    the largest gap, per particle from its ``k`` nearest neighbours, in batches.

    A neighbour counts when its normal is within ``arccos(normal_threshold)`` of the
    particle's (either sign unless ``oriented``), and its offset rises at most
    ``max_elevation`` out of the particle's tangent plane (another sheet nearby, the
    other side of a thin part, a part piercing the surface, does not close a rim).
    """
    n, k = idx.shape
    gap = np.empty(n)
    offset = np.empty(n)
    normal = np.empty((n, 3))
    across = np.empty((n, 3))
    tan_el = np.tan(max_elevation)
    for s in range(0, n, _CHUNK):
        e = min(s + _CHUNK, n)
        ni = _consensus_normals(nrm, idx[s:e, :_CONSENSUS], oriented)
        t, r, keep = _neighbour_filter(pts, nrm, ni, np.arange(s, e), idx[s:e, 1:], normal_threshold, tan_el, oriented)
        u, v = tangent_frames(ni)
        x = np.einsum("nd,nkd->nk", u, t)
        y = np.einsum("nd,nkd->nk", v, t)
        gap[s:e], mid = _dense_gaps(np.arctan2(y, x), keep, bisector=True)
        normal[s:e] = ni
        across[s:e] = np.cos(mid)[:, None] * u + np.sin(mid)[:, None] * v
        cnt = keep.sum(axis=1)
        mean_r = np.where(keep, r, 0.0).sum(axis=1)
        cx, cy = np.where(keep, x, 0.0).sum(axis=1), np.where(keep, y, 0.0).sum(axis=1)
        offset[s:e] = np.where((cnt > 0) & (mean_r > 0), np.hypot(cx, cy) / np.where(mean_r > 0, mean_r, 1.0), 1.0)
    return gap, offset, normal, across


_SMOOTH = np.cos(np.radians(45.0))  # normals (with their sign) of a sheet that continues smoothly


def _nearest_in_cone(pts, nrm, ni, centre, direction, tree, k, thr, tan_el, oriented, cone):
    """The nearest same-sheet neighbour (among the ``k`` nearest) of each particle ``centre``
    within ``arccos(cone)`` of ``direction`` (tangent, unit) whose normal, with its sign, is
    within 45 degrees of the particle's; its tangential distance (inf and -1 when there is
    none). In batches of rows."""
    dist_out = np.full(len(centre), np.inf)
    j_out = np.full(len(centre), -1, dtype=np.int64)
    step = max(1, _CHUNK * 24 // k)
    for s in range(0, len(centre), step):
        e = min(s + step, len(centre))
        _, nb = tree.query(pts[centre[s:e]], k=k, workers=get_num_threads())
        t, r, keep = _neighbour_filter(pts, nrm, ni[s:e], centre[s:e], nb, thr, tan_el, oriented)
        keep &= np.einsum("nkd,nd->nk", t, direction[s:e]) > cone[s:e, None] * r
        keep &= np.einsum("nd,nkd->nk", ni[s:e], nrm[nb]) > _SMOOTH  # the sheet continues (a fold or a facing sheet: not)
        dist = np.where(keep, r, np.inf)
        j = dist.argmin(axis=1)
        rows = np.arange(e - s)
        found = np.isfinite(dist[rows, j])
        dist_out[s:e] = np.where(found, dist[rows, j], np.inf)
        j_out[s:e] = np.where(found, nb[rows, j], -1)
    return dist_out, j_out


def _unresolved_gaps(pts, nrm, normal, across, gap, cand, tree, k, thr, tan_el, oriented, ratio):
    """Candidates whose empty side is only the sampling getting sparser (True: not a rim).

    Across the gap of candidate ``i`` the nearest same-sheet particle ``j`` lies at
    ``rho`` (none: a rim); beyond ``j``, in the same direction, the next one at
    ``rho_j``. A hole or a rim leaves ``rho`` several spacings wider than the
    sampling beyond it; where the sampling only gets sparser (a dense lip next to a
    coarse wall, the long side of anisotropic triangles) the step ``rho`` is about
    the next one: ``rho < ratio * rho_j``.
    """
    c = np.flatnonzero(cand)
    if c.size == 0:
        return np.zeros_like(cand)
    cone = np.cos(np.minimum(np.radians(60.0), gap[c] / 2 - np.radians(5.0)))  # within the gap
    rho, j = _nearest_in_cone(pts, nrm, normal[c], c, across[c], tree, k, thr, tan_el, oriented, cone)
    has = j >= 0
    out = np.zeros_like(cand)
    if not has.any():
        return out
    c, rho, j, cone = c[has], rho[has], j[has], cone[has]
    dj = across[c] - np.einsum("nd,nd->n", across[c], normal[j])[:, None] * normal[j]
    norm = np.linalg.norm(dj, axis=1)
    ok = norm > 1e-6
    dj = dj / np.where(ok, norm, 1.0)[:, None]
    rho_j, _ = _nearest_in_cone(pts, nrm, normal[j], j, dj, tree, k, thr, tan_el, oriented, cone)
    out[c] = ok & np.isfinite(rho_j) & (rho < ratio * rho_j)
    return out


def _bridges(pts, idx, lab, kept, which):
    """Particles ``which`` between kept particles of two different pieces (labels ``lab``) on
    opposite sides (more than 120 degrees apart as seen from the particle): removing them
    would cut a rim in two."""
    c = np.flatnonzero(which)
    out = np.zeros_like(which)
    if c.size == 0:
        return out
    step = 8192  # rows per batch of the (rows, k, k) pair arrays
    for s in range(0, c.size, step):
        cs = c[s : s + step]
        nb = idx[cs, 1:]
        ok = kept[nb]
        d = pts[nb] - pts[cs][:, None, :]
        d /= np.maximum(np.linalg.norm(d, axis=2, keepdims=True), 1e-300)
        opposite = np.einsum("nid,njd->nij", d, d) < -0.5
        other = lab[nb][:, :, None] != lab[nb][:, None, :]
        out[cs] = (opposite & other & ok[:, :, None] & ok[:, None, :]).any(axis=(1, 2))
    return out


def _pieces(mask, rows, cols, n):
    """Connected pieces of the particles ``mask`` in the neighbour graph (rows, cols)."""
    both = mask[rows] & mask[cols] & (rows != cols)
    G = sp.coo_matrix((np.ones(int(both.sum())), (rows[both], cols[both])), shape=(n, n))
    return csgraph.connected_components(G, directed=False)[1]


def detect_boundary(
    surface: OperatorSet | PointCloud | ArrayLike,
    normals: ArrayLike | None = None,
    *,
    k: int = 24,
    max_gap: float = 110.0,
    max_offset: float = 0.3,
    normal_threshold: float = 0.3,
    max_elevation: float = 45.0,
    seed_gap: float = 160.0,
    min_piece: int = 3,
    oriented: bool = False,
    seed_size: int | None = 12,
    resolve: float | None = 1.5,
) -> BoundaryReport:
    """Find the particles on open boundaries (holes, rims) of a point-cloud surface.

    Each particle's neighbours are projected into its tangent plane; a particle is a
    boundary *candidate* when the largest angular gap between their directions
    exceeds ``max_gap`` **and** their centroid is shifted by more than
    ``max_offset`` mean radii (module notes). Then the candidates are linked
    through the neighbour graph, and a piece is kept only when it holds at least
    ``min_piece`` particles and one *seed*, a particle whose gap exceeds
    ``seed_gap`` (hysteresis, as in Canny's edge detector: a rim has particles
    with a half-plane or more empty; isolated specks of a clumpy or anisotropic
    sampling rarely do), or when it holds at least ``seed_size`` particles: the
    rim of a small hole (radius 2-5 spacings) curves so much within a
    neighbourhood that none of its particles has a half-plane empty, but it is
    a loop of a dozen or more particles, longer than the specks (and than most
    voids of a uniformly random sampling, which are holes of 1-2 spacings).

    For points (not a Surface), a neighbour takes part only when its normal is
    within ``arccos(normal_threshold)`` of the particle's, **either sign** (a
    minority of normals that point inward no longer cuts a neighbourhood apart),
    and when it lies within ``max_elevation`` of the particle's tangent plane,
    so that another sheet close by (the other side of a thin part, a lid
    resting on a rim, a handle piercing a body) does not fill a rim's empty side.
    A particle whose normal disagrees (by more than 70 degrees) with most of its
    8 nearest neighbours' takes the neighbour normal that most of them agree
    with: a minority of bad normals (5 % turned by 90 degrees on a hemisphere)
    then adds no false boundary.

    Parameters
    ----------
    surface : Surface, PointCloud or array_like (N, 3)
        A :class:`~manifold_sph.Surface` is analysed with its own neighbourhood
        and tangent frames; otherwise the ``k`` nearest neighbours (filtered as
        above; normals are estimated if missing) are used.
    normals : array_like, shape (N, 3), optional
        For points or a PointCloud (replacing its normals). Sign does not matter.
    k : int
        Neighbours (itself included) when ``surface`` is not a Surface; 3 <= k <= N.
    max_gap : float
        Angular gap (degrees, in (0, 360]) that a boundary candidate exceeds.
    max_offset : float
        Centroid shift (fraction of the mean neighbour distance, > 0) that a
        candidate also exceeds.
    normal_threshold : float
        Neighbours need ``|n_i . n_j| > normal_threshold``, in [0, 1) (not for a Surface).
    max_elevation : float
        Largest angle (degrees, in (0, 90]) between a neighbour's offset and the
        tangent plane (90 switches the test off; not for a Surface).
    seed_gap : float
        Every kept piece holds a particle with a gap above this (degrees, at least
        ``max_gap``; pass ``max_gap`` to keep every candidate piece).
    min_piece : int
        Smallest piece kept (>= 1; 1 keeps lone candidates).
    seed_size : int or None
        Pieces of at least this many candidates (>= 1) are kept without a seed;
        None: every kept piece needs a seed.
    resolve : float or None
        Drop a candidate (points only, not a Surface) when its empty side is only the
        sampling getting sparser: the nearest particle across its gap, on the same
        sheet continuing smoothly (normals within 45 degrees, with their sign), lies
        less than ``resolve`` times farther than the next particle beyond it (a dense
        lip next to a coarse wall, the long side of anisotropic triangles); a hole or a
        rim leaves a step several spacings wider than the sampling beyond it.
        Candidates between two pieces of the kept ones, on opposite sides, stay (a
        rim is not cut). None: no such
        test (the behaviour before it).
    oriented : bool
        The normals are consistently oriented (a mesh's, or estimated ones without
        orientation seams): neighbours need ``n_i . n_j > normal_threshold`` with its
        sign, which separates the two sides of a thin part and a lid from the rim it
        rests on (the teapot with its mesh's normals and ``resolve=None``: recall
        0.79 -> 0.89; with the default ``resolve`` 0.79 -> 0.68, see Notes); a lone
        flipped normal is turned back by its neighbours', but a seam where the
        orientation changes then looks like a boundary. Not for a Surface.

    Returns
    -------
    BoundaryReport
        ``gap`` and ``offset`` are the raw measures of every particle; ``mask`` the
        kept candidates; ``n_loops`` and ``labels`` their pieces.

    Raises
    ------
    ValueError
        For points that are not (N, 3) and finite, normals of another shape, or
        parameters outside the ranges above.

    Notes
    -----
    Measured on public test meshes whose vertices are used as bare points
    (``python tests/test_boundary.py`` prints them): against the mesh's boundary
    vertices, with the meshes' normals the teapot gives recall 0.79 with 11 %
    false positives in 6 pieces (its mesh has 6 boundary loops; without the
    ``resolve`` test 0.79 / 24 %; before any of these filters 0.67 / 49 % in 9;
    with ``oriented=True`` 0.68 / 21 %, without ``resolve`` 0.89 / 25 %), the
    beetle 0.50 / 42 % in 3 pieces (without ``resolve`` 0.53 / 48 %; 23 loops,
    many of 2-10 vertices), the planar alligator 0.80 / 2.5 % in 1 (unchanged).
    With estimated normals the teapot gives 0.57 / 18 % (without ``resolve``
    40 %), the beetle 0.50 / 41 % (0.54 / 45 %). Part of the teapot's mesh
    boundary is none of the cloud's: the handle's ends and the spout's base end
    inside the body (53 of its 160 boundary vertices are inside by winding
    number); of the other 107 (the lid's and the body's rims, the spout's tip)
    recall is 0.78, 0.71 with estimated normals; the lid's rim and the body's lie
    0.1 apart at a spacing of 0.17, and where they are found it is mostly through
    the anisotropy of the sampling (the empty side found points along the rim or
    down the wall, where the next particle is one ordinary step away: with
    ``oriented=True`` the ``resolve`` test drops those). On the 22 that nothing
    else approaches within 0.75 edge lengths recall is 0.82 (0.91 with
    ``oriented=True``). The false positives ``resolve`` drops are the wall just
    under the spout's rolled lip (a dense bead of particles next to a wall
    sampled 5-10 times coarser) and, on the beetle, rows next to its boundary.
    Both meshes are strongly anisotropic (a particle's nearest neighbours lie on
    one meridian); the beetle's false positives lie 1-3 mesh edges from its
    boundary, and its loops of 2-10 vertices are smaller than a neighbourhood. A
    finer mesh of the same beetle (19,885 vertices, 1,134 on its boundary) gives
    0.94 / 4 % with its mesh normals (without ``resolve`` 0.95 / 11 %), 0.94 /
    13 % with estimated ones (0.94 / 18 %).
    On synthetic clouds with exact answers (a sphere with holes of radius 1-6 mean
    spacings, Poisson, random and variable-density samplings) the rims of holes of
    radius 3 spacings or more are found whole (variable density: 5 of 8 at 3, all
    from 4), and nothing more than 2 spacings from a rim is flagged (random: 9
    particles around its own voids); holes of radius 2 or less are not found.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph.reference import shapes
    >>> detect_boundary(shapes.sphere(1000)).n_boundary
    0
    >>> g = np.linspace(0, 1, 20)
    >>> x, y = np.meshgrid(g, g)
    >>> plate = np.c_[x.ravel(), y.ravel(), np.zeros(400)]
    >>> rep = detect_boundary(plate, np.tile([0.0, 0, 1], (400, 1)))
    >>> rep.n_boundary, rep.n_loops                # the 76 particles on the square's edges
    (76, 1)
    >>> c = shapes.sphere(2000, sampling="poisson", seed=1)
    >>> cap = c.points[:, 2] < 0.5                 # a sphere with its north cap cut off
    >>> rep = detect_boundary(c.points[cap], c.normals[cap])
    >>> rep.n_loops, bool(c.points[cap][rep.mask, 2].min() > 0.35)
    (1, True)
    """
    from ..operators import OperatorSet

    max_gap_deg = check_positive("max_gap", max_gap)
    if max_gap_deg > 360.0:
        raise ValueError(f"max_gap must be at most 360 degrees, got {max_gap!r}")
    max_offset = check_positive("max_offset", max_offset)
    seed_deg = check_positive("seed_gap", seed_gap)
    if seed_deg < max_gap_deg:
        raise ValueError(f"seed_gap must be at least max_gap ({max_gap_deg:g}), got {seed_gap!r}")
    thr = check_positive("normal_threshold", normal_threshold, allow_zero=True)
    if thr >= 1.0:
        raise ValueError(f"normal_threshold must be below 1, got {normal_threshold!r}")
    elev = check_positive("max_elevation", max_elevation)
    if elev > 90.0:
        raise ValueError(f"max_elevation must be at most 90 degrees, got {max_elevation!r}")
    min_piece = check_int("min_piece", min_piece, minimum=1)
    oriented = check_bool("oriented", oriented)
    if seed_size is not None:
        seed_size = check_int("seed_size", seed_size, minimum=1)
    if resolve is not None:
        resolve = check_positive("resolve", resolve)
    if isinstance(surface, OperatorSet):
        nb = surface.neighborhood
        xy = surface.pair_offsets()
        indptr, rows, cols = nb.indptr, nb.rows, nb.indices
        n = nb.n_rows
        gap = angular_gaps(xy, indptr)
        r = np.hypot(xy[:, 0], xy[:, 1])
        cnt = np.maximum(np.diff(indptr), 1)
        mean_xy = np.stack([np.bincount(rows, weights=xy[:, a], minlength=n) for a in range(2)], axis=1) / cnt[:, None]
        mean_r = np.bincount(rows, weights=r, minlength=n) / cnt
        offset = np.where(mean_r > 0, np.hypot(mean_xy[:, 0], mean_xy[:, 1]) / np.where(mean_r > 0, mean_r, 1.0), 1.0)
    else:
        if isinstance(surface, PointCloud):
            pts = surface.points
            nrm = surface.normals if normals is None else as_points("normals", normals)
        else:
            pts = as_points("points", surface)
            nrm = None if normals is None else as_points("normals", normals)
        n = pts.shape[0]
        k = check_int("k", k, minimum=3)
        if k > n:
            raise ValueError(f"k must be at most the number of points {n}, got {k}")
        if nrm is None:
            from ..normals import estimate_normals

            nrm = estimate_normals(pts)
        elif nrm.shape != pts.shape:
            raise ValueError(f"normals must have shape {pts.shape} to match points, got shape {nrm.shape}")
        length = np.linalg.norm(nrm, axis=1, keepdims=True)
        if not np.all(length > 0):
            raise ValueError(f"normals must be non-zero; {int((length == 0).sum())} are zero")
        nrm = nrm / length
        tree = cKDTree(pts)
        _, idx = tree.query(pts, k=k, workers=get_num_threads())
        gap, offset, normal, across = _cloud_measures(pts, nrm, idx, thr, np.radians(elev), oriented)
        rows = np.repeat(np.arange(n), k - 1)
        cols = idx[:, 1:].ravel()
    cand = (gap > np.radians(max_gap_deg)) & (offset > max_offset)
    labels = np.full(n, -1, dtype=np.int64)
    mask = np.zeros(n, dtype=bool)
    n_loops = 0
    if cand.any():
        lab = _pieces(cand, rows, cols, n)
        size = np.bincount(lab[cand], minlength=lab.max() + 1)
        seeded = np.bincount(lab[cand & (gap > np.radians(seed_deg))], minlength=lab.max() + 1) > 0
        if seed_size is not None:
            seeded |= size >= seed_size
        mask = cand & (size[lab] >= min_piece) & seeded[lab]
        if not isinstance(surface, OperatorSet) and resolve is not None and mask.any():
            veto = _unresolved_gaps(pts, nrm, normal, across, gap, mask, tree, min(n, 4 * k), thr, np.tan(np.radians(elev)),
                                    oriented, resolve)
            kept = mask & ~veto
            mask = kept | _bridges(pts, idx, _pieces(kept, rows, cols, n), kept, veto & mask)
            lab = _pieces(mask, rows, cols, n)
            mask &= np.bincount(lab[mask], minlength=lab.max() + 1)[lab] >= min_piece
        if mask.any():
            _, lab_b = np.unique(lab[mask], return_inverse=True)
            labels[mask] = lab_b.ravel()
            n_loops = int(lab_b.max()) + 1
    return BoundaryReport(mask=mask, gap=gap, offset=offset, n_loops=n_loops, labels=labels)
