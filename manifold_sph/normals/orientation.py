"""Consistent and outward orientation of unoriented normals.

Propagation over the spanning forest of :mod:`.graph`, then a global check with the
generalised winding number (:mod:`.winding`): the cloud is cut into patches (spanning-tree
pieces separated by doubtful edges and by particles whose probes disagree), and the patch
signs minimise ``sum_i a_i [(w_in - w_out - 1)^2 + (w_in + w_out - 1)^2]`` at the probes
``p_i -+ delta_i n_i`` (the field is linear in the patch signs, so this is a small quadratic
problem in +-1 variables, solved by greedy single-patch and whole-component flips).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from .._validation import as_points, check_int
from ..threads import get_num_threads
from . import tuning
from .fitting import knn, point_array, unit
from .graph import graph_edges, orientation_graph, spanning_forest
from .shells import closed_sheets
from .visibility import visible_signs
from .winding import best_signs, winding_numbers


def _patches(N, ta, tb, tconf, flag):
    """Cut the spanning forest into patches at doubtful edges and where ``flag`` changes."""
    conf_cut = tconf < tuning.TRUST
    flag_cut = flag[ta] != flag[tb]
    keep = ~(conf_cut | flag_cut)

    def comps(keep):
        T = sp.coo_matrix((np.ones(int(keep.sum())), (ta[keep], tb[keep])), shape=(N, N))
        return csgraph.connected_components(T, directed=False)

    n_p, lab = comps(keep)
    for _ in range(3):  # merge tiny patches back through their doubtful (not flag) edges
        size = np.bincount(lab, minlength=n_p)
        small = ((size[lab[ta]] < tuning.MIN_PATCH) | (size[lab[tb]] < tuning.MIN_PATCH)) & ~keep & ~flag_cut
        if not small.any():
            break
        keep = keep | small
        n_p, lab = comps(keep)
    if n_p > tuning.MAX_PATCHES:  # a forest: restoring any cut edge merges two patches
        cut = np.flatnonzero(~keep)
        prio = tconf[cut] - 2.0 * flag_cut[cut]  # restore confident, not-flag cuts first
        keep = keep.copy()
        keep[cut[np.argsort(-prio, kind="stable")[: n_p - tuning.MAX_PATCHES]]] = True
        n_p, lab = comps(keep)
    return n_p, lab.astype(np.int64)


def _outward(pts, nrm, neighbors, distances, noise=0.0):
    """Consistent, then globally checked outward orientation (docs/normals.md, steps 3-4).

    Returns the oriented normals, the connected component of every particle and
    the orientation confidence in [0, 1].
    """
    N = pts.shape[0]
    ko = min(tuning.ORIENT_K, neighbors.shape[1])
    a, b, s, length, comps = orientation_graph(pts, nrm, neighbors)
    sign, _, ta, tb, tconf = spanning_forest(N, a, b, s, length)
    if tuning.CUT_THIN:  # tree edges where the reflection rule and the parallel rule disagree cross a thin part: patches decide
        e = pts[tb] - pts[ta]
        e = e / np.maximum(np.linalg.norm(e, axis=1), 1e-300)[:, None]
        pred = nrm[ta] - 2.0 * np.einsum("ij,ij->i", nrm[ta], e)[:, None] * e
        refl = np.einsum("ij,ij->i", pred, nrm[tb])
        par = np.einsum("ij,ij->i", nrm[ta], nrm[tb])
        tconf = np.where((refl * par < 0) & (np.abs(par) > tuning.CUT_THIN), 0.0, tconf)
    n = nrm * sign[:, None]
    n_comp = int(comps.max()) + 1 if N else 0
    # area and probe offset per particle from the local spacing
    ka = min(8, distances.shape[1])
    r = distances[:, ka - 1]
    r = np.where(r > 0, r, np.median(r[r > 0]) if np.any(r > 0) else 1.0)
    area = np.pi * r**2 / max(ka - 0.5, 1.0)
    h = np.sqrt(area)
    if N <= tuning.MAX_PROBES:
        probes = np.arange(N)
    else:
        probes = np.sort(np.random.default_rng(0).choice(N, tuning.MAX_PROBES, replace=False))
    delta = tuning.PROBE_OFFSET * h[probes]
    if tuning.THICK_PROBE > 0:  # probes stay inside thin parts: at most this fraction of the height across
        L = pts[neighbors[probes, 1:]] - pts[probes][:, None, :]
        z = np.abs(np.einsum("nkj,nj->nk", L, nrm[probes]))
        par = np.abs(np.einsum("nkj,nj->nk", nrm[neighbors[probes, 1:]], nrm[probes])) > tuning.THICK_PAR
        steep = z * z > np.maximum(np.einsum("nkj,nkj->nk", L, L) - z * z, 0.0)
        floor = tuning.THICK_NOISE * noise * distances[probes, min(tuning.THIN_K, distances.shape[1]) - 1]
        across = np.where(par & steep & (z > floor[:, None]), z, np.inf).min(axis=1)
        delta = np.maximum(np.minimum(delta, tuning.THICK_PROBE * across), tuning.THICK_FLOOR * delta)
    if tuning.CALIBRATE:
        # the jump w_in - w_out across the particle is its local dipole density over the true
        # one (the far field cancels in the difference, whatever its orientation): rescale the areas
        q = np.vstack([pts[probes] - delta[:, None] * n[probes], pts[probes] + delta[:, None] * n[probes]])
        W = winding_numbers(q, pts, n, area, 0.2 * h, np.zeros(N, dtype=np.int64), 1)[:, 0]
        jump = np.abs(W[: probes.size] - W[probes.size :])
        near = cKDTree(pts[probes]).query(pts, k=1, workers=get_num_threads())[1] if probes.size < N else np.arange(N)
        # areas are only ever reduced: in a noisy layer the probes sit among the points and
        # the jump is too small there
        jump = np.clip(np.median(jump[near][neighbors[:, :ko]], axis=1), 1.0, 4.0)
        area = area / jump
    omega = area[probes] * (N / probes.size)
    sheet_d = closed_sheets(pts, n, neighbors, probes, delta, area, h) if tuning.SHEETS else None
    flag = np.zeros(N, dtype=bool)
    D = np.ones(probes.size)
    S = np.ones(probes.size)
    for rnd in range(tuning.ROUNDS):
        n_p, lab = _patches(N, ta, tb, tconf, flag if sheet_d is None else flag + 3 * (sheet_d + 1))
        pp = lab[probes]
        q = np.vstack([pts[probes] - delta[:, None] * n[probes], pts[probes] + delta[:, None] * n[probes]])
        W = winding_numbers(q, pts, n, area, 0.2 * h, lab, n_p)
        if sheet_d is not None:  # a closed sheet's probes see its own field only (docs/normals.md, step 4)
            patch_sheet = np.full(n_p, -1, dtype=np.int64)
            patch_sheet[lab] = sheet_d
            own = sheet_d[probes]
            other = (own[:, None] >= 0) & (patch_sheet[None, :] != own[:, None])
            W[np.vstack([other, other])] = 0.0
        w_in, w_out = W[: probes.size], W[probes.size :]
        Dm, Sm = w_in - w_out, w_in + w_out
        M = np.zeros((n_p, n_p))
        np.add.at(M, pp, omega[:, None] * Dm)
        H = Dm.T @ (omega[:, None] * Dm) + Sm.T @ (omega[:, None] * Sm) - (M + M.T)
        g = omega @ Sm
        comp_of_patch = np.zeros(n_p, dtype=np.int64)
        comp_of_patch[lab] = comps
        blocks = np.zeros((n_comp, n_p)) if n_comp > 1 else np.zeros((0, n_p))
        if n_comp > 1:
            blocks[comp_of_patch, np.arange(n_p)] = 1.0
        sP = best_signs(H, g, blocks)
        if tuning.FLAG_S_HIGH is not None and rnd > 0:
            # patches cut for both probes inside (flag 2) flip only where the flip explains it, i.e. their
            # probes are then no longer both inside (a part inside another shell reads both inside either way)
            wt = np.bincount(pp, weights=omega, minlength=n_p)
            high = (np.bincount(pp, weights=omega * (flag[probes] == 2), minlength=n_p) > 0.5 * wt) & (sP < 0)
            if high.any():
                sw = sP[pp] < 0
                s_new = np.where(sw, w_out @ sP, w_in @ sP) + np.where(sw, w_in @ sP, w_out @ sP)
                s_old = w_in.sum(axis=1) + w_out.sum(axis=1)
                excess_new = np.bincount(pp, weights=omega * (s_new - 1.0), minlength=n_p)
                excess_old = np.bincount(pp, weights=omega * (s_old - 1.0), minlength=n_p)
                stay = high & (excess_new > np.where(excess_old > 0, tuning.FLAG_S_EXPLAIN * excess_old, 0.0))
                if stay.any():
                    sP = best_signs(H, g, blocks, np.where(stay, np.inf, 0.0))
        n = n * sP[lab][:, None]
        # field of the new orientation at the (possibly swapped) probes
        sw = sP[pp] < 0
        wi = np.where(sw, w_out @ sP, w_in @ sP)
        wo = np.where(sw, w_in @ sP, w_out @ sP)
        D, S = wi - wo, wi + wo
        if rnd > 0 and np.all(sP > 0):
            break
        bad = ((D < 0) | (S < tuning.FLAG_S)).astype(np.int64)
        if tuning.FLAG_S_HIGH is not None:  # a class of its own: cut from both the good and the flipped probes
            bad[(bad == 0) & (S > tuning.FLAG_S_HIGH)] = 2
        near = cKDTree(pts[probes]).query(pts, k=1, workers=get_num_threads())[1] if probes.size < N else np.arange(N)
        flag = bad[near]
        if tuning.FLAG_S_HIGH is not None and tuning.HIGH_MIN > 1 and (flag == 2).any():  # only sizeable both-inside regions
            both = (flag[ta] == 2) & (flag[tb] == 2)
            _, hl = csgraph.connected_components(sp.coo_matrix((np.ones(int(both.sum())), (ta[both], tb[both])), shape=(N, N)),
                                                 directed=False)
            hsize = np.bincount(hl[flag == 2], minlength=N)
            flag[(flag == 2) & (hsize[hl] < tuning.HIGH_MIN)] = 0
    # flat sheets: no winding-number evidence either way -> mean normal with a positive largest component
    pc = comps[probes]
    evidence = np.bincount(pc, weights=omega * S, minlength=n_comp)
    total = np.bincount(pc, weights=omega, minlength=n_comp)
    flat = np.abs(evidence) <= 0.05 * total
    if flat.any():
        mean_n = np.stack([np.bincount(comps, weights=n[:, i], minlength=n_comp) for i in range(3)], axis=1)
        big = mean_n[np.arange(n_comp), np.abs(mean_n).argmax(axis=1)]
        cs = np.where(flat & (big < 0), -1.0, 1.0)
        n = n * cs[comps][:, None]
    # isolated particles against a clear majority of their neighbours (reflection rule) are flipped
    for _ in range(2):
        a, b, s, _ = graph_edges(pts, n, neighbors[:, :ko])
        V = sp.coo_matrix((np.r_[s, s], (np.r_[a, b], np.r_[b, a])), shape=(N, N)).tocsr()
        vote = np.asarray(V.sum(axis=1)).ravel()
        weight = np.asarray(abs(V).sum(axis=1)).ravel()
        flip = vote < -0.5 * weight
        if not flip.any():
            break
        n[flip] *= -1.0
    near = cKDTree(pts[probes]).query(pts, k=1, workers=get_num_threads())[1] if probes.size < N else np.arange(N)
    oconf = np.clip(4.0 * D, 0.0, 1.0)[near]  # D = 1 inside a closed surface, about 1/2 at the rim of an open sheet
    oconf[np.abs(vote) < 0.5 * weight] *= 0.5  # neighbours split on the sign
    return n, comps, oconf


def _consistent(pts, nrm, neighbors):
    N = pts.shape[0]
    a, b, s, length, comps = orientation_graph(pts, nrm, neighbors)
    sign, *_ = spanning_forest(N, a, b, s, length)
    return nrm * sign[:, None], comps


def check_orient(orient: str | ArrayLike) -> str | np.ndarray:
    if not isinstance(orient, str):
        view = np.asarray(orient, dtype=np.float64) if np.ndim(orient) == 1 else np.zeros(0)
        if view.shape != (3,) or not np.all(np.isfinite(view)):
            raise ValueError(f"orient must be one of {list(tuning.ORIENTATIONS)} or a viewpoint of shape (3,), got {orient!r}")
        return view
    if orient not in tuning.ORIENTATIONS:
        raise ValueError(f"orient must be one of {list(tuning.ORIENTATIONS)} or a viewpoint of shape (3,), got {orient!r}")
    return orient


def orient_to_view(pts: np.ndarray, nrm: np.ndarray, view: np.ndarray) -> np.ndarray:
    """Every normal flipped towards the viewpoint ``view`` (3,)."""
    s = np.sign(np.einsum("ij,ij->i", view - pts, nrm))
    s[s == 0] = 1.0
    return nrm * s[:, None]


def apply_orientation(pts: np.ndarray, nrm: np.ndarray, neighbors: np.ndarray, distances: np.ndarray, orient: str | np.ndarray,
                      noise: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orient unit normals; returns (normals, component labels, orientation confidence)."""
    N = pts.shape[0]
    if not isinstance(orient, str):
        return orient_to_view(pts, nrm, orient), np.zeros(N, dtype=np.int64), np.ones(N)
    if orient == "none":
        n, comps = nrm.copy(), _consistent(pts, nrm, neighbors)[1]
        return n, comps, np.ones(N)
    if orient == "consistent":
        n, comps = _consistent(pts, nrm, neighbors)
        return n, comps, np.ones(N)
    return _outward(pts, nrm, neighbors, distances, noise)  # "outward" and "visible" (its last pass follows)


