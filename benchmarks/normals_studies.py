"""Studies of the clean-cloud path of estimate_normals: mesh vertices and analytic shapes.

The comparison with Open3D and CGAL (published clouds, noise, non-uniform samples, the test
models, multi-part models, time) is ``benchmarks/normals.py``; these are the studies behind the
choices of the clean path (docs/normals.md, steps 1-9, records their measurements).

Every model of the shared test data (``MANIFOLD_SPH_DATA``, default ``../shared/data`` beside the
repository; missing files are skipped): the VERTICES are the point cloud (faces dropped, exact
duplicate positions merged), the faces give the reference (area-weighted vertex normals,
outward; or the normals of the mesh's Loop subdivision limit surface at the vertices, and the
normals with Max's weights).

Run: ``python benchmarks/normals_studies.py`` (the model table, the limit-surface table, the
convergence orders on analytic shapes and the thin synthetic clouds); options: ``--check-loop``
(the limit normals against repeated subdivision), ``--limit``, ``--quick``, ``--visible``,
``--poles``, ``--models a.obj b.ply ...``, ``--random [--seeds=0-7]``, ``--crossing``, ``--noisy``.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from manifold_sph.normals import estimate, estimate_normals, tuning
from manifold_sph.reference import shapes
from manifold_sph.reference.sampling import sample_triangles
from manifold_sph.scans.io import read_mesh

DATA = Path(os.environ.get("MANIFOLD_SPH_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
MODELS = [DATA / "models" / f for f in ("cow.obj", "homer.obj", "rocker-arm.obj", "cheburashka.obj", "teapot.obj", "beetle.obj",
                                        "alligator.obj")]
SCANS = [DATA / "scans" / "stanford-bunny.obj", DATA / "scans" / "igea.ply"]


def _welded(path):
    """The mesh's distinct vertices and its faces on them, degenerate faces dropped."""
    V, F = read_mesh(str(path))
    U, inv = np.unique(V, axis=0, return_inverse=True)
    F = inv.ravel()[F]
    return U, F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]


def _area_normals(X, F):
    """Area-weighted vertex normals of the faces ``F`` on the vertices ``X`` (unit; zero where undefined)."""
    c = np.cross(X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]])
    N = np.zeros_like(X)
    for a in range(3):
        np.add.at(N, F[:, a], c)
    return N / np.maximum(np.linalg.norm(N, axis=1), 1e-300)[:, None]


def mesh_reference(path, limit=False):
    """Distinct vertex positions (those used by faces), area-weighted unit normals, closed?, shells.

    With ``limit=True`` also the Loop limit normals at those vertices (:func:`loop_limit_normals`;
    area-weighted where the vertex is not a manifold fan) and the mask of those that are limit
    normals; with ``limit="all"`` then also the normals with Max's weights (:func:`max_normals`).
    """
    U, F = _welded(path)
    c = np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]])  # twice the area times the normal
    N = np.zeros_like(U)
    for a in range(3):
        np.add.at(N, F[:, a], c)
    length = np.linalg.norm(N, axis=1)
    used = np.zeros(len(U), bool)
    used[F.ravel()] = True
    keep = used & (length > 0)
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    closed = bool(np.all(counts == 2))
    A = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(U), len(U)))
    shells = csgraph.connected_components(A, directed=False)[0] - int((~used).sum())
    ref = N / np.where(length > 0, length, 1.0)[:, None]
    if not limit:
        return U[keep], ref[keep], closed, shells
    lim, good, _, _ = loop_limit_normals(U, F, ref)
    if limit == "all":
        return U[keep], ref[keep], closed, shells, lim[keep], good[keep], max_normals(U, F)[keep]
    return U[keep], ref[keep], closed, shells, lim[keep], good[keep]


