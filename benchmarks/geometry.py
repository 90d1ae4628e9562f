"""Geometry against the peers, same points, same run: geodesics, vector heat, smoothing, curvature.

Tables (``python benchmarks/geometry.py [--only NAME[,NAME]] [--quick] [--big] [--sampled N [--loop K]]``):

``models``
    Geodesic distance on the vertices of ../shared/data/models (bare points, faces dropped)
    and on a Poisson-disk torus (R = 0.8, r = 0.2, meshed by a periodic Delaunay of its
    parameters): mean relative error against libigl's exact polyhedral geodesic on the
    mesh, from 3 random sources (seed 0), over the particles farther than 2 % of the
    bounding-box diagonal; ours (``GeodesicSolver``, wavefront and heat) and potpourri3d's
    ``PointCloudHeatSolver``; seconds for the build plus the first query, and the fastest and the
    median of 40 later queries from other random sources (seed 1), ours and potpourri3d's alternated.
``sphere``
    Unit sphere, Fibonacci and uniformly random points: relative L2 error from one source,
    fitted order, and the two-source error (the second source where ``x . x_0 = -0.2``).
``noisy``
    Geodesic distance on noisy points: the unit sphere (16,000 Fibonacci and uniformly random
    points; 4,000 with ``--quick``), the Poisson-disk torus and the model vertices, plus Gaussian
    noise of 0, 0.1, 0.2 and 0.3 spacings per coordinate (seed 0; the spacing the mean edge length
    on the meshes, ``sqrt(4 pi / N)`` on the sphere); the error against the exact distance between
    the points' clean positions (the sphere: great-circle distance between the projections; meshes:
    libigl's exact geodesic between the clean vertices, as in ``models``): the noise reading
    (``GeodesicSolver.noise``), ours with ``denoise=False`` / ``"auto"`` (the default) / ``True``,
    and potpourri3d on the same noisy points.
``vector``
    Vector heat method on the unit sphere: mean error of the transported frame vector
    against the exact parallel transport (the rotation about ``x_0 x x``), the log map's
    relative L2 error and mean absolute error, away from the antipode (0.1); then the log
    map's radius on the Poisson-disk torus against libigl's exact geodesic.
``smooth``
    Noisy samples of the models (vertices plus Gaussian noise of 0.5 spacings per
    coordinate, seed 0): mean distance to the clean mesh before and after, ours (jet,
    jet with features: the default, flow) and CGAL's ``jet_smooth_point_set`` (k = 24; from the
    ``cgal`` wheel), the clean vertices smoothed the same way (the default: the smoothing's own
    bias), and on the rocker-arm the 95th percentile distance of the vertices on a sharp edge
    (dihedral angle above 60 degrees), in spacings. With ``--sampled N``: see ``sampled`` below.
``curvature``
    Model vertices, clean and with 0.3 and 0.9 spacings of noise: Spearman rank correlation of the
    mean curvature (pointwise, ``scale="auto"``, ``scale=r``) with the mesh's cotan mean
    curvature at the vertex scale and diffused on the mesh over the scales ``r`` = 1, 2, 4, 8
    mean edge lengths (``scale=r`` against the same ``r``), and at the radius the automatic
    scale chose per vertex; beside them the noisy vertices meshed with the clean faces, their
    cotan curvature diffused over ``r`` (what knowing the connectivity gives).
``--sampled N [--loop K]`` (for ``smooth`` and ``curvature``)
    The same on ``N`` points drawn uniformly at random on each clean mesh's surface
    (``trimesh.sample.sample_surface``, seed 0), after ``K`` Loop subdivisions of the mesh (default
    0: the polyhedral mesh itself; ``K`` = 2 gives a smooth surface of the same shape). The spacing
    ``h1`` is that sample's mean distance from a point to its nearest other point; noise and
    distances are in ``h1``. Smoothing: noise of 0.5 ``h1``, mean distance to the clean (subdivided)
    mesh before and after, ours (default) and CGAL's jet smoothing (k = 24 and k = 48), the clean
    sample smoothed (bias), seconds. Curvature: noise of 0.3 and 0.9 ``h1``; the reference at each
    sample point is the mesh's cotan ``H`` diffused over ``r`` (as above) interpolated linearly
    (barycentric weights on the point's face) to the clean point it came from; Spearman
    correlation over the points whose face has no boundary or non-manifold vertex, ``scale="auto"``
    against the reference at the radius it chose per point and ``scale=r`` at ``r`` = 8 and 16 ``h1``.
``--open`` (for ``smooth``)
    Open surfaces with exact distances (a spherical cap, an open cylinder, a saddle patch), 8,000
    points uniformly random (``--quick``: 3,000, one seed), noise 0.5 ``h1``: the reduction within
    5 ``h1`` of the boundary and farther, without the rim fits (``RIM_WIDER = 1``) and with them.
``big`` (with ``--big``)
    Wavefront geodesic on a 1,048,576-point Fibonacci sphere: build, first query, peak memory.

Peers missing from the environment are skipped with a note (they come with the ``bench`` extra).
"""

from __future__ import annotations

import resource
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from manifold_sph import Surface
from manifold_sph.geometry import GeodesicSolver, VectorHeatSolver, smooth
from manifold_sph.reference import shapes
from manifold_sph.scans.io import read_mesh