def orient_normals(points: ArrayLike, normals: ArrayLike, k: int = tuning.DEFAULT_K, *, orient: str | ArrayLike = "outward",
                   neighbors: ArrayLike | None = None, distances: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Flip unoriented normals to a consistent (and, for closed surfaces, outward) orientation.

    Parameters
    ----------
    points : array_like (N, 3), or anything point-like (a PointCloud, Surface, path, ...)
    normals : array_like, shape (N, 3)
    k : int
        Neighbours per particle of the orientation graph (itself included).
    orient : {"outward", "visible", "consistent", "none"} or array_like, shape (3,)
        "consistent": propagation over the maximum-confidence spanning tree only
        (each component's root keeps its sign); "outward": then the winding-number
        check, which repairs patches and orients every component outward
        (docs/normals.md, step 4); "visible": "outward", then every normal that faces away from the
        viewpoints around the cloud that see it is flipped (closed surfaces with
        thin parts only; docs/normals.md, step 8); a point (3,): flip every normal
        towards that viewpoint (single-view scans; no propagation); "none": return
        the normals unchanged.
    neighbors, distances : ndarray, shape (N, k), optional
        Precomputed k-nearest-neighbour indices (itself first) and distances.

    Returns
    -------
    normals : ndarray, shape (N, 3)
    labels : ndarray of int, shape (N,)
        Connected component of every particle in the k-nearest-neighbour graph.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph.reference import shapes
    >>> cloud = shapes.sphere(500)
    >>> signs = np.where(np.arange(500) % 3 == 0, -1.0, 1.0)[:, None]
    >>> n, labels = orient_normals(cloud.points, signs * cloud.normals)
    >>> bool(np.allclose(n, cloud.normals)), int(labels.max()) + 1
    (True, 1)
    """
    pts = point_array(points)
    nrm = as_points("normals", normals)
    N = pts.shape[0]
    if nrm.shape != pts.shape:
        raise ValueError(f"normals must have shape {pts.shape} to match points, got shape {nrm.shape}")
    nrm = unit(nrm)
    orient = check_orient(orient)
    if neighbors is None or distances is None:
        k = check_int("k", k, minimum=2)
        distances, neighbors = knn(pts, min(k, N))
    n, labels, _ = apply_orientation(pts, nrm, np.asarray(neighbors), np.asarray(distances), orient)
    if isinstance(orient, str) and orient == "visible":
        n, _ = visible_signs(pts, n)
    return n, labels