def max_normals(U, F):
    """Vertex normals with Max's weights (1999): each face's ``u x v / (|u|^2 |v|^2)`` at the vertex,
    ``u``, ``v`` its two edges from the vertex; exact when the vertex and its one-ring lie on a
    sphere (the area-weighted normal is not). Unit; zero where undefined."""
    N = np.zeros_like(U)
    for a in range(3):
        u = U[F[:, (a + 1) % 3]] - U[F[:, a]]
        v = U[F[:, (a + 2) % 3]] - U[F[:, a]]
        den = np.einsum("ij,ij->i", u, u) * np.einsum("ij,ij->i", v, v)
        np.add.at(N, F[:, a], np.cross(u, v) / np.where(den > 0, den, np.inf)[:, None])
    length = np.linalg.norm(N, axis=1)
    return N / np.where(length > 0, length, 1.0)[:, None]


def loop_limit_normals(U, F, area_normals, positions=False):
    """Unit normals of the Loop subdivision limit surface at the vertices, exactly (limit tangent masks).

    Loop subdivision as trimesh's ``subdivide_loop`` does it (Loop's interior rules; boundary
    edges and vertices follow the cubic B-spline of the boundary: 1/2 1/2 and 1/8 3/4 1/8).
    The limit normal at a vertex is the cross product of its two limit tangents, each a mask
    over the vertex's one-ring: at an interior vertex of valence ``n`` with the ring
    ``p_0 .. p_{n-1}`` in order, ``sum_j cos(2 pi j / n) p_j`` and ``sum_j sin(2 pi j / n) p_j``
    (whatever Loop's centre weight beta); at a boundary vertex with ``k`` faces and the ring
    ``r_0 .. r_k`` (``r_0``, ``r_k`` on the boundary) ``r_0 - r_k`` along the boundary, and
    across it the left eigenvector, of the largest eigenvalue other than 1 and that of the
    along mask, of the one-ring subdivision matrix (k = 1: ``r_0 + r_1 - 2 v``; k = 2:
    ``r_1 - v``, as in Hoppe et al. 1994; k >= 3 differs from their mask, which is no
    eigenvector of these rules). Signs follow the area-weighted normals ``area_normals``.
    Vertices whose faces do not form one fan (non-manifold, or an edge used twice in one
    direction) keep ``area_normals``. Checked against repeated subdivision
    (``--check-loop``): the area-weighted normal of the original vertex after ``m`` levels
    converges to this one, by 4x per level inside and 2x per level on the boundary.

    Returns the normals, the mask of vertices with a limit normal, the mask of boundary
    vertices among them, and the mask of those whose limit normal opposed ``area_normals``;
    with ``positions=True`` also the limit positions (``v`` itself where there is no limit
    normal): inside ``(1 - n w) v + w sum p_j``, ``w = 1 / (3 / (8 beta) + n)`` with Loop's
    ``beta``; on the boundary ``(r_0 + 4 v + r_k) / 6``.
    """
    nv = len(U)
    # directed ring pairs: at vertex v of face (a, b, c) (counter-clockwise), b -> c
    v = F.ravel()
    fr = F[:, [1, 2, 0]].ravel()
    to = F[:, [2, 0, 1]].ravel()
    key = v.astype(np.int64) * nv + fr
    order = np.argsort(key, kind="stable")
    key, fr_s, to_s, v_s = key[order], fr[order], to[order], v[order]
    dup_out = np.zeros(nv, bool)
    dup_out[v_s[1:][key[1:] == key[:-1]]] = True
    ikey = v.astype(np.int64) * nv + to
    ik = np.sort(ikey)
    dup_in = np.zeros(nv, bool)
    dup_in[(ik[1:][ik[1:] == ik[:-1]]) // nv] = True
    faces_at = np.bincount(v, minlength=nv)
    # number of distinct neighbours
    nb = np.unique(np.r_[key, ikey])
    valence = np.bincount(nb // nv, minlength=nv)
    # start of each ring: for boundary vertices the neighbour with an outgoing but no incoming pair
    has_in = np.isin(key, ik)  # (v, from) with from also a 'to' of v
    start = np.full(nv, -1)
    bstart = ~has_in
    nstart = np.bincount(v_s[bstart], minlength=nv)
    start[v_s[bstart]] = fr_s[bstart]
    first = np.full(nv, -1)
    first[v_s[::-1]] = fr_s[::-1]
    boundary = nstart == 1
    interior = (nstart == 0) & (valence == faces_at)
    boundary &= valence == faces_at + 1
    ok = (interior | boundary) & ~dup_out & ~dup_in & (faces_at > 0)
    start = np.where(boundary, start, first)
    K = int(valence[ok].max()) + 1
    ring = np.full((nv, K), -1)
    cur = start.copy()
    ring[:, 0] = cur
    for j in range(1, K):
        q = np.where(cur >= 0, np.arange(nv) * nv + np.maximum(cur, 0), -1)
        pos = np.clip(np.searchsorted(key, q), 0, len(key) - 1)
        hit = (key[pos] == q) & (cur >= 0)
        cur = np.where(hit, to_s[pos], -1)
        ring[:, j] = cur
    # ring length check: interior rings close after valence steps
    length = (ring >= 0).sum(axis=1)
    ok &= np.where(interior, (length >= valence + 1) & (ring[np.arange(nv), np.minimum(valence, K - 1)] == start), length == valence)
    nrm = area_normals.copy()
    P = np.vstack([U, np.zeros((1, 3))])
    R = P[np.where(ring >= 0, ring, nv)]
    j = np.arange(K)[None, :]
    # interior: t1 = sum cos(2 pi j / n) p_j, t2 = sum sin(2 pi j / n) p_j over j < n
    n_int = np.maximum(valence, 1)[:, None]
    wmask = (j < n_int)
    t1 = np.einsum("nk,nki->ni", np.where(wmask, np.cos(2 * np.pi * j / n_int), 0.0), R)
    t2 = np.einsum("nk,nki->ni", np.where(wmask, np.sin(2 * np.pi * j / n_int), 0.0), R)
    ni = np.cross(t1, t2)
    # boundary: ring r_0..r_k (k faces); along r_0 - r_k; across: the left eigenvector of the
    # largest other eigenvalue of the one-ring subdivision matrix (boundary B-spline rules)
    kf = faces_at
    rk = R[np.arange(nv), np.clip(kf, 0, K - 1)]
    along = R[:, 0] - rk
    across = np.zeros((nv, 3))
    for k in np.unique(kf[boundary]):
        m = _across_mask(int(k))
        rows = np.flatnonzero(boundary & (kf == k))
        across[rows] = m[0] * U[rows] + np.einsum("k,nki->ni", m[1:], R[rows, : k + 1])
    nb_ = np.cross(along, across)
    lim = np.where(boundary[:, None], nb_, ni)
    L = np.linalg.norm(lim, axis=1)
    good = ok & (L > 0)
    lim = lim / np.where(L > 0, L, 1)[:, None]
    s = np.sign(np.einsum("ij,ij->i", lim, area_normals))
    flipped = good & (s < 0)
    nrm[good] = lim[good] * np.where(s[good] < 0, -1.0, 1.0)[:, None]
    if not positions:
        return nrm, good, boundary & good, flipped
    beta = (40.0 - (2.0 * np.cos(2 * np.pi / n_int[:, 0]) + 3) ** 2) / (64 * n_int[:, 0])
    w = 1.0 / (3.0 / (8.0 * beta) + n_int[:, 0])
    ring_sum = np.einsum("nk,nki->ni", wmask.astype(np.float64), R)
    pos = (1.0 - n_int * w[:, None]) * U + w[:, None] * ring_sum
    pos = np.where(boundary[:, None], (R[:, 0] + 4.0 * U + rk) / 6.0, pos)
    pos = np.where(good[:, None], pos, U)
    return nrm, good, boundary & good, flipped, pos


def _across_mask(k):
    """Cross-boundary limit tangent mask (v, r_0..r_k) of Loop subdivision with boundary B-spline rules."""
    m = k + 2
    S = np.zeros((m, m))
    S[0, 0], S[0, 1], S[0, k + 1] = 0.75, 0.125, 0.125
    for i in range(k + 1):
        row = 1 + i
        if i == 0 or i == k:
            S[row, 0] = S[row, row] = 0.5
        else:
            S[row, 0] = S[row, row] = 0.375
            S[row, row - 1] = S[row, row + 1] = 0.125
    w, vl = np.linalg.eig(S.T)
    w, vl = w.real, vl.real
    along = np.zeros(m)
    along[1], along[k + 1] = 1.0, -1.0
    along /= np.linalg.norm(along)
    other = np.abs(w - 1.0) > 1e-9
    vl = vl / np.linalg.norm(vl, axis=0)
    par = np.abs(along @ vl) > 1 - 1e-9
    cand = np.flatnonzero(other & ~par)
    lam = w[cand].max()
    top = cand[np.abs(w[cand] - lam) < 1e-9]
    j = top[np.argmin(np.abs(along @ vl[:, top]))]
    return vl[:, j]


def reference_table(paths):
    """How far the references are apart: the area-weighted vertex normals against the Loop limit
    normals (vertices with a limit normal, boundary ones among them, area-weighted fallbacks;
    median, 90th percentile, count beyond 10 degrees) and against the normals with Max's weights."""
    print(f"{'model':14s} {'points':>7s} {'limit':>7s} {'boundary':>8s} {'fallback':>8s} {'median':>7s} {'p90':>7s} {'>10deg':>7s} "
          f"{'Max med':>8s} {'Max p90':>8s}")
    for path in paths:
        if not path.exists():
            continue
        P, ref, _, _, lim, good, mx = mesh_reference(path, limit="all")
        U, G = _welded(path)
        nb = int(loop_limit_normals(U, G, np.ones_like(U))[2].sum())
        a = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", ref, lim)), 0.0, 1.0)))
        b = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", ref, mx)), 0.0, 1.0)))
        print(f"{path.stem:14s} {len(P):7d} {int(good.sum()):7d} {nb:8d} {int((~good).sum()):8d} {np.median(a):6.2f}d "
              f"{np.percentile(a, 90):6.2f}d {int((a > 10).sum()):7d} {np.median(b):7.2f}d {np.percentile(b, 90):7.2f}d", flush=True)


def limit_table(paths, variants=(("default", {}),)):
    """Smooth surfaces with the models' coarse sampling and exact normals: the points are the
    limit positions of the mesh vertices on the Loop limit surface, the exact normals its limit
    normals there (:func:`loop_limit_normals`). Median angle to the exact normals, count more
    than 30 degrees off and inward / disagreeing, for :func:`estimate_normals` and, for
    comparison, the area-weighted and Max-weighted normals of the mesh with its vertices moved
    to those positions (the mesh knows its connectivity; the points do not). Vertices with no
    limit normal stay in the cloud and out of the statistics."""
    print(f"{'model':14s} {'normals':>12s} {'points':>7s} {'median':>7s} {'>30deg':>7s} {'wrong sign':>10s}")
    for path in paths:
        if not path.exists():
            continue
        U, F = _welded(path)
        used = np.zeros(len(U), bool)
        used[F.ravel()] = True
        F = (np.cumsum(used) - 1)[F]
        U = U[used]

        def area_normals(X):
            return _area_normals(X, F)

        exact, good, _, _, pos = loop_limit_normals(U, F, area_normals(U), positions=True)
        good &= np.linalg.norm(area_normals(pos), axis=1) > 0
        rows = [(label, lambda kw=kw: estimate_normals(pos, **kw)) for label, kw in variants]
        rows += [("mesh area", lambda: area_normals(pos)), ("mesh Max", lambda: max_normals(pos, F))]
        for label, make in rows:
            n = make()[good]
            d = np.einsum("ij,ij->i", n, exact[good])
            ang = np.degrees(np.arccos(np.clip(np.abs(d), 0.0, 1.0)))
            print(f"{path.stem:14s} {label:>12s} {int(good.sum()):7d} {np.median(ang):6.2f}d {int((ang > 30).sum()):7d} "
                  f"{int((d < 0).sum()):10d}", flush=True)


def check_loop(paths, levels=4):
    """The exact limit normals against the area-weighted normals of the original vertices after
    ``levels`` rounds of trimesh's Loop subdivision (meshes with no edge shared by more than
    two faces: trimesh renumbers the vertices of the others). Median and largest angle, interior and boundary."""
    import trimesh.remesh

    for path in paths:
        if not path.exists():
            continue
        U, F = _welded(path)
        area_normals = _area_normals
        _, counts = np.unique(np.sort(np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1), axis=0, return_counts=True)
        if counts.max() > 2:
            print(f"{path.stem:14s} edges shared by more than 2 faces: trimesh subdivides piece by piece and renumbers; skipped")
            continue
        lim, good, bnd, _ = loop_limit_normals(U, F, area_normals(U, F))
        X, G = U, F
        for m in range(1, levels + 1):
            X, G = trimesh.remesh.subdivide_loop(X, G)
            a = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", area_normals(X, G)[: len(U)], lim)), 0.0, 1.0)))
            inner, edge = good & ~bnd, good & bnd
            line = f"{path.stem:14s} level {m}: interior median {np.median(a[inner]):.4f} max {a[inner].max():.4f} deg"
            if edge.any():
                line += f"; boundary median {np.median(a[edge]):.4f} max {a[edge].max():.4f} deg"
            print(line, flush=True)


def model_table(paths, variants=(("default", {}), ("degree=4", {"degree": 4}))):
    """One row per model and variant of :func:`estimate_normals`; ``>30deg`` counts the
    particles whose direction is more than 30 degrees off (their sign is moot: thin or
    coarsely sampled parts), ``sign ok`` the orientation among the others."""
    print(f"{'model':14s} {'normals':>9s} {'points':>7s} {'shells':>6s} {'<10deg':>7s} {'median':>7s} {'>30deg':>7s} "
          f"{'orientation':>22s} {'sign ok':>8s} {'limit med':>9s} {'>30deg':>6s} {'Max med':>7s} {'time':>7s}")
    for path in paths:
        if not path.exists():
            print(f"{path.stem:14s} (missing, skipped)")
            continue
        P, ref, closed, shells, lim, _, mx = mesh_reference(path, limit="all")
        for label, kw in variants:
            t = time.perf_counter()
            n = estimate_normals(P, **kw)
            t = time.perf_counter() - t
            d = np.einsum("ij,ij->i", n, ref)
            ang = np.degrees(np.arccos(np.clip(np.abs(d), 0.0, 1.0)))
            orient = f"{100 * np.mean(d < 0):6.2f} % inward" if closed and shells == 1 else f"{100 * np.mean(d > 0):6.2f} % agree (open)"
            sure = ang <= 30
            a_lim = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", n, lim)), 0.0, 1.0)))
            a_max = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", n, mx)), 0.0, 1.0)))
            print(f"{path.stem:14s} {label:>9s} {len(P):7d} {shells:6d} {100 * np.mean(ang < 10):6.1f}% {np.median(ang):6.2f}d "
                  f"{int((~sure).sum()):7d} {orient:>22s} {100 * np.mean(d[sure] > 0):7.2f}% {np.median(a_lim):8.2f}d "
                  f"{int((a_lim > 30).sum()):6d} {np.median(a_max):6.2f}d {t:6.2f}s", flush=True)


def random_table(paths, variants=(("default", {}),), seeds=(0, 1)):
    """Area-uniform random samples of each mesh (as many points as it has vertices, at least
    2000), against the normals of the faces sampled: median angle, particles more than 30
    degrees off, inward (closed) or disagreeing (open) normals, per seed and variant."""
    print(f"\n{'random samples':14s} {'normals':>9s} {'points':>7s} {'seed':>5s} {'median':>7s} {'>30deg':>7s} {'wrong':>6s} {'time':>7s}")
    for path in paths:
        if not path.exists():
            print(f"{path.stem:14s} (missing, skipped)")
            continue
        U, F = _welded(path)
        c = np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]])
        A = np.linalg.norm(c, axis=1)
        fn = c / np.maximum(A, 1e-300)[:, None]
        e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
        closed = bool(np.all(np.unique(e, axis=0, return_counts=True)[1] == 2))
        m = max(2000, int(np.unique(F).size))
        for seed in seeds:
            P, f = sample_triangles(U, F, m, seed)
            for label, kw in variants:
                t = time.perf_counter()
                d = np.einsum("ij,ij->i", estimate_normals(P, **kw), fn[f])
                t = time.perf_counter() - t
                ang = np.degrees(np.arccos(np.clip(np.abs(d), 0.0, 1.0)))
                wrong = int((d < 0).sum()) if closed else int((d <= 0).sum())
                print(f"{path.stem:14s} {label:>9s} {m:7d} {seed:5d} {np.median(ang):6.2f}d {int((ang > 30).sum()):7d} "
                      f"{wrong:6d} {t:6.2f}s", flush=True)