MODELS = Path(__file__).resolve().parents[2] / "shared" / "data" / "models"
MODEL_NAMES = ("cow", "homer", "rocker-arm", "cheburashka", "teapot", "beetle", "alligator")
#: libigl's exact geodesic (MMP) crashes on meshes with edges of three or more faces.
NON_MANIFOLD = ("beetle",)
#: Later geodesic queries timed per model (the fastest and the median are printed).
LATER = 40


def quiet(fn, *a, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*a, **kw)


def peer(name):
    try:
        return __import__(name)
    except ImportError:
        print(f"({name} is not installed: its rows are skipped)")
        return None


def welded(path):
    """Distinct vertices used by faces, and the faces on them (degenerate ones dropped)."""
    V, F = read_mesh(str(path))
    U, inv = np.unique(V, axis=0, return_inverse=True)
    F = inv.ravel()[F]
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    used = np.zeros(len(U), bool)
    used[F.ravel()] = True
    remap = np.cumsum(used) - 1
    return U[used], remap[F].astype(np.int64)


def torus_mesh(n, R=0.8, r=0.2, seed=0):
    """Poisson-disk torus points and a triangle mesh on them (periodic Delaunay of the scaled parameters)."""
    from scipy.spatial import Delaunay

    P = shapes.torus(n, R=R, r=r, seed=seed).points
    th = np.arctan2(P[:, 1], P[:, 0])
    ph = np.arctan2(P[:, 2], np.hypot(P[:, 0], P[:, 1]) - R)
    X = np.stack([th * R, ph * r], axis=1)  # periodic with periods 2 pi R, 2 pi r
    W = np.array([2 * np.pi * R, 2 * np.pi * r])
    tiles = [(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1)]
    Y = np.concatenate([X + np.array(t) * W for t in tiles])
    T = Delaunay(Y).simplices
    centre = T // len(P) == tiles.index((0, 0))
    keep = centre.any(axis=1) & (np.ptp(Y[T][:, :, 0], axis=1) < 0.1 * W[0]) & (np.ptp(Y[T][:, :, 1], axis=1) < 0.3 * W[1])
    F = np.unique(np.sort(T[keep] % len(P), axis=1), axis=0)
    return P, F


def exact_geodesic(igl, U, F, src):
    return igl.exact_geodesic(U, F, np.array([src]), np.array([], dtype=np.int64), np.arange(len(U)), np.array([], dtype=np.int64))


def mean_rel(d, ex, P):
    diag = np.linalg.norm(P.max(0) - P.min(0))
    m = np.isfinite(ex) & (ex > 0.02 * diag)
    return float(np.mean(np.abs(d[m] - ex[m]) / ex[m]))


def timed(fn, *a, **kw):
    t = time.perf_counter()
    out = fn(*a, **kw)
    return out, time.perf_counter() - t


def models_table(quick):
    igl, pp3d = peer("igl"), peer("potpourri3d")
    if igl is None:
        return
    print("\nGeodesic distance, mean relative error against libigl's exact polyhedral geodesic (3 sources)")
    print(f"{'model':12s} {'N':>6s} {'wavefront':>10s} {'heat':>9s} {'pp3d':>9s} {'ratio':>6s} | "
          f"{'ours build+1st':>14s} {'later min/med':>15s} | {'pp3d build+1st':>14s} {'later min/med':>15s}")
    cases = [(name, MODELS / f"{name}.obj") for name in MODEL_NAMES]
    cases.append(("torus", None))
    for name, path in cases:
        if path is None:
            U, F = torus_mesh(8000 if quick else 20000)
        elif not path.exists():
            continue
        else:
            U, F = welded(path)
        if name in NON_MANIFOLD:
            print(f"{name:12s} {len(U):6d}  (no reference: libigl's exact geodesic crashes on its non-manifold edges)")
            continue
        srcs = np.random.default_rng(0).choice(len(U), 3, replace=False)
        exact = [exact_geodesic(igl, U, F, int(s)) for s in srcs]
        solver, tb = timed(quiet, GeodesicSolver, U)
        d0, t1 = timed(quiet, solver.distance, int(srcs[0]))
        rest = [timed(quiet, solver.distance, int(s)) for s in srcs[1:]]
        ours = [d0] + [r[0] for r in rest]
        later = np.mean([r[1] for r in rest])
        e_w = np.mean([mean_rel(d, e, U) for d, e in zip(ours, exact)])
        heat = quiet(GeodesicSolver, U, method="heat")
        e_h = np.mean([mean_rel(quiet(heat.distance, int(s)), e, U) for s, e in zip(srcs, exact)])
        row = f"{name:12s} {len(U):6d} {e_w:10.2e} {e_h:9.2e}"
        if pp3d is not None:
            pp, pb = timed(pp3d.PointCloudHeatSolver, U)
            p0, p1 = timed(pp.compute_distance, int(srcs[0]))
            prest = [pp.compute_distance(int(s)) for s in srcs[1:]]
            e_p = np.mean([mean_rel(d, e, U) for d, e in zip([p0] + prest, exact)])
            # later queries: LATER sources more, ours and potpourri3d's alternated (the same load on both)
            times = np.array([[timed(quiet, solver.distance, int(s))[1], timed(pp.compute_distance, int(s))[1]]
                              for s in np.random.default_rng(1).choice(len(U), LATER, replace=False)])
            fast, med = times.min(axis=0), np.median(times, axis=0)
            row += (f" {e_p:9.2e} {e_w / e_p:6.2f} | {tb + t1:14.3f} {fast[0]:7.4f}/{med[0]:7.4f} | "
                    f"{pb + p1:14.3f} {fast[1]:7.4f}/{med[1]:7.4f}")
        else:
            row += f" {'-':>9s} {'-':>6s} | {tb + t1:14.3f} {later:7.4f} |"
        print(row, flush=True)


