"""Global orientation: reliable patches, their signs from the winding number, the rest from their neighbours.

The backbone of ``estimate_normals`` for clouds with noise (scans). It sees the whole cloud at
once instead of propagating signs along a tree, where one wrong edge flips everything behind it:

1. **Safe patches.** Edges of the k-nearest-neighbour graph whose ends have nearly parallel
   normal lines (``|n_i . n_j| > tuning.SAFE_DOT``) and lie near each other's tangent plane
   (the tilt beyond the noise level below ``tuning.SAFE_TILT``) carry the sign of ``n_i . n_j``
   reliably, except near particles where two sheets meet: particles with a point steeply across
   their tangent plane above the noise (thin parts, touching parts, creases) or whose fit residual
   is well above the noise level (junctions) are left out. The components of the safe edges are
   the patches, signed by a breadth-first tree inside each.
2. **Patch signs.** Patches of at least ``tuning.PATCH_MIN`` particles take the signs that make the
   generalised winding number of the cloud 1 just inside and 0 just outside at probes
   ``p -+ delta n`` (``delta`` at least ``tuning.PROBE_NOISE`` noise levels), a quadratic problem in
   the patch signs (:func:`~manifold_sph.normals.winding.objective`).
3. **The rest** (left-out particles and small patches) take, ring by ring from the oriented ones,
   the sign that the dipoles of their ``tuning.ATTACH_K`` nearest oriented neighbours predict:
   ``n_i . n_j - 3 t_i t_j`` with ``t = n . e`` the tilts of the edge beyond the noise (the field
   of a dipole: right across thin parts, where the reflection of the normal in the edge is the
   prediction, and on smooth sheets, where it is ``n_i . n_j``).
4. **Repair.** Regions whose probes read the field far from 1 (``w_in + w_out`` below 0.5 or
   above 1.5) are flipped where that lowers the objective.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from ..threads import get_num_threads
from . import tuning
from .arrays import unique_sorted
from .graph import tree_signs
from .winding import best_signs, integer_signs, objective, winding_numbers

__all__ = ["attach_agreement", "correct_parts", "dipole_agreement", "global_orientation", "unsafe_particles"]


def _edges(pts: np.ndarray, nrm: np.ndarray, neighbors: np.ndarray, sigma: np.ndarray):
    """Unique undirected k-NN edges ``a < b``: ``n_a . n_b`` and the largest edge tilt beyond the noise."""
    N, k = neighbors.shape
    rows = np.repeat(np.arange(N, dtype=np.int64), k - 1)
    cols = neighbors[:, 1:].ravel().astype(np.int64)
    off = rows != cols
    a, b = np.minimum(rows[off], cols[off]), np.maximum(rows[off], cols[off])
    key = unique_sorted(a * N + b)
    a, b = key // N, key % N
    e = pts[b] - pts[a]
    length = np.maximum(np.linalg.norm(e, axis=1), 1e-300)
    e /= length[:, None]
    noise = tuning.TILT_NOISE * 0.5 * (sigma[a] + sigma[b]) / length
    tilt = np.maximum(np.maximum(np.abs(np.einsum("ij,ij->i", nrm[a], e)), np.abs(np.einsum("ij,ij->i", nrm[b], e))) - noise, 0.0)
    return a, b, np.einsum("ij,ij->i", nrm[a], nrm[b]), tilt


def dipole_agreement(pts: np.ndarray, nrm: np.ndarray, a: np.ndarray, b: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """``n_a . n_b - 3 t_a t_b`` for the pairs ``(a, b)``: positive where the two normals agree in sign.

    ``t = n . e`` are the tilts of the unit edge ``e`` out of the two tangent planes, shrunk by
    ``tuning.TILT_NOISE`` noise levels over the edge length (a noisy edge leaves the tangent plane
    by chance). The same sign as the field of a dipole ``n_b`` at ``p_a`` along ``n_a``, without its
    ``1 / r^3`` weight: ``n_a . n_b`` on a smooth sheet, the reflection rule across a thin part.
    """
    e = pts[b] - pts[a]
    length = np.maximum(np.linalg.norm(e, axis=1), 1e-300)
    e = e / length[:, None]
    noise = tuning.TILT_NOISE * 0.5 * (sigma[a] + sigma[b]) / length
    ta = np.einsum("ij,ij->i", nrm[a], e)
    tb = np.einsum("ij,ij->i", nrm[b], e)
    ta = np.sign(ta) * np.maximum(np.abs(ta) - noise, 0.0)
    tb = np.sign(tb) * np.maximum(np.abs(tb) - noise, 0.0)
    return np.einsum("ij,ij->i", nrm[a], nrm[b]) - 3.0 * ta * tb


def unsafe_particles(pts: np.ndarray, nrm: np.ndarray, neighbors: np.ndarray, sigma: np.ndarray,
                     residual: np.ndarray | None = None, floor: float = 0.0) -> np.ndarray:
    """Particles near which two sheets may meet: not used for the safe patches.

    A particle is unsafe where one of its ``tuning.UNSAFE_K`` nearest lies steeply across its
    tangent plane (height above ``tuning.UNSAFE_STEEP`` times the distance, and above
    ``tuning.UNSAFE_NOISE`` noise levels: a thin part, a touching part or a crease), or where its
    fit ``residual`` (a length) exceeds ``tuning.UNSAFE_RESIDUAL`` times its noise level (at least
    ``floor``): a junction of sheets.
    """
    k = min(tuning.UNSAFE_K, neighbors.shape[1])
    L = pts[neighbors[:, 1:k]] - pts[:, None, :]
    z = np.abs(np.einsum("nkj,nj->nk", L, nrm))
    across = (z > tuning.UNSAFE_STEEP * np.linalg.norm(L, axis=2)) & (z > tuning.UNSAFE_NOISE * sigma[:, None])
    out = across.any(axis=1)
    if residual is not None:
        out |= residual > tuning.UNSAFE_RESIDUAL * np.maximum(sigma, floor)
    return out


def _probes(pts, nrm, h, sigma, rows):
    delta = np.maximum(tuning.PROBE_OFFSET * h[rows], tuning.PROBE_NOISE * sigma[rows])
    return np.vstack([pts[rows] - delta[:, None] * nrm[rows], pts[rows] + delta[:, None] * nrm[rows]])


def _sample(rows: np.ndarray, m: int) -> np.ndarray:
    if rows.size <= m:
        return rows
    return np.sort(np.random.default_rng(0).choice(rows, m, replace=False))


def _attach(pts, out, neighbors, done, sigma):
    """Left-out particles, ring by ring from the oriented ones: the sign their oriented neighbours' dipoles predict."""
    rest = np.flatnonzero(~done)
    k = min(tuning.ATTACH_K, neighbors.shape[1])
    for _ in range(tuning.ATTACH_ROUNDS):
        if rest.size == 0:
            break
        nb = neighbors[rest, 1:k]
        ok = done[nb]
        agree = dipole_agreement(pts, out, np.repeat(rest, k - 1), nb.ravel(), sigma).reshape(rest.size, k - 1)
        vote = np.where(ok, agree, 0.0).sum(axis=1)
        has = ok.any(axis=1)
        out[rest[has & (vote < 0)]] *= -1.0
        done[rest[has]] = True
        rest = rest[~has]
    return out, done