def orders(quick=False):
    cases = [
        ("sphere fibonacci", lambda n: shapes.sphere(n), (1000, 4000, 16000)),
        ("sphere poisson", lambda n: shapes.sphere(n, sampling="poisson"), (1000, 4000, 16000)),
        ("torus poisson", lambda n: shapes.torus(n), (2000, 8000, 32000)),
    ]
    variants = [("jet d2 (default)", {}), ("jet d3", {"degree": 3}), ("jet d4", {"degree": 4}), ("pca", {"method": "pca"})]
    print(f"\n{'cloud':18s} {'normals':18s} {'mean angle error (deg) at N':>40s} {'order':>6s}")
    for name, make, ns in cases:
        ns = ns[:2] if quick else ns
        clouds = [make(n) for n in ns]
        h = np.array([n**-0.5 for n in ns])
        for label, kw in variants:
            err = []
            for c in clouds:
                n = estimate_normals(c.points, **kw)
                err.append(np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, c.normals), -1.0, 1.0))).mean())
            slope = np.polyfit(np.log(h), np.log(err), 1)[0]
            print(f"{name:18s} {label:18s} {' '.join(f'{e:.2e}' for e in err):>40s} {slope:6.2f}", flush=True)


def meridian_torus(meridians=40, per=16, R=1.0, r=0.08, seed=0):
    """A thin torus on planar meridian circles of ``per`` points (a rolled lip; as in tests/test_normals.py)."""
    rng = np.random.default_rng(seed)
    phi = np.repeat((np.arange(meridians) + 0.3 * rng.random(meridians)) * 2 * np.pi / meridians, per)
    th = ((np.arange(per)[None, :] + 0.3 * rng.random((meridians, per))) * 2 * np.pi / per).ravel()
    n = np.c_[np.cos(th) * np.cos(phi), np.cos(th) * np.sin(phi), np.sin(th)]
    return np.c_[R * np.cos(phi), R * np.sin(phi), np.zeros_like(phi)] + r * n, n


