"""Closed sheets: surfaces that pass through each other, cut apart and judged by their own field.

Sheets are the components of the k-NN graph kept where both ends lie near each other's
tangent plane with nearly parallel normal lines, without junctions (particles whose sheet
neighbours' normals are not parallel and follow no single shape operator) and without
bridges (edges in fewer than two triangles of sheet edges).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from . import tuning
from .fitting import tangents
from .graph import tree_signs
from .winding import winding_numbers


def sheet_segments(pts: np.ndarray, nrm: np.ndarray, neighbors: np.ndarray) -> tuple[np.ndarray, int, np.ndarray] | None:
    """The sheets of a cloud: labels (0 to ``n - 1``; ``n`` for particles in none), ``n``, and the normals
    oriented consistently inside each sheet (on its own edges, by the reflection rule).

    Sheets are the components of the k-NN graph kept where both ends lie near each other's
    tangent plane with nearly parallel normal lines, without junctions and bridges: surfaces
    that cross (interpenetrating parts of a model) fall apart there. Sheets have at least
    ``tuning.SHEET_MIN`` particles (and ``tuning.SHEET_FRACTION`` of the cloud); particles left
    out join a neighbouring sheet over up to ``tuning.SHEET_GROW`` rings. None where more than
    ``tuning.SHEET_MAX_JUNCTION`` of the particles are junctions (coarse or noisy: not trusted) or
    fewer than two sheets exist.
    """
    N = pts.shape[0]
    ko = min(tuning.ORIENT_K, neighbors.shape[1])
    rows = np.repeat(np.arange(N, dtype=np.int64), ko - 1)
    cols = neighbors[:, 1:ko].ravel().astype(np.int64)
    L = pts[cols] - pts[rows]
    l2 = np.einsum("ij,ij->i", L, L)
    zi = np.abs(np.einsum("ij,ij->i", L, nrm[rows]))
    zj = np.abs(np.einsum("ij,ij->i", L, nrm[cols]))
    tan2 = tuning.SHEET_TAN**2
    par = np.abs(np.einsum("ij,ij->i", nrm[rows], nrm[cols])) > tuning.SHEET_DOT
    edge = (par & (zi * zi <= tan2 * np.maximum(l2 - zi * zi, 0.0)) & (zj * zj <= tan2 * np.maximum(l2 - zj * zj, 0.0))).reshape(N, ko - 1)
    # a junction: its sheet neighbours are not parallel among themselves (a normal averaged over two
    # crossing sheets) and their normals do not follow one shape operator (on one strongly curved
    # surface the normal turns linearly with the position; across a crossing it jumps)
    nb = nrm[neighbors[:, 1:ko]] * edge[:, :, None]
    G = np.abs(np.einsum("nkj,nlj->nkl", nb, nb))
    junction = np.any(edge[:, :, None] & edge[:, None, :] & (G < tuning.SHEET_JUNCTION), axis=(1, 2))
    if tuning.SHEET_SHAPE and junction.any():
        r = np.flatnonzero(junction)
        t1, t2 = tangents(nrm[r])
        Lr = L.reshape(N, ko - 1, 3)[r]
        x, y = np.einsum("nkj,nj->nk", Lr, t1), np.einsum("nkj,nj->nk", Lr, t2)
        nj = nrm[neighbors[r, 1:ko]]
        nj = nj * np.where(np.einsum("nkj,nj->nk", nj, nrm[r]) < 0, -1.0, 1.0)[:, :, None]
        u, v = np.einsum("nkj,nj->nk", nj, t1), np.einsum("nkj,nj->nk", nj, t2)
        wgt = edge[r].astype(np.float64)
        # u = a x + b y + u0, v = b x + c y + v0 (a symmetric shape operator and an offset), least squares
        Z = np.zeros_like(x)
        O = np.ones_like(x)
        A = np.concatenate([np.stack([x, y, Z, O, Z], axis=2), np.stack([Z, x, y, Z, O], axis=2)], axis=1)
        rhs = np.concatenate([u, v], axis=1)
        W2 = np.concatenate([wgt, wgt], axis=1)
        M = np.einsum("nki,nk,nkj->nij", A, W2, A) + 1e-12 * np.eye(5)[None]
        coef = np.linalg.solve(M, np.einsum("nki,nk,nk->ni", A, W2, rhs)[..., None])[..., 0]
        res = rhs - np.einsum("nki,ni->nk", A, coef)
        dev = rhs - (np.einsum("nk,nk->n", W2, rhs) / np.maximum(W2.sum(axis=1), 1e-300))[:, None]
        rel = np.sqrt(np.einsum("nk,nk->n", W2, res * res) / np.maximum(np.einsum("nk,nk->n", W2, dev * dev), 1e-300))
        junction[r[rel < tuning.SHEET_SHAPE]] = False
    if junction.mean() > tuning.SHEET_MAX_JUNCTION:  # coarse or noisy: the sheets are not trusted
        return None
    keep = (edge & ~junction[:, None]).ravel() & ~junction[cols]
    A = sp.coo_matrix((np.ones(int(keep.sum())), (rows[keep], cols[keep])), shape=(N, N)).tocsr()
    A = ((A + A.T) > 0).astype(np.float64)
    for _ in range(tuning.SHEET_PRUNE):  # edges in fewer than tuning.SHEET_SUPPORT triangles are bridges, not sheet
        A = A.multiply((A @ A).multiply(A) >= tuning.SHEET_SUPPORT).tocsr()
    n_s, sheet = csgraph.connected_components(A, directed=False)
    size = np.bincount(sheet, minlength=n_s)
    big = np.flatnonzero(size >= max(tuning.SHEET_MIN, tuning.SHEET_FRACTION * N))
    if big.size < 2:
        return None
    label = np.full(n_s, -1, dtype=np.int64)
    label[big] = np.arange(big.size)
    lab = label[sheet]
    # particles left out (junctions, small pieces: the cap of a surface cut off where another
    # crosses it) join the sheet of a neighbour with a parallel normal line, over a few rings
    nbr = neighbors[:, 1:ko]
    for _ in range(tuning.SHEET_GROW):
        cand = np.where(edge & (lab[nbr] >= 0), lab[nbr], -1)
        has = (lab < 0) & (cand >= 0).any(axis=1)
        if not has.any():
            break
        lab[has] = cand[has, (cand[has] >= 0).argmax(axis=1)]
    lab = np.where(lab < 0, big.size, lab)
    # each sheet oriented consistently on its own edges (propagation over the whole graph may have
    # mixed its signs where it crosses another), for the test of closure below
    inner = edge.ravel() & (lab[rows] == lab[cols]) & (lab[rows] < big.size)
    ri, ci = rows[inner], cols[inner]
    Lu = L[inner] / np.sqrt(np.maximum(l2[inner], 1e-300))[:, None]
    pred = nrm[ri] - 2.0 * np.einsum("ij,ij->i", nrm[ri], Lu)[:, None] * Lu  # the reflection rule of step 3
    sgn = np.where(np.einsum("ij,ij->i", pred, nrm[ci]) < 0, -1.0, 1.0)
    Sg = sp.coo_matrix((sgn, (ri, ci)), shape=(N, N)).tocsr()
    Sg = Sg + Sg.T  # (a pair found from both ends has the same sign twice)
    roots = np.unique(csgraph.connected_components(Sg, directed=False)[1], return_index=True)[1]
    sn = nrm * tree_signs(N, Sg, roots, lambda child, par: np.sign(np.asarray(Sg[child, par]).ravel()))[:, None]
    return lab, int(big.size), sn


def closed_sheets(pts: np.ndarray, nrm: np.ndarray, neighbors: np.ndarray, probes: np.ndarray, delta: np.ndarray, area: np.ndarray,
                  h: np.ndarray) -> np.ndarray | None:
    """Label of the closed sheet of every particle (-1: none), or None: nothing to judge apart.

    The sheets of :func:`sheet_segments`. A sheet is closed where its own winding number, with
    its propagated signs, is decisive at its probes (``|mean(w_in + w_out)| >= tuning.SHEET_CLOSED``)
    and it is not wholly inside the others. None unless two closed sheets exist and one crosses
    another (docs/normals.md, step 4, surfaces that pass through each other).
    """
    segments = sheet_segments(pts, nrm, neighbors)
    if segments is None:
        return None
    lab, n_sheets, sn = segments
    big = np.arange(n_sheets)
    q = np.vstack([pts[probes] - delta[:, None] * sn[probes], pts[probes] + delta[:, None] * sn[probes]])
    W = winding_numbers(q, pts, sn, area, 0.2 * h, lab, big.size + 1)
    own = lab[probes]
    m = own < big.size
    S = np.zeros(probes.size)
    S[m] = W[: probes.size][m, own[m]] + W[probes.size :][m, own[m]]
    w = area[probes] * m
    wt = np.maximum(np.bincount(own[m], weights=w[m], minlength=big.size), 1e-300)
    mean = np.bincount(own[m], weights=(w * S)[m], minlength=big.size) / wt
    closed = np.abs(mean) >= tuning.SHEET_CLOSED
    # the share of a sheet's probes inside the other sheets' field: wholly inside (the inner wall
    # of a hollow part), it keeps the whole field, whose answer (facing the cavity) is the convention
    # there; partly inside, it crosses another surface
    Wsum = 0.5 * (W[: probes.size].sum(axis=1) + W[probes.size :].sum(axis=1))
    inside = np.zeros(probes.size, dtype=bool)
    inside[m] = np.abs(Wsum[m] - 0.5 * S[m]) > 0.5
    frac_in = np.bincount(own[m], weights=(w * inside)[m], minlength=big.size) / wt
    closed &= (frac_in < tuning.SHEET_NESTED) | (np.abs(mean) < tuning.SHEET_SEALED)
    # only where closed sheets pass through each other is the whole field misleading; touching
    # pieces of one coarse surface are left to it
    if closed.sum() < 2 or not np.any(closed & (frac_in >= tuning.SHEET_CROSS)):
        return None
    ids = np.full(big.size + 1, -1, dtype=np.int64)
    ids[np.flatnonzero(closed)] = np.arange(int(closed.sum()))
    return ids[lab]


def _own_means(pts, nrm, lab, n_labels, area, h, delta, probes):
    """Area-weighted mean of ``w_in + w_out`` of each label's own field at its probes."""
    q = np.vstack([pts[probes] - delta[:, None] * nrm[probes], pts[probes] + delta[:, None] * nrm[probes]])
    W = winding_numbers(q, pts, nrm, area, 0.2 * h, lab, n_labels)
    own = lab[probes]
    m = probes.size
    S = W[np.arange(m), own] + W[m + np.arange(m), own]
    wt = np.bincount(own, weights=area[probes], minlength=n_labels)
    return np.bincount(own, weights=area[probes] * S, minlength=n_labels) / np.maximum(wt, 1e-300), wt


