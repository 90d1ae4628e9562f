"""Normals for clouds that have none: PCA, consistent orientation, outward.

1. **PCA.** The normal of particle ``i`` is the eigenvector of the smallest
   eigenvalue of the covariance of its ``k`` nearest neighbours (itself
   included); all ``N`` 3x3 eigenproblems are solved in one batched ``eigh``.
2. **Consistent orientation** (Hoppe et al. 1992). A PCA normal has no sign.
   On the symmetrised k-nearest-neighbour graph, with edge cost
   ``1 - |n_i . n_j|`` (plus a small distance term), a minimum spanning tree is
   grown in every connected component from its root (the particle farthest from
   the component's centroid) and every normal is flipped to agree with its tree
   parent. The sign of each particle relative to the root is the product of the
   edge signs along the tree path, computed for all particles at once by
   pointer jumping (``log2(depth)`` vectorised steps, no loop over particles).
3. **Outward.** For a closed surface, ``sum_i (p_i - c) . n_i dA_i`` is three
   times the enclosed volume (divergence theorem), positive for outward normals.
   Each component is flipped so that this sum, with ``dA_i`` estimated from the
   local spacing, is positive. It also orients open scans such as the bunny
   (whose holes are small) and is left to chance only for flat open patches,
   where the sum vanishes: those are oriented so that their mean normal has a
   positive largest component.

The per-particle **confidence** is ``1 - lambda_0 / lambda_1`` (smallest over
middle eigenvalue of the covariance): 1 on a clean flat neighbourhood, near 0
where the neighbourhood is isotropic (noise, outliers, sharp corners) or
collinear, so that the normal is not defined by the data.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from ._validation import as_points, check_int
from .threads import get_num_threads

__all__ = ["estimate_normals", "pca_normals", "orient_normals", "ORIENTATIONS", "DEFAULT_K"]

#: Orientation modes of :func:`estimate_normals` (a viewpoint (3,) is also accepted).
ORIENTATIONS = ("outward", "consistent", "none")

#: Default number of nearest neighbours (itself included) of the PCA.
DEFAULT_K = 16


def _knn(points: np.ndarray, k: int, tree: cKDTree | None = None):
    tree = cKDTree(points) if tree is None else tree
    dist, idx = tree.query(points, k=k, workers=get_num_threads())
    return dist, idx


def pca_normals(points, k: int = DEFAULT_K, *, neighbors=None):
    """Unoriented PCA normals and their confidence.

    Parameters
    ----------
    points : array_like, shape (N, 3)
    k : int
        Neighbours per particle, itself included (at least 3, below N).
    neighbors : ndarray of int, shape (N, k), optional
        Precomputed neighbour indices (overrides ``k``).

    Returns
    -------
    normals : ndarray, shape (N, 3)
        Unit normals with the sign convention of ``numpy.linalg.eigh`` (arbitrary).
    confidence : ndarray, shape (N,)
        ``1 - lambda_0 / lambda_1`` in [0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> p = np.c_[rng.uniform(size=(200, 2)), np.zeros(200)]     # the plane z = 0
    >>> n, c = pca_normals(p, k=10)
    >>> float(np.abs(n[:, 2]).min().round(6)), float(c.min().round(6))
    (1.0, 1.0)
    """
    pts = as_points("points", points)
    if neighbors is None:
        k = check_int("k", k, minimum=3)
        if k > pts.shape[0]:
            raise ValueError(f"k must be at most the number of points {pts.shape[0]}, got {k}")
        _, neighbors = _knn(pts, k)
    nbr = pts[neighbors]  # (N, k, 3)
    # centre on the particle's own mean; subtract the particle first for conditioning
    local = nbr - pts[:, None, :]
    local -= local.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", local, local) / neighbors.shape[1]
    w, v = np.linalg.eigh(cov)  # ascending eigenvalues
    normals = v[:, :, 0]
    w = np.maximum(w, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(w[:, 1] > 0, w[:, 0] / w[:, 1], 1.0)
    confidence = np.clip(1.0 - ratio, 0.0, 1.0)
    return normals, confidence


def _tree_signs(n_nodes: int, mst: sp.csr_matrix, roots: np.ndarray, edge_sign_fn) -> np.ndarray:
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
    sign[nodes] = edge_sign_fn(nodes, parent[nodes])
    anc = parent
    while True:  # pointer jumping: sign relative to anc, whose distance doubles each step
        sign = sign * sign[anc]
        nxt = anc[anc]
        if np.array_equal(nxt, anc):
            return sign
        anc = nxt


def orient_normals(points, normals, k: int = DEFAULT_K, *, orient="outward", neighbors=None, distances=None):
    """Flip unoriented normals to a consistent (and, for closed surfaces, outward) orientation.

    Parameters
    ----------
    points, normals : array_like, shape (N, 3)
    k : int
        Neighbours per particle of the orientation graph (itself included).
    orient : {"outward", "consistent", "none"} or array_like, shape (3,)
        "consistent": minimum-spanning-tree propagation only (each component's
        root keeps its sign); "outward": then flip each component outward;
        a point (3,): flip every normal towards that viewpoint (single-view
        scans; no propagation); "none": return the normals unchanged.
    neighbors, distances : ndarray, shape (N, k), optional
        Precomputed k-nearest-neighbour indices and distances.

    Returns
    -------
    normals : ndarray, shape (N, 3)
    labels : ndarray of int, shape (N,)
        Connected component of every particle in the k-nearest-neighbour graph.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import shapes
    >>> cloud = shapes.sphere(500)
    >>> signs = np.where(np.arange(500) % 3 == 0, -1.0, 1.0)[:, None]
    >>> n, labels = orient_normals(cloud.points, signs * cloud.normals)
    >>> bool(np.allclose(n, cloud.normals)), int(labels.max()) + 1
    (True, 1)
    """
    pts = as_points("points", points)
    nrm = as_points("normals", normals)
    N = pts.shape[0]
    if nrm.shape != pts.shape:
        raise ValueError(f"normals must have shape {pts.shape} to match points, got shape {nrm.shape}")
    nrm = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    if not isinstance(orient, str):
        view = np.asarray(orient, dtype=np.float64)
        if view.shape != (3,) or not np.all(np.isfinite(view)):
            raise ValueError(f"orient must be one of {list(ORIENTATIONS)} or a viewpoint of shape (3,), got {orient!r}")
        s = np.sign(np.einsum("ij,ij->i", view - pts, nrm))
        s[s == 0] = 1.0
        return nrm * s[:, None], np.zeros(N, dtype=np.int64)
    if orient not in ORIENTATIONS:
        raise ValueError(f"orient must be one of {list(ORIENTATIONS)} or a viewpoint of shape (3,), got {orient!r}")
    if neighbors is None:
        k = check_int("k", k, minimum=2)
        k = min(k, N)
        distances, neighbors = _knn(pts, k)
    # symmetric kNN graph; cost 1 - |n_i . n_j| plus a small distance term (never 0:
    # csgraph treats stored zeros as missing edges)
    rows = np.repeat(np.arange(N), neighbors.shape[1])
    cols = neighbors.ravel()
    off = rows != cols
    rows, cols = rows[off], cols[off]
    dots = np.einsum("ij,ij->i", nrm[rows], nrm[cols])
    d = distances.ravel()[off]
    scale = float(np.median(d)) if d.size else 1.0
    cost = (1.0 - np.abs(dots)) + 1e-3 * d / max(scale, 1e-300) + 1e-12
    G = sp.coo_matrix((cost, (rows, cols)), shape=(N, N)).tocsr()
    G = G.maximum(G.T)
    n_comp, labels = csgraph.connected_components(G, directed=False)
    labels = labels.astype(np.int64)
    if orient == "none":
        return nrm.copy(), labels
    # roots: the particle farthest from its component centroid (deterministic)
    counts = np.bincount(labels, minlength=n_comp).astype(np.float64)
    cent = np.stack([np.bincount(labels, weights=pts[:, a], minlength=n_comp) for a in range(3)], axis=1) / counts[:, None]
    r2 = np.einsum("ij,ij->i", pts - cent[labels], pts - cent[labels])
    order = np.lexsort((-r2, labels))  # within each label, farthest first
    first = np.searchsorted(labels[order], np.arange(n_comp))
    roots = order[first]
    mst = csgraph.minimum_spanning_tree(G).tocsr()

    def edge_sign(child, par):
        s = np.sign(np.einsum("ij,ij->i", nrm[child], nrm[par]))
        s[s == 0] = 1.0
        return s

    sign = _tree_signs(N, mst, roots, edge_sign)
    out = nrm * sign[:, None]
    if orient == "outward":
        # divergence theorem per component: sum (p - c) . n dA = 3 V > 0 outward
        dA = distances[:, -1] ** 2 if distances is not None else np.ones(N)
        flux = np.bincount(labels, weights=np.einsum("ij,ij->i", pts - cent[labels], out) * dA, minlength=n_comp)
        size = np.sqrt(r2.max()) if N else 1.0
        total_dA = np.bincount(labels, weights=dA, minlength=n_comp)
        flat = np.abs(flux) <= 1e-9 * size * total_dA
        mean_n = np.stack([np.bincount(labels, weights=out[:, a], minlength=n_comp) for a in range(3)], axis=1)
        big = mean_n[np.arange(n_comp), np.abs(mean_n).argmax(axis=1)]
        comp_sign = np.where(flat, np.sign(big), np.sign(flux))
        comp_sign[comp_sign == 0] = 1.0
        out = out * comp_sign[labels][:, None]
    return out, labels


def estimate_normals(points, k: int | None = None, *, orient="outward", return_confidence: bool = False):
    """Estimate unit normals of a point cloud: PCA, then consistent and outward orientation.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        At least 3 distinct points; N >= k.
    k : int, optional
        Nearest neighbours per particle, itself included (default
        ``min(16, N)``). Use more on noisy clouds.
    orient : {"outward", "consistent", "none"} or array_like, shape (3,)
        See :func:`orient_normals`. "outward" (the default) propagates a
        consistent orientation over a minimum spanning tree in every connected
        component and flips each component outward.
    return_confidence : bool
        Also return the per-particle confidence (see the module notes).

    Returns
    -------
    normals : ndarray, shape (N, 3)
    confidence : ndarray, shape (N,), only if ``return_confidence``
        In [0, 1]; below about 0.5 the normal is poorly determined.

    Raises
    ------
    ValueError
        On a bad ``points`` array, ``k`` or ``orient``.

    Examples
    --------
    >>> import numpy as np
    >>> from manifold_sph import shapes
    >>> cloud = shapes.sphere(1000)
    >>> n, conf = estimate_normals(cloud.points, return_confidence=True)
    >>> float(np.einsum("ij,ij->i", n, cloud.normals).min().round(3)), bool(conf.min() > 0.9)
    (1.0, True)
    """
    pts = as_points("points", points)
    N = pts.shape[0]
    if N < 3:
        raise ValueError(f"points must hold at least 3 points to estimate normals, got {N}")
    if k is None:
        k = min(DEFAULT_K, N)
    k = check_int("k", k, minimum=3)
    if k > N:
        raise ValueError(f"k must be at most the number of points {N}, got {k}")
    if isinstance(orient, str) and orient not in ORIENTATIONS:
        raise ValueError(f"orient must be one of {list(ORIENTATIONS)} or a viewpoint of shape (3,), got {orient!r}")
    dist, idx = _knn(pts, k)
    nrm, conf = pca_normals(pts, neighbors=idx)
    nrm, _ = orient_normals(pts, nrm, orient=orient, neighbors=idx, distances=dist)
    return (nrm, conf) if return_confidence else nrm