def flat_ellipsoid(n=2000, thickness=1.0, seed=0):
    """A thin closed slab (:func:`manifold_sph.reference.shapes.flat_ellipsoid`): points, exact normals."""
    c = shapes.flat_ellipsoid(n, thickness, seed)
    return c.points, c.normals


def synthetic():
    clouds = [(f"thin torus seed {s}", shapes.thin_torus(seed=s)) for s in range(3)]
    clouds += [(f"ring sphere seed {s}", shapes.ring_sphere(seed=s)) for s in range(3)]
    cases = [(name, (c.points, c.normals)) for name, c in clouds]
    cases += [(f"meridian torus {s}", meridian_torus(seed=s)) for s in range(2)]
    cases += [(f"slab {t:g} sp seed {s}", flat_ellipsoid(thickness=t, seed=s)) for t in (0.5, 1.0, 2.0) for s in range(2)]
    print(f"\n{'cloud':20s} {'points':>7s} {'steps':>10s} {'median':>7s} {'>30deg':>7s} {'inward':>7s}")
    original, steep = estimate.consensus_normals, tuning.ROW_STEEP
    for name, (p, exact) in cases:
        for label in ("all", "no step 7", "no 2b"):
            if label == "no step 7":
                estimate.consensus_normals = lambda pts, nb, n, fixed=None: (n, None)
            if label == "no 2b":
                tuning.ROW_STEEP = 0
            try:
                d = np.einsum("ij,ij->i", estimate_normals(p), exact)
            finally:
                estimate.consensus_normals, tuning.ROW_STEEP = original, steep
            ang = np.degrees(np.arccos(np.clip(np.abs(d), 0.0, 1.0)))
            print(f"{name:20s} {len(p):7d} {label:>10s} {np.median(ang):6.2f}d {int((ang > 30).sum()):7d} {int((d < 0).sum()):7d}",
                  flush=True)