def random_sphere(n, seed=0):
    x = np.random.default_rng(seed).standard_normal((n, 3))
    return x / np.linalg.norm(x, axis=1)[:, None]


def rel(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def sphere_table(quick):
    pp3d = peer("potpourri3d")
    sizes = (4000, 16000) if quick else (4000, 16000, 64000)
    print("\nUnit sphere: relative L2 error from one source (order), two sources (kink)")
    print(f"{'points':9s} {'N':>6s} {'wavefront':>10s} {'two-src':>9s} {'heat msph':>10s} {'two-src':>9s} {'pp3d':>9s} {'two-src':>9s}")
    errs = {}
    for kind in ("fibonacci", "random"):
        for n in sizes:
            P = shapes.sphere(n).points if kind == "fibonacci" else random_sphere(n)
            ex = np.arccos(np.clip(P @ P[0], -1, 1))
            j = int(np.argmin(np.abs(P @ P[0] + 0.2)))
            ex2 = np.minimum(ex, np.arccos(np.clip(P @ P[j], -1, 1)))
            w = quiet(GeodesicSolver, P)
            h = quiet(GeodesicSolver, quiet(Surface, P, P.copy()), method="heat")
            row = [rel(w.distance(0), ex), rel(w.distance([0, j]), ex2), rel(h.distance(0), ex), rel(h.distance([0, j]), ex2)]
            if pp3d is not None:
                pp = pp3d.PointCloudHeatSolver(P)
                row += [rel(pp.compute_distance(0), ex), rel(pp.compute_distance_multisource([0, j]), ex2)]
            errs.setdefault(kind, []).append(row)
            print(f"{kind:9s} {n:6d} " + " ".join(f"{x:9.2e} " for x in row), flush=True)
        e = np.array(errs[kind])
        orders = np.log(e[:-1] / e[1:]) / np.log(2.0)  # N x 4: h / 2
        print(f"{kind:9s} {'order':>6s} " + " ".join(f"{x:9.2f} " for x in orders.mean(axis=0)))


NOISE_LEVELS = (0.0, 0.1, 0.2, 0.3)


def noisy_table(quick):
    igl, pp3d = peer("igl"), peer("potpourri3d")
    print("\nNoisy points: geodesic error (sphere: relative L2, one source; meshes: mean relative error, 3 sources) "
          "against the clean surface's distance")
    print(f"{'cloud':12s} {'N':>6s} {'noise':>5s} {'reads':>6s} {'raw':>9s} {'auto':>9s} {'denoised':>9s} {'pp3d':>9s}")
    n_sphere = 4000 if quick else 16000
    cases = [("fibonacci", None), ("random", None), ("torus", None)]
    if igl is not None:
        cases += [(name, MODELS / f"{name}.obj") for name in MODEL_NAMES if name not in NON_MANIFOLD]
    for name, path in cases:
        if name in ("fibonacci", "random"):
            U = shapes.sphere(n_sphere).points if name == "fibonacci" else random_sphere(n_sphere, seed=1)
            h, srcs = np.sqrt(4 * np.pi / n_sphere), [0]
        else:
            if path is None:
                if igl is None:
                    continue
                U, F = torus_mesh(8000 if quick else 20000)
            elif not path.exists():
                continue
            else:
                U, F = welded(path)
            h = float(np.mean(np.linalg.norm(U[F[:, [0, 1, 2]]] - U[F[:, [1, 2, 0]]], axis=2)))
            srcs = [int(s) for s in np.random.default_rng(0).choice(len(U), 3, replace=False)]
            exact = [exact_geodesic(igl, U, F, s) for s in srcs]
        for sigma in NOISE_LEVELS:
            Q = U + sigma * h * np.random.default_rng(0).standard_normal(U.shape)
            if path is None and name != "torus":
                V = Q / np.linalg.norm(Q, axis=1)[:, None]

                def err(d, s=0, V=V):
                    return rel(d, np.arccos(np.clip(V @ V[s], -1, 1)))
            else:
                def err(d, s=0, U=U, exact=exact, srcs=srcs):
                    return mean_rel(d, exact[srcs.index(s)], U)
            row = []
            for denoise in (False, "auto", True):
                solver = quiet(GeodesicSolver, Q, denoise=denoise)
                row.append(np.mean([err(quiet(solver.distance, s), s) for s in srcs]))
                if denoise == "auto":
                    reads, auto = solver.noise, solver.denoised
            if pp3d is not None:
                pp = pp3d.PointCloudHeatSolver(Q)
                row.append(np.mean([err(pp.compute_distance(s), s) for s in srcs]))
            print(f"{name:12s} {len(U):6d} {sigma:5.2f} {reads:6.3f} " + " ".join(
                f"{x:8.2e}{'*' if k == 1 and auto else ' '}" for k, x in enumerate(row)), flush=True)
    print("(* auto smoothed the cloud)")


def rotate(f, t, a):
    c = np.einsum("nd,nd->n", f, t)
    w = np.cross(f, t)
    wa = np.cross(w, a)
    return a + wa + np.cross(w, wa) / (1 + c)[:, None]


def vector_table(quick):
    print("\nVector heat method, unit sphere (away from the antipode): transport mean |error|, log map rel L2 / mean |error|")
    for kind in ("fibonacci", "random"):
        for n in ((16000,) if quick else (16000, 40000)):
            P = shapes.sphere(n).points if kind == "fibonacci" else random_sphere(n)
            s = quiet(Surface, P, P.copy())
            (vh, tb) = timed(VectorHeatSolver, s)
            Y, tt = timed(vh.transport, 0, s.u[0])
            p = P[0]
            ex = rotate(np.broadcast_to(p, P.shape), P, np.broadcast_to(s.u[0], P.shape))
            far = np.arccos(np.clip(P @ p, -1, 1)) < np.pi - 0.1
            L, tl = timed(vh.log_map, 0)
            v = P - (P @ p)[:, None] * p
            lv = np.arccos(np.clip(P @ p, -1, 1))[:, None] * v / np.maximum(np.linalg.norm(v, axis=1), 1e-300)[:, None]
            exL = np.stack([lv @ s.u[0], lv @ s.v[0]], 1)
            print(f"{kind:9s} {n:6d} transport {np.linalg.norm(Y - ex, axis=1)[far].mean():9.2e}  log map "
                  f"{rel(L[far], exL[far]):9.2e} / {np.linalg.norm(L - exL, axis=1)[far].mean():9.2e}   "
                  f"(set-up {tb:.1f} s, transport {tt:.2f} s, log map {tl:.2f} s)", flush=True)
    igl = peer("igl")
    if igl is None or quick:
        return
    print("Log map radius against libigl's exact geodesic (mean relative error, 3 sources, points farther than 2 % of "
          "the diagonal): geodesics='heat' / 'wavefront' (default)")
    P, F = torus_mesh(20000)
    s = quiet(Surface, P)
    solvers = [quiet(VectorHeatSolver, s, geodesics=g) for g in ("heat", "wavefront")]
    errs = [[mean_rel(np.linalg.norm(quiet(vh.log_map, int(i)), axis=1), exact_geodesic(igl, P, F, int(i)), P)
             for vh in solvers] for i in np.random.default_rng(0).choice(len(P), 3, replace=False)]
    e = np.mean(errs, axis=0)
    print(f"Poisson-disk torus 20000: {e[0]:9.2e} / {e[1]:9.2e}", flush=True)


def cgal_jet_smooth(X, k):
    """CGAL's ``jet_smooth_point_set`` (degree-2 jets over ``k`` nearest points) of the points ``X``."""
    from CGAL import CGAL_Point_set_processing_3 as psp
    from CGAL.CGAL_Kernel import Point_3
    from CGAL.CGAL_Point_set_3 import Point_set_3

    ps = Point_set_3()
    for x in X:
        ps.insert(Point_3(*map(float, x)))
    psp.jet_smooth_point_set(ps, k)
    return np.array([[p.x(), p.y(), p.z()] for p in ps.points()])


def open_surface(shape, n, rng):
    """``n`` points uniformly random on an open surface: a spherical cap (polar angle up to 60 degrees),
    an open cylinder (radius 0.5, height 1.5) or the saddle ``z = (x^2 - y^2) / 2`` over the unit disk;
    with the exact distance to the surface and the distance to its boundary (along the surface)."""
    if shape == "cap":
        z, f = rng.uniform(0.5, 1.0, n), rng.uniform(0.0, 2.0 * np.pi, n)
        P = np.c_[np.sqrt(1 - z * z) * np.cos(f), np.sqrt(1 - z * z) * np.sin(f), z]
        return P, lambda X: np.abs(np.linalg.norm(X, axis=1) - 1.0), np.pi / 3 - np.arccos(z)
    if shape == "cylinder":
        f, z = rng.uniform(0.0, 2.0 * np.pi, n), rng.uniform(0.0, 1.5, n)
        return np.c_[0.5 * np.cos(f), 0.5 * np.sin(f), z], lambda X: np.abs(np.hypot(X[:, 0], X[:, 1]) - 0.5), np.minimum(z, 1.5 - z)
    x = np.zeros((0, 2))
    while len(x) < n:  # uniform in the disk, then accepted in proportion to the area element
        y = rng.uniform(-1.0, 1.0, (4 * n, 2))
        y = y[(y * y).sum(axis=1) < 1.0]
        J = np.sqrt(1.0 + (y * y).sum(axis=1))
        x = np.concatenate([x, y[rng.uniform(0.0, np.sqrt(2.0), len(y)) < J]])
    x = x[:n]

    def dist(X):
        return np.abs(X[:, 2] - 0.5 * (X[:, 0] ** 2 - X[:, 1] ** 2)) / np.sqrt(1.0 + X[:, 0] ** 2 + X[:, 1] ** 2)
    return np.c_[x, 0.5 * (x[:, 0] ** 2 - x[:, 1] ** 2)], dist, 1.0 - np.hypot(x[:, 0], x[:, 1])


def open_smooth_table(quick):
    """Open surfaces: reduction of the mean distance near the boundary and inside, without and with the rim fits."""
    from scipy.spatial import cKDTree

    from manifold_sph.geometry import smoothing

    n, seeds = (3000, (0,)) if quick else (8000, (0, 1, 2))
    print(f"\nSmoothing {n} random points on open surfaces, noise 0.5 h1, seeds {seeds}: reduction of the mean distance to the "
          "surface within 5 h1 of the boundary (rim), farther (inside) and overall; without rim fits (RIM_WIDER = 1) / default; "
          "the clean cloud's mean distance after smoothing (default), in h1")
    print(f"{'surface':9s} {'rim':>19s} {'inside':>13s} {'whole':>13s} {'clean':>8s}")
    default = smoothing.RIM_WIDER
    for shape in ("cap", "cylinder", "saddle"):
        x = np.zeros((len(seeds), 2, 3))
        bias = []
        for i, seed in enumerate(seeds):
            rng = np.random.default_rng(seed)
            P, dist, to_rim = open_surface(shape, n, rng)
            h1 = float(cKDTree(P).query(P, k=2)[0][:, 1].mean())
            noisy = P + 0.5 * h1 * rng.standard_normal(P.shape)
            near = to_rim < 5.0 * h1
            d0 = dist(noisy)
            for j, wider in enumerate((1.0, default)):
                smoothing.RIM_WIDER = wider
                try:
                    d1 = dist(quiet(smooth, noisy).points)
                finally:
                    smoothing.RIM_WIDER = default
                x[i, j] = [d0[m].mean() / d1[m].mean() for m in (near, ~near, np.ones_like(near))]
            bias.append(dist(quiet(smooth, P).points).mean() / h1)
        m = x.mean(axis=0)
        print(f"{shape:9s} {m[0, 0]:5.2f} / {m[1, 0]:5.2f} ({x[:, 1, 0].min():.2f}-{x[:, 1, 0].max():.2f}) {m[0, 1]:5.2f} / {m[1, 1]:5.2f}"
              f" {m[0, 2]:5.2f} / {m[1, 2]:5.2f} {max(bias):8.1e}", flush=True)


def smooth_table(quick, sampled=None, loop=0):
    if "--open" in sys.argv:
        return open_smooth_table(quick)
    igl = peer("igl")
    if igl is None:
        return
    if sampled:
        return sampled_smooth_table(igl, sampled, loop, quick)
    try:
        from CGAL import CGAL_Point_set_processing_3 as psp
    except ImportError:
        psp = None
        print("(CGAL is not installed: its column is skipped)")
    print("\nSmoothing noisy model vertices (0.5 spacings of noise): mean distance to the clean mesh, in spacings")
    print(f"{'model':12s} {'noisy':>7s} {'jet':>7s} {'jet+feat':>8s} {'flow':>7s} {'CGAL jet':>8s} {'x less':>6s} "
          f"{'clean':>6s} | edge p95: {'noisy':>6s} {'jet':>6s} {'jet+feat':>8s} {'CGAL':>6s}")
    for name in MODEL_NAMES if not quick else ("homer", "rocker-arm"):
        path = MODELS / f"{name}.obj"
        if not path.exists():
            continue
        U, F = welded(path)
        h = float(np.mean(np.linalg.norm(U[F] - U[np.roll(F, 1, axis=1)], axis=2)))  # mean edge length
        noisy = U + 0.5 * h * np.random.default_rng(0).standard_normal(U.shape)

        def dist(X, U=U, F=F, h=h):
            return np.sqrt(igl.point_mesh_squared_distance(X, U, F)[0]) / h

        outs = {
            "jet": quiet(smooth, noisy, features=False).points,
            "feat": quiet(smooth, noisy).points,
            "flow": quiet(smooth, noisy, method="flow").points,
        }
        if psp is not None:
            outs["cgal"] = cgal_jet_smooth(noisy, 24)
        row = f"{name:12s} {dist(noisy).mean():7.3f} {dist(outs['jet']).mean():7.3f} {dist(outs['feat']).mean():8.3f} " \
              f"{dist(outs['flow']).mean():7.3f} " + (f"{dist(outs['cgal']).mean():8.3f}" if "cgal" in outs else f"{'-':>8s}") \
            + f" {dist(noisy).mean() / dist(outs['feat']).mean():6.2f} {dist(quiet(smooth, U).points).mean():6.3f}"
        if name == "rocker-arm":
            fn = np.cross(U[F[:, 1]] - U[F[:, 0]], U[F[:, 2]] - U[F[:, 0]])
            fn /= np.linalg.norm(fn, axis=1)[:, None]
            e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
            face = np.tile(np.arange(len(F)), 3)  # the face of each edge, in the order of e
            order = np.lexsort((e[:, 1], e[:, 0]))
            es, fs = e[order], face[order]
            same = np.all(es[1:] == es[:-1], axis=1)
            sharp_v = set()
            for k in np.flatnonzero(same):
                if fn[fs[k]] @ fn[fs[k + 1]] < np.cos(np.radians(60)):
                    sharp_v.update(es[k].tolist())
            sharp = np.zeros(len(U), bool)
            sharp[list(sharp_v)] = True
            row += " | " + " ".join(f"{np.percentile(dist(X)[sharp], 95):6.2f}" for X in (noisy, outs["jet"], outs["feat"])) \
                + (f" {np.percentile(dist(outs['cgal'])[sharp], 95):6.2f}" if "cgal" in outs else "")
        print(row, flush=True)


def sampled_surface(name, n, loop=0, seed=0):
    """The model's mesh (``loop`` Loop subdivisions of its welded vertices and faces), ``n`` points drawn
    uniformly at random on it, the face of each point and its barycentric coordinates there, and the
    sample's spacing ``h1`` (mean distance to the nearest other point)."""
    import trimesh
    from scipy.spatial import cKDTree

    U, F = welded(MODELS / f"{name}.obj")
    if loop:
        U, F = trimesh.remesh.subdivide_loop(U, F, iterations=loop)
        U, F = np.asarray(U, dtype=float), np.asarray(F, dtype=np.int64)
    P, face = trimesh.sample.sample_surface(trimesh.Trimesh(U, F, process=False), n, seed=seed)
    P = np.asarray(P, dtype=float)
    bary = trimesh.triangles.points_to_barycentric(U[F[face]], P)
    h1 = float(cKDTree(P).query(P, k=2)[0][:, 1].mean())
    return U, F, P, face, bary, h1


SAMPLED_MODELS = ("cow", "homer", "rocker-arm", "cheburashka", "teapot", "beetle", "alligator")


def sampled_smooth_table(igl, n, loop, quick):
    from manifold_sph.geometry.jets import mean_spacing

    try:
        from CGAL import CGAL_Point_set_processing_3  # noqa: F401
        cgal = True
    except ImportError:
        cgal = False
        print("(CGAL is not installed: its columns are skipped)")
    print(f"\nSmoothing {n} random points on each mesh ({loop} Loop subdivisions), Gaussian noise of 0.5 h1 per coordinate "
          "(h1: the sample's mean nearest-neighbour distance): mean distance to the clean mesh, in h1")
    print(f"{'model':12s} {'h/h1':>5s} {'noisy':>7s} {'ours':>7s} {'CGAL24':>7s} {'CGAL48':>7s} {'x ours':>6s} "
          f"{'x CGAL':>6s} {'clean':>6s} {'s ours':>6s} {'s CGAL':>6s}")
    for name in SAMPLED_MODELS if not quick else ("homer",):
        if not (MODELS / f"{name}.obj").exists():
            continue
        U, F, P, _, _, h1 = sampled_surface(name, n, loop)
        noisy = P + 0.5 * h1 * np.random.default_rng(0).standard_normal(P.shape)

        def dist(X, U=U, F=F, h1=h1):
            return float(np.mean(np.sqrt(igl.point_mesh_squared_distance(X, U, F)[0]))) / h1

        ours, t_ours = timed(quiet, smooth, noisy)
        before = dist(noisy)
        row = f"{name:12s} {mean_spacing(P) / h1:5.2f} {before:7.3f} {dist(ours.points):7.3f}"
        if cgal:
            c24, t_cgal = timed(cgal_jet_smooth, noisy, 24)
            c24, c48 = dist(c24), dist(cgal_jet_smooth(noisy, 48))
            row += f" {c24:7.3f} {c48:7.3f}"
        else:
            c24 = c48 = t_cgal = np.nan
            row += f" {'-':>7s} {'-':>7s}"
        row += (f" {before / dist(ours.points):6.2f} {before / min(c24, c48):6.2f} {dist(quiet(smooth, P).points):6.3f}"
                f" {t_ours:6.1f} {t_cgal:6.1f}")
        print(row, flush=True)


def sampled_curvature_table(igl, n, loop, quick):
    from scipy.stats import spearmanr

    from manifold_sph.geometry import curvature_scale

    scales = (8, 16)  # scale=r, in h1
    print(f"\nMean curvature of {n} random points on each mesh ({loop} Loop subdivisions), clean and with Gaussian noise of "
          f"0.3 and 0.9 h1 (h1: the sample's mean nearest-neighbour distance): Spearman correlation with the mesh's cotan H "
          "diffused over r, interpolated to the points; 'auto' at the radius it chose per point, 'r=..' scale=r matched")
    print(f"{'model':12s} {'input':6s} {'auto':>6s} " + " ".join(f"{'r=' + str(r) + 'h1':>7s}" for r in scales)
          + f" {'auto r (h1) median':>18s} {'misor.':>7s} {'s':>6s}")
    for name in ("cow", "homer", "cheburashka", "rocker-arm", "teapot", "beetle") if not quick else ("homer",):
        if not (MODELS / f"{name}.obj").exists():
            continue
        U, F, P, face, bary, h1 = sampled_surface(name, n, loop)
        H0, m, Nm = cotan_mean_curvature(igl, U, F)
        keep = np.all(interior(F, len(U))[F[face]], axis=1) & np.all(m[F[face]] > 0, axis=1)
        Np = np.einsum("nk,nkd->nd", bary, Nm[F[face]])
        cache = {}

        def ref(r, U=U, F=F, m=m, H0=H0, face=face, bary=bary, cache=cache):
            key = round(r / h1, 6)
            if key not in cache:
                cache[key] = np.einsum("nk,nk->n", bary, heat_smoothed(igl, U, F, m, H0, r)[F[face]])
            return cache[key]

        def rho(a, b, keep=keep):
            return spearmanr(a[keep], b[keep])[0]

        gauss = np.random.default_rng(0).standard_normal(P.shape)
        for label, X in [("clean", P)] + [(f"{a}h1", P + a * h1 * gauss) for a in CURVATURE_NOISE]:
            t0 = time.perf_counter()
            s = quiet(Surface, X)
            side = np.sign(np.einsum("nd,nd->n", s.normals, Np))
            auto = quiet(s.mean_curvature, scale="auto") * side
            radii = curvature_scale(s)
            own = np.empty(len(P))
            for r in np.unique(radii):
                at = radii == r
                own[at] = ref(r)[at]
            matched = [rho(quiet(s.mean_curvature, scale=r * h1) * side, ref(r * h1)) for r in scales]
            print(f"{name:12s} {label:6s} {rho(auto, own):6.2f} " + " ".join(f"{v:7.2f}" for v in matched)
                  + f" {np.median(radii) / h1:18.1f} {np.mean(side[keep] < 0):7.3f} {time.perf_counter() - t0:6.1f}",
                  flush=True)


def cotan_mean_curvature(igl, U, F):
    """The mesh's mean curvature at each vertex (cotan Laplacian of the coordinates on the Voronoi areas,
    along libigl's area-weighted vertex normals), the Voronoi areas and those normals."""
    m = igl.massmatrix(U, F, igl.MASSMATRIX_TYPE_VORONOI).diagonal()
    Hn = -0.5 * (igl.cotmatrix(U, F) @ U) / np.maximum(m, 1e-300)[:, None]
    N = igl.per_vertex_normals(U, F)
    return np.einsum("nd,nd->n", Hn, N), m, N


def heat_smoothed(igl, U, F, m, f, r, steps=4):
    """``f`` diffused on the mesh (cotan stiffness, Voronoi mass) for the time ``r^2 / 16`` in ``steps``
    implicit steps: the heat kernel ``exp(-(2 d / r)^2)``, the weights of the fits at scale ``r``."""
    from scipy.sparse import diags
    from scipy.sparse.linalg import factorized

    M = diags(m)
    solve = factorized((M - (r * r / 16 / steps) * igl.cotmatrix(U, F)).tocsc())
    for _ in range(steps):
        f = solve(M @ f)
    return f


def interior(F, n):
    """Vertices on no boundary edge and no non-manifold edge (each edge in exactly two faces)."""
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    u, c = np.unique(e, axis=0, return_counts=True)
    keep = np.ones(n, bool)
    keep[u[c != 2].ravel()] = False
    return keep


CURVATURE_SCALES = (1, 2, 4, 8)  # reference scales r, in mean edge lengths
CURVATURE_NOISE = (0.3, 0.9)  # Gaussian noise per coordinate, in mean edge lengths


def opposite_distance(U, N, k=128):
    """Distance from each vertex to the nearest vertex whose normal faces the other way (``n_j . n_i < 0``),
    among its ``k`` nearest (the ``k``-th distance where none is)."""
    from scipy.spatial import cKDTree

    d, idx = cKDTree(U).query(U, k=min(k, len(U)))
    away = np.einsum("nkd,nd->nk", N[idx], N) < 0
    return np.where(away.any(axis=1), d[np.arange(len(U)), np.argmax(away, axis=1)], d[:, -1])


def curvature_table(quick, sampled=None, loop=0):
    igl = peer("igl")
    if igl is None:
        return
    if sampled:
        return sampled_curvature_table(igl, sampled, loop, quick)
    from scipy.stats import spearmanr

    from manifold_sph.geometry import curvature_scale

    print("\nMean curvature of the model vertices (bare points), clean and with Gaussian noise of 0.3 and 0.9 spacings h "
          "(mean edge length) per coordinate:\nSpearman correlation over the interior vertices with the mesh's curvature: 'vertex' the "
          "cotan H at each vertex (the scale of its one-ring), 'r=2h' ... that H diffused on the mesh over the scale r "
          "(heat kernel exp(-(2d/r)^2)), 'own r' at the radius scale='auto' chose per vertex. 'scale=r' is ours at the "
          "column's r (matched). Our H is signed by our normals\nagainst the mesh's; 'misor.' the share of our normals "
          "against the mesh's, 'user' the auto estimate with its own sign against 'vertex'. 'noisy mesh': the mesh's faces on "
          "the noisy vertices,\nits cotan H diffused over r (what knowing the connectivity gives).")
    cols = ["vertex"] + [f"r={r}h" for r in CURVATURE_SCALES] + ["own r"]
    print(f"{'model':12s} {'input':6s} {'estimate':10s} " + " ".join(f"{c:>7s}" for c in cols) + f" {'misor.':>7s} {'user':>6s}")
    names = ("cow", "homer", "cheburashka", "rocker-arm", "teapot", "beetle") if not quick else ("cow", "homer")
    for name in names:
        path = MODELS / f"{name}.obj"
        if not path.exists():
            continue
        U, F = welded(path)
        H0, m, Nm = cotan_mean_curvature(igl, U, F)
        keep = interior(F, len(U)) & (m > 0)
        h = float(np.mean(np.linalg.norm(U[F] - U[np.roll(F, 1, axis=1)], axis=2)))  # mean edge length
        refs = [heat_smoothed(igl, U, F, m, H0, r * h) for r in CURVATURE_SCALES]
        gauss = np.random.default_rng(0).standard_normal(U.shape)
        inputs = [("clean", U)] + [(f"{a}h", U + a * h * gauss) for a in CURVATURE_NOISE]
        thick = opposite_distance(U, Nm) / h

        def rho(a, b, keep=keep):
            return spearmanr(a[keep], b[keep])[0]

        print(f"{name}: {len(U)} vertices; distance to the nearest vertex facing the other way (a thin part's far "
              f"side), in h: median {np.median(thick[keep]):.1f}, below 8 for {np.mean(thick[keep] < 8):.0%} of them; "
              "the vertex H against itself at r = " + ", ".join(f"{r}h {rho(H0, ref):.2f}" for r, ref in zip(CURVATURE_SCALES, refs)))

        global_sign = 1.0 if rho(quiet(Surface, U).mean_curvature(), H0) >= 0 else -1.0
        for label, P in inputs:
            s = quiet(Surface, P)
            side = np.sign(np.einsum("nd,nd->n", s.normals, Nm))
            auto = quiet(s.mean_curvature, scale="auto")
            radii = curvature_scale(s)
            ladder = np.unique(radii)
            own = np.empty(len(U))
            for r in ladder:
                at = radii == r
                own[at] = heat_smoothed(igl, U, F, m, H0, r)[at]
            misor = f"{np.mean(side[keep] < 0):7.3f}"
            user = f"{rho(global_sign * auto, H0):6.2f}"
            rows = [("pointwise", quiet(s.mean_curvature) * side, None), ("scale=auto", auto * side, own)]
            for est, H, own_ref in rows:
                vals = [rho(H, H0)] + [rho(H, ref) for ref in refs] + [rho(H, own_ref) if own_ref is not None else np.nan]
                print(f"{name:12s} {label:6s} {est:10s} " + " ".join(f"{v:7.2f}" for v in vals)
                      + f" {misor} {user if est == 'scale=auto' else '':>6s}", flush=True)
            matched = [rho(quiet(s.mean_curvature, scale=r * h) * side, ref) for r, ref in zip(CURVATURE_SCALES, refs)]
            print(f"{name:12s} {label:6s} {'scale=r':10s} {'':>7s} " + " ".join(f"{v:7.2f}" for v in matched), flush=True)
            if P is not U:  # the mesh on the noisy vertices (faces kept), its cotan H diffused over r: no search, no normals
                Hm, mm, _ = cotan_mean_curvature(igl, P, F)
                mm = np.maximum(mm, 1e-300)
                mesh = [rho(heat_smoothed(igl, P, F, mm, np.nan_to_num(Hm), r * h), ref) for r, ref in zip(CURVATURE_SCALES, refs)]
                print(f"{name:12s} {label:6s} {'noisy mesh':10s} {'':>7s} " + " ".join(f"{v:7.2f}" for v in mesh), flush=True)


def big_table():
    n = 1 << 20
    P = shapes.sphere(n).points
    c0 = time.process_time()
    solver, tb = timed(GeodesicSolver, P)
    d, tq = timed(solver.distance, 0)
    cpu = time.process_time() - c0
    _, tq2 = timed(solver.distance, 777)
    ex = np.arccos(np.clip(P @ P[0], -1, 1))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    print(f"\nFibonacci sphere N = {n}: wavefront build {tb:.1f} s, first query {tq:.1f} s (CPU of both, all threads: "
          f"{cpu:.1f} s), a later query {tq2:.1f} s; rel L2 {rel(d, ex):.2e}; peak memory of the process {peak:.2f} GB")


TABLES = {"models": models_table, "sphere": sphere_table, "noisy": noisy_table, "vector": vector_table, "smooth": smooth_table,
          "curvature": curvature_table}

if __name__ == "__main__":
    quick = "--quick" in sys.argv
    only = None
    if "--only" in sys.argv:
        only = sys.argv[sys.argv.index("--only") + 1].split(",")
    if "--big" in sys.argv:
        big_table()
        if only is None:
            sys.exit(0)
    sampled = int(sys.argv[sys.argv.index("--sampled") + 1]) if "--sampled" in sys.argv else None
    loop = int(sys.argv[sys.argv.index("--loop") + 1]) if "--loop" in sys.argv else 0
    for name, fn in TABLES.items():
        if only is None or name in only:
            fn(quick, sampled, loop) if name in ("smooth", "curvature") else fn(quick)