def separate_parts(pts: np.ndarray, nrm: np.ndarray, neighbors: np.ndarray, distances: np.ndarray, nested: str,
                   sigma: np.ndarray | None = None) -> np.ndarray:
    """Every closed part outward by its own field (``nested="separate"``), or as oriented (``"cavity"``).

    Parts are first the connected components of the graph of the ``tuning.ORIENT_K`` nearest, then
    the sheets of :func:`sheet_segments` (closed surfaces that touch or cross others fall apart
    there). A part is closed where the mean of ``w_in + w_out`` of its own field at its probes is
    at least ``tuning.PART_CLOSED`` in size. One whose own field reads it inward (a part inside
    another, oriented as the wall of a cavity by the whole field) is flipped; a sheet whose signs
    are mixed (its own field not decisive) but closed with the signs propagated on its own edges
    takes those, outward. The sheets are used on clean clouds only (``sigma`` None): on a noisy
    scan they also cut one surface apart where its density changes, and a piece read inward by
    its own field was flipped (docs/normals.md, parts).
    """
    if nested == "cavity":
        return nrm
    N = pts.shape[0]
    ka = min(8, distances.shape[1])
    r = distances[:, ka - 1]
    r = np.where(r > 0, r, np.median(r[r > 0]) if np.any(r > 0) else 1.0)
    area = np.pi * r**2 / max(ka - 0.5, 1.0)
    h = np.sqrt(area)
    probes = np.arange(N)
    if N > tuning.MAX_PROBES:
        probes = np.sort(np.random.default_rng(0).choice(N, tuning.MAX_PROBES, replace=False))
    delta = h[probes] if sigma is None else np.maximum(h[probes], tuning.PROBE_NOISE * sigma[probes])
    ko = min(tuning.ORIENT_K, neighbors.shape[1])
    rows = np.repeat(np.arange(N, dtype=np.int64), ko - 1)
    G = sp.coo_matrix((np.ones(rows.size), (rows, neighbors[:, 1:ko].ravel())), shape=(N, N))
    n_parts, part = csgraph.connected_components(G, directed=False)
    out = nrm
    if n_parts > 1:
        mean, wt = _own_means(pts, out, part, n_parts, area, h, delta, probes)
        flip = (wt > 0) & (mean <= -tuning.PART_CLOSED)
        out = np.where(flip[part][:, None], -out, out)
    if not tuning.PART_SHEETS or sigma is not None:  # clean clouds only (noisy: sheets cut one surface apart)
        return out
    segments = sheet_segments(pts, out, neighbors)
    if segments is None:
        return out
    lab, n_sheets, sn = segments
    mean, wt = _own_means(pts, out, lab, n_sheets + 1, area, h, delta, probes)
    flip = (wt > 0) & (mean <= -tuning.PART_CLOSED)
    flip[n_sheets] = False
    mixed = (wt > 0) & (np.abs(mean) < tuning.PART_CLOSED)
    mixed[n_sheets] = False
    res = np.where(flip[lab][:, None], -out, out)
    if mixed.any():
        mean_s, _ = _own_means(pts, sn, lab, n_sheets + 1, area, h, delta, probes)
        take = mixed & (np.abs(mean_s) >= tuning.PART_CLOSED)
        if take.any():
            sign = np.where(mean_s < 0, -1.0, 1.0)
            res = np.where(take[lab][:, None], sn * sign[lab][:, None], res)
    return res