def _crossing_cloud(name, sampling, seed, noise):
    """Closed surfaces that pass through each other; points, exact outward normals of each surface."""
    parts = {"2 spheres": [(shapes.sphere, 4000, dict(radius=1.0)), (shapes.sphere, 2560, dict(radius=0.8, center=(1.2, 0, 0)))],
             "3 spheres": [(shapes.sphere, 4000, dict(radius=1.0)), (shapes.sphere, 2560, dict(radius=0.8, center=(1.2, 0, 0))),
                           (shapes.sphere, 1440, dict(radius=0.6, center=(0, 1.1, 0.3)))],
             "torus through sphere": [(shapes.sphere, 3000, dict(radius=0.8)),
                                      (shapes.torus, 4000, dict(R=1.0, r=0.25, center=(0.9, 0, 0)))],
             "2 unequal spheres": [(shapes.sphere, 3000, dict(radius=1.0)), (shapes.sphere, 3000, dict(radius=0.9, center=(0.9, 0.3, 0)))],
             "nested spheres": [(shapes.sphere, 4000, dict(radius=1.0)), (shapes.sphere, 1000, dict(radius=0.5, center=(0.1, 0, 0)))],
             # a head (12,000 points) with two eyes half out of it and six teeth across its surface
             "head, eyes, teeth": [(shapes.sphere, 12000, dict(radius=1.0))]
             + [(shapes.sphere, 400, dict(radius=0.18, center=(x, 0.3, np.sqrt(1 - x * x - 0.09) - 0.08))) for x in (-0.35, 0.35)]
             + [(shapes.sphere, 150, dict(radius=0.06, center=(x, -0.5, np.sqrt(1 - x * x - 0.25))))
                for x in np.linspace(-0.25, 0.25, 6)]}[name]
    clouds = [f(n, sampling=sampling, seed=seed + 10 * i, **kw) for i, (f, n, kw) in enumerate(parts)]
    P = np.vstack([c.points for c in clouds])
    spacing = np.sqrt(4 * np.pi / 4000)
    P = P + noise * spacing * np.random.default_rng(seed).normal(size=P.shape)
    return P, np.vstack([c.normals for c in clouds])


