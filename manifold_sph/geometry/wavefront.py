"""Geodesic distance by wavefront propagation over the cloud's local Delaunay triangles.

The heat method (:mod:`manifold_sph.geometry.heat`) smooths the distance over the heat
time ``t``: kinks where fronts meet are rounded and coarse or thin models lose 2-5 %.
This module computes the distance the way exact polyhedral algorithms do, on triangles
the cloud itself defines:

1. **Local triangles.** Each particle's neighbours (its ``neighbors`` nearest points) are
   projected to its tangent plane, and the Voronoi cell of the particle among them is
   computed (:func:`manifold_sph.voronoi.voronoi_cells`, with each neighbour's height
   over the plane lifting its bisector, so that points of another sheet across a gap do
   not cut). The neighbours that bound the cell are the particle's Delaunay neighbours;
   consecutive ones (in angle) span the triangles of its fan. A fan with an angular gap
   of at least ``0.95 pi`` is open: the particle lies on a boundary. The union of all
   fans is the triangle set; each triangle's edge lengths are the distances in space.
2. **Wavefront.** A Dijkstra-ordered sweep from the sources (a binary heap, each particle
   re-opened when its distance falls later). A triangle ``(a, b, c)`` with ``a``, ``b``
   final (popped from the heap) gives ``c`` the distance from the virtual point source that lies at distances
   ``d_a`` from ``a`` and ``d_b`` from ``b`` in the triangle's plane, unfolded across the
   edge ``ab`` (Novotni and Klein 2002), when the straight ray from that source to ``c``
   crosses ``ab``; every Delaunay pair and triangle side gives ``d_a + |x_a - x_c|``. The smallest candidate
   wins. In a plane, and across any developable strip of triangles, this is exact.
3. **Front curvature.** The virtual source sits at the front's radius of curvature from
   ``a``. A point source's front in a plane has curvature ``1 / d``; on a curved surface its
   geodesic curvature obeys the Riccati equation ``kappa' = -kappa^2 - K`` along the rays
   (``K`` the Gaussian curvature; ``cot d`` on the unit sphere). Taking ``1 / d`` there costs
   a relative error of first order in the spacing (an error ``O(h^2)`` per triangle over
   ``O(1 / h)`` triangles), so each particle carries its front's curvature as the correction
   ``w = d^2 (1 / d - kappa)`` (0 in a plane, smooth at the source), interpolated along the edge
   the ray crosses and stepped to the particle by the exact solution for constant ``K``.
   ``K`` is that of a quadric fitted to each particle's nearest points, used only where it
   resolves the surface (:data:`RESOLVED_CURVATURE`).

4. **Particles no triangle reaches.** On random points (pairs much closer than the spacing: slivers,
   obtuse corners) a particle may be reached by no triangle from two final corners, only along an
   edge, too long by about the spacing times the angle to the true ray; every later update would copy
   that downstream. Such a particle, about to be final, is re-solved through every pair of its final
   edge neighbours, adjacent in a fan or not (virtual triangles), where the ray from the pair's
   virtual source crosses the segment between them (:func:`_rescue`); only away from open fans and
   unresolved curvature (:meth:`LocalTriangles.rescuable`). Behind a hole in the sample no pair of
   final neighbours may cross the ray: pairs with the second ring are then tried
   (:data:`RESCUE_ALIGNED`). Each particle also carries the direction its ray arrived in: a
   triangle whose corners' fronts move away from the third corner's side of their edge has its
   virtual source on that side, where the construction would take its mirror image (too far), and
   gives no candidate.

The result is clamped to the straight-line distance to the nearest source, so it is never
below it. Several sources are one sweep, so the kink where their fronts meet is exact. The
sweep stops as soon as every requested target is final (point-to-point queries).

Coordinates are divided by the cloud's extent before anything is computed, so the
result does not depend on the units (:data:`~manifold_sph.geometry.common.WAVEFRONT_SCALE_RANGE`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from .._jit.compile import ENABLED, njit
from ..results import Result
from ..voronoi import INCOMPLETE, voronoi_cells

__all__ = ["OPEN_GAP", "RESOLVED_CURVATURE", "LocalTriangles", "local_triangles", "pca_normals", "propagate",
           "quadric_gauss"]

#: A fan whose consecutive Delaunay neighbours leave an angular gap of at least this is open (a boundary).
OPEN_GAP = 0.95 * np.pi
#: The fronts use a particle's Gaussian curvature only where ``|K| h^2`` is at most this (``h`` the mean
#: edge length: a radius of curvature of at least 5.8 spacings); elsewhere (creases, features a few
#: spacings across, where a quadric over 16 points does not resolve the surface) ``K = 0`` there.
RESOLVED_CURVATURE = 0.03
#: A particle's distance from an edge is re-solved (:func:`_rescue`) only through pairs of neighbours
#: whose front has travelled at least this many times the particle's distance to the farther of them
#: (near a source the front's curvature is large and a pair of edges is a coarse chord of it).
RESCUE_MIN_RADIUS = 3.0
#: Where no pair of a particle's final edge neighbours crosses its ray, :func:`_rescue` tries pairs of a neighbour
#: and a neighbour's neighbour (no longer than three times the particle's farthest edge), unless the edge that
#: reached it runs within ``arccos(RESCUE_ALIGNED)`` of the ray at its upstream end (then that edge is nearly the ray).
RESCUE_ALIGNED = 0.95


def _compile(fn):
    """``fn`` compiled by numba (the package's options: cached on disk, GIL released) when the compiled
    kernels are on, else ``fn`` itself (plain Python: the same numbers, slowly)."""
    return njit(fn) if ENABLED else fn


# ----------------------------------------------------------------------------- kernels
def _sift_up(heap, key, pos, k):
    """Move entry ``k`` of the binary heap (particles ``heap``, their distances ``key`` beside them) up."""
    v = heap[k]
    kv = key[k]
    while k > 0:
        p = (k - 1) >> 1
        if key[p] <= kv:
            break
        heap[k] = heap[p]
        key[k] = key[p]
        pos[heap[k]] = k
        k = p
    heap[k] = v
    key[k] = kv
    pos[v] = k


def _sift_down(heap, key, pos, k, size):
    v = heap[k]
    kv = key[k]
    while True:
        c = 2 * k + 1
        if c >= size:
            break
        if c + 1 < size and key[c + 1] < key[c]:
            c += 1
        if key[c] >= kv:
            break
        heap[k] = heap[c]
        key[k] = key[c]
        pos[heap[k]] = k
        k = c
    heap[k] = v
    key[k] = kv
    pos[v] = k


_sift_up = _compile(_sift_up)
_sift_down = _compile(_sift_down)


def _triangle_ray(lab, cx, cy, da, db, k):
    """The front seen through the edge ``ab`` of triangle ``(a, b, c)`` at ``c``: ``(distance, t, s, ux, uy)``,
    distance inf if none.

    The triangle is unfolded with ``a`` at the origin, ``b = (lab, 0)`` and ``c = (cx, cy)``,
    ``cy > 0``. The front reaches ``a`` and ``b`` at distances ``da``, ``db`` with curvature
    ``k`` (``1 / da`` for a point source in a plane, 0 for a straight front): its unit normal ``g`` at ``a``
    solves ``(b - a) . g = D + k (D^2 - lab^2) / 2``, ``D = db - da`` (the circle intersection
    written without cancellation); the distance at ``c = a + y`` is
    ``da + (k |y|^2 + 2 y . g) / (1 + |k y + g|)``, when the ray to ``c`` crosses ``ab``: at
    ``t lab`` from ``a``, a length ``s`` before ``c``, arriving in the direction ``(ux, uy)``.
    """
    if lab <= 0.0 or cy <= 0.0 or not k < np.inf:
        return np.inf, 0.0, 0.0, 0.0, 0.0
    delta = db - da
    gx = (delta + 0.5 * k * (delta * delta - lab * lab)) / lab
    if gx * gx > 1.0:
        return np.inf, 0.0, 0.0, 0.0, 0.0
    gy = np.sqrt(1.0 - gx * gx)
    qx = k * cx + gx
    qy = k * cy + gy
    nq = np.sqrt(qx * qx + qy * qy)
    if nq <= 0.0:
        return np.inf, 0.0, 0.0, 0.0, 0.0
    ux = qx / nq
    uy = qy / nq
    if uy <= 0.0:
        return np.inf, 0.0, 0.0, 0.0, 0.0
    s = cy / uy
    xc = cx - s * ux
    if xc < 0.0 or xc > lab:  # the ray from the front to c misses the edge ab
        return np.inf, 0.0, 0.0, 0.0, 0.0
    return da + (k * (cx * cx + cy * cy) + 2.0 * (cx * gx + cy * gy)) / (1.0 + nq), xc / lab, s, ux, uy


_triangle_ray = _compile(_triangle_ray)


def _push(heap, key, pos, size, v, dv):
    """Insert particle ``v`` with distance ``dv``, or lower its entry to ``dv``; the heap's new size."""
    if pos[v] < 0:
        heap[size] = v
        pos[v] = size
        size += 1
    key[pos[v]] = dv
    _sift_up(heap, key, pos, pos[v])
    return size


_push = _compile(_push)


def _kappa(r, w):
    """Geodesic curvature of a point source's front at distance ``r`` with Jacobi correction ``w``:
    ``1 / r - w / r^2`` (``w = 0`` in a plane); inf at the source."""
    if not r > 0.0:
        return np.inf
    return (1.0 - w / r) / r


_kappa = _compile(_kappa)


def _carry(w0, r0, r1, K):
    """The correction ``w = r^2 (1 / r - kappa)`` of a point source's front carried from distance ``r0`` to ``r1``
    along a ray through constant Gaussian curvature ``K``, by the exact solution of ``kappa' = -kappa^2 - K``
    over the step ``s``: ``kappa1 = (kappa0 - K tau) / (1 + kappa0 tau)``, ``tau = tan(c s) / c`` for
    ``K = c^2`` (``tanh`` for ``K = -c^2``, ``s`` for 0; a series in ``K s^2`` on the short steps of a
    sweep, no trigonometry). A front focused to a point (the cut locus is near) is held short of it."""
    if r0 > 0.0:
        k0 = (1.0 - w0 / r0) / r0
        s = r1 - r0
    else:
        k0 = np.inf
        s = r1
    x = K * s * s
    if x * x <= 0.0016:  # |c s| <= 0.2: tan(c s) / (c s) to 8 digits or better
        tau = s * (1.0 + x * (1.0 / 3.0 + x * (2.0 / 15.0 + x * (17.0 / 315.0))))
    elif K > 0.0:
        c = np.sqrt(K)
        tau = np.tan(min(c * s, 0.5 * np.pi - 1e-9)) / c
    else:
        c = np.sqrt(-K)
        tau = np.tanh(c * s) / c
    if k0 == np.inf:
        k1 = 1.0 / tau
    else:  # past a focal point 1 + k0 tau would change sign: held at 1e-3
        k1 = (k0 - K * tau) / max(1.0 + k0 * tau, 1e-3)
    return r1 - r1 * r1 * k1


_carry = _compile(_carry)


def _pair_ray(P, y, a, b, ra, rb, ka, g, max_len2):
    """The candidate of :func:`_rescue` at ``y`` through the virtual triangle ``(a, b, y)``: ``(distance, t, s, gx,
    gy, gz)`` (the ray's direction in space), distance inf when the ray misses ``ab``, ``ab`` is longer than
    ``sqrt(max_len2)``, the front has not travelled :data:`RESCUE_MIN_RADIUS` times the triangle's size or the
    fronts at ``a`` and ``b`` move away from ``y``'s side of ``ab``."""
    ay0 = P[y, 0] - P[a, 0]
    ay1 = P[y, 1] - P[a, 1]
    ay2 = P[y, 2] - P[a, 2]
    l2 = ay0 * ay0 + ay1 * ay1 + ay2 * ay2
    e0 = P[b, 0] - P[a, 0]
    e1 = P[b, 1] - P[a, 1]
    e2 = P[b, 2] - P[a, 2]
    lab2 = e0 * e0 + e1 * e1 + e2 * e2
    if not 0.0 < lab2 <= max_len2:
        return np.inf, 0.0, 0.0, 0.0, 0.0, 0.0
    lab = np.sqrt(lab2)
    e0 /= lab
    e1 /= lab
    e2 /= lab
    cx = ay0 * e0 + ay1 * e1 + ay2 * e2
    cy = np.sqrt(max(l2 - cx * cx, 0.0))
    far = max(l2, (cx - lab) * (cx - lab) + cy * cy)
    if cy <= 0.0 or ra * ra < RESCUE_MIN_RADIUS * RESCUE_MIN_RADIUS * far:
        return np.inf, 0.0, 0.0, 0.0, 0.0, 0.0
    n0 = (ay0 - cx * e0) / cy  # the unit normal of ab towards y, in the plane of a, b, y
    n1 = (ay1 - cx * e1) / cy
    n2 = (ay2 - cx * e2) / cy
    if (g[a, 0] + g[b, 0]) * n0 + (g[a, 1] + g[b, 1]) * n1 + (g[a, 2] + g[b, 2]) * n2 < 0.0:
        return np.inf, 0.0, 0.0, 0.0, 0.0, 0.0
    cand, t, s, ux, uy = _triangle_ray(lab, cx, cy, ra, rb, ka)
    return cand, t, s, ux * e0 + uy * n0, ux * e1 + uy * n1, ux * e2 + uy * n2


_pair_ray = _compile(_pair_ray)


def _rescue(P, y, d, o, sid, w, g, pos, e_ptr, e_idx, K, riccati):
    """Re-solve particle ``y``, about to be final, whose distance came from an edge; True if it fell.

    On thin or obtuse local triangles (random points: pairs much closer than the spacing) a particle
    may be reached by no triangle from two final corners, its upstream neighbours all to one side.
    The edge candidate ``d_a + |x_a - x_y|`` is then long by about the spacing times the angle to the
    true ray, and every later update copies that error downstream. Here every pair ``(a, b)`` of
    ``y``'s final edge neighbours of one source, adjacent in a fan or not (a virtual triangle, as fast
    marching forms for obtuse triangles), gives the distance from the virtual source through the
    segment ``ab``, accepted only where the ray crosses ``ab`` (never longer than the edge candidate,
    which stays when none does), away from the source (:data:`RESCUE_MIN_RADIUS`) and where the
    fronts at ``a`` and ``b`` move towards ``y``'s side of ``ab`` (else the virtual source lies on
    that side). Of the accepted pairs the one crossed nearest its middle wins (the best conditioned;
    the smallest would bias the distance short). Where no pair of the first ring crosses (a hole in a
    random sample: the particles upstream all to one side), pairs of a first-ring and a second-ring
    final particle are tried the same way (:data:`RESCUE_ALIGNED`)."""
    best = d[y]
    score = np.inf
    ba = -1
    bb = -1
    bt = 0.0
    bs = 0.0
    gy0 = 0.0
    gy1 = 0.0
    gy2 = 0.0
    reach = 0.0
    aligned = 1.0  # the cosine between the edge that gave d[y] and the ray arriving at its upstream end
    for q in range(e_ptr[y], e_ptr[y + 1]):
        a = e_idx[q]
        ay0 = P[y, 0] - P[a, 0]
        ay1 = P[y, 1] - P[a, 1]
        ay2 = P[y, 2] - P[a, 2]
        l2 = ay0 * ay0 + ay1 * ay1 + ay2 * ay2
        reach = max(reach, l2)
        if pos[a] < 0 and l2 > 0.0 and abs(d[a] + np.sqrt(l2) - d[y]) <= 1e-12 * d[y]:
            aligned = (g[a, 0] * ay0 + g[a, 1] * ay1 + g[a, 2] * ay2) / np.sqrt(l2)
    for ring in range(2):
        if ring == 1 and (ba >= 0 or aligned > RESCUE_ALIGNED):
            break
        for q in range(e_ptr[y], e_ptr[y + 1]):
            a = e_idx[q]
            if pos[a] >= 0 or not d[a] < d[y]:
                continue
            ra = d[a] - o[a]
            ka = _kappa(ra, w[a]) if riccati else (1.0 / ra if ra > 0.0 else np.inf)
            # ring 0: b among y's edge neighbours; ring 1: among its neighbours' neighbours
            m_lo = e_ptr[y] if ring == 1 else 0
            m_hi = e_ptr[y + 1] if ring == 1 else 1
            for qm in range(m_lo, m_hi):
                lo = e_ptr[y] if ring == 0 else e_ptr[e_idx[qm]]
                hi = e_ptr[y + 1] if ring == 0 else e_ptr[e_idx[qm] + 1]
                for q2 in range(lo, hi):
                    b = e_idx[q2]
                    if b == a or b == y or pos[b] >= 0 or not d[b] < d[y] or sid[b] != sid[a] or o[b] != o[a]:
                        continue
                    cand, t, s, h0, h1, h2 = _pair_ray(P, y, a, b, ra, d[b] - o[a], ka, g, 9.0 * reach if ring else np.inf)
                    cand += o[a]
                    if cand < d[y] * (1.0 - 1e-12) and abs(t - 0.5) < score:
                        score = abs(t - 0.5)
                        best = cand
                        ba = a
                        bb = b
                        bt = t
                        bs = s
                        gy0 = h0
                        gy1 = h1
                        gy2 = h2
    if ba < 0:
        return False
    d[y] = best
    o[y] = o[ba]
    sid[y] = sid[ba]
    g[y, 0] = gy0
    g[y, 1] = gy1
    g[y, 2] = gy2
    if riccati:
        r = best - o[ba]
        w[y] = _carry((1.0 - bt) * w[ba] + bt * w[bb], r - bs, r, 0.5 * K[y] + 0.5 * ((1.0 - bt) * K[ba] + bt * K[bb]))
    return True


_rescue = _compile(_rescue)


def _propagate(P, vt_ptr, vt_pair, vt_geom, e_ptr, e_idx, e_len, src, d0, targets, K, riccati, rescue):
    n = P.shape[0]
    d = np.full(n, np.inf)
    o = np.zeros(n)  # the offset of the source each particle's front comes from
    sid = np.full(n, -1, np.int64)  # and which source that is
    w = np.zeros(n)  # the Jacobi correction of each front's curvature (see _kappa)
    g = np.zeros((n, 3))  # the unit direction of each particle's ray (0 at the sources)
    by_edge = np.zeros(n, np.bool_)  # the distance came from an edge candidate
    heap = np.empty(n, np.int64)
    key = np.empty(n)  # the heap entries' distances, stored beside them (no indirection in the sifts)
    pos = np.full(n, -1, np.int64)
    size = 0
    for k in range(src.size):
        v = src[k]
        if d0[k] < d[v]:
            d[v] = d0[k]
            o[v] = d0[k]
            sid[v] = v
            size = _push(heap, key, pos, size, v, d[v])
    wanted = np.zeros(n, np.bool_)
    left = 0
    for k in range(targets.size):
        if not wanted[targets[k]]:
            wanted[targets[k]] = True
            left += 1
    while size > 0:
        v = heap[0]
        pos[v] = -1
        size -= 1
        if size > 0:
            heap[0] = heap[size]
            key[0] = key[size]
            pos[heap[0]] = 0
            _sift_down(heap, key, pos, 0, size)
        if wanted[v]:
            wanted[v] = False
            left -= 1
            if left == 0:
                break
        if rescue[v] and by_edge[v] and _rescue(P, v, d, o, sid, w, g, pos, e_ptr, e_idx, K, riccati):
            by_edge[v] = False
        dv = d[v]
        ov = o[v]
        sv = sid[v]
        rv = dv - ov
        kv = _kappa(rv, w[v]) if riccati else (1.0 / rv if rv > 0.0 else np.inf)
        for q in range(e_ptr[v], e_ptr[v + 1]):
            x = e_idx[q]
            cand = dv + e_len[q]
            if cand < d[x] * (1.0 - 1e-12):
                d[x] = cand
                o[x] = ov
                sid[x] = sv
                by_edge[x] = True
                g[x, 0] = (P[x, 0] - P[v, 0]) / e_len[q]
                g[x, 1] = (P[x, 1] - P[v, 1]) / e_len[q]
                g[x, 2] = (P[x, 2] - P[v, 2]) / e_len[q]
                if riccati:
                    w[x] = _carry(w[v], rv, cand - ov, 0.5 * (K[v] + K[x]))
                size = _push(heap, key, pos, size, x, cand)
        for q in range(vt_ptr[v], vt_ptr[v + 1]):
            for r in range(2):
                x = vt_pair[q, r]
                y = vt_pair[q, 1 - r]
                if pos[x] >= 0:  # x is not final yet: the triangle is swept when x is, from both final corners
                    continue
                dx = d[x]
                if dx == np.inf:
                    continue
                lab = vt_geom[q, 3 * r]
                cx = vt_geom[q, 3 * r + 1]
                cy = vt_geom[q, 3 * r + 2]
                # any candidate through the edge vx is at least (dv + dx - |vx|) / 2 (the front's distance is
                # 1-Lipschitz along the edge) plus y's height cy over it: skip y when that cannot improve it
                if d[y] <= 0.5 * (dv + dx - lab) + cy:
                    continue
                sx = sid[x]
                t = 0.0
                s = 0.0
                ux = 0.0
                uy = 0.0
                if sx == sv:  # both corners' fronts come from one point source
                    cand, t, s, ux, uy = _triangle_ray(lab, cx, cy, rv, dx - ov, kv)
                    cand += ov
                else:
                    ax = P[sx, 0] - P[sv, 0]
                    ay = P[sx, 1] - P[sv, 1]
                    az = P[sx, 2] - P[sv, 2]
                    if ax * ax + ay * ay + az * az <= 9.0 * lab * lab and o[x] == ov:
                        # neighbouring sources of a set (a curve, a boundary): one straight front
                        cand, t, s, ux, uy = _triangle_ray(lab, cx, cy, dv, dx, 0.0)
                    else:  # fronts of distinct sources meet here (a kink): no front spans them
                        cand = np.inf
                e0 = e1 = e2 = m0 = m1 = m2 = 0.0
                if cand < d[y] * (1.0 - 1e-12):
                    # the triangle laid flat in space: vx along e, y's side along m
                    e0 = (P[x, 0] - P[v, 0]) / lab
                    e1 = (P[x, 1] - P[v, 1]) / lab
                    e2 = (P[x, 2] - P[v, 2]) / lab
                    m0 = (P[y, 0] - P[v, 0] - cx * e0) / cy
                    m1 = (P[y, 1] - P[v, 1] - cx * e1) / cy
                    m2 = (P[y, 2] - P[v, 2] - cx * e2) / cy
                    if (g[v, 0] + g[x, 0]) * m0 + (g[v, 1] + g[x, 1]) * m1 + (g[v, 2] + g[x, 2]) * m2 < 0.0:
                        # the fronts at v and x move away from y's side of vx: their virtual source lies on
                        # that side (y nearly on the line vx), the construction's mirror image of it is too far
                        cand = np.inf
                if cand < d[y] * (1.0 - 1e-12):
                    d[y] = cand
                    o[y] = ov
                    sid[y] = sv
                    by_edge[y] = False
                    g[y, 0] = ux * e0 + uy * m0
                    g[y, 1] = ux * e1 + uy * m1
                    g[y, 2] = ux * e2 + uy * m2
                    if riccati:  # the correction carried from where the ray crosses vx (s before y) to y
                        w[y] = _carry((1.0 - t) * w[v] + t * w[x], cand - ov - s, cand - ov,
                                      0.5 * K[y] + 0.5 * ((1.0 - t) * K[v] + t * K[x]))
                    size = _push(heap, key, pos, size, y, cand)
    return d


_propagate = _compile(_propagate)


def propagate(
    P: np.ndarray,
    incidence: tuple[np.ndarray, np.ndarray, np.ndarray],
    edges: tuple[np.ndarray, np.ndarray, np.ndarray],
    sources: np.ndarray,
    offsets: np.ndarray,
    targets: np.ndarray | None = None,
    gauss: np.ndarray | None = None,
    rescue: np.ndarray | None = None,
) -> np.ndarray:
    """Run the wavefront sweep (see the module notes); distances in the units of ``P``, inf where not reached.

    Parameters
    ----------
    P : ndarray, shape (N, 3)
        Coordinates (best of size about 1: :class:`LocalTriangles` keeps the cloud so scaled).
    incidence : tuple of ndarray
        :meth:`LocalTriangles.incidence`: ``(ptr (N + 1,), pairs (3 T, 2), unfolded (3 T, 6))``;
        for particle ``v``, ``pairs[ptr[v]:ptr[v + 1]]`` are the two other corners ``x, y`` of
        every triangle at ``v``, ``unfolded`` the triangle laid flat from ``v`` along ``vx``
        (``|vx|`` and ``y``'s coordinates) and along ``vy`` (``|vy|`` and ``x``'s).
    edges : tuple of ndarray
        :meth:`LocalTriangles.adjacency`: ``(ptr (N + 1,), idx (E,), length (E,))``, the edge
        neighbours of every particle (CSR) and the edges' lengths.
    sources : ndarray of int, shape (S,)
    offsets : ndarray, shape (S,)
        Distance each source starts with (0 for a point source). Each particle remembers the
        source its front comes from and that source's offset: a triangle update from one
        source places the virtual source at the corners' distances less the offset; corners
        reached from neighbouring sources of a set (sources closer than 3 edge lengths, same
        offset) carry one straight front; others (fronts of distinct sources meeting) none.
    targets : ndarray of int, optional
        Stop once all of these are final; the others may be left larger or inf.
    gauss : ndarray, shape (N,), optional
        Gaussian curvature at every particle (units of ``P``). When given, each point source's
        front carries its geodesic curvature along the rays by the Riccati equation
        ``kappa' = -kappa^2 - K``; without it the curvature is ``1 / r`` (exact in a plane).
    rescue : ndarray of bool, shape (N,), optional
        Particles that, reached only by an edge candidate, are re-solved through pairs of their final
        neighbours before they pass their distance on (see :func:`_rescue`;
        :meth:`LocalTriangles.rescuable`). None: nowhere.
    """
    targets = np.zeros(0, np.int64) if targets is None else np.ascontiguousarray(targets, dtype=np.int64)
    K = np.zeros(P.shape[0]) if gauss is None else np.ascontiguousarray(gauss, dtype=np.float64)
    return _propagate(P, incidence[0], incidence[1], incidence[2], edges[0], edges[1], edges[2],
                      np.ascontiguousarray(sources, dtype=np.int64), np.ascontiguousarray(offsets, dtype=np.float64), targets,
                      K, gauss is not None,
                      np.zeros(P.shape[0], np.bool_) if rescue is None else np.ascontiguousarray(rescue, dtype=np.bool_))


# ----------------------------------------------------------------------------- triangles
def pca_normals(points: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Unit normals (unoriented), shape (N, 3): the least-variance direction of each row of ``points[idx]``."""
    q = points[idx]
    mean = q.mean(axis=1)
    C = np.einsum("rki,rkj->rij", q, q) / idx.shape[1] - np.einsum("ri,rj->rij", mean, mean)
    _, vec = np.linalg.eigh(C)
    return np.ascontiguousarray(vec[:, :, 0])


@dataclasses.dataclass(frozen=True, repr=False)
class LocalTriangles(Result):
    """The triangles of every particle's tangent-plane Delaunay fan (see the module notes).

    Attributes
    ----------
    points : ndarray, shape (N, 3)
        The cloud moved to its bounding box's centre and divided by ``scale``.
    scale : float
        The cloud's extent (largest bounding-box side).
    triangles : ndarray of int, shape (T, 3)
        Distinct triangles (sorted corner indices).
    edges : ndarray of int, shape (E, 2)
        Every Delaunay pair and every triangle side ``(i, j)`` once, ``i < j``.
    open : ndarray of bool, shape (N,)
        Particles whose fan is open (boundary particles of an open surface, or particles
        without a closed neighbourhood).
    normals : ndarray, shape (N, 3)
        Unit normals of the tangent planes the fans were computed in.
    gauss : ndarray, shape (N,)
        Gaussian curvature of the quadric fitted to each particle's nearest points (in the
        units of ``points``), for the front's curvature.
    roughness : ndarray, shape (N,)
        Root mean square residual of that quadric fit (in the units of ``points``; NaN where the
        fit is singular): noise normal to the surface, or the quadric's misfit on a coarse cloud.
    spacing : float
        Mean distance of the particles to their 6 nearest points (units of ``points``).
    """

    points: np.ndarray
    scale: float
    triangles: np.ndarray
    edges: np.ndarray
    open: np.ndarray
    normals: np.ndarray
    gauss: np.ndarray
    roughness: np.ndarray
    spacing: float

    def noise(self) -> float:
        """The cloud's noise level in spacings: the median :attr:`roughness` over :attr:`spacing` (0 without fits).

        Gaussian noise of ``s`` spacings per coordinate reads about ``0.9 s`` (0.05-0.5 spacings on spheres,
        tori and models); clean clouds read their quadrics' misfit (0.000-0.003 on spheres and tori, 0.02-0.16
        on the coarse test models)."""
        r = self.roughness[np.isfinite(self.roughness)]
        return float(np.median(r) / self.spacing) if r.size and self.spacing > 0 else 0.0

    def incidence(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(ptr, pairs, unfolded)`` for :func:`propagate`: the two other corners of each triangle at each
        particle, and the triangle laid flat from the particle along each of its two sides."""
        n, tri, P = self.points.shape[0], self.triangles, self.points
        corner = tri.ravel()
        other = np.stack([tri[:, [1, 2]], tri[:, [2, 0]], tri[:, [0, 1]]], axis=1).reshape(-1, 2)
        order = np.argsort(corner, kind="stable")
        ptr = np.concatenate([[0], np.cumsum(np.bincount(corner, minlength=n))]).astype(np.int64)
        v, pairs = corner[order], np.ascontiguousarray(other[order], dtype=np.int64)
        geom = np.empty((v.size, 6))
        for r in range(2):
            ab = P[pairs[:, r]] - P[v]
            ac = P[pairs[:, 1 - r]] - P[v]
            lab = np.sqrt(np.einsum("pd,pd->p", ab, ab))
            cx = np.einsum("pd,pd->p", ac, ab) / np.where(lab > 0, lab, 1.0)
            cy = np.sqrt(np.maximum(np.einsum("pd,pd->p", ac, ac) - cx * cx, 0.0))
            geom[:, 3 * r], geom[:, 3 * r + 1], geom[:, 3 * r + 2] = lab, cx, cy
        return ptr, pairs, geom

    def resolved_gauss(self) -> np.ndarray:
        """``gauss`` where the quadric resolves it (:data:`RESOLVED_CURVATURE`), 0 elsewhere; shape (N,)."""
        e = self.edges
        if e.shape[0] == 0:
            return np.zeros(self.points.shape[0])
        h = float(np.mean(np.linalg.norm(self.points[e[:, 0]] - self.points[e[:, 1]], axis=1)))
        return np.where(np.abs(self.gauss) * h * h <= RESOLVED_CURVATURE, self.gauss, 0.0)

    def rescuable(self) -> np.ndarray:
        """Where :func:`propagate` may re-solve a particle reached only by an edge, shape (N,) bool: away
        (by more than two edges) from open fans and from particles whose curvature the quadric does not
        resolve (creases, thin features, the gaps between sheets: there a pair of neighbours may span
        what is not surface)."""
        bad = self.open | (self.resolved_gauss() != self.gauss)
        e = self.edges
        for _ in range(2):
            grown = bad.copy()
            grown[e[:, 0][bad[e[:, 1]]]] = True
            grown[e[:, 1][bad[e[:, 0]]]] = True
            bad = grown
        return ~bad

    def adjacency(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(ptr, idx, length)`` for :func:`propagate`: the edge neighbours of each particle (CSR, both
        directions) and the edges' lengths."""
        n, e = self.points.shape[0], self.edges
        both = np.concatenate([e, e[:, ::-1]])
        order = np.argsort(both[:, 0], kind="stable")
        ptr = np.concatenate([[0], np.cumsum(np.bincount(both[:, 0], minlength=n))]).astype(np.int64)
        idx = np.ascontiguousarray(both[order, 1], dtype=np.int64)
        length = np.linalg.norm(self.points[idx] - self.points[np.repeat(np.arange(n), np.diff(ptr))], axis=1)
        return ptr, idx, length


def quadric_gauss(P: np.ndarray, nrm: np.ndarray, u: np.ndarray, v: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Gaussian curvature (N,) of the quadric height function ``z = c0 + c1 x + c2 y + c3 x^2 + c4 x y + c5 y^2``
    fitted by least squares to the points ``P[idx[i]]`` in particle ``i``'s frame ``(u, v, nrm)``:
    ``(4 c3 c5 - c4^2) / (1 + c1^2 + c2^2)^2``; 0 where the fit is singular (fewer than 6 points, collinear)."""
    return _quadric_fits(P, nrm, u, v, idx)[0]


def _quadric_fits(P, nrm, u, v, idx):
    """:func:`quadric_gauss` and the fits' residuals: ``(K, rms)``, each (N,); ``rms`` the root mean square of the
    heights' residuals over the fit's degrees of freedom (``k - 6`` for ``k`` points), NaN where singular."""
    out = np.zeros(P.shape[0])
    rms = np.full(P.shape[0], np.nan)
    if idx.shape[1] < 6:
        return out, rms
    for lo in range(0, P.shape[0], 8192):
        sl = slice(lo, lo + 8192)
        off = P[idx[sl]] - P[sl][:, None, :]
        x = np.einsum("rkd,rd->rk", off, u[sl])
        y = np.einsum("rkd,rd->rk", off, v[sl])
        z = np.einsum("rkd,rd->rk", off, nrm[sl])
        scale = np.sqrt(np.mean(x * x + y * y, axis=1))[:, None]
        scale = np.where(scale > 0, scale, 1.0)
        x, y, z = x / scale, y / scale, z / scale  # a fit in units of the neighbourhood: well conditioned
        A = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=-1)
        AtA = np.einsum("rki,rkj->rij", A, A)
        Atz = np.einsum("rki,rk->ri", A, z)
        # singular fits (points on a line, too few distinct points): det far below the diagonal's product
        ok = np.linalg.det(AtA) > 1e-12 * np.prod(np.einsum("rii->ri", AtA), axis=1)
        c = np.zeros((AtA.shape[0], 6))
        if ok.any():
            c[ok] = np.linalg.solve(AtA[ok], Atz[ok][..., None])[..., 0]
        K = (4.0 * c[:, 3] * c[:, 5] - c[:, 4] ** 2) / (1.0 + c[:, 1] ** 2 + c[:, 2] ** 2) ** 2
        out[sl] = np.where(ok, K, 0.0) / scale[:, 0] ** 2
        if idx.shape[1] > 6:
            r = z - np.einsum("rki,ri->rk", A, c)
            rms[sl] = np.where(ok, np.sqrt(np.einsum("rk,rk->r", r, r) / (idx.shape[1] - 6)) * scale[:, 0], np.nan)
    return out, rms


def _knn(tree, X, k):
    dist, idx = tree.query(X, k=k, workers=-1 if X.shape[0] > 50_000 else 1)
    return (dist[:, None], idx[:, None]) if k == 1 else (dist, idx)


def _delaunay_pairs(P, nrm, u, v, tree, rows, k, knn=None):
    """Delaunay neighbours of ``rows`` among their ``k`` nearest points (``knn``: that query's result, if
    made) in their tangent planes: ``(row, col, angle, distance)`` of every pair, the cells' flags and the
    distance to the farthest of the ``k``."""
    m = rows.size
    dist, idx = _knn(tree, P[rows], k) if knn is None else knn
    off = P[idx] - P[rows][:, None, :]
    xy = np.stack([np.einsum("rkd,rd->rk", off, u[rows]), np.einsum("rkd,rd->rk", off, v[rows])], axis=-1).reshape(-1, 2)
    z = np.einsum("rkd,rd->rk", off, nrm[rows]).ravel()
    del off
    indptr = np.arange(m + 1, dtype=np.int64) * k
    radius = np.maximum(dist[:, -1], 1e-300) * (1.0 + 1e-9) if k < P.shape[0] else np.full(m, np.inf)
    cells = voronoi_cells(indptr, xy, radius, height=z)
    owner = np.repeat(rows, k)
    keep = (cells.weights > 0) & (idx.ravel() != owner)
    return owner[keep], idx.ravel()[keep], np.arctan2(xy[keep, 1], xy[keep, 0]), dist.ravel()[keep], cells.flags, dist[:, -1]


def _unique_rows(a: np.ndarray, n: int) -> np.ndarray:
    """Distinct rows of a non-negative int array of 2 or 3 columns (values < n), sorted: one 1-D sort of keys."""
    a = a.astype(np.int64)
    if a.shape[0] == 0:
        return a.reshape(0, a.shape[1])
    if a.shape[1] == 3 and n > 2_000_000:  # n^3 would overflow int64: the slower row-wise unique
        return np.unique(a, axis=0)
    key = a[:, 0]
    for c in range(1, a.shape[1]):
        key = key * n + a[:, c]
    _, first = np.unique(key, return_index=True)
    return a[first]


def _fans(rows, cols, ang, n):
    """Sort pairs into fans (by row, then angle); the next neighbour of each pair round its fan, and
    whether the angle to it closes (below :data:`OPEN_GAP`)."""
    order = np.argsort(rows + (ang + np.pi) / (2.0 * np.pi + 1e-9), kind="stable")  # by row, then angle
    rows, cols, ang = rows[order], cols[order], ang[order]
    count = np.bincount(rows, minlength=n)
    start = np.concatenate([[0], np.cumsum(count)])
    nxt = np.arange(rows.size) + 1
    has = count > 0
    nxt[start[1:][has] - 1] = start[:-1][has]  # the last neighbour of a fan wraps round to its first
    gap = (ang[nxt] - ang) % (2.0 * np.pi)
    closed = (gap < OPEN_GAP) & (nxt != np.arange(rows.size))
    return order, rows, cols, nxt, closed, has


def local_triangles(points: np.ndarray, normals: np.ndarray | None = None, *, neighbors: int = 16) -> LocalTriangles:
    """The local Delaunay triangles of a cloud (see the module notes).

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        Finite coordinates (any scale within float64's range).
    normals : ndarray, shape (N, 3), optional
        Normals of the tangent planes (their orientation does not matter); by default the
        least-variance direction of each particle's ``neighbors`` nearest points.
    neighbors : int
        Nearest points (the particle included) among which each fan is computed; a cell
        that farther points could still cut is computed again among 4 times as many (see
        the comments of the code for which result is kept).

    Returns
    -------
    LocalTriangles
    """
    n = points.shape[0]
    lo, hi = points.min(axis=0), points.max(axis=0)
    scale = float(np.max(hi - lo))
    if not scale > 0:
        raise ValueError("points must not all coincide (the cloud has zero extent)")
    P = np.ascontiguousarray((points - (lo + 0.5 * (hi - lo))) / scale)
    tree = cKDTree(P)
    k = min(int(neighbors), n)
    knn = _knn(tree, P, k)
    if normals is None:
        nrm = pca_normals(P, knn[1])
    else:
        nrm = np.asarray(normals, dtype=np.float64)
    helper = np.where(np.abs(nrm[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(nrm, helper)
    u /= np.linalg.norm(u, axis=1)[:, None]
    v = np.cross(nrm, u)
    rows, cols, ang, _, flags, reach = _delaunay_pairs(P, nrm, u, v, tree, np.arange(n), k, knn)
    gauss, rough = _quadric_fits(P, nrm, u, v, knn[1])
    spacing = float(np.mean(knn[0][:, 1:7])) if k > 1 else 0.0
    del knn
    redo = np.flatnonzero((flags & INCOMPLETE) != 0)
    interior = np.zeros(n, bool)  # fans that close only in the wider search
    if redo.size and k < n:
        # a cell farther points could cut: computed again among 4 times as many. Its fan replaces the
        # first if it then closes within 1.25 times the first search radius (an interior particle whose
        # nearest points lie to one side); if it closes within twice that radius the particle is not on a
        # boundary, but its triangles stay the first fan's (a fan closed farther out may bridge a thin
        # gap of the surface: an ear's two sheets, a notch in a boundary)
        r2, c2, a2, d2, _, _ = _delaunay_pairs(P, nrm, u, v, tree, redo, min(4 * k, n))
        _, r2s, _, _, closed2, has2 = _fans(r2, c2, a2, n)
        ok = has2.copy()
        np.logical_and.at(ok, r2s, closed2)
        far = np.zeros(n)
        np.maximum.at(far, r2, d2)
        take = np.zeros(n, bool)
        take[redo] = ok[redo] & (far[redo] <= 1.25 * reach[redo])
        interior[redo] = ok[redo] & (far[redo] <= 2.0 * reach[redo])
        keep = ~take[rows]
        sel = take[r2]
        rows, cols, ang = (np.concatenate([rows[keep], r2[sel]]), np.concatenate([cols[keep], c2[sel]]),
                           np.concatenate([ang[keep], a2[sel]]))
    _, rows, cols, nxt, closed, has = _fans(rows, cols, ang, n)
    is_open = ~has
    is_open[rows[~closed]] = True
    is_open &= ~interior
    tri = _unique_rows(np.sort(np.stack([rows[closed], cols[closed], cols[nxt][closed]], axis=1), axis=1), n)
    pairs = np.concatenate([np.stack([rows, cols], axis=1), tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]]])
    lonely = np.flatnonzero(~has & (k > 1))  # no Delaunay neighbour (a degenerate cell): its nearest point
    if lonely.size:
        pairs = np.concatenate([pairs, np.stack([lonely, tree.query(P[lonely], k=2)[1][:, 1]], axis=1)])
    edges = _unique_rows(np.sort(pairs, axis=1), n)
    return LocalTriangles(points=P, scale=scale, triangles=tri.astype(np.int64), edges=edges.astype(np.int64), open=is_open,
                          normals=np.ascontiguousarray(nrm), gauss=gauss,
                          roughness=rough, spacing=spacing)
