"""The orientation graph and its maximum-confidence spanning forest.

On the k-nearest-neighbour graph the sign across an edge ``(i, j)`` is predicted by
reflecting ``n_i`` in the bisector plane of ``p_i p_j`` (the normal a circle through both
points tangent to ``n_i`` has at ``p_j``; König & Gumhold 2009) and compared with ``n_j``;
the edge confidence is ``|n_j . R n_i|``. Unlike Hoppe's ``|n_i . n_j|`` this is right across
thin parts and symmetric creases. Signs are propagated over the maximum-confidence spanning
tree by pointer jumping. Where the k-NN graph falls apart (clouds sampled much more densely
along lines than across them), components are bridged to their nearest other component.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from . import tuning
from .arrays import unique_sorted
from .fitting import knn


def tree_signs(n_nodes: int, mst: sp.csr_matrix, roots: np.ndarray, edge_sign_fn: Callable[[np.ndarray, np.ndarray],
               np.ndarray]) -> np.ndarray:
    """Sign of every node relative to its component root along the spanning forest.

    One breadth-first search from a virtual node joined to every root gives all
    tree parents; the signs along the paths are multiplied by pointer jumping.
    """
    sym = (mst + mst.T).tocsr()
    link = sp.coo_matrix((np.ones(roots.size), (roots, np.full(roots.size, n_nodes))), shape=(n_nodes + 1, n_nodes + 1))
    sym = sp.bmat([[sym, None], [None, sp.csr_matrix((1, 1))]], format="csr") + link + link.T
    _, pred = csgraph.breadth_first_order(sym, n_nodes, directed=False, return_predecessors=True)
    pred = pred[:n_nodes]
    idx = np.arange(n_nodes)
    parent = np.where((pred >= 0) & (pred < n_nodes), pred, idx)
    sign = np.ones(n_nodes)
    nodes = np.flatnonzero(parent != idx)
    if nodes.size:
        sign[nodes] = edge_sign_fn(nodes, parent[nodes])
    anc = parent
    while True:  # pointer jumping: sign relative to anc, whose distance doubles each step
        sign = sign * sign[anc]
        nxt = anc[anc]
        if np.array_equal(nxt, anc):
            return sign
        anc = nxt


def _pair_edges(pts, nrm, rows, cols):
    """Undirected edges of the pairs ``(rows, cols)``, unique and sorted by key, with ``s`` and length."""
    N = pts.shape[0]
    off = rows != cols
    a, b = np.minimum(rows[off], cols[off]), np.maximum(rows[off], cols[off])
    key = unique_sorted(a * N + b)
    a, b = key // N, key % N
    e = pts[b] - pts[a]
    length = np.linalg.norm(e, axis=1)
    e = e / np.where(length > 0, length, 1.0)[:, None]
    pred = nrm[a] - 2.0 * np.einsum("ij,ij->i", nrm[a], e)[:, None] * e  # n_a reflected in the bisector plane
    return a, b, np.einsum("ij,ij->i", pred, nrm[b]), length


def graph_edges(pts: np.ndarray, nrm: np.ndarray, neighbors: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Undirected k-NN edges ``(a, b)`` with the reflection-predicted sign agreement ``s`` and length."""
    N, k = neighbors.shape
    return _pair_edges(pts, nrm, np.repeat(np.arange(N, dtype=np.int64), k), neighbors.ravel().astype(np.int64))