def crossing(seeds=(0, 1, 2)):
    """Closed surfaces passing through each other (the parts of artists' models, assemblies):
    normals disagreeing with each surface's own outward normal, without and with the closed
    sheets of step 4 (``tuning.SHEETS``). Nested spheres: the inner one wholly inside keeps the
    whole field's answer (inward, the inner wall of a hollow ball)."""
    print(f"\n{'crossing surfaces':22s} {'sampling':>8s} {'noise':>5s} {'points':>6s} "
          f"{'wrong, sheets off':>22s} {'wrong, on (default)':>22s}")
    for name in ("2 spheres", "3 spheres", "torus through sphere", "2 unequal spheres", "head, eyes, teeth", "nested spheres"):
        for sampling in ("random", "poisson"):
            for noise in (0.0, 0.1):
                res = {}
                for flag in (False, True):
                    tuning.SHEETS, wrong = flag, []
                    try:
                        for seed in seeds:
                            P, exact = _crossing_cloud(name, sampling, seed, noise)
                            wrong.append(int((np.einsum("ij,ij->i", estimate_normals(P), exact) < 0).sum()))
                    finally:
                        tuning.SHEETS = True
                    res[flag] = "/".join(map(str, wrong))
                print(f"{name:22s} {sampling:>8s} {noise:5.1f} {len(P):6d} {res[False]:>22s} {res[True]:>22s}", flush=True)