def attach_agreement(pts: np.ndarray, nrm: np.ndarray, neighbors: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Share of the dipole predictions of the nearest (``neighbors``, itself first) that agree with each sign.

    1 where all neighbours' dipoles agree, 0.5 where they are split: the orientation confidence
    of particles outside the safe patches.
    """
    N, k = neighbors.shape
    agree = dipole_agreement(pts, nrm, np.repeat(np.arange(N), k - 1), neighbors[:, 1:].ravel(), sigma).reshape(N, k - 1)
    total = np.abs(agree).sum(axis=1)
    return np.where(total > 0, 0.5 + 0.5 * agree.sum(axis=1) / np.maximum(total, 1e-300), 1.0).clip(0.0, 1.0)


def _repair(pts, out, neighbors, sigma, area, h):
    """Regions whose probes read the field far from 1 are flipped where that lowers the objective."""
    N = pts.shape[0]
    probes = _sample(np.arange(N), tuning.MAX_PROBES)
    near = np.arange(N) if probes.size == N else cKDTree(pts[probes]).query(pts, k=1, workers=get_num_threads())[1]
    ko = min(tuning.ORIENT_K, neighbors.shape[1])
    rows = np.repeat(np.arange(N, dtype=np.int64), ko - 1)
    cols = neighbors[:, 1:ko].ravel().astype(np.int64)
    omega = area[probes]
    for _ in range(tuning.REPAIR_ROUNDS):
        q = _probes(pts, out, h, sigma, probes)
        W = winding_numbers(q, pts, out, area, 0.2 * h, np.zeros(N, dtype=np.int64), 1)[:, 0]
        S = W[: probes.size] + W[probes.size :]
        bad = ((S < tuning.FLAG_S) | (S > tuning.FLAG_S_HIGH))[near]
        keep = bad[rows] & bad[cols] & (np.einsum("ij,ij->i", out[rows], out[cols]) > 0.5)
        _, reg = csgraph.connected_components(sp.coo_matrix((np.ones(int(keep.sum())), (rows[keep], cols[keep])), shape=(N, N)),
                                              directed=False)
        cand = bad & (np.bincount(reg)[reg] >= tuning.REPAIR_MIN)
        if not cand.any():
            break
        ids = np.full(reg.max() + 1, -1, dtype=np.int64)
        regions = np.unique(reg[cand])
        ids[regions] = np.arange(regions.size)
        lab = np.where(cand, ids[reg], regions.size)  # the last label: everything else, kept
        W = winding_numbers(q, pts, out, area, 0.2 * h, lab, regions.size + 1)
        H, g = objective(W, lab[probes], omega)
        margin = np.zeros(regions.size + 1)
        margin[-1] = np.inf
        s = best_signs(H, g, np.zeros((0, regions.size + 1)), margin)
        if np.all(s > 0):
            break
        out = out * s[lab][:, None]
    return out


def _areas(distances):
    ka = min(8, distances.shape[1])
    r = distances[:, ka - 1]
    r = np.where(r > 0, r, np.median(r[r > 0]) if np.any(r > 0) else 1.0)
    area = np.pi * r**2 / max(ka - 0.5, 1.0)
    return area, np.sqrt(area)


def _safe_patches(pts, nrm, neighbors, sigma, residual, h):
    """Labels of the safe patches (components of the safe edges) and each particle's sign inside its patch."""
    N = pts.shape[0]
    ko = min(tuning.ORIENT_K, neighbors.shape[1])
    a, b, d, tilt = _edges(pts, nrm, neighbors[:, :ko], sigma)
    unsafe = unsafe_particles(pts, nrm, neighbors, sigma, residual, 1e-3 * float(np.median(h)))
    safe = (np.abs(d) > tuning.SAFE_DOT) & (tilt < tuning.SAFE_TILT) & ~unsafe[a] & ~unsafe[b]
    sa, sb, sg = a[safe], b[safe], np.where(d[safe] < 0, -1.0, 1.0)
    G = sp.coo_matrix((np.ones(sa.size), (sa, sb)), shape=(N, N)).tocsr()
    _, lab = csgraph.connected_components(G, directed=False)
    T = csgraph.minimum_spanning_tree(G).tocsr()  # a spanning forest of the safe edges
    Sg = sp.coo_matrix((sg, (sa, sb)), shape=(N, N)).tocsr()
    Sg = Sg + Sg.T
    roots = np.unique(lab, return_index=True)[1]
    return lab, tree_signs(N, T + T.T, roots, lambda c, p: np.sign(np.asarray(Sg[c, p]).ravel()))


def _calibrated(pts, nrm, neighbors, sigma, area, h):
    """Areas divided by the measured jump of the winding number across each particle (clipped to [1, 4]).

    The jump ``w_in - w_out`` does not depend on the orientation (the far field cancels in the
    difference): it is the local dipole density over the true one, above 1 where the areas
    ``pi r_8^2 / 7.5`` are too large (coarse, strongly curved parts: thin tubes, small parts).
    """
    N = pts.shape[0]
    probes = _sample(np.arange(N), tuning.MAX_PROBES)
    W = winding_numbers(_probes(pts, nrm, h, sigma, probes), pts, nrm, area, 0.2 * h, np.zeros(N, dtype=np.int64), 1)[:, 0]
    jump = np.abs(W[: probes.size] - W[probes.size :])
    near = np.arange(N) if probes.size == N else cKDTree(pts[probes]).query(pts, k=1, workers=get_num_threads())[1]
    ko = min(tuning.ORIENT_K, neighbors.shape[1])
    return area / np.clip(np.median(jump[near][neighbors[:, :ko]], axis=1), 1.0, 4.0)


def _patch_fields(pts, out, lab, sigma, area, h):
    """The patches of at least ``tuning.PATCH_MIN`` particles, their fields at the probes of their particles."""
    size = np.bincount(lab)
    good = size[lab] >= tuning.PATCH_MIN
    big = np.flatnonzero(size >= tuning.PATCH_MIN)
    ids = np.full(size.size, -1, dtype=np.int64)
    ids[big] = np.arange(big.size)
    plab = np.where(good, ids[lab], big.size)  # the last label: particles in no patch (no field)
    probes = _sample(np.flatnonzero(good), tuning.MAX_PROBES)
    W = winding_numbers(_probes(pts, out, h, sigma, probes), pts, np.where(good[:, None], out, 0.0), area, 0.2 * h,
                        plab, big.size + 1)[:, : big.size]
    return good, plab, probes, W


def global_orientation(pts: np.ndarray, nrm: np.ndarray, neighbors: np.ndarray, distances: np.ndarray,
                       sigma: np.ndarray, residual: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Orient unit normals over the whole cloud at once (module notes); returns the normals and the safe mask.

    Parameters
    ----------
    pts, nrm : ndarray, shape (N, 3)
        Points and unit normals (signs arbitrary).
    neighbors, distances : ndarray, shape (N, K)
        Nearest neighbours, itself first (``K`` at least ``tuning.ATTACH_K``).
    sigma : ndarray, shape (N,)
        Noise level of every particle (a length; :func:`~manifold_sph.normals.scale.noise_level`).
    residual : ndarray, shape (N,), optional
        Fit residuals (lengths): particles far above their noise level are left out of the patches.
    """
    area, h = _areas(distances)
    lab, gauge = _safe_patches(pts, nrm, neighbors, sigma, residual, h)
    out = nrm * gauge[:, None]
    if tuning.CALIBRATE:
        area = _calibrated(pts, out, neighbors, sigma, area, h)
    good, plab, probes, W = _patch_fields(pts, out, lab, sigma, area, h)
    n_patches = W.shape[1]
    if n_patches:
        H, g = objective(W, plab[probes], area[probes])
        s = best_signs(H, g, np.zeros((0, n_patches)))
        s = integer_signs(W, plab[probes], s, area[probes])
        out[good] *= s[plab[good]][:, None]
    else:  # no patch: start from the first particle
        good[0] = True
    out, _ = _attach(pts, out, neighbors, good.copy(), sigma)
    out = _repair(pts, out, neighbors, sigma, area, h)
    return out, good


def correct_parts(pts: np.ndarray, nrm: np.ndarray, neighbors: np.ndarray, distances: np.ndarray,
                  sigma: np.ndarray | None = None) -> np.ndarray:
    """Oriented normals with whole safe patches flipped where the field then counts whole parts.

    For an oriented cloud (the propagation of :mod:`.orientation`): each safe patch starts with the
    majority of its particles' signs, and :func:`~manifold_sph.normals.winding.integer_signs` flips
    patches where the winding number then reads a whole number of parts (parts that cross each
    other: eyes through a head, limbs through a body). Where a patch flips, the particles in no
    patch that take their sign from it follow; elsewhere nothing changes.
    """
    N = pts.shape[0]
    sigma = np.zeros(N) if sigma is None else sigma
    area, h = _areas(distances)
    lab, gauge = _safe_patches(pts, nrm, neighbors, sigma, None, h)
    # the start sign of each patch: the majority of the oriented particles (in the patch's own gauge)
    start = np.where(np.bincount(lab, weights=gauge) >= 0, 1.0, -1.0)
    out = nrm * (gauge * start[lab])[:, None]  # patches consistent inside, majority sign kept
    if tuning.CALIBRATE:
        area = _calibrated(pts, out, neighbors, sigma, area, h)
    good, plab, probes, W = _patch_fields(pts, out, lab, sigma, area, h)
    if W.shape[1] == 0:
        return nrm
    s = integer_signs(W, plab[probes], np.ones(W.shape[1]), area[probes])
    if np.all(s > 0):
        return nrm
    flipped = np.zeros(N, dtype=bool)
    flipped[good] = s[plab[good]] < 0
    res = nrm.copy()
    res[good] = out[good] * s[plab[good]][:, None]
    # particles in no patch whose nearest patch particle flipped are attached again
    near = cKDTree(pts[good]).query(pts[~good], k=1, workers=get_num_threads())[1] if (~good).any() else np.zeros(0, dtype=np.int64)
    redo = np.flatnonzero(~good)[flipped[np.flatnonzero(good)][near]]
    done = np.ones(N, dtype=bool)
    done[redo] = False
    res, _ = _attach(pts, res, neighbors, done, sigma)
    return res