def orientation_graph(pts: np.ndarray, nrm: np.ndarray, neighbors: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                      np.ndarray]:
    """Edges of the orientation graph and the components of the k-NN graph alone.

    The k-NN graph of a cloud sampled much more densely along lines than across them
    (scan lines, the rings of a surface of revolution) falls apart into bands of lines;
    oriented separately, a band has no winding-number evidence of its own (a third of a
    ring-sampled sphere pointed inward). Each particle with another component among its
    ``tuning.BRIDGE_K`` nearest therefore also gets an edge to the nearest such particle; the
    spanning forest then carries the sign across where the reflection rule is confident,
    and the patch check still separates what it is not confident about.
    """
    N = pts.shape[0]
    ko = min(tuning.ORIENT_K, neighbors.shape[1])
    a, b, s, length = graph_edges(pts, nrm, neighbors[:, :ko])
    n_comp, comps = csgraph.connected_components(sp.coo_matrix((np.ones(a.size), (a, b)), shape=(N, N)), directed=False)
    comps = comps.astype(np.int64)
    if n_comp > 1:
        tree = cKDTree(pts)
        _, idx = knn(pts, min(tuning.BRIDGE_K, N), tree)
        other = comps[idx] != comps[:, None]
        rows = np.flatnonzero(other.any(axis=1))
        cols = idx[rows, other[rows].argmax(axis=1)].astype(np.int64)
        # small components with no other one among their particles' nearest (a tight ring
        # at a pole): the nearest particle outside, searched from a few of their particles
        size = np.bincount(comps, minlength=n_comp)
        lonely = np.setdiff1d(np.flatnonzero(size <= tuning.BRIDGE_MAX_SIZE), comps[rows])
        extra_r, extra_c = [rows], [cols]
        for c in lonely[:tuning.BRIDGE_MAX_LONELY]:  # a loop over components, each one batched query
            members = np.flatnonzero(comps == c)
            src = members[np.linspace(0, members.size - 1, min(members.size, 16)).astype(np.int64)]
            dist_c, idx_c = tree.query(pts[src], k=min(int(size[c]) + 1, N))
            out = comps[idx_c] != c
            ok = out.any(axis=1)
            if ok.any():
                first = out.argmax(axis=1)
                best = np.argmin(np.where(ok, dist_c[np.arange(src.size), first], np.inf))
                extra_r.append(src[best : best + 1])
                extra_c.append(idx_c[best : best + 1, first[best]].astype(np.int64))
        rows, cols = np.concatenate(extra_r), np.concatenate(extra_c)
        if rows.size:
            knn_rows = np.repeat(np.arange(N, dtype=np.int64), ko)
            a, b, s, length = _pair_edges(pts, nrm, np.concatenate([knn_rows, rows]),
                                          np.concatenate([neighbors[:, :ko].ravel().astype(np.int64), cols]))
    return a, b, s, length, comps


def spanning_forest(N: int, a: np.ndarray, b: np.ndarray, s: np.ndarray, length: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                    np.ndarray, np.ndarray]:
    """Maximum-confidence spanning forest: its signs relative to each root, edges, components."""
    conf = np.abs(s)
    scale = float(np.median(length)) if length.size else 1.0
    cost = (1.0 - conf) + 1e-3 * length / max(scale, 1e-300) + 1e-12  # never 0 (stored zeros are no edges)
    G = sp.coo_matrix((cost, (a, b)), shape=(N, N)).tocsr()
    G = G.maximum(G.T)
    _, labels = csgraph.connected_components(G, directed=False)
    mst = csgraph.minimum_spanning_tree(G).tocoo()
    ta, tb = mst.row.astype(np.int64), mst.col.astype(np.int64)
    # the sign and confidence of each tree edge, looked up by its key
    key = a * N + b
    tkey = np.minimum(ta, tb) * N + np.maximum(ta, tb)
    pos = np.searchsorted(key, tkey)  # key is sorted
    tsign = np.where(s[pos] < 0, -1.0, 1.0)
    tconf = conf[pos]
    roots = np.unique(labels, return_index=True)[1]
    T = sp.coo_matrix((tsign, (ta, tb)), shape=(N, N)).tocsr()
    T = T + T.T

    def edge_sign(child, par):
        return np.asarray(T[child, par]).ravel()

    sign = tree_signs(N, mst.tocsr(), roots, edge_sign)
    return sign, labels.astype(np.int64), ta, tb, tconf