def noisy(paths, noises=(0.1, 0.3), seeds=(0, 1)):
    """The models' vertices with Gaussian noise of ``noise`` nearest-neighbour spacings (per
    coordinate, seeded): normals disagreeing in sign with the mesh's, with the thin-part cuts of
    step 3 (``tuning.CUT_THIN``) off and on (the default)."""
    from scipy.spatial import cKDTree

    print(f"\n{'noisy vertices':14s} {'points':>7s} " + " ".join(f"{f'{z:g} sp, seed {s}':>16s}" for z in noises for s in seeds))
    print(f"{'':14s} {'':>7s} " + " ".join(f"{'off -> on':>16s}" for _ in noises for _ in seeds))
    for path in paths:
        if not path.exists():
            print(f"{path.stem:14s} (missing, skipped)")
            continue
        P, ref, _, _ = mesh_reference(path)
        h = np.median(cKDTree(P).query(P, 2)[0][:, 1])
        cells = []
        for z in noises:
            for seed in seeds:
                Q = P + z * h * np.random.default_rng(seed).normal(size=P.shape)
                wrong = []
                for cut in (0.0, tuning.CUT_THIN):
                    saved, tuning.CUT_THIN = tuning.CUT_THIN, cut
                    try:
                        wrong.append(int((np.einsum("ij,ij->i", estimate_normals(Q), ref) < 0).sum()))
                    finally:
                        tuning.CUT_THIN = saved
                cells.append(f"{wrong[0]:>7d} -> {wrong[1]:<5d}")
        print(f"{path.stem:14s} {len(P):7d} " + " ".join(f"{c:>16s}" for c in cells), flush=True)


if __name__ == "__main__":
    if "--noisy" in sys.argv:  # the models' vertices with noise, thin-part cuts of step 3 off and on
        noisy([Path(a) for a in sys.argv[sys.argv.index("--models") + 1:] if not a.startswith("--")] if "--models" in sys.argv
              else MODELS + SCANS[:1])
        raise SystemExit
    if "--crossing" in sys.argv:  # closed surfaces passing through each other, sheets of step 4 off and on
        crossing()
        raise SystemExit
    variants = (("default", {}),) + ((("visible", {"orient": "visible"}),) if "--visible" in sys.argv else ())
    variants += (("poles", {"poles": True}),) if "--poles" in sys.argv else ()
    if "--check-loop" in sys.argv:  # the limit normals against repeated subdivision, and the two references
        check_loop(MODELS, levels=4)
        reference_table(MODELS + SCANS)
        raise SystemExit
    if "--limit" in sys.argv:  # estimated normals on the limit positions of the vertices, exact normals
        limit_table(MODELS + SCANS[:1])
        raise SystemExit
    if "--random" in sys.argv:  # area-uniform random samples of the models (and --models meshes), face normals
        paths = [Path(a) for a in sys.argv[sys.argv.index("--models") + 1:] if not a.startswith("--")] if "--models" in sys.argv else MODELS
        seeds = (0, 1)
        for a in sys.argv:  # --seeds=0-7 or --seeds=0,3,5
            if a.startswith("--seeds="):
                v = a.split("=", 1)[1]
                lo, _, hi = v.partition("-")
                seeds = tuple(range(int(lo), int(hi) + 1)) if hi else tuple(int(x) for x in v.split(","))
        random_table(paths, variants=variants, seeds=seeds)
        raise SystemExit
    if "--models" in sys.argv:  # any meshes: python benchmarks/normals.py --models a.obj b.ply ...
        model_table([Path(a) for a in sys.argv[sys.argv.index("--models") + 1:] if not a.startswith("--")], variants=variants)
        raise SystemExit
    if "--visible" in sys.argv or "--poles" in sys.argv:  # --visible / --poles: the models with orient="visible" / poles=True too
        model_table(MODELS + SCANS[:1], variants=variants)
        raise SystemExit
    quick = "--quick" in sys.argv
    model_table(MODELS + SCANS[: 1 if quick else 2])
    limit_table(MODELS + SCANS[:1])
    orders(quick)
    synthetic()
